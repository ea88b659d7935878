"""The cross-layer shared uncertainty: execution model (Eq. 1), radius m_i (Eq. 15), D_i and h_i (Eqs. 11-14).

All functions broadcast over leading axes (behaviors, obstacles, steps), so the imagination, the CBF filter and
the baselines evaluate the same formulas.
"""
from __future__ import annotations

import numpy as np

from ..params.stack import ExecutionModel, UncertaintyParams
from ..types import Obstacles


def rotation(theta) -> np.ndarray:
    """R(theta) (..., 2, 2): maps a body-frame (base_link) vector to the odom frame."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def nominal_velocity(theta, u, model: ExecutionModel) -> np.ndarray:
    """Eq. (1) without the residual: v = R(theta) (A_xy u + d_xy) [m/s] in odom, shape (..., 2).

    ``u`` (..., 3) is the body twist (vx, vy, wz); A_xy are the translational rows of A (2x3).
    """
    A = np.asarray(model.A, float)
    body = np.asarray(u, float) @ A[:2].T + np.asarray(model.d[:2], float)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * body[..., 0] - s * body[..., 1], s * body[..., 0] + c * body[..., 1]], -1)


def residual_bound(speed_xy, model: ExecutionModel) -> np.ndarray:
    """The calibrated bound on ||r|| [m/s] at command speed ||u_xy||: linear interpolation of the knots,
    clamped beyond the last knot."""
    return np.interp(speed_xy, model.residual_speed_mps, model.residual_bound_mps)


def e_exec(u, model: ExecutionModel) -> np.ndarray:
    """The robot-execution term of Eq. (15): e_exec(u) = residual_horizon_s * bound(||u_xy||) [m].

    ``u`` (..., 3) body twist; returns shape (...,).
    """
    u = np.asarray(u, float)
    return model.residual_horizon_s * residual_bound(np.hypot(u[..., 0], u[..., 1]), model)


def lambda_max_2x2(cov) -> np.ndarray:
    """Largest eigenvalue of symmetric 2x2 matrices (..., 2, 2), closed form (clamped at 0)."""
    cov = np.asarray(cov, float)
    a, b, c = cov[..., 0, 0], 0.5 * (cov[..., 0, 1] + cov[..., 1, 0]), cov[..., 1, 1]
    return np.maximum(0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b), 0.0)


def uncertainty_radius(theta, u_ref, v_obs, cov_obs, unc: UncertaintyParams) -> np.ndarray:
    """Eq. (15), the common relative-position uncertainty radius m_i [m]:

        m_i = ||R(theta)(A u_ref + d) - v_i|| tau95          (relative-motion delay)
            + beta sqrt(lambda_max(Sigma_i))                (obstacle prediction)
            + e_exec(u_ref)                                 (robot execution)
            + e_ZOH                                         (sampled-data motion)

    Broadcasts: theta (...), u_ref (..., 3), v_obs (..., 2), cov_obs (..., 2, 2).
    """
    ex = unc.execution
    v_rob = nominal_velocity(theta, u_ref, ex)
    rel = v_rob - np.asarray(v_obs, float)
    return (np.hypot(rel[..., 0], rel[..., 1]) * unc.tau95_s
            + unc.beta * np.sqrt(lambda_max_2x2(cov_obs))
            + e_exec(u_ref, ex) + unc.e_zoh_m)


def inflated_radius(r_obs, m, kappa: float, unc: UncertaintyParams) -> np.ndarray:
    """Eq. (14): D_i = r_R + r_i + d0 + kappa_l m_i [m] (the sufficient condition of Eq. (13) is ||q_i|| >= D_i)."""
    return unc.r_robot_m + np.asarray(r_obs, float) + unc.d0_m + kappa * np.asarray(m, float)


def barrier(q, D) -> np.ndarray:
    """Eq. (14): h_i = ||q_i||^2 - D_i^2 [m^2], with q_i = p - p_i (Eq. 11)."""
    q = np.asarray(q, float)
    return q[..., 0] ** 2 + q[..., 1] ** 2 - np.asarray(D, float) ** 2


def kappa_img(obstacles: Obstacles, unc: UncertaintyParams) -> float:
    """kappa of the imagination layer: ``kappa_img``, or ``kappa_img_static`` when set and no dynamic obstacle is
    tracked (Sec. V uses kappa_img = 0.8 in dynamic scenes only)."""
    if unc.kappa_img_static is not None and not has_dynamic(obstacles):
        return unc.kappa_img_static
    return unc.kappa_img


def has_dynamic(obstacles: Obstacles) -> bool:
    """Whether any tracked obstacle (id >= 0) is classified dynamic."""
    return bool(np.any(~np.asarray(obstacles.static, bool) & (np.asarray(obstacles.ids) >= 0)))
