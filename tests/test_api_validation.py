"""The Python API checks what it is given as the command line does (bigcbf/validate.py, shared with the Gymnasium
env): every mistake is one UserError naming the field, before any work; run_bench refuses a call at a script's top
level (its spawned workers import the script) and a bench whose every episode failed."""
from __future__ import annotations

import ast
import math
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import bigcbf
from bigcbf import api, gym_env, validate
from bigcbf.errors import UserError
from bigcbf.scenario import load_scenario, scenario_files

SCENE = "single_person_crossing"
PLUGINS = Path(__file__).parent / "plugins"
MAX_SEED = 2**32 - 1


@pytest.fixture(scope="module")
def short_scene(tmp_path_factory) -> str:
    """The shipped single_person_crossing cut to 2 s."""
    text, n = re.subn(r"(?m)^time_limit_s = .*$", "time_limit_s = 2.0", scenario_files()[SCENE].read_text())
    assert n == 1
    p = tmp_path_factory.mktemp("scene") / "short.toml"
    p.write_text(text)
    return str(p)


def raises_naming(field: str, fn, *args, **kwargs) -> str:
    with pytest.raises(UserError) as err:
        fn(*args, **kwargs)
    msg = str(err.value)
    assert field in msg and "\n" not in msg, msg
    return msg


# --- run_episode ------------------------------------------------------------------------------------------------
EPISODE_CASES = [
    ({"seed": -1}, "seed"), ({"seed": None}, "seed"), ({"seed": 1.5}, "seed"), ({"seed": 2**40}, "seed"),
    ({"seed": MAX_SEED + 1}, "seed"), ({"seed": True}, "seed"), ({"seed": "3"}, "seed"),
    ({"time_limit_s": math.nan}, "time_limit_s"), ({"time_limit_s": math.inf}, "time_limit_s"),
    ({"time_limit_s": 1e9}, "time_limit_s"), ({"time_limit_s": 600.001}, "time_limit_s"),
    ({"time_limit_s": 0.05}, "time_limit_s"), ({"time_limit_s": 1e-300}, "time_limit_s"),
    ({"time_limit_s": 0.0}, "time_limit_s"), ({"time_limit_s": -2.0}, "time_limit_s"),
    ({"time_limit_s": "3"}, "time_limit_s"), ({"time_limit_s": True}, "time_limit_s"),
    ({"perception": "radar"}, "perception"), ({"camera": "side"}, "camera"), ({"video": ""}, "video"),
    ({"video": 3}, "video"), ({"log": ""}, "log"), ({"observers": [1]}, "observers"), ({"observers": 5}, "observers"),
    ({"config": 5}, "config"), ({"config": ""}, "config"), ({"profile": 5}, "profile"), ({"method": ""}, "method"),
    ({"scenario": None}, "scenario"), ({"scenario": 5}, "scenario"), ({"scenario": ""}, "scenario"),
]


@pytest.mark.parametrize("kwargs, field", EPISODE_CASES, ids=[f"{f}={list(k.values())[0]!r}" for k, f in EPISODE_CASES])
def test_run_episode_refuses_a_bad_argument_naming_it(kwargs, field, tmp_path):
    kwargs = {"scenario": SCENE, "method": "cbf-only", "seed": 0, "time_limit_s": 0.5, **kwargs}
    raises_naming(field, bigcbf.run_episode, **kwargs)
    assert list(tmp_path.iterdir()) == []


def test_run_episode_takes_the_edges_of_the_ranges():
    res = bigcbf.run_episode(SCENE, "cbf-only", seed=MAX_SEED, time_limit_s=np.float64(1.0))
    assert res.time_s <= 1.0 + 1e-9 and not res.collision
    res = bigcbf.run_episode(SCENE, "cbf-only", seed=np.int64(3), time_limit_s=1)        # an int is a number too
    assert res.time_s <= 1.0 + 1e-9
    sc = load_scenario(SCENE, 0)
    assert validate.check_time_limit(600, sc) == 600.0 and validate.check_time_limit(np.float32(0.1), sc) > 0
    assert validate.check_seed(MAX_SEED) == MAX_SEED and validate.check_seed(np.uint32(MAX_SEED)) == MAX_SEED


def test_the_gym_env_api_and_cli_share_the_checks():
    """gym_env's checks are the API's (same words), and the seed rule is the CLI's --seed parser."""
    import argparse

    from bigcbf.cli.argtypes import nonneg_int

    sc = load_scenario(SCENE, 0)
    for bad in (-1, 2**40, 1.5, None):
        with pytest.raises(UserError) as a:
            gym_env.check_seed(bad)
        with pytest.raises(UserError) as b:
            bigcbf.load_scenario(SCENE, bad)
        assert str(a.value) == str(b.value)
    with pytest.raises(argparse.ArgumentTypeError) as cli:
        nonneg_int(str(2**40))
    assert str(validate_error(validate.check_seed, 2**40)) == f"field 'seed': {cli.value}"
    for bad in (math.nan, 1e9, 0):
        assert str(validate_error(gym_env.check_time_limit, sc, bad)) == str(validate_error(
            validate.check_time_limit, bad, sc))


