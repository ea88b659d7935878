"""A planner of one's own (tests/plugins/my_planners.py, outside the package): by module path and by entry point,
in bigcbf run and in a 2-worker bench whose workers import it by name from PYTHONPATH; bigcbf methods lists it."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from bigcbf.bench.store import ResultStore
from bigcbf.episode import DETERMINISTIC_KEYS

PLUGINS = Path(__file__).resolve().parent / "plugins"
BIGCBF = str(Path(sys.executable).with_name("bigcbf"))
USER = "my_planners:GoalSeeker"


def bigcbf(*args, pythonpath=(PLUGINS,), cwd=None):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(map(str, pythonpath))}
    return subprocess.run([BIGCBF, *map(str, args)], capture_output=True, text=True, env=env, cwd=cwd, timeout=600)


@pytest.fixture(scope="module")
def short_scene(tmp_path_factory):
    from bigcbf.scenario import scenario_files
    text = scenario_files()["single_person_crossing"].read_text()
    lines = [f"time_limit_s = 3.0" if ln.startswith("time_limit_s") else ln for ln in text.splitlines()]
    path = tmp_path_factory.mktemp("scene") / "spc_short.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_user_planner_by_module_path_in_a_two_worker_bench(tmp_path, short_scene):
    cfg = tmp_path / "run.toml"
    cfg.write_text(f'[methods."{USER}"]\nspeed_mps = 0.35\n')
    out = tmp_path / "bench"
    p = bigcbf("bench", "--out", out, "--methods", USER, "cbf-only", "--scenarios", short_scene, "--seeds", "2",
               "--workers", "2", "--config", cfg, "--progress", "off")
    assert p.returncode == 0, p.stderr
    with ResultStore(out / "results.sqlite") as st:
        rows = {(r["method"], r["seed"]): r for r in st.rows()}
    assert set(rows) == {(m, s) for m in (USER, "cbf-only") for s in (0, 1)}
    assert all(r["status"] == "ok" for r in rows.values()), [r["error"] for r in rows.values()]
    assert {m["mode_history"][0][1] for (m_, _), r in rows.items() if m_ == USER for m in [r["metrics"]]} == {"SEEK"}
    # the workers used the configuration's speed: their rows equal bigcbf run with the same file
    run = bigcbf("run", short_scene, "--method", USER, "--seed", "1", "--config", cfg, "--json")
    assert run.returncode == 0, run.stderr
    ref = json.loads(run.stdout)
    assert {k: rows[(USER, 1)]["metrics"][k] for k in DETERMINISTIC_KEYS} == {k: ref[k] for k in DETERMINISTIC_KEYS}
    slower = json.loads(bigcbf("run", short_scene, "--method", USER, "--seed", "1", "--json").stdout)
    assert slower["final_goal_dist_m"] < ref["final_goal_dist_m"]          # the default 0.5 m/s gets further


def test_user_planner_through_an_entry_point(tmp_path, short_scene):
    """An installed distribution declaring [bigcbf.methods] goal-seeker = my_planners:GoalSeeker (a dist-info
    folder on the path, as pip leaves it)."""
    dist = tmp_path / "site" / "my_planners-0.1.dist-info"
    dist.mkdir(parents=True)
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: my-planners\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[bigcbf.methods]\ngoal-seeker = my_planners:GoalSeeker\n")
    path = (tmp_path / "site", PLUGINS)
    listing = bigcbf("methods", pythonpath=path)
    assert listing.returncode == 0, listing.stderr
    line = next(ln for ln in listing.stdout.splitlines() if ln.startswith("goal-seeker"))
    assert "entry point bigcbf.methods: my_planners:GoalSeeker" in line and "GoalSeekerParams" in line
    run = bigcbf("run", short_scene, "--method", "goal-seeker", "--json", pythonpath=path)
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout)["method"] == "goal-seeker"
    # an entry point may not take a built-in method's name
    (dist / "entry_points.txt").write_text("[bigcbf.methods]\ndwa = my_planners:GoalSeeker\n")
    bad = bigcbf("run", short_scene, "--method", "goal-seeker", pythonpath=path)
    assert bad.returncode == 2 and "has the name of a built-in method" in bad.stderr
    assert "Traceback" not in bad.stderr


@pytest.mark.parametrize("method, message", [
    ("no_such_module:X", "cannot import 'no_such_module'"),
    ("my_planners:Nope", "module 'my_planners' has no attribute 'Nope'"),
    ("my_planners:not_a_planner", "is not a planner (no reset, plan"),
    ("nope", "unknown method 'nope'; known: big-cbf"),
])
def test_bad_methods_are_one_line_errors(method, message, short_scene):
    p = bigcbf("run", short_scene, "--method", method)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and message in err[0], p.stderr
