"""Speed of the control stack (figures for ``bigcbf perf``): behavior imagination and the CBF-QP.

imagination_p95_ms: one full behavior-selection cycle (imagine 6 behaviors x N=15 steps x 8 obstacles, score,
select; plus the fallback's own rollout when every behavior is rejected), over seeded random scenes (4 pedestrians
with covariance, 4 static obstacles, none closer than 0.3 m to the robot's footprint).
cbf_qp_p95_ms: one CbfFilter.filter call with 8 obstacle constraints plus the box bounds where the QP is solved
(8 obstacles in a ring around the robot, u_in sweeping round so that different constraints become active, as in
a control loop where consecutive commands are close).
cbf_pass_p95_ms: a filter call whose box-clipped u_in is already safe (no QP).
plan_tick_p95_ms: a BIG-CBF plan() call between selections (eq:online_behavior_command (8) policy regeneration only).
route_scan_p95_ms, route_plan_p95_ms, route_goal_p95_ms: the route layer (control/route.py) on its default 18 m x 10 m
grid of 0.1 m cells (an 8 m route's start-goal box widened by the 5 m margin), on synthetic 360-beam
scans of a U-shaped pocket on the goal line with four walkers (two of them moving): one scan into the map (every
scan, 10 Hz), one replan (inflation + A*, replan_hz), one look-ahead point between replans (every control tick).
route_tick_mean_ms: their cost per control tick T_C at those rates (medians: a scan every 1 / (10 Hz T_C) ticks, a
replan every 1 / (replan_hz T_C), a look-ahead point every tick); ``bigcbf perf`` gives each as X_steps too, its
ratio to the bare physics step (a control tick is T_C / dt = 25 physics steps).
"""
from __future__ import annotations

import time

import numpy as np

from ..params.stack import SIMULATION
from ..types import LaserScan, Obstacles, RobotState
from .big_cbf import BigCbfPlanner
from .cbf import CbfFilter
from .metrics import percentile
from .route import RouteLayer, RouteParams


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


def _pocket_scan(x: float, y: float, walkers: np.ndarray, n: int = 360) -> LaserScan:
    """A 360-beam scan from (x, y) (heading 0, laser at the centre) of a U-shaped pocket open toward the robot
    (back wall x = 5, arms y = +-1.5 from x = 2.5), a corridor's walls y = +-4 and walkers (k, 2) of radius 0.25."""
    ang = -np.pi + 2 * np.pi / n * np.arange(n)
    c, s = np.cos(ang), np.sin(ang)
    r = np.full(n, np.inf)
    segs = [((5.0, -1.5), (5.0, 1.5)), ((2.5, 1.5), (5.0, 1.5)), ((2.5, -1.5), (5.0, -1.5)),
            ((-2.0, 4.0), (10.0, 4.0)), ((-2.0, -4.0), (10.0, -4.0))]
    for (ax, ay), (bx, by) in segs:           # ray-segment intersections
        ex, ey = bx - ax, by - ay
        den = c * ey - s * ex
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((ax - x) * ey - (ay - y) * ex) / den
            u = ((ax - x) * s - (ay - y) * c) / den
        ok = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
        r = np.where(ok, np.minimum(r, t), r)
    for wx, wy in walkers:                    # ray-circle intersections
        px, py = wx - x, wy - y
        b = c * px + s * py
        disc = b * b - (px * px + py * py - 0.25 ** 2)
        t = b - np.sqrt(np.maximum(disc, 0.0))
        r = np.where((disc >= 0) & (t > 0), np.minimum(r, t), r)
    r = np.where(r <= 12.0, r, np.inf)
    return LaserScan(0.0, -np.pi, 2 * np.pi / n, 0.15, 12.0, r.astype(np.float32))


