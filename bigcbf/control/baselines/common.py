"""Helpers shared by the comparison methods: the shared prediction (``eq:obs_prop``, ``eq:cov_prop``), rollouts
under the nominal execution model (``eq:execution``) and each method's own collision barrier h_i = ||q_i||^2 - D_i^2
along a horizon. The formulas are in :mod:`bigcbf.control.kernels`.

Every baseline that looks ahead uses the same constant-velocity obstacle prediction with growing covariance as
BIG-CBF (``predict_obstacles``; all methods receive identical observations). Their collision geometry is their
own (:class:`Geometry`): D_i = scale (r_R + r_i) + d0 + margin_m, the task's clearance of
eq:true_safety_requirement (6) (the robot's and the obstacle's radii and the base clearance d0, part of the task for
every method) plus the method's own published safety margin (each module documents its choice and its source).
They do *not* plan with the shared
uncertainty radius m_i of ``eq:uncertainty_margin``: in the paper, sharing that uncertainty with the planning layer is
BIG-CBF's contribution, and the common hard CBF (``bigcbf.control.cbf``) applies it to every method at execution.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...params.stack import StackParams
from ...types import Obstacles, RobotState
from ..planner import clip_command  # noqa: F401  (re-exported for the baselines)
from ..prediction import predict_obstacles, q_sigma_for
from .. import kernels
from ..kernels import body_from_world  # noqa: F401  (re-exported for the baselines)
from ..uncertainty import barrier, rotation

_TINY = 1e-12


@dataclass(frozen=True)
class Geometry:
    """A method's collision geometry: obstacle i is avoided at D_i = scale (r_R + r_i) + d0 + margin_m [m]: the
    task's clearance r_R + r_i + d0 of eq:true_safety_requirement (6) (the footprint r_R and the obstacle's radius
    r_i, optionally scaled as the method's source does, and the base clearance d0 of ``UncertaintyParams.d0_m``)
    plus the method's own published safety margin."""

    margin_m: float = 0.0     # the method's own safety margin [m]
    scale: float = 1.0        # multiplies r_R + r_i [-]

    def __post_init__(self):
        if not (self.margin_m >= 0 and self.scale >= 1.0):
            raise ValueError("a planning geometry needs margin_m >= 0 and scale >= 1")

    def radius(self, r_obs, params: StackParams) -> np.ndarray:
        """D_i (...,) [m] for obstacle radii r_obs (...,): scale (r_R + r_i) + d0 + margin_m."""
        unc = params.uncertainty
        return self.scale * (unc.r_robot_m + np.asarray(r_obs, float)) + unc.d0_m + self.margin_m


@dataclass(frozen=True)
class Prediction:
    """O^k for k = 0..K (eq:obs_prop, eq:cov_prop, eq:predicted_obstacles): p (K+1, M, 2) [m], cov (K+1, M, 2, 2)
    [m^2], v (M, 2) [m/s], r (M,) [m]."""

    p: np.ndarray
    cov: np.ndarray
    v: np.ndarray
    r: np.ndarray

    @property
    def M(self) -> int:
        return len(self.r)


def predict(obstacles: Obstacles, params: StackParams, K: int | None = None, dt: float | None = None,
            t0_s: float = 0.0) -> Prediction:
    """The shared prediction (``eq:obs_prop``, ``eq:cov_prop``) over K steps of dt (default N and dt_s of
    StackParams), starting ``t0_s`` seconds ahead of the estimates (positions advanced by t0 v_i and covariance
    grown by t0 q_Sigma: ``kernels.advance_obstacles``)."""
    K = params.N if K is None else K
    dt = params.dt_s if dt is None else dt
    q = q_sigma_for(obstacles, params.uncertainty)
    if t0_s > 0 and len(obstacles):
        p0, cov0 = kernels.advance_obstacles(obstacles.p, obstacles.v, obstacles.cov, q, t0_s)
        obstacles = Obstacles(p0, obstacles.v, cov0, obstacles.r, obstacles.static, obstacles.ids)
    p, cov = predict_obstacles(obstacles, K, dt, q)
    return Prediction(p, cov, np.asarray(obstacles.v, float), np.asarray(obstacles.r, float))


def integrate(state: RobotState, u: np.ndarray, dt: float, params: StackParams,
              p0: np.ndarray | None = None, theta0: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``eq:execution`` without the residual, integrated with forward Euler from the state (or p0, theta0): body
    twists u (B, K, 3) held for dt each (``kernels.euler_paths``). Returns positions (B, K+1, 2) [m] and yaws
    (B, K+1) [rad]."""
    p0 = state.p if p0 is None else np.asarray(p0, float)
    theta0 = state.theta if theta0 is None else float(theta0)
    return kernels.euler_paths(p0, theta0, u, dt, params.uncertainty.execution)


def world_velocity(state: RobotState) -> np.ndarray:
    """The measured planar velocity in odom: R(theta) [vx, vy] (2,) [m/s]."""
    return rotation(state.theta) @ np.array([state.vx, state.vy])


def barrier_along(paths: np.ndarray, pred: Prediction, params: StackParams, geometry: Geometry) -> np.ndarray:
    """h_i^k = ||p_k - p_{i,k}||^2 - D_i^2 for every rollout b, state k = 0..K and obstacle i, shape (B, K+1, M)
    [m^2], with the method's own D_i = ``geometry.radius(r_i)`` against the shared prediction p_{i,k}
    (``eq:obs_prop``); the barrier of ``eq:shared_barrier`` with the method's D_i (``kernels.barrier``)."""
    B, K1 = paths.shape[:2]
    if pred.M == 0:
        return np.full((B, K1, 0), np.inf)
    D = geometry.radius(pred.r, params)
    return barrier(paths[:, :, None, :] - pred.p[None], D[None, None])


def surface_distance(paths: np.ndarray, pred: Prediction, params: StackParams, geometry: Geometry) -> np.ndarray:
    """||q_i|| - D_i along the rollouts (B, K+1, M) [m]: the signed distance to the method's own collision radius."""
    B, K1 = paths.shape[:2]
    if pred.M == 0:
        return np.full((B, K1, 0), np.inf)
    qn = np.hypot(*(paths[:, :, None, :] - pred.p[None]).transpose(3, 0, 1, 2))
    return qn - geometry.radius(pred.r, params)[None, None]


def at_goal(state: RobotState, goal: np.ndarray, params: StackParams) -> bool:
    """Inside the goal region ``eq:goal_region``, ||p - p_g|| <= eps_g: every method commands zero there."""
    return bool(kernels.in_goal_region(kernels.goal_distance(state.p, goal), params.eps_g_m))


def accel_limited(v0: np.ndarray, v_cmd: np.ndarray, a_max: float, dt: float) -> np.ndarray:
    """The velocity actually reached when the commanded world velocity v_cmd (B, 2) is tracked from v0 (B, 2)
    with at most a_max [m/s^2] over dt: v0 + (v_cmd - v0) min(1, a_max dt / ||v_cmd - v0||)."""
    dv = v_cmd - v0
    n = np.hypot(dv[..., 0], dv[..., 1])
    return v0 + dv * np.minimum(1.0, a_max * dt / np.maximum(n, _TINY))[..., None]