def validate_error(fn, *args) -> UserError:
    with pytest.raises(UserError) as err:
        fn(*args)
    return err.value


# --- load_config, load_scenario ---------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, field", [
    ({"config": 5}, "config"), ({"config": ""}, "config"), ({"config": ["run.toml"]}, "config"),
    ({"profile": 5}, "profile"), ({"profile": " "}, "profile"), ({"base": "run.toml"}, "base"),
    ({"notes": "print"}, "notes"), ({"config": "missing/run.toml"}, "missing/run.toml"),
])
def test_load_config_refuses_a_bad_argument_naming_it(kwargs, field):
    raises_naming(field, bigcbf.load_config, **kwargs)


@pytest.mark.parametrize("args, field", [
    ((SCENE, -1), "seed"), ((SCENE, 1.5), "seed"), ((SCENE, 2**40), "seed"), ((SCENE, None), "seed"),
    ((None, 0), "scenario"), (("", 0), "scenario"), ((5, 0), "scenario"), (("no_such_scene", 0), "scenario"),
])
def test_load_scenario_refuses_a_bad_argument_naming_it(args, field):
    raises_naming(field, bigcbf.load_scenario, *args)


def test_load_scenario_takes_a_path_and_the_largest_seed(short_scene):
    sc = bigcbf.load_scenario(Path(short_scene), MAX_SEED)
    assert sc.time_limit_s == 2.0 and bigcbf.load_scenario(sc, 0) is sc


# --- bench_config, run_bench ------------------------------------------------------------------------------------
BENCH_CASES = [
    ({"methods": []}, "field 'methods': no methods given"), ({"methods": "big-cbf"}, "methods"),
    ({"methods": [5]}, "methods"), ({"methods": ["no-such-method"]}, "method"),
    ({"scenarios": []}, "field 'scenarios': no scenarios given"), ({"scenarios": SCENE}, "scenarios"),
    ({"seeds": 0}, "seeds"), ({"seeds": []}, "field 'seeds': no seeds given"), ({"seeds": -1}, "seeds"),
    ({"seeds": 1.5}, "seeds"), ({"seeds": True}, "seeds"), ({"seeds": "3"}, "seeds"), ({"seeds": [1.5]}, "seeds"),
    ({"seeds": [-1]}, "seeds"), ({"seeds": [2**40]}, "seeds"), ({"seeds": 10_001}, "seeds"),
    ({"seeds": range(10_001)}, "seeds"), ({"workers": 0}, "workers"), ({"workers": -1}, "workers"),
    ({"workers": 1.5}, "workers"), ({"workers": True}, "workers"), ({"workers": 10**6}, "workers"),
    ({"engine": "slurm"}, "engine"), ({"perception": "radar"}, "perception"), ({"suite": "nope"}, "suite"),
    ({"suite": 5}, "suite"), ({"split": 5}, "split"), ({"ray_address": ""}, "ray_address"),
    ({"notes": 5}, "notes"), ({"config": 5}, "config"), ({"profile": ""}, "profile"),
]


@pytest.mark.parametrize("fn", [bigcbf.bench_config, bigcbf.run_bench])
@pytest.mark.parametrize("kwargs, field", BENCH_CASES, ids=[f"{list(k)[0]}={list(k.values())[0]!r}"[:40]
                                                            for k, _ in BENCH_CASES])
def test_bench_refuses_a_bad_argument_naming_it_before_any_work(fn, kwargs, field, tmp_path, short_scene):
    kwargs = {"methods": ["cbf-only"], "scenarios": [short_scene], "seeds": 1, "workers": 1, **kwargs}
    raises_naming(field, fn, tmp_path / "out", **kwargs)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("out", ["", " ", None, 5])
def test_bench_refuses_a_bad_out(out):
    raises_naming("out", bigcbf.bench_config, out, methods=["cbf-only"])
    raises_naming("out", bigcbf.run_bench, out, methods=["cbf-only"])


@pytest.mark.parametrize("kwargs, field", [({"method": ["cbf-only"]}, "method"), ({"seed": 1}, "seed"),
                                           ({"progress": "yes"}, "progress"), ({"report_only": 1}, "report_only")])
def test_run_bench_refuses_unknown_keywords_and_bad_flags(kwargs, field, tmp_path):
    msg = raises_naming(f"field '{field}'", bigcbf.run_bench, tmp_path / "out", **kwargs)
    assert not (tmp_path / "out").exists() and ("unknown argument" in msg) == (field in ("method", "seed"))


def test_bench_config_takes_the_defaults_and_the_edges(tmp_path, short_scene):
    cfg = bigcbf.bench_config(tmp_path / "out", methods=None, scenarios=[Path(short_scene)], seeds=None,
                              workers=4 * (os.cpu_count() or 1))
    assert len(cfg.methods) == len(bigcbf.methods()) >= 8 and cfg.seeds == tuple(range(50))
    assert cfg.scenarios == (short_scene,) and cfg.workers == 4 * (os.cpu_count() or 1)
    cfg = bigcbf.bench_config(tmp_path / "out", methods=("cbf-only",), seeds=iter([0, MAX_SEED]))
    assert cfg.seeds == (0, MAX_SEED) and len(cfg.scenarios) == 9
    assert bigcbf.bench_config(tmp_path / "out", seeds=np.int64(10_000)).seeds[-1] == 9_999
    assert not (tmp_path / "out").exists()


