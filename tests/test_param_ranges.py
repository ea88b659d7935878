"""Issue 21, item 2: every parameter has a documented physical range, every episode a resource bound (bigcbf/cost.py),
every file a size cap. Each finding of the independent test has a case here; the refusals come before any work, so
every case is fast."""
from __future__ import annotations

import dataclasses
import time
import typing

import pytest

from bigcbf import cost
from bigcbf.cli import main
from bigcbf.config import RunConfig, load_run_config
from bigcbf.control.baselines.dwa import DwaParams
from bigcbf.control.baselines.mppi import MppiParams
from bigcbf.control.methods import METHODS, method_params_type
from bigcbf.episode import Episode
from bigcbf.errors import UserError
from bigcbf.params.checks import field_range
from bigcbf.params.perception import PerceptionParams
from bigcbf.params.robot import RobotProfile
from bigcbf.params.stack import StackParams
from bigcbf.scenario import load_scenario, parse_scenario, scenario_files
from bigcbf.sim.pedestrians import SocialForceParams

BASE = ('name = "ranges"\ndescription = "a room"\ntime_limit_s = 4.0\n[robot]\nstart = [-2.0, 0.0, 0.0]\n'
        'goal = [2.0, 0.0]\n')


def write(tmp_path, text, name="f.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def one_line_error(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


# --- the findings: each refused at load time, naming the file and the field -----------------------------------------

@pytest.mark.parametrize("table, field", [
    ("[methods.mppi]\nsamples = 1000000000\n", "methods.mppi.samples"),
    ("[methods.mppi]\niterations = 1000000000\n", "methods.mppi.iterations"),
    ("[methods.dwa]\nn_xy = 100000\n", "methods.dwa.n_xy"),
    ("[stack]\nN = 100000\n", "stack.N"),
    ("[perception]\nwall_max_points = 1000000\n", "perception.wall_max_points"),
    ("[pedestrians]\ntau_s = 1e6\n", "pedestrians.tau_s"),
])
def test_run_configuration_values_out_of_range_are_one_line_errors(tmp_path, capsys, table, field):
    p = write(tmp_path, table)
    with pytest.raises(UserError) as err:
        load_run_config(p)
    assert err.value.file == str(p) and err.value.field == field and "must be" in err.value.message
    t0 = time.perf_counter()
    line = one_line_error(capsys, ["run", "single_person_crossing", "--config", str(p), "--time-limit", "2"])
    assert str(p) in line and f"field '{field}'" in line and time.perf_counter() - t0 < 5


@pytest.mark.parametrize("lidar, field", [("rate_hz = 300.0", "rate_hz"), ("rate_hz = 1e9", "rate_hz"),
                                          ("n_beams = 1000000000", "n_beams"), ("range_max_m = 1e6", "range_max_m")])
def test_lidar_out_of_range_in_a_scenario_names_the_field(tmp_path, lidar, field):
    p = write(tmp_path, BASE + f"[robot_profile.lidar]\n{lidar}\n")
    with pytest.raises(UserError) as err:
        load_scenario(p, 0)
    assert err.value.file == str(p) and err.value.field == f"robot_profile.lidar.{field}"


def test_the_python_api_refuses_the_same_values():
    for make in (lambda: MppiParams(samples=10 ** 9), lambda: MppiParams(iterations=10 ** 9),
                 lambda: DwaParams(n_xy=10 ** 5), lambda: StackParams(N=10 ** 6),
                 lambda: RobotProfile().merged(lidar=dataclasses.replace(RobotProfile().lidar, rate_hz=300.0))):
        with pytest.raises(ValueError, match="must be"):
            make()


def test_the_highest_lidar_rate_scans_every_few_physics_steps():
    """rate_hz above 250 made the scan period 0 physics steps (a division by zero): the range stops at 100 Hz and the
    period is at least one step anyway."""
    from bigcbf.sim.lidar import LidarConfig
    rng = field_range(next(f for f in dataclasses.fields(LidarConfig) if f.name == "rate_hz"))
    assert rng.hi <= 250
    assert LidarConfig(rate_hz=rng.hi).steps_per_scan(0.002) >= 1
    assert LidarConfig(rate_hz=10.0).steps_per_scan(0.002) == 50
    sc = parse_scenario(BASE + f"[robot_profile.lidar]\nrate_hz = {rng.hi}\n", "fast_lidar.toml")
    res = Episode(sc, "cbf-only", 0, time_limit_s=0.2).run()        # a real (short) episode at the highest rate
    assert res.sim_time_s == pytest.approx(0.2, abs=0.011) and not res.collision


def test_dev_zero_as_a_configuration_is_refused_fast(capsys):
    t0 = time.perf_counter()
    line = one_line_error(capsys, ["run", "single_person_crossing", "--config", "/dev/zero"])
    assert "/dev/zero" in line and "bytes" in line and time.perf_counter() - t0 < 5


def test_a_file_over_the_cap_is_refused_and_one_under_it_loads(tmp_path):
    from bigcbf.params.toml_io import MAX_TOML_BYTES, load_toml
    big = write(tmp_path, "# " + "x" * MAX_TOML_BYTES + "\n", "big.toml")
    with pytest.raises(UserError, match="bytes"):
        load_toml(big)
    ok = write(tmp_path, "# " + "x" * (MAX_TOML_BYTES - 100) + "\na = 1\n", "ok.toml")
    assert load_toml(ok) == {"a": 1}


def test_replay_window_has_a_range(capsys, tmp_path):
    from twin.replay import MAX_WINDOW_S, MIN_WINDOW_S, ReplayOptions

    from bigcbf.cli import replay as cli_replay
    assert (cli_replay.MIN_WINDOW_S, cli_replay.MAX_WINDOW_S) == (MIN_WINDOW_S, MAX_WINDOW_S)
    line = one_line_error(capsys, ["replay", str(tmp_path / "x.bag"), "--window", "1e-300"])
    assert "--window" in line
    with pytest.raises(ValueError, match="window_s"):
        ReplayOptions(window_s=1e-300)


# --- the cost bound ---------------------------------------------------------------------------------------------

def _crowded(n_walls: int, n_walkers: int, time_limit_s: float) -> str:
    text = BASE.replace("time_limit_s = 4.0", f"time_limit_s = {time_limit_s}")
    for i in range(n_walls):
        x, y = -20 + (i % 40), 20 + 0.5 * (i // 40)
        text += f"[[walls]]\nstart = [{x}, {y}]\nend = [{x + 0.5}, {y}]\n"
    for k in range(n_walkers):
        x, y = -20 + (k % 20) * 2.0, -10 - 2.0 * (k // 20)
        text += (f'[[pedestrians]]\nname = "w{k}"\nwaypoints = [[{x}, {y}], [{x}, {y - 1.5}]]\nspeed_mps = 1.0\n'
                 "loop = true\n")
    return text


def test_the_documented_maxima_together_are_refused_before_the_episode_is_built(tmp_path, capsys):
    p = write(tmp_path, _crowded(1000, 200, 600.0), "maxima.toml")
    sc = load_scenario(p, 0)
    t0 = time.perf_counter()
    with pytest.raises(UserError) as err:
        Episode(sc, "big-cbf", 0)
    assert time.perf_counter() - t0 < 1.0                 # refused before MuJoCo compiles anything
    msg = str(err.value)
    assert str(p) in msg and "walkers" in msg and "pedestrians" in msg and "\n" not in msg
    assert cost.episode_cost(sc, "big-cbf", StackParams()).total > cost.MAX_EPISODE_UNITS
    # the same scene with a short time limit is fine
    assert cost.episode_cost(sc, "big-cbf", StackParams(), time_limit_s=30.0).total < cost.MAX_EPISODE_UNITS
    line = one_line_error(capsys, ["run", str(p)])
    assert "units" in line


def test_extreme_method_parameters_within_their_ranges_are_refused_by_the_bound(tmp_path, capsys):
    sc = load_scenario("single_person_crossing", 0)
    cfg = RunConfig(methods={"mppi": MppiParams(samples=20000, iterations=100)})
    with pytest.raises(UserError, match="planner"):
        Episode.from_config(sc, "mppi", 0, cfg)
    p = write(tmp_path, "[methods.dwa]\nn_xy = 101\nn_wz = 101\n")
    line = one_line_error(capsys, ["run", "single_person_crossing", "--method", "dwa", "--config", str(p)])
    assert "n_xy" in line and "units" in line


def test_every_shipped_scene_and_generated_world_is_far_below_the_bound():
    from bigcbf.worlds import FAMILIES, generate
    cfg = RunConfig()
    worst = 0.0
    scenes = [load_scenario(path, 0) for path in scenario_files().values()]
    scenes += [parse_scenario(generate(f, s).toml, f"{f}_{s}.toml") for f in FAMILIES for s in (0, 1)]
    for sc in scenes:
        for m in METHODS.names():
            worst = max(worst, cost.episode_cost(sc, m, cfg.stack, method_params=cfg.method_params(m)).total)
    assert worst * cost.MIN_MARGIN <= cost.MAX_EPISODE_UNITS
    assert worst <= cost.SHIPPED_MAX_UNITS * 1.05


# --- every parameter documents its range -------------------------------------------------------------------------

def _numeric_fields(cls, prefix=""):
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        inner = [a for a in typing.get_args(tp) if a is not type(None)] or [tp]
        if dataclasses.is_dataclass(inner[0]):
            yield from _numeric_fields(inner[0], prefix + f.name + ".")
        elif inner[0] in (float, int) or typing.get_origin(inner[0]) is tuple:
            yield prefix + f.name, f


def test_every_numeric_parameter_declares_its_range():
    from bigcbf.params.faults import RobotFaults
    classes = [StackParams, PerceptionParams, SocialForceParams, RobotProfile]
    classes += [t for t in (method_params_type(m) for m in METHODS.names()) if t is not None]
    missing = [f"{cls.__name__}.{name}" for cls in classes for name, f in _numeric_fields(cls)
               if field_range(f) is None and not (cls is RobotProfile and name.startswith("faults.blanked"))]
    assert not missing, missing
    assert RobotFaults().blanked_sectors_deg == ()      # its pairs are checked per element in RobotFaults


def test_bigcbf_methods_shows_the_ranges(capsys):
    assert main(["methods", "mppi"]) == 0
    out = capsys.readouterr().out
    assert "in [2, 20000]" in out and "in [1, 100]" in out
