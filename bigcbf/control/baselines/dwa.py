"""DWA + CBF: the dynamic window approach of Fox, Burgard and Thrun (1997), for a holonomic base.

Fox et al. search the velocities reachable within a short interval (the dynamic window) that are admissible
(the robot can stop before a collision), simulate each as a constant velocity over the horizon, and maximize
G(v) = sigma(alpha heading + beta dist + gamma vel). Here, at every control tick:

* Window: body twists (vx, vy, wz) within the actuator box and |v_xy| <= v_max, reachable from the measured
  twist within ``window_s`` at ``acc_xy_mps2`` / ``acc_wz_radps2``; a regular grid of ``n_xy`` x ``n_xy`` x
  ``n_wz`` samples (plus the exact stop command, so braking is always a candidate). ``window_s`` = 0.25 s, not
  one 50 ms tick: the odometry twist lags the command by the actuation delay, and a one-tick window would let
  the planner barely change its command.
* Rollout: each sample held for the 1.5 s horizon (N = 15 steps of dt = 0.1 s) under eq:execution (arcs when
  wz != 0), against the shared prediction (eq:obs_prop, eq:cov_prop) of every obstacle.
* Admissibility: the rollout stays outside every collision radius D_i = r_R + r_i (the method's own geometry: Fox et al.
  admit a velocity when the robot's footprint can stop before touching the obstacle; no margin, ``margin_m`` 0; the
  shared uncertainty m_i of eq:uncertainty_margin is BIG-CBF's, applied to every method by the common hard CBF
  downstream) at every step of the 1.5 s horizon. Fox's Va (the robot can stop before the first collision on its
  trajectory, ||v|| <= sqrt(2 a dist)) is implied: an admissible trajectory has no collision within the horizon, and the
  braking distance at v_max, 0.8^2 / (2 * 2.0) = 0.16 m, is far shorter than the horizon's path. If no sample is
  admissible, the sample with the largest worst-case clearance wins.
* Objective (holonomic "heading" = goal progress): progress = ||p_0 - p_g|| - ||p_K - p_g|| [m]; dist = the
  smallest clearance ||q_i|| - D_i over the rollout, capped at ``clearance_cap_m``; vel = ||v_xy||. As in Fox et
  al., each term is normalized over the window (divided by its largest value) before weighting; a small penalty
  on |wz| keeps the yaw still when turning buys nothing (circular footprint).
* Yaw: ``n_wz`` > 1 samples wz in the window too (Fox's (v, omega) search). The default is n_wz = 1 (wz = 0
  exactly, whatever the measured yaw rate; as the paper allows for the holonomic base): with wz sampled, blind_corner seed 0 ended in a contact (min
  clearance -0.03 m) because the body-frame command turns with the robot during the actuation delay, which the
  common filter (a yaw-free model) does not anticipate; with wz = 0 the same episode stays collision-free.
Deterministic (a grid, no sampling).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...params.checks import check_ranges, ranged
from ...params.stack import StackParams
from ...types import Obstacles, RobotState
from ..planner import PlanInfo, fail_safe
from .common import Geometry, at_goal, clip_command, integrate, predict, surface_distance


@dataclass(frozen=True)
class DwaParams:
    """Dynamic-window sampling and objective weights (Fox et al. give the form; values chosen here)."""

    acc_xy_mps2: float = ranged(2.0, 0, 50, lo_open=True)  # translational acceleration limit [m/s^2]
    acc_wz_radps2: float = ranged(3.0, 0, 100)  # yaw acceleration limit [rad/s^2]
    window_s: float = ranged(0.25, 0, 10, lo_open=True)  # interval defining the reachable window [s]
    n_xy: int = ranged(9, 1, 101)  # grid points per translational axis [-]
    n_wz: int = ranged(1, 1, 101)  # grid points in yaw rate [-] (1: wz = 0, see the module docstring)
    w_heading: float = ranged(1.0, 0, 1000000.0)  # weight of goal progress [-]
    w_clearance: float = ranged(0.3, 0, 1000000.0)  # weight of clearance [-]
    w_velocity: float = ranged(0.1, 0, 1000000.0)  # weight of speed [-]
    w_yaw: float = ranged(0.1, 0, 1000000.0)  # penalty on |wz| / wz_max [-]
    clearance_cap_m: float = ranged(1.0, 0, 100, lo_open=True)  # clearance beyond this does not count [m]
    margin_m: float = ranged(0.0, 0, 2)  # the method's own safety margin beyond r_R + r_i (module docstring) [m]

    def __post_init__(self):
        check_ranges(self, positive=("acc_xy_mps2", "window_s", "clearance_cap_m"),
                     nonneg=("acc_wz_radps2", "w_heading", "w_clearance", "w_velocity", "w_yaw"),
                     min_int={"n_xy": 1, "n_wz": 1})


def window_samples(state: RobotState, params: StackParams, dp: DwaParams) -> np.ndarray:
    """The dynamic window as a grid of body twists (S, 3): the current twist +- acc window_s per axis,
    intersected with the actuator box and |v_xy| <= v_max (grid points outside the speed disc are scaled onto
    it), plus the stop command."""
    lo, hi = np.asarray(params.u_min, float), np.asarray(params.u_max, float)
    cur = np.array([state.vx, state.vy, state.wz])
    span = np.array([dp.acc_xy_mps2, dp.acc_xy_mps2, dp.acc_wz_radps2]) * dp.window_s
    a = np.clip(cur - span, lo, hi)
    b = np.clip(cur + span, lo, hi)
    gx = np.linspace(a[0], b[0], dp.n_xy)
    gy = np.linspace(a[1], b[1], dp.n_xy)
    gw = np.linspace(a[2], b[2], dp.n_wz) if dp.n_wz > 1 else np.zeros(1)     # n_wz = 1: wz = 0, always
    U = np.stack(np.meshgrid(gx, gy, gw, indexing="ij"), -1).reshape(-1, 3)
    U = np.concatenate([U, np.zeros((1, 3))])
    return clip_command(U, params)


def dwa_scores(U: np.ndarray, state: RobotState, obstacles: Obstacles, goal, params: StackParams,
               dp: DwaParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rollouts and objective for the samples U (S, 3). Returns (G (S,), admissible (S,), worst clearance
    min_k,i ||q_i|| - D_i (S,) [m] (+inf without obstacles), paths (S, N+1, 2))."""
    K, dt = params.N, params.dt_s
    Ur = np.repeat(U[:, None, :], K, axis=1)
    paths, theta = integrate(state, Ur, dt, params)
    goal = np.asarray(goal, float)
    progress = np.hypot(*(state.p - goal)) - np.hypot(*(paths[:, -1] - goal).T)
    speed = np.hypot(U[:, 0], U[:, 1])
    pred = predict(obstacles, params, K, dt)
    if pred.M:
        sd = surface_distance(paths, pred, params, Geometry(dp.margin_m))    # (S, K+1, M)
        clear = sd[:, 1:].min(axis=(1, 2))           # k >= 1: the sample cannot change state 0
        admissible = clear >= 0.0
    else:
        clear = np.full(len(U), np.inf)
        admissible = np.ones(len(U), bool)
    dist = np.clip(clear, 0.0, dp.clearance_cap_m)

    def norm(x):
        top = np.max(np.abs(x))
        return x / top if top > 1e-12 else np.zeros_like(x)

    wz_max = max(abs(params.u_min[2]), abs(params.u_max[2]), 1e-9)
    G = (dp.w_heading * norm(progress) + dp.w_clearance * norm(dist) + dp.w_velocity * norm(speed)
         - dp.w_yaw * np.abs(U[:, 2]) / wz_max)
    return G, admissible, clear, paths


