"""Speed of the comparison planners (figures for ``bigcbf perf``).

mppi_p95_ms: one MPPI planning cycle (2 sampling updates x 512 sequences x 15 steps, warm-started), the call
made at 2 Hz. dwa_p95_ms: one DWA call (window grid, 1.5 s rollouts), made at every 50 ms tick.
backup_cbf_p95_ms, pl_cbf_p95_ms, apf_p95_ms: one call of each shield / field (every tick).
Scenes: the 8-obstacle scenes of ``bigcbf.control.perf`` (4 pedestrians, 4 static obstacles) plus 16 LiDAR wall
points (a wall 1.2 m to the robot's side), i.e. M = 24 obstacle estimates as in a running episode.
"""
from __future__ import annotations

import time

import numpy as np

from ...params.stack import SIMULATION
from ...types import Obstacles, RobotState
from ..perf import _p, _scene
from . import BASELINES


def _with_wall(state: RobotState, obs: Obstacles) -> Obstacles:
    x = np.linspace(-1.0, 4.0, 16)
    wall = Obstacles.from_lists(np.c_[x, np.full(16, 1.2)], ids=np.full(16, -1))
    return obs.concat(wall)


def bench(quick: bool = False) -> dict:
    rng = np.random.default_rng(1)
    params = SIMULATION
    scenes = []
    for _ in range(20):
        state, obs, goal = _scene(rng)
        scenes.append((RobotState(state.px, state.py, state.theta, 0.4 * np.cos(state.theta),
                                  -0.4 * np.sin(state.theta)), _with_wall(state, obs), goal))
    out = {}
    n = 60 if quick else 300
    for name in ("mppi", "dwa", "backup-cbf", "pl-cbf", "apf"):
        planner = BASELINES[name](params)
        planner.reset(0)
        ts = []
        for k in range(n + 10):
            state, obs, goal = scenes[k % len(scenes)]
            t_plan = k * params.T_B_s if name == "mppi" else k * params.T_C_s   # every MPPI call is a cycle
            t0 = time.perf_counter()
            _, info = planner.plan(t_plan, state, obs, goal)
            dt = time.perf_counter() - t0
            if k >= 10 and info.planned:
                ts.append(dt)
        out[f"{name.replace('-', '_')}_p95_ms"] = _p(ts, 95)
        if name in ("mppi", "dwa"):
            out[f"{name}_median_ms"] = _p(ts, 50)
    return out
