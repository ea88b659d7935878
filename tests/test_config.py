"""The run configuration (bigcbf.config): loading, validation with file and field, the bench key over all of it,
and the Python API that the command line calls."""
from __future__ import annotations

import dataclasses

import pytest

import bigcbf
from bigcbf.bench.tasks import params_key, params_toml
from bigcbf.cli import main
from bigcbf.config import RunConfig, config_from_toml, config_toml, load_run_config
from bigcbf.control.baselines import DwaParams
from bigcbf.errors import UserError
from bigcbf.params.stack import SIMULATION, default_stack_params


def write(tmp_path, text, name="run.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_tables_reach_their_dataclasses_and_defaults_stay(tmp_path):
    p = write(tmp_path, "[stack]\nalpha_per_s = 1.2\n[stack.uncertainty]\nkappa_img = 0.9\n"
                        "[perception]\ngate_chi2 = 8.0\n[pedestrians]\nA_robot_mps2 = 1.5\n[methods.dwa]\nn_xy = 7\n")
    from bigcbf.config import untuned
    c = load_run_config(p, base=untuned())     # over the authors' defaults (a shipped tuned file sets dwa's weights)
    assert c.stack.alpha_per_s == 1.2 and c.stack.uncertainty.kappa_img == 0.9
    assert c.stack.T_C_s == SIMULATION.T_C_s and c.stack.uncertainty.d0_m == SIMULATION.uncertainty.d0_m
    assert c.perception.gate_chi2 == 8.0 and c.pedestrians.A_robot_mps2 == 1.5
    assert c.method_params("dwa") == DwaParams(n_xy=7) and c.method_params("apf") is not None
    assert c.method_params("big-cbf") is None
    back = config_from_toml(config_toml(c))
    assert back == RunConfig(c.stack, c.perception, c.pedestrians, back.methods, method_stacks=c.method_stacks)
    assert config_toml(config_from_toml(config_toml(c))) == config_toml(c)         # a fixed point


def test_bench_key_covers_the_whole_configuration(tmp_path):
    key = lambda c: params_key(params_toml(c), "lidar")                           # noqa: E731
    base = key(RunConfig())
    assert key(default_stack_params()) == base          # StackParams = the default configuration with them
    assert key(SIMULATION) != base                      # the default stack is Table I with the X3's calibrated profile
    assert key(load_run_config(write(tmp_path, "[methods.dwa]\nn_xy = 20\n"))) == base   # an explicit default
    changed = {
        "stack": "[stack]\nalpha_per_s = 1.4\n", "perception": "[perception]\ngate_chi2 = 8.0\n",
        "pedestrians": "[pedestrians]\nB_m = 0.25\n", "dwa": "[methods.dwa]\nn_xy = 7\n",
        "mppi": "[methods.mppi]\nsamples = 256\n",
    }
    keys = {name: key(load_run_config(write(tmp_path, text, f"{name}.toml"))) for name, text in changed.items()}
    assert base not in keys.values() and len(set(keys.values())) == len(keys)


@pytest.mark.parametrize("text, field, message", [
    ("[lidar]\nn_beams = 90\n", "lidar", "unknown table"),
    ("[stack]\nalpha = 1.0\n", "stack.alpha", "unknown key"),
    ("[stack.uncertainty]\nbeta = 'x'\n", "stack.uncertainty.beta", "expected a number"),
    ("[perception]\nmax_tracks = 1.5\n", "perception.max_tracks", "expected an integer"),
    ("[pedestrians]\nanisotropy = 2.0\n", "pedestrians.anisotropy", "anisotropy must be in [0, 1]"),
    ("[methods.dwa]\nn_xyz = 3\n", "methods.dwa.n_xyz", "unknown key"),
    ("[methods.mppi]\nsamples = 1\n", "methods.mppi.samples", "samples must be >= 2"),
    ("[methods.big-cbf]\nN = 3\n", "methods.big-cbf", "has no parameters of its own"),
    ("[methods.nope]\nx = 1\n", "methods.nope", "unknown method 'nope'"),
    ("stack = 1\n", "stack", "expected a table"),
])
def test_mistakes_name_the_file_and_the_field(tmp_path, capsys, text, field, message):
    p = write(tmp_path, text)
    with pytest.raises(UserError) as err:
        load_run_config(p)
    assert err.value.file == str(p) and err.value.field == field and message in str(err.value)
    assert main(["run", "single_person_crossing", "--config", str(p)]) == 2
    out = capsys.readouterr().err.strip().splitlines()
    assert len(out) == 1 and str(p) in out[0] and f"field '{field}'" in out[0]


def test_profile_overlays_the_configurations_stack(tmp_path):
    cfg = write(tmp_path, "[stack]\nalpha_per_s = 1.2\n[stack.uncertainty]\ntau95_s = 0.2\n")
    prof = write(tmp_path, "[uncertainty]\ntau95_s = 0.3\n", "profile.toml")
    c = bigcbf.load_config(cfg, prof)
    assert c.stack.alpha_per_s == 1.2 and c.stack.uncertainty.tau95_s == 0.3


def test_api_run_episode_is_the_episode_and_the_cli(tmp_path, capsys):
    import json

    from bigcbf.episode import DETERMINISTIC_KEYS, Episode, EpisodeResult
    from bigcbf.scenario import load_scenario

    cfg = write(tmp_path, "[methods.apf]\nk_att_per_s = 0.8\n")
    res = bigcbf.run_episode("single_person_crossing", "apf", seed=2, config=cfg, time_limit_s=3.0,
                             log=tmp_path / "a.mcap")
    assert isinstance(res, EpisodeResult) and (tmp_path / "a.mcap").stat().st_size > 0
    ref = Episode.from_config(load_scenario("single_person_crossing", 2), "apf", 2, load_run_config(cfg),
                              time_limit_s=3.0).run()
    assert {k: getattr(res, k) for k in DETERMINISTIC_KEYS} == {k: getattr(ref, k) for k in DETERMINISTIC_KEYS}
    default = bigcbf.run_episode("single_person_crossing", "apf", seed=2, time_limit_s=3.0)
    assert default.final_goal_dist_m != res.final_goal_dist_m          # the configuration reached the planner
    assert set(bigcbf.scenarios()) >= {"crowd_crossing", "required_sidestepping"}
    assert bigcbf.methods()["big-cbf"] == "built-in"
    with pytest.raises(UserError, match="unknown method"):
        bigcbf.run_episode("single_person_crossing", "nope")
    assert main(["run", "single_person_crossing", "--method", "apf", "--seed", "2", "--config", str(cfg),
                 "--log", str(tmp_path / "b.mcap")]) == 0
    assert f"wrote {tmp_path / 'b.mcap'}" in capsys.readouterr().out


def test_api_run_bench_returns_its_outcome(tmp_path):
    from bigcbf.bench.runner import BenchOutcome
    from bigcbf.scenario import scenario_files

    text = scenario_files()["corridor_meeting"].read_text().replace("time_limit_s = ", "time_limit_s = 2.0 #", 1)
    scene = write(tmp_path, text, "corridor_short.toml")
    out = bigcbf.run_bench(tmp_path / "b", methods=["cbf-only"], scenarios=[scene], seeds=[0, 1], workers=1)
    assert isinstance(out, BenchOutcome) and out.total == 2 and out.ran == 2 and out.errors == 0
    assert out.summary["methods"]["cbf-only"]["episodes"] == 2
    again = bigcbf.run_bench(tmp_path / "b", methods=["cbf-only"], scenarios=[scene], seeds=[0, 1], workers=1)
    assert again.ran == 0 and again.already_done == 2


def test_version_and_methods_subcommand(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"bigcbf {bigcbf.__version__}"
    assert main(["methods"]) == 0
    out = capsys.readouterr().out
    assert "dwa" in out and "[methods.dwa] (DwaParams)" in out and "package.module:Class" in out


def test_config_dataclass_is_typed():
    c = RunConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.stack = SIMULATION
