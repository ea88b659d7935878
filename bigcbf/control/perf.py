"""Speed of the control stack (figures for ``bigcbf perf``): behavior imagination and the CBF-QP.

imagination_p95_ms: one full behavior-selection cycle (imagine 6 behaviors x N=15 steps x 8 obstacles, score,
select; plus the fallback's own rollout when every behavior is rejected), over seeded random scenes (4 pedestrians
with covariance, 4 static obstacles, none closer than 0.3 m to the robot's footprint).
cbf_qp_p95_ms: one CbfFilter.filter call with 8 obstacle constraints plus the box bounds where the QP is solved
(8 obstacles in a ring around the robot, u_in sweeping round so that different constraints become active, as in
a control loop where consecutive commands are close).
cbf_pass_p95_ms: a filter call whose box-clipped u_in is already safe (no QP).
plan_tick_p95_ms: a BIG-CBF plan() call between selections (eq:online_behavior_command (8) policy regeneration only).
"""
from __future__ import annotations

import time

import numpy as np

from ..params.stack import SIMULATION
from ..types import Obstacles, RobotState
from .big_cbf import BigCbfPlanner
from .cbf import CbfFilter
from .metrics import percentile


def _scene(rng: np.random.Generator) -> tuple[RobotState, Obstacles, np.ndarray]:
    """8 obstacles ahead of the robot (none closer than 0.3 m to its footprint, as in a running episode)."""
    state = RobotState(0.0, 0.0, float(rng.uniform(-np.pi, np.pi)))
    while True:
        p = np.concatenate([rng.uniform([0.8, -2.0], [3.5, 2.0], (4, 2)),
                            rng.uniform([0.5, -1.5], [3.0, 1.5], (4, 2))])
        if np.all(np.hypot(p[:, 0], p[:, 1]) > 0.15 + 0.4 + 0.3):
            break
    v = np.concatenate([rng.normal(0.0, 0.7, (4, 2)), np.zeros((4, 2))])
    cov = np.concatenate([np.tile(np.eye(2) * 0.01, (4, 1, 1)), np.tile(np.eye(2) * 0.002, (4, 1, 1))])
    r = np.concatenate([np.full(4, 0.25), rng.uniform(0.1, 0.4, 4)])
    static = np.array([False] * 4 + [True] * 4)
    return state, Obstacles(p, v, cov, r, static, np.arange(8)), np.array([5.0, 0.0])


def _p(ts, q) -> float:
    """The q-th percentile of timings ``ts`` [s] in ms (the project's one rule, ``metrics.percentile``)."""
    return round(percentile(np.asarray(ts) * 1e3, q), 4)


def bench(quick: bool = False) -> dict:
    rng = np.random.default_rng(0)
    params = SIMULATION

    # one selection cycle (imagination + scoring + selection)
    planner = BigCbfPlanner(params)
    scenes = [_scene(rng) for _ in range(20)]
    n_img = 200 if quick else 1000
    img_ts = []
    for k in range(n_img + 20):
        state, obs, goal = scenes[k % len(scenes)]
        t0 = time.perf_counter()
        planner.select(0.5 * k, state, obs, goal)
        if k >= 20:                                   # warm-up
            img_ts.append(time.perf_counter() - t0)
    tick_ts = []
    planner.reset(0)
    state, obs, goal = scenes[0]
    for k in range(n_img):
        t0 = time.perf_counter()
        _, info = planner.plan(0.05 * k, state, obs, goal)
        if not info.planned:
            tick_ts.append(time.perf_counter() - t0)

    # the CBF-QP: 8 obstacles around the robot, constraints active
    filt = CbfFilter(params)
    ang = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
    ring = Obstacles.from_lists(np.c_[np.cos(ang), np.sin(ang)] * 0.75, r=0.15)
    state = RobotState(0.0, 0.0, 0.0)
    n_qp = 1000 if quick else 5000
    qp_ts, pass_ts, n_rows = [], [], []
    for k in range(n_qp + 50):
        a = 0.02 * k
        u_in = np.array([0.6 * np.cos(a), 0.6 * np.sin(a), 0.2])
        t0 = time.perf_counter()
        _, info = filt.filter(state, ring, u_in)
        dt = time.perf_counter() - t0
        if k >= 50 and info.active:
            qp_ts.append(dt)
            n_rows.append(info.n_constraints)
        u_slow = np.array([0.05 * np.cos(a), 0.05 * np.sin(a), 0.0])
        t0 = time.perf_counter()
        _, info = filt.filter(state, ring, u_slow)
        dt = time.perf_counter() - t0
        if k >= 50 and not info.active:
            pass_ts.append(dt)
    return {
        "imagination_p95_ms": _p(img_ts, 95),
        "imagination_median_ms": _p(img_ts, 50),
        "plan_tick_p95_ms": _p(tick_ts, 95),
        "cbf_qp_p95_ms": _p(qp_ts, 95),
        "cbf_qp_median_ms": _p(qp_ts, 50),
        "cbf_qp_rows_mean": round(float(np.mean(n_rows)), 2),
        "cbf_pass_p95_ms": _p(pass_ts, 95),
    }