class DwaPlanner:
    """DWA (Fox et al. 1997), holonomic, at every control tick; deterministic."""

    name = "dwa"
    params_type = DwaParams

    def __init__(self, params: StackParams, dwa: DwaParams = DwaParams()):
        self.params, self.dwa = params, dwa

    def reset(self, seed: int) -> None:
        """Stateless (a deterministic grid search)."""

    @fail_safe
    def plan(self, t: float, state: RobotState, obstacles: Obstacles, goal) -> tuple[np.ndarray, PlanInfo]:
        t0 = time.perf_counter()
        goal = np.asarray(goal, float).reshape(2)
        if at_goal(state, goal, self.params):
            return np.zeros(3), PlanInfo("DWA", True, (time.perf_counter() - t0) * 1e3, None)
        U = window_samples(state, self.params, self.dwa)
        G, ok, clear, paths = dwa_scores(U, state, obstacles, goal, self.params, self.dwa)
        if ok.any():
            j = int(np.argmax(np.where(ok, G, -np.inf)))
            mode = "DWA"
        else:                              # nothing admissible: the sample that keeps the most clearance
            j = int(np.argmax(clear))
            mode = "DWA-NONE"
        u = clip_command(U[j], self.params)
        return u, PlanInfo(mode, True, (time.perf_counter() - t0) * 1e3, paths[j])
