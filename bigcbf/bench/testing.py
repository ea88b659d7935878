"""Episode functions for testing an engine or a store (``run_bench(..., episode_fn=...)``), like numpy.testing.

``fake_episode`` returns made-up metrics computed from the task alone (no physics), so engine and store tests run
in milliseconds; the others fail in chosen ways for one episode. They live in the package, not beside the tests,
so that every worker (a spawned process, a Ray worker on another node) imports them by the same name.
"""
from __future__ import annotations

import os


def fake_episode(task) -> dict:
    """Deterministic metrics from the key only: success for even seeds, 100 + seed control steps."""
    steps = 100 + task.seed
    return {"scenario": task.scenario, "method": task.method, "seed": task.seed, "success": task.seed % 2 == 0,
            "collision": False, "timeout": task.seed % 2 == 1, "time_s": 10.0 + task.seed,
            "min_clearance_m": 0.5, "e_cbf": float(task.seed), "cbf_active_ratio": 10 / steps,
            "qp_infeasible_ratio": 0.0, "planner_p95_ms": 1.0, "cbf_p95_ms": 0.5, "perception_p95_ms": 2.0,
            "stopped_time_s": 0.0, "final_goal_dist_m": 0.1, "sim_time_s": 10.0 + task.seed,
            "wall_time_s": 0.01, "control_steps": steps, "mode_history": [[0.0, "GOAL"]],
            "perception": task.perception, "warnings": {}}


def raise_on_seed1(task) -> dict:
    """A Python exception inside the episode of seed 1 of method 'cbf-only'."""
    if task.seed == 1 and task.method == "cbf-only":
        raise RuntimeError("injected failure")
    return fake_episode(task)


def die_on_seed1(task) -> dict:
    """The worker process dies (as in a segfault) in the episode of seed 1 of method 'cbf-only'."""
    if task.seed == 1 and task.method == "cbf-only":
        os._exit(17)
    return fake_episode(task)
