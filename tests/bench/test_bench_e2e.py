"""`bigcbf bench` end to end with real (short) episodes: outputs, equality with `bigcbf run --json`, independence
of the worker count and the engine, resume after SIGKILL, and the CLI's errors."""
from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bigcbf.bench import engines, report
from bigcbf.bench.runner import OUTPUTS
from bigcbf.bench.store import ResultStore
from bigcbf.bench.tasks import code_sha
from bigcbf.cli import main
from bigcbf.episode import DETERMINISTIC_KEYS

METHODS = ["cbf-only", "big-cbf"]
BIGCBF = str(Path(sys.executable).with_name("bigcbf"))


def bench_args(out, scenarios, *extra):
    return ["bench", "--out", str(out), "--methods", *METHODS, "--scenarios", *scenarios, "--seeds", "2",
            "--progress", "off", *extra]


def det(metrics: dict) -> dict:
    return {k: metrics[k] for k in DETERMINISTIC_KEYS}


def by_key(rows):
    return {(r["scenario"], r["method"], r["seed"]): r for r in rows}


@pytest.fixture(scope="module")
def small_bench(tmp_path_factory, short_scenarios):
    """2 methods x 2 scenarios x 2 seeds on 2 local workers, through the CLI."""
    out = tmp_path_factory.mktemp("bench") / "out"
    assert main(bench_args(out, short_scenarios, "--workers", "2")) == 0
    with ResultStore(out / "results.sqlite") as st:
        rows = st.rows()
    return out, by_key(rows)


def test_small_bench_outputs_equal_bigcbf_run(small_bench, short_scenarios, capsys):
    out, rows = small_bench
    for name in OUTPUTS:
        assert (out / name).stat().st_size > 0, name
    assert len(rows) == 8 and all(r["status"] == "ok" for r in rows.values())
    assert {r["code_sha"] for r in rows.values()} == {code_sha()}   # the workers ran this code
    capsys.readouterr()
    runs = []
    for path in short_scenarios:
        for m in METHODS:
            for seed in (0, 1):
                assert main(["run", path, "--method", m, "--seed", str(seed), "--json"]) == 0
                res = json.loads(capsys.readouterr().out)
                runs.append(res)
                assert det(rows[(res["scenario"], m, seed)]["metrics"]) == det(res), (path, m, seed)
    # and once as the real command line, in its own process
    proc = subprocess.run([BIGCBF, "run", short_scenarios[0], "--method", "big-cbf", "--seed", "1", "--json"],
                          capture_output=True, text=True, check=True)
    res = json.loads(proc.stdout)
    assert det(rows[(res["scenario"], "big-cbf", 1)]["metrics"]) == det(res)
    # the summary's numbers are those of the `bigcbf run` results
    summary = json.loads((out / "summary.json").read_text())
    for m in METHODS:
        ours = report.summarize([{"status": "ok", "metrics": r} for r in runs if r["method"] == m])
        for k in ("success_pct", "time_s", "min_clearance_m", "e_cbf", "cbf_active_pct", "qp_infeasible_pct",
                  "collisions"):
            assert summary["methods"][m][k] == pytest.approx(ours[k]), (m, k)
    assert set(summary["by_scenario"]["big-cbf"]) == {"corridor_meeting", "single_person_crossing"}
    # the CSV has every episode
    assert len((out / "episodes.csv").read_text().strip().splitlines()) == 9


def test_rerun_skips_everything_and_one_worker_gives_the_same_rows(small_bench, short_scenarios, tmp_path, capsys):
    out, rows = small_bench
    capsys.readouterr()
    assert main(bench_args(out, short_scenarios)) == 0
    assert "8 already done, 0 run now" in capsys.readouterr().err
    assert main(bench_args(tmp_path, short_scenarios, "--workers", "1")) == 0
    with ResultStore(tmp_path / "results.sqlite") as st:
        one = by_key(st.rows())
    assert one.keys() == rows.keys()
    for k in rows:
        assert det(one[k]["metrics"]) == det(rows[k]["metrics"]), k


def test_ray_engine_gives_the_same_rows(small_bench, short_scenarios, tmp_path):
    pytest.importorskip("ray")
    out, rows = small_bench
    assert main(bench_args(tmp_path, short_scenarios, "--engine", "ray", "--workers", "2")) == 0
    with ResultStore(tmp_path / "results.sqlite") as st:
        got = by_key(st.rows())
    assert got.keys() == rows.keys()
    assert {r["status"] for r in got.values()} == {"ok"}
    for k in rows:
        assert det(got[k]["metrics"]) == det(rows[k]["metrics"]), k
    assert json.loads((tmp_path / "summary.json").read_text())["bench"]["engine"] == "ray"