def _route(quick: bool, params) -> dict:
    rp = RouteParams(enabled=True)
    layer = RouteLayer(rp, params.uncertainty.r_robot_m, params.uncertainty.d0_m)
    goal = np.array([8.0, 0.0])
    n = 30 if quick else 150
    scan_ts, plan_ts, goal_ts = [], [], []
    for rep in range(2):                      # the first pass compiles (or loads) the kernels
        layer.reset((0.0, 0.0), goal)
        for k in range(n):
            x, y = 0.015 * k, 0.01 * k
            walkers = np.array([[1.5 + 0.01 * k, 2.5], [6.5, -2.0 + 0.02 * k], [1.0, -2.5], [7.0, 2.5]])
            obs = Obstacles.from_lists(walkers, v=[[0.2, 0.0], [0.0, 0.4], [0.0, 0.0], [0.0, 0.0]], r=0.25)
            state = RobotState(x, y, 0.0)
            t0 = time.perf_counter()
            layer.scan(_pocket_scan(x, y, walkers), (x, y, 0.0), obs)
            t1 = time.perf_counter()
            layer.plan(state.p)
            t2 = time.perf_counter()
            layer.local_goal(0.0, state, goal)   # between replans: the look-ahead point only
            t3 = time.perf_counter()
            if rep and k:                     # (k = 0: local_goal's first call plans)
                scan_ts.append(t1 - t0)
                plan_ts.append(t2 - t1)
                goal_ts.append(t3 - t2)
    rate_scan, rate_tick = 10.0, 1.0 / params.T_C_s
    per_tick = (rate_scan * np.median(scan_ts) + rp.replan_hz * np.median(plan_ts)) / rate_tick + np.median(goal_ts)
    return {"route_scan_p95_ms": _p(scan_ts, 95), "route_plan_p95_ms": _p(plan_ts, 95),
            "route_plan_median_ms": _p(plan_ts, 50), "route_goal_p95_ms": _p(goal_ts, 95),
            "route_scan_median_ms": _p(scan_ts, 50), "route_tick_mean_ms": round(1e3 * float(per_tick), 4)}


def _selection(planner, quick: bool) -> dict:
    """imagination_p95_ms / _median_ms (one selection cycle of ``planner`` over the seeded scenes of
    :func:`_scene`) and plan_tick_p95_ms (a plan() call between selections)."""
    rng = np.random.default_rng(0)
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
    return {"imagination_p95_ms": _p(img_ts, 95), "imagination_median_ms": _p(img_ts, 50),
            "plan_tick_p95_ms": _p(tick_ts, 95)}


def _cbf_qp(filt: CbfFilter, quick: bool) -> dict:
    """cbf_qp_p95_ms / _median_ms, cbf_qp_rows_mean, cbf_pass_p95_ms of ``filt`` (module docstring)."""
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
    return {"cbf_qp_p95_ms": _p(qp_ts, 95), "cbf_qp_median_ms": _p(qp_ts, 50),
            "cbf_qp_rows_mean": round(float(np.mean(n_rows)), 2), "cbf_pass_p95_ms": _p(pass_ts, 95)}


def bench(quick: bool = False) -> dict:
    params = SIMULATION
    return {**_selection(BigCbfPlanner(params), quick), **_cbf_qp(CbfFilter(params), quick),
            **_route(quick, params)}


def bench_big_cbf_plus(quick: bool = False) -> dict:
    """The figures of :func:`bench` for ``big-cbf-plus`` (its default rules, :class:`~bigcbf.params.stack.PlusRules`)
    measured in this call: its selection cycle over the same scenes, the CBF-QP of the filter it runs under
    (``control.methods.filter_params``), perception per scan (the same pipeline: ``bigcbf.perception.perf``), and a
    whole episode with its route layer on (``bigcbf.episode_perf.episode_figures``: the route layer's map, A* and
    look-ahead point are in its real-time factor; ``route_*`` give their own cost)."""
    from ..episode_perf import episode_figures
    from ..perception.perf import bench as perception_bench
    from .methods import filter_params, make_planner
    params = SIMULATION
    planner = make_planner("big-cbf-plus", params)
    return {**_selection(planner, quick), **_cbf_qp(CbfFilter(filter_params(planner, params)), quick),
            "perception_ms": perception_bench(quick)["perception_ms"],
            **episode_figures("big-cbf-plus", quick, route=RouteParams(enabled=True)),
            **_route(quick, params)}
