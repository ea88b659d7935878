"""DWA + CBF: the dynamic window approach of Fox, Burgard and Thrun (1997), "The dynamic window approach to
collision avoidance", for a holonomic base; Nav2's DWB controller (ros-navigation/navigation2,
nav2_dwb_controller) as the modern reading of its window and sampling.

Fox et al. search the velocities reachable within one control interval (the dynamic window V_d), keep the
admissible ones (V_a: the robot can stop before the first obstacle on the trajectory), and maximize
G(v) = sigma(alpha heading(v) + beta dist(v) + gamma vel(v)) over V_r = V_s ^ V_a ^ V_d. Here, at every control
tick (20 Hz, T_C = 0.05 s, the paper's DWA rate):

* Window V_d: body velocities within acc_xy T_C of the measured twist per axis (Fox's interval is the control
  period; DWB's ``sim_period`` likewise), intersected with the actuator box and |v_xy| <= v_max (V_s); a regular
  grid of ``n_xy`` x ``n_xy`` samples (DWB's ``vx_samples`` default 20, used on both translational axes of the
  holonomic base), yaw rate 0 (``n_wz`` = 1, the circular footprint gains nothing from turning; ``n_wz`` > 1
  samples wz in the window too).
* Trajectory: each sample held for the 1.5 s horizon (N = 15 steps of dt = 0.1 s, the paper's DWA horizon) under
  eq:execution against the shared prediction (eq:obs_prop, eq:cov_prop).
* dist(v): the path length travelled before the trajectory first comes within D_i = r_R + r_i + d0 + ``margin_m``
  of an obstacle (the task's clearance of eq:true_safety_requirement (6); Fox's dist to "the closest obstacle that
  intersects with the curvature"), measured up to the last simulated state before the first one inside D_i
  (or, when the robot already is inside D_i, deeper inside than it starts: moving out or along stays
  admissible); ``dist_free_m`` (the "large constant") when none does within the horizon.
* Admissible V_a (Fox's eq. for V_a): ||v|| <= sqrt(2 dist(v) acc_xy), the robot can stop before it. If no sample is admissible the robot brakes
  (command 0, mode DWA-NONE), as DWB stops when no trajectory is valid.
* heading(v) = pi - |theta|, theta the angle between the motion direction and the goal as seen from the position
  predicted one control interval ahead (Fox: "the angle of the target point relative to the robot's heading
  direction", computed at the predicted position); a sample at rest has heading 0. vel(v) = ||v||.
* Normalization to [0, 1] (Fox: "all three components are normalized"): heading / pi, dist / dist_free_m,
  vel / v_max. sigma: the weighted sum smoothed over the velocity grid by a separable [1, 2, 1]/4 kernel (Fox's
  smoothing, giving more side clearance), then the best admissible sample is taken.
* Weights alpha, beta, gamma = ``w_heading``, ``w_clearance``, ``w_velocity`` = 2.0, 0.2, 0.2: the values quoted
  for Fox et al.'s RHINO experiments (not re-checked against the paper's text here; a named configuration,
  not tuned on the scenes).
Deterministic (a grid, no sampling).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ...params.checks import check_ranges, ranged
from ...params.stack import StackParams
from ...types import Obstacles, RobotState
from ..jit import kernel
from ..planner import PlanInfo, fail_safe
from .common import Geometry, at_goal, clip_command, integrate, predict


@dataclass(frozen=True)
class DwaParams:
    """Fox et al.'s objective and window; DWB's sample count; this robot's acceleration limits."""

    acc_xy_mps2: float = ranged(2.0, 0, 50, lo_open=True)  # translational acceleration limit [m/s^2]
    acc_wz_radps2: float = ranged(3.0, 0, 100)  # yaw acceleration limit [rad/s^2]
    n_xy: int = ranged(20, 1, 101)  # grid points per translational axis [-] (DWB vx_samples)
    n_wz: int = ranged(1, 1, 101)  # grid points in yaw rate [-] (1: wz = 0)
    w_heading: float = ranged(2.0, 0, 1000000.0)  # alpha [-]
    w_clearance: float = ranged(0.2, 0, 1000000.0)  # beta [-]
    w_velocity: float = ranged(0.2, 0, 1000000.0)  # gamma [-]
    dist_free_m: float = ranged(1.2, 0, 100, lo_open=True)  # dist of a trajectory with no obstacle (v_max x 1.5 s) [m]
    margin_m: float = ranged(0.0, 0, 2)  # the method's margin beyond r_R + r_i + d0 (Fox et al. state none) [m]

    def __post_init__(self):
        check_ranges(self, positive=("acc_xy_mps2", "dist_free_m"),
                     nonneg=("acc_wz_radps2", "w_heading", "w_clearance", "w_velocity"),
                     min_int={"n_xy": 1, "n_wz": 1})


def window_samples(state: RobotState, params: StackParams, dp: DwaParams) -> np.ndarray:
    """The dynamic window V_d ^ V_s as a grid of body twists (n_xy, n_xy, n_wz, 3): the measured twist +- acc T_C
    per axis, intersected with the actuator box; grid points outside the speed disc are scaled onto it."""
    lo, hi = np.asarray(params.u_min, float), np.asarray(params.u_max, float)
    cur = np.array([state.vx, state.vy, state.wz])
    span = np.array([dp.acc_xy_mps2, dp.acc_xy_mps2, dp.acc_wz_radps2]) * params.T_C_s
    a = np.clip(cur - span, lo, hi)
    b = np.clip(cur + span, lo, hi)
    gx = np.linspace(a[0], b[0], dp.n_xy)
    gy = np.linspace(a[1], b[1], dp.n_xy)
    gw = np.linspace(a[2], b[2], dp.n_wz) if dp.n_wz > 1 else np.zeros(1)
    U = np.stack(np.meshgrid(gx, gy, gw, indexing="ij"), -1)
    return clip_command(U, params)