def _session_members(sid: int) -> list[int]:
    """Processes of a session (field 6 of /proc/PID/stat), i.e. the bench started with start_new_session."""
    pids = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[3]) == sid and fields[0] != "Z":
                pids.append(int(d.name))
    return pids


def test_resume_after_sigkill(short_scenarios, tmp_path, capsys):
    out = tmp_path / "out"
    db = out / "results.sqlite"
    proc = subprocess.Popen([BIGCBF, *bench_args(out, short_scenarios, "--workers", "1")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    n_before = 0
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if db.exists():
                try:
                    con = sqlite3.connect(db, timeout=5)
                    n_before = con.execute("SELECT COUNT(*) FROM episodes").fetchone()[0]
                    con.close()
                except sqlite3.OperationalError:   # the table is not created yet
                    n_before = 0
                if n_before >= 2:
                    break
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)           # the bench process only, as `kill -9 PID` would
        proc.wait()
        deadline = time.monotonic() + 10           # its orphaned worker notices and exits
        while _session_members(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _session_members(proc.pid) == [], "a worker outlived the killed bench"
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)    # cleanup if anything of ours is left
        except ProcessLookupError:
            pass
    assert 2 <= n_before < 8, "the bench was not interrupted part-way"
    with ResultStore(db) as st:
        before = by_key(st.rows())
    capsys.readouterr()
    assert main(bench_args(out, short_scenarios, "--workers", "2")) == 0
    assert f"{len(before)} already done, {8 - len(before)} run now" in capsys.readouterr().err
    con = sqlite3.connect(db)
    keys = con.execute("SELECT scenario, method, seed, COUNT(*) FROM episodes GROUP BY 1, 2, 3").fetchall()
    con.close()
    assert len(keys) == 8 and all(k[3] == 1 for k in keys)
    with ResultStore(db) as st:
        after = by_key(st.rows())
    for k, r in before.items():                     # the rows written before the kill were kept, not rerun
        assert after[k]["finished_utc"] == r["finished_utc"] and after[k]["attempts"] == 1


@pytest.mark.parametrize("extra, message", [
    (["--methods", "nope"], "unknown method 'nope'"),
    (["--scenarios", "nope"], "unknown scenario 'nope'"),
    (["--seeds", "0"], "--seeds must be >= 1"),
    (["--seeds", "two"], "--seeds expects a whole number"),
    (["--seed-list", "3", "-1"], "--seed-list must be >= 0"),
    (["--workers", "0"], "--workers must be >= 1"),
    (["--workers", "many"], "--workers expects a whole number"),
    (["--engine", "spark"], "--engine must be one of local, ray"),
    (["--ray-address", "auto"], "--ray-address needs --engine ray"),
    (["--profile", "/nonexistent/profile.toml"], "/nonexistent/profile.toml"),
    (["--suite", "nope"], "unknown suite 'nope'; known: hardware, paper"),
])
def test_cli_errors_are_one_line(extra, message, tmp_path, capsys):
    seeds = [] if {"--seeds", "--seed-list"} & set(extra) else ["--seeds", "1"]
    assert main(["bench", "--out", str(tmp_path / "o"), *seeds, *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()


def test_cli_ray_engine_without_ray(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(engines, "ray_available", lambda: False)
    assert main(["bench", "--out", str(tmp_path / "o"), "--engine", "ray"]) == 2
    err = capsys.readouterr().err
    assert "needs Ray" in err and "pip install 'bigcbf[ray]'" in err and err.count("\n") == 1


def test_paper_suite_is_the_nine_of_table_ii(tmp_path):
    from bigcbf.bench.paper import SCENARIO_ORDER
    from bigcbf.cli import build_parser
    from bigcbf.cli.bench import config_from_args

    args = build_parser().parse_args(["bench", "--out", str(tmp_path / "o")])
    config = config_from_args(args)
    assert config.scenarios == SCENARIO_ORDER and config.seeds == tuple(range(50))
    args = build_parser().parse_args(["bench", "--out", str(tmp_path / "o"), "--suite", "paper", "--seeds", "3",
                                      "--scenarios", "corridor_meeting"])
    config = config_from_args(args)
    assert config.scenarios == ("corridor_meeting",) and config.seeds == (0, 1, 2)
