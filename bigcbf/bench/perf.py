"""Speed figures of the bench layer, for ``bigcbf perf`` (never asserted in tests).

- ``bench_store_put_per_s``: result rows committed per second (one transaction per row, WAL).
- ``bench_report_3600_s``: time to write every output for 3,600 made-up episodes (8 x 9 x 50).
- ``bench_local_episodes_per_min``: real episodes per minute of wall time on the local engine with one worker
  per core (full-length episodes of two scenarios, two methods); ``bench_episode_mean_wall_s``: the mean wall
  time of one episode inside its worker; ``bench_full_estimate_min``: 3,600 episodes at that rate.
"""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path


def _fake_row(scenario: str, method: str, seed: int) -> dict:
    steps = 400 + seed
    return dict(scenario=scenario, method=method, seed=seed, params_hash="p", scenario_sha="s", status="ok",
                error=None, worker_wall_s=1.0, host="h", pid=1, attempts=1,
                metrics=dict(success=seed % 3 != 0, collision=False, timeout=seed % 3 == 0, time_s=12.0 + seed % 5,
                             min_clearance_m=0.4, e_cbf=0.1 * (seed % 7), cbf_active_ratio=40 / steps,
                             qp_infeasible_ratio=0.0, planner_p95_ms=20.0, cbf_p95_ms=0.5, perception_p95_ms=3.0,
                             stopped_time_s=1.0, final_goal_dist_m=0.1, sim_time_s=12.0, wall_time_s=2.0,
                             control_steps=steps, mode_history=[[0.0, "GOAL"], [2.5, "SIDE-L"]],
                             perception="lidar", warnings={}))


def bench(quick: bool = False) -> dict:
    from ..control.methods import METHODS
    from . import report
    from .paper import METHOD_ORDER, SCENARIO_ORDER
    from .runner import BenchConfig, run_bench
    from .store import ResultStore

    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="bigcbf-bench-perf-") as tmp:
        tmp = Path(tmp)
        n = 200 if quick else 1000
        with ResultStore(tmp / "store.sqlite") as st:
            t0 = time.perf_counter()
            for i in range(n):
                st.put(_fake_row("a", "m", i))
            out["bench_store_put_per_s"] = n / (time.perf_counter() - t0)

        rows = [_fake_row(s, m, k) for k in range(50) for s in SCENARIO_ORDER for m in METHOD_ORDER]
        (tmp / "rep").mkdir()
        t0 = time.perf_counter()
        report.write_reports(tmp / "rep", rows, list(METHOD_ORDER), list(SCENARIO_ORDER), list(range(50)))
        out["bench_report_3600_s"] = time.perf_counter() - t0

        methods = tuple(m for m in ("cbf-only", "big-cbf") if m in METHODS)
        scenarios = ("single_person_crossing",) if quick else ("single_person_crossing", "required_sidestepping")
        cfg = BenchConfig(out=tmp / "eps", methods=methods, scenarios=scenarios, seeds=(0,),
                          workers=os.cpu_count() or 1)
        res = run_bench(cfg, progress=False, log=lambda msg: None)
        with ResultStore(tmp / "eps" / "results.sqlite") as st:
            walls = [r["worker_wall_s"] for r in st.rows()]
        out["bench_local_episodes_per_min"] = res.episodes_per_min
        out["bench_local_workers"] = cfg.workers
        out["bench_episode_mean_wall_s"] = sum(walls) / len(walls)
        out["bench_full_estimate_min"] = 3600 / res.episodes_per_min if res.episodes_per_min else float("nan")
    return out
