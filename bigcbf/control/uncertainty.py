"""The cross-layer shared uncertainty at one robot state and command: execution model (``eq:execution``), radius
m_i (``eq:uncertainty_margin``), D_i and h_i (``eq:shared_barrier``), and the imagination's kappa.

The formulas themselves are in :mod:`bigcbf.control.kernels` (one implementation each); these functions take a
robot yaw and a body twist (..., 3) and broadcast over leading axes (behaviors, obstacles, steps).
"""
from __future__ import annotations

import numpy as np

from ..params.stack import ExecutionModel, UncertaintyParams
from ..types import Obstacles
from . import kernels as K
from .kernels import lambda_max_2x2, residual_bound  # noqa: F401  (re-exported)


def rotation(theta) -> np.ndarray:
    """R(theta) (..., 2, 2): maps a body-frame (base_link) vector to the odom frame."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def nominal_velocity(theta, u, model: ExecutionModel) -> np.ndarray:
    """``eq:execution`` without the residual: v = R(theta) (A_xy u + d_xy) [m/s] in odom, shape (..., 2)
    (:func:`bigcbf.control.kernels.execution_velocity`)."""
    return K.execution_velocity(theta, u, model)


def e_exec(u, model: ExecutionModel) -> np.ndarray:
    """The robot-execution term of ``eq:uncertainty_margin``: e_exec(u) = residual_horizon_s * bound(||u_xy||) [m]
    (:func:`bigcbf.control.kernels.e_exec_speed`). ``u`` (..., 3) body twist; returns shape (...,)."""
    u = np.asarray(u, float)
    return K.e_exec_speed(np.hypot(u[..., 0], u[..., 1]), model)


def uncertainty_radius(theta, u_ref, v_obs, cov_obs, unc: UncertaintyParams) -> np.ndarray:
    """``eq:uncertainty_margin``, the common relative-position uncertainty radius m_i [m] at a robot yaw and
    command (:func:`bigcbf.control.kernels.uncertainty_radius` from its terms):

        m_i = ||R(theta)(A u_ref + d) - v_i|| tau95          (relative-motion delay)
            + beta sqrt(lambda_max(Sigma_i))                (obstacle prediction)
            + e_exec(u_ref)                                 (robot execution)
            + e_ZOH                                         (sampled-data motion)

    Broadcasts: theta (...), u_ref (..., 3), v_obs (..., 2), cov_obs (..., 2, 2).
    """
    ex = unc.execution
    rel = K.execution_velocity(theta, u_ref, ex) - np.asarray(v_obs, float)
    return K.uncertainty_radius(np.hypot(rel[..., 0], rel[..., 1]), K.prediction_term(cov_obs, unc),
                                e_exec(u_ref, ex), unc)


def inflated_radius(r_obs, m, kappa: float, unc: UncertaintyParams) -> np.ndarray:
    """``eq:shared_barrier``: D_i = r_R + r_i + d0 + kappa_l m_i [m] (the sufficient condition of
    ``eq:robust_distance_condition`` is ||q_i|| >= D_i); :func:`bigcbf.control.kernels.inflated_radius`."""
    return K.inflated_radius(r_obs, kappa * np.asarray(m, float), unc)


def barrier(q, D) -> np.ndarray:
    """``eq:shared_barrier``: h_i = ||q_i||^2 - D_i^2 [m^2], with q_i = p - p_i (``eq:relative_position_error``);
    :func:`bigcbf.control.kernels.barrier`."""
    return K.barrier(K.squared_norm(q), np.asarray(D, float))


def kappa_img(obstacles: Obstacles, unc: UncertaintyParams) -> float:
    """kappa of the imagination layer: ``kappa_img``, or ``kappa_img_static`` when set and no dynamic obstacle is
    tracked (Sec. V uses kappa_img = 0.8 in dynamic scenes only)."""
    if unc.kappa_img_static is not None and not has_dynamic(obstacles):
        return unc.kappa_img_static
    return unc.kappa_img


def has_dynamic(obstacles: Obstacles) -> bool:
    """Whether any tracked obstacle (id >= 0) is classified dynamic."""
    return bool(np.any(~np.asarray(obstacles.static, bool) & (np.asarray(obstacles.ids) >= 0)))
