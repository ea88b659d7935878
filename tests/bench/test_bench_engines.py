"""Engines and the runner with made-up episodes (no physics): completeness, crashes, dead workers, resume."""
from __future__ import annotations

from pathlib import Path

from bigcbf.bench import testing
import pytest

from bigcbf.bench import engines
from bigcbf.bench.runner import BenchConfig, plan, run_bench
from bigcbf.bench.store import ResultStore
from bigcbf.errors import UserError


def config(out: Path, scenarios, **kw) -> BenchConfig:
    base = dict(out=out, methods=("cbf-only", "big-cbf"), scenarios=tuple(scenarios), seeds=(0, 1), workers=2)
    base.update(kw)
    return BenchConfig(**base)


def test_plan_is_seed_major_and_paired(tmp_path, short_scenarios):
    tasks, methods, names = plan(config(tmp_path, short_scenarios))
    assert methods == ["cbf-only", "big-cbf"]                  # the paper's order
    assert names == ["corridor_meeting", "single_person_crossing"]
    assert [t.seed for t in tasks] == [0] * 4 + [1] * 4
    assert len({t.key for t in tasks}) == 8
    assert len({t.params_hash for t in tasks}) == 1 and len({t.scenario_sha for t in tasks}) == 2


def collect(fn, tasks, workers=2):
    rows = []
    engines.run_local(tasks, workers, rows.append, fn)
    return {(r["scenario"], r["method"], r["seed"]): r for r in rows}


def test_local_engine_crash_and_dead_worker(tmp_path, short_scenarios):
    tasks, _, _ = plan(config(tmp_path, short_scenarios))
    rows = collect(testing.fake_episode, tasks)
    assert len(rows) == 8 and all(r["status"] == "ok" for r in rows.values())
    assert rows[("corridor_meeting", "big-cbf", 1)]["metrics"]["control_steps"] == 101
    assert len({r["pid"] for r in rows.values()}) >= 1

    rows = collect(testing.raise_on_seed1, tasks)           # an exception in one episode
    bad = {k for k, r in rows.items() if r["status"] == "error"}
    assert bad == {(s, "cbf-only", 1) for s in ("corridor_meeting", "single_person_crossing")}
    assert all("RuntimeError: injected failure" in rows[k]["error"] for k in bad)
    assert len(rows) == 8

    rows = collect(testing.die_on_seed1, tasks)             # the worker process dies in one episode
    bad = {k for k, r in rows.items() if r["status"] == "error"}
    assert bad == {(s, "cbf-only", 1) for s in ("corridor_meeting", "single_person_crossing")}
    assert all("worker process died" in rows[k]["error"] for k in bad)
    assert len(rows) == 8 and all(r["status"] == "ok" for k, r in rows.items() if k not in bad)


def test_runner_records_errors_and_retries_only_them(tmp_path, short_scenarios):
    lines = []
    out = run_bench(config(tmp_path, short_scenarios), episode_fn=testing.raise_on_seed1, progress=False,
                    log=lines.append)
    assert (out.total, out.ran, out.errors) == (8, 8, 2)
    assert "2 errors" in lines[-1]
    assert (tmp_path / "summary.md").read_text().count("injected failure") == 2
    with ResultStore(tmp_path / "results.sqlite") as st:
        first = {(r["scenario"], r["method"], r["seed"]): r for r in st.rows()}
    out = run_bench(config(tmp_path, short_scenarios), episode_fn=testing.fake_episode, progress=False,
                    log=lines.append)
    assert (out.already_done, out.ran, out.errors) == (6, 2, 0)
    with ResultStore(tmp_path / "results.sqlite") as st:
        rows = {(r["scenario"], r["method"], r["seed"]): r for r in st.rows()}
    assert len(rows) == 8 and all(r["status"] == "ok" for r in rows.values())
    for k, r in rows.items():
        assert r["attempts"] == (2 if first[k]["status"] == "error" else 1)
        if first[k]["status"] == "ok":
            assert r["finished_utc"] == first[k]["finished_utc"]
    # a third run has nothing left to do; a changed parameter set gives new episodes, not mixed rows
    out = run_bench(config(tmp_path, short_scenarios), episode_fn=testing.fake_episode, progress=False,
                    log=lines.append)
    assert (out.already_done, out.ran) == (8, 0)
    runs = out.summary["bench"]["runs"]                       # two invocations ran episodes: 8 + 2
    assert runs == 2 and out.summary["bench"]["episodes_per_min"] > 0
    with ResultStore(tmp_path / "results.sqlite") as st:
        assert [r["episodes_run"] for r in st.runs()] == [8, 2] and [r["errors"] for r in st.runs()] == [2, 0]
    out = run_bench(config(tmp_path, short_scenarios, perception="truth"), episode_fn=testing.fake_episode,
                    progress=False, log=lines.append)
    assert (out.already_done, out.ran) == (0, 8)


def test_plan_rejects_user_mistakes(tmp_path, short_scenarios):
    for kw, msg in ((dict(methods=("nope",)), "unknown method"), (dict(scenarios=("nope",)), "unknown scenario"),
                    (dict(seeds=(0, 0)), "more than once"), (dict(workers=0), "--workers"),
                    (dict(engine="spark"), "unknown engine"), (dict(seeds=()), "no seeds")):
        with pytest.raises(UserError, match=msg):
            plan(config(tmp_path, kw.pop("scenarios", short_scenarios), **kw))
    with pytest.raises(UserError, match="two scenarios are named"):
        plan(config(tmp_path, short_scenarios + ["single_person_crossing"]))
    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(UserError, match="must be a directory"):
        run_bench(config(f, short_scenarios), episode_fn=testing.fake_episode, progress=False)


def test_plan_checks_every_seed_up_to_200_then_a_spread_sample():
    from bigcbf.bench.runner import CHECK_ALL_SEEDS, seed_sample
    assert seed_sample(range(5)) == [0, 1, 2, 3, 4]
    assert seed_sample(range(CHECK_ALL_SEEDS)) == list(range(CHECK_ALL_SEEDS))
    s = seed_sample(range(10_000))
    assert len(s) == CHECK_ALL_SEEDS and s[:100] == list(range(100)) and s[-1] == 9_999
    assert s == sorted(set(s)) and max(b - a for a, b in zip(s, s[1:])) < 10_000 / 90
    assert seed_sample([7, 3, 9] * 1 + list(range(100, 400)))[:3] == [7, 3, 9]     # in the list's order