def test_run_bench_raises_when_every_episode_failed_naming_the_first_error(tmp_path, short_scene, monkeypatch):
    monkeypatch.syspath_prepend(str(PLUGINS))            # (the spawned worker gets the parent's sys.path)
    with pytest.raises(UserError, match=r"^every one of the bench's 1 episodes failed \(recorded in .*out\); the "
                                        r"first: single_person_crossing / bad_planners:TwoVector / seed 0: UserError: method "
                                        r"'bad_planners:TwoVector': plan\(\) returned a command of shape \(2,\)") as err:
        bigcbf.run_bench(tmp_path / "out", methods=["bad_planners:TwoVector"], scenarios=[short_scene], seeds=1,
                         workers=1)
    assert "\n" not in str(err.value) and (tmp_path / "out" / "summary.json").is_file()


# --- a script that calls run_bench at its top level -------------------------------------------------------------
def script(folder: Path, name: str, body: str, scene: str) -> Path:
    p = folder / f"{name}.py"
    p.write_text(textwrap.dedent(body).replace("SCENE", repr(scene)))
    return p


def run_script(path: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "MUJOCO_GL": "egl"}
    return subprocess.run([sys.executable, *args], cwd=path.parent, env=env, capture_output=True, text=True,
                          timeout=180)


def test_a_guarded_script_runs_a_bench_with_two_workers(tmp_path, short_scene):
    p = script(tmp_path, "guarded", """
        import bigcbf

        if __name__ == "__main__":
            out = bigcbf.run_bench("res", methods=["cbf-only"], scenarios=[SCENE], seeds=[4294967295], workers=2)
            print("RESULT", out.ran, out.errors)
        """, short_scene)
    r = run_script(p, p.name)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[-1] == "RESULT 1 0" and (tmp_path / "res" / "summary.json").is_file()


def test_an_unguarded_script_gets_one_line_and_runs_nothing(tmp_path, short_scene):
    p = script(tmp_path, "unguarded", """
        import bigcbf
        out = bigcbf.run_bench("res", methods=["cbf-only"], scenarios=[SCENE], seeds=1,
                               workers=2)
        print("RESULT", out.ran, out.errors)
        """, short_scene)
    r = run_script(p, p.name)
    assert r.returncode != 0 and "RESULT" not in r.stdout
    assert r.stderr.splitlines()[-1] == (
        f"bigcbf.errors.UserError: run_bench is called at the top level of {p}:3: put the call under "
        '`if __name__ == "__main__":` (bench workers are fresh Python processes that import your script)')
    assert not (tmp_path / "res").exists()


def test_a_bench_worker_importing_the_script_runs_no_bench(tmp_path, short_scene):
    """What a spawned worker does with the script (runs it as __mp_main__): the call raises, nothing is written."""
    p = script(tmp_path, "reimported", """
        import sys
        import bigcbf
        if len(sys.argv) > 0:          # a condition the parent's check cannot tell: the worker's check catches it
            bigcbf.run_bench("res", methods=["cbf-only"], scenarios=[SCENE], seeds=1, workers=2)
        print("NOT REACHED")
        """, short_scene)
    r = run_script(p, "-c", f"import runpy; runpy.run_path({p.name!r}, run_name='__mp_main__')")
    assert r.returncode != 0 and "NOT REACHED" not in r.stdout
    assert r.stderr.splitlines()[-1] == f"bigcbf.errors.UserError: {api.UNGUARDED_MESSAGE}"
    assert not (tmp_path / "res").exists()


@pytest.mark.parametrize("code, runs_again", [
    ("bigcbf.run_bench('r')", True),
    ("main()", True),
    ("for s in (1, 2):\n    bigcbf.run_bench('r', seeds=s)", True),
    ("with open('x') as f:\n    bigcbf.run_bench('r')", True),
    ("try:\n    pass\nexcept Exception:\n    pass\nelse:\n    bigcbf.run_bench('r')", True),
    ("if __name__ == '__main__':\n    bigcbf.run_bench('r')", False),
    ("if '__main__' == __name__:\n    main()", False),
    ("if __name__ != '__main__':\n    pass\nelse:\n    main()", False),
    ("if __name__ == '__main__' and True:\n    main()", False),
    ("if not __name__ == '__main__':\n    main()", True),
    ("if __name__ == '__mp_main__':\n    main()", True),
    ("if __name__ == '__main__':\n    pass\nelse:\n    main()", True),
    ("if __name__ == '__main__':\n    pass\nelif len(sys.argv) > 1:\n    main()", False),   # benefit of the doubt
    ("def main():\n    bigcbf.run_bench('r')", False),
])
def test_the_top_level_check_tells_what_a_worker_would_run_again(code, runs_again):
    last = code.count("\n") + 1                  # the call is on the last line of each snippet
    assert api._runs_in_workers(ast.parse(code).body, last) is runs_again
