"""Helpers shared by the comparison methods: the shared prediction (Eqs. 2-3), rollouts under the nominal
execution model (Eq. 1) and the shared barrier h_i = ||q_i||^2 - D_i^2 along a horizon (Eqs. 14-15).

Every baseline that looks ahead uses the same constant-velocity obstacle prediction with growing covariance as
BIG-CBF (``predict_obstacles``) and the same inflated radius D_i (Eq. 14) with the uncertainty radius m_i of
Eq. (15) evaluated at the command that moves the robot at each step, scaled by ``kappa_exec``: the baselines'
certificates and costs then talk about the same set the common execution filter enforces.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...params.stack import StackParams
from ...types import Obstacles, RobotState
from ..planner import clip_command  # noqa: F401  (re-exported for the baselines)
from ..prediction import predict_obstacles, q_sigma_for
from ..uncertainty import barrier, inflated_radius, nominal_velocity, rotation, uncertainty_radius

_TINY = 1e-12


@dataclass(frozen=True)
class Prediction:
    """O^k for k = 0..K (Eqs. 2-4): p (K+1, M, 2) [m], cov (K+1, M, 2, 2) [m^2], v (M, 2) [m/s], r (M,) [m]."""

    p: np.ndarray
    cov: np.ndarray
    v: np.ndarray
    r: np.ndarray

    @property
    def M(self) -> int:
        return len(self.r)


def predict(obstacles: Obstacles, params: StackParams, K: int | None = None, dt: float | None = None,
            t0_s: float = 0.0) -> Prediction:
    """The shared prediction (Eqs. 2-3) over K steps of dt (default N and dt_s of StackParams), starting
    ``t0_s`` seconds ahead of the estimates (positions advanced by t0 v_i and covariance grown by t0 q_Sigma)."""
    K = params.N if K is None else K
    dt = params.dt_s if dt is None else dt
    q = q_sigma_for(obstacles, params.uncertainty)
    if t0_s > 0 and len(obstacles):
        obstacles = Obstacles(obstacles.p + t0_s * obstacles.v, obstacles.v,
                              obstacles.cov + (t0_s * q)[:, None, None] * np.eye(2), obstacles.r,
                              obstacles.static, obstacles.ids)
    p, cov = predict_obstacles(obstacles, K, dt, q)
    return Prediction(p, cov, np.asarray(obstacles.v, float), np.asarray(obstacles.r, float))


def integrate(state: RobotState, u: np.ndarray, dt: float, params: StackParams,
              p0: np.ndarray | None = None, theta0: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (1) without the residual, integrated with forward Euler: body twists u (B, K, 3) held for dt each.

    Body-frame realized twist A u + d; yaw theta_{k+1} = theta_k + dt (A u + d)_wz; position
    p_{k+1} = p_k + dt R(theta_k)(A u + d)_xy. Returns positions (B, K+1, 2) [m] and yaws (B, K+1) [rad].
    """
    u = np.asarray(u, float)
    ex = params.uncertainty.execution
    A, d = np.asarray(ex.A, float), np.asarray(ex.d, float)
    p0 = state.p if p0 is None else np.asarray(p0, float)
    theta0 = state.theta if theta0 is None else float(theta0)
    B, K = u.shape[:2]
    wz = u @ A[2] + d[2]                                         # (B, K)
    theta = np.concatenate([np.full((B, 1), theta0), theta0 + dt * np.cumsum(wz, axis=1)], axis=1)
    v = nominal_velocity(theta[:, :-1], u, ex)                   # (B, K, 2)
    p = np.concatenate([np.broadcast_to(p0, (B, 1, 2)), p0 + dt * np.cumsum(v, axis=1)], axis=1)
    return p, theta


def body_from_world(theta, v_world) -> np.ndarray:
    """u = [R(theta)^T v, 0] (..., 3) for world-frame velocities v (..., 2) (yaw rate 0)."""
    v = np.asarray(v_world, float)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1], np.zeros(v.shape[:-1])], -1)


def world_velocity(state: RobotState) -> np.ndarray:
    """The measured planar velocity in odom: R(theta) [vx, vy] (2,) [m/s]."""
    return rotation(state.theta) @ np.array([state.vx, state.vy])


def barrier_along(paths: np.ndarray, theta: np.ndarray, u: np.ndarray, pred: Prediction,
                  params: StackParams) -> np.ndarray:
    """h_i^k = ||p_k - p_{i,k}||^2 - D_{i,k}^2 (Eq. 14) for every rollout b, state k = 0..K and obstacle i,
    shape (B, K+1, M) [m^2]. D_{i,k} = r_R + r_i + d0 + kappa_exec m_{i,k} (Eq. 14), m_{i,k} from Eq. (15) with
    the predicted covariance Sigma_{i,k} (Eq. 3) and the command that moves the robot from state k (the last
    command u_{K-1} for the terminal state, as in the imagination)."""
    unc = params.uncertainty
    B, K1 = paths.shape[:2]
    if pred.M == 0:
        return np.full((B, K1, 0), np.inf)
    u = np.asarray(u, float)
    u_ref = np.concatenate([u, u[:, -1:]], axis=1)               # (B, K+1, 3)
    m = uncertainty_radius(np.asarray(theta)[:, :, None], u_ref[:, :, None, :], pred.v[None, None],
                           pred.cov[None], unc)                 # (B, K+1, M)
    D = inflated_radius(pred.r[None, None], m, unc.kappa_exec, unc)
    return barrier(paths[:, :, None, :] - pred.p[None], D)


def surface_distance(paths: np.ndarray, theta: np.ndarray, u: np.ndarray, pred: Prediction,
                     params: StackParams) -> np.ndarray:
    """||q_i|| - D_i along the rollouts (B, K+1, M) [m]: the signed distance to the inflated radius (Eq. 14),
    recovered from h = ||q||^2 - D^2 and ||q||."""
    h = barrier_along(paths, theta, u, pred, params)
    if pred.M == 0:
        return h
    qn = np.hypot(*(paths[:, :, None, :] - pred.p[None]).transpose(3, 0, 1, 2))
    D = np.sqrt(np.maximum(qn * qn - h, 0.0))
    return qn - D


def at_goal(state: RobotState, goal: np.ndarray, params: StackParams) -> bool:
    """Inside the goal region ||p - p_g|| <= eps_g (Sec. II): every method commands zero there."""
    return bool(np.hypot(*(state.p - goal)) <= params.eps_g_m)


def accel_limited(v0: np.ndarray, v_cmd: np.ndarray, a_max: float, dt: float) -> np.ndarray:
    """The velocity actually reached when the commanded world velocity v_cmd (B, 2) is tracked from v0 (B, 2)
    with at most a_max [m/s^2] over dt: v0 + (v_cmd - v0) min(1, a_max dt / ||v_cmd - v0||)."""
    dv = v_cmd - v0
    n = np.hypot(dv[..., 0], dv[..., 1])
    return v0 + dv * np.minimum(1.0, a_max * dt / np.maximum(n, _TINY))[..., None]