def _smooth(G: np.ndarray) -> np.ndarray:
    """sigma: a separable [1, 2, 1]/4 smoothing over the two translational grid axes (edges replicated)."""
    for ax in (0, 1):
        if G.shape[ax] > 1:
            Gp = np.concatenate([np.take(G, [0], ax), G, np.take(G, [-1], ax)], ax)
            n = G.shape[ax]
            G = 0.25 * np.take(Gp, range(0, n), ax) + 0.5 * np.take(Gp, range(1, n + 1), ax) \
                + 0.25 * np.take(Gp, range(2, n + 2), ax)
    return G


@kernel
def _first_hit(paths, pred_p, D):
    """For each rollout s of paths (S, K+1, 2): the first state k in 1..K whose signed distance to some predicted
    obstacle, ||p_k - p_{i,k}|| - D_i, is below min(its value at k = 0, 0) - 1e-9 (0 when none), against
    pred_p (K+1, M, 2). The scan stops at the first hit; the distances are np.hypot's (``surface_distance``)."""
    S, K1 = paths.shape[0], paths.shape[1]
    M = D.shape[0]
    out = np.zeros(S, np.int64)
    lim = np.empty(M)
    for s in range(S):
        for i in range(M):
            sd0 = math.hypot(paths[s, 0, 0] - pred_p[0, i, 0], paths[s, 0, 1] - pred_p[0, i, 1]) - D[i]
            lim[i] = min(sd0, 0.0) - 1e-9
        for k in range(1, K1):
            hit = False
            for i in range(M):
                sd = math.hypot(paths[s, k, 0] - pred_p[k, i, 0], paths[s, k, 1] - pred_p[k, i, 1]) - D[i]
                if sd < lim[i]:
                    hit = True
                    break
            if hit:
                out[s] = k
                break
    return out


def dwa_scores(U: np.ndarray, state: RobotState, obstacles: Obstacles, goal, params: StackParams,
               dp: DwaParams) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fox's terms for the window grid U (..., 3). Returns (G = sigma(...) (...), admissible (...), dist(v) (...)
    [m], paths (S, N+1, 2) over the flattened grid)."""
    shape = U.shape[:-1]
    Uf = U.reshape(-1, 3)
    K, dt = params.N, params.dt_s
    paths, _ = integrate(state, np.repeat(Uf[:, None, :], K, axis=1), dt, params)
    goal = np.asarray(goal, float)
    speed = np.hypot(Uf[:, 0], Uf[:, 1])
    pred = predict(obstacles, params, K, dt)
    dist = np.full(len(Uf), dp.dist_free_m)
    if pred.M:
        # a state collides when it is inside D_i, or deeper inside than the start if that already was; the first
        # colliding state of each sample, 1..K (0: none), found by the compiled scan (the same comparisons as
        # surface_distance's array, which it replaces for speed: tests/control/test_dwa_kernel.py)
        D = Geometry(dp.margin_m).radius(pred.r, params)
        first = _first_hit(np.ascontiguousarray(paths), np.ascontiguousarray(pred.p), D) - 1     # index into 1..K
        seg = np.hypot(*np.diff(paths, axis=1).transpose(2, 0, 1))                     # (S, K)
        travelled = np.concatenate([np.zeros((len(Uf), 1)), np.cumsum(seg, axis=1)], 1)
        # dist: the path length up to the last state before the first collision (0 when the first step collides)
        dist = np.where(first >= 0, travelled[np.arange(len(Uf)), np.maximum(first, 0)], dp.dist_free_m)
        dist = np.minimum(dist, dp.dist_free_m)
    admissible = speed <= np.sqrt(2.0 * dist * dp.acc_xy_mps2) + 1e-12
    # heading at the position predicted one control interval ahead
    c, s = np.cos(state.theta), np.sin(state.theta)
    vw = np.stack([c * Uf[:, 0] - s * Uf[:, 1], s * Uf[:, 0] + c * Uf[:, 1]], -1)
    p1 = state.p[None] + params.T_C_s * vw
    to_goal = goal[None] - p1
    theta = np.arctan2(vw[:, 0] * to_goal[:, 1] - vw[:, 1] * to_goal[:, 0], (vw * to_goal).sum(1))
    heading = np.where(speed > 1e-9, np.pi - np.abs(theta), 0.0)
    G = (dp.w_heading * heading / np.pi + dp.w_clearance * dist / dp.dist_free_m
         + dp.w_velocity * speed / max(params.v_max_mps, 1e-9))
    G = _smooth(G.reshape(shape)).reshape(-1)
    return G.reshape(shape), admissible.reshape(shape), dist.reshape(shape), paths


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
        G, ok, _, paths = dwa_scores(U, state, obstacles, goal, self.params, self.dwa)
        G, ok, Uf = G.reshape(-1), ok.reshape(-1), U.reshape(-1, 3)
        if not ok.any():                   # no admissible velocity: brake (DWB stops without a valid trajectory)
            return np.zeros(3), PlanInfo("DWA-NONE", True, (time.perf_counter() - t0) * 1e3, None)
        j = int(np.argmax(np.where(ok, G, -np.inf)))
        u = clip_command(Uf[j], self.params)
        return u, PlanInfo("DWA", True, (time.perf_counter() - t0) * 1e3, paths[j])
