"""Speed of the simulator: bare physics stepping and one LiDAR scan (figures for ``bigcbf perf``)."""
from __future__ import annotations

import time

import mujoco
import numpy as np

from .scene import SCENE_XML, Cylinder, SceneSpec, Wall
from .world import SimWorld


def bare_physics_realtime_factor(model: mujoco.MjModel, n_steps: int) -> float:
    """Simulated seconds per wall second of n_steps bare mj_step calls of ``model`` from its initial state, the
    wheels driven at constant targets (the robot rolls forward, as in an episode)."""
    d = mujoco.MjData(model)
    mujoco.mj_forward(model, d)
    d.ctrl[:] = 5.0                       # the four wheel velocity targets [rad/s]
    t0 = time.perf_counter()
    done = 0
    while done < n_steps:
        nb = min(1000, n_steps - done)
        mujoco.mj_step(model, d, nb)
        done += nb
    return n_steps * model.opt.timestep / (time.perf_counter() - t0)


def replay_realtime_factor(model: mujoco.MjModel, log) -> tuple[float, np.ndarray]:
    """Simulated seconds per wall second of the physics of a recorded run (``SimWorld.record_blocks``) stepped
    again without the stack: from the recorded state, each block's wheel targets and mocap positions written and
    ``mj_step`` called for its steps, nothing else. The floor the episode loop could reach for the very physics it
    ran (its contacts and solver work, which a drive at constant wheel targets does not have). Also returns the
    final qpos (the replay is the run's physics to the bit: ``tests/sim/test_sim_perf.py``)."""
    d = mujoco.MjData(model)
    mujoco.mj_setState(model, d, log.state0, mujoco.mjtState.mjSTATE_INTEGRATION)
    steps = 0
    t0 = time.perf_counter()
    for nb, ctrl, mocap in log.blocks:
        d.ctrl[:] = ctrl
        d.mocap_pos[:] = mocap
        mujoco.mj_step(model, d, nb)
        steps += nb
    wall = time.perf_counter() - t0
    return steps * model.opt.timestep / wall, d.qpos.copy()


def bare_steps_per_s(quick: bool = False) -> tuple[float, float]:
    """(steps per wall second, timestep [s]) of bare mj_step calls of the robot alone (``SCENE_XML``), driving: the
    physics step every ``bigcbf perf`` figure is also given as a ratio to (``bigcbf.cli.perf``)."""
    m = mujoco.MjModel.from_xml_path(str(SCENE_XML))
    d = mujoco.MjData(m)
    d.ctrl[:] = (10.0, 12.0, 12.0, 10.0)
    n = 2000 if quick else 10000
    for _ in range(200):
        mujoco.mj_step(m, d)
    t0 = time.perf_counter()
    for _ in range(n):
        mujoco.mj_step(m, d)
    return n / (time.perf_counter() - t0), m.opt.timestep


def bench(quick: bool = False) -> dict:
    steps_per_s, timestep = bare_steps_per_s(quick)

    scene = SceneSpec(walls=(Wall(-4, -3, 4, -3), Wall(-4, 3, 4, 3), Wall(4, -3, 4, 3)),
                      cylinders=tuple(Cylinder(1.0 + 0.8 * k, (-1) ** k * 0.8, 0.2) for k in range(4)))
    world = SimWorld(scene)
    times = []
    for _ in range(50 if quick else 300):
        t0 = time.perf_counter()
        world.scan()
        times.append(time.perf_counter() - t0)
    return {"physics_steps_per_s": round(steps_per_s, 1),
            "physics_step_us": round(1e6 / steps_per_s, 3),
            "physics_realtime_factor": round(steps_per_s * timestep, 2),
            "lidar_scan_ms": round(1e3 * float(np.median(times)), 4)}
