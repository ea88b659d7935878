"""Obstacle prediction shared by every method: constant velocity with growing covariance, eq:obs_prop, eq:cov_prop,
eq:predicted_obstacles (one step of the first two: ``kernels.advance_obstacles``)."""
from __future__ import annotations

import numpy as np

from ..params.stack import UncertaintyParams
from ..types import Obstacles
from . import kernels


def q_sigma_for(obstacles: Obstacles, unc: UncertaintyParams) -> np.ndarray:
    """Per-obstacle covariance-growth intensity q_Sigma,i of eq:cov_prop [m^2/s], shape (M,).

    Dynamic obstacles grow with ``q_sigma_m2_per_s``; static ones and wall points (which do not move) with
    ``q_sigma_static_m2_per_s``.
    """
    return np.where(np.asarray(obstacles.static, bool), unc.q_sigma_static_m2_per_s, unc.q_sigma_m2_per_s)


def predict_obstacles(obstacles: Obstacles, N: int, dt: float,
                      q_sigma: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """eq:obs_prop, eq:cov_prop, eq:predicted_obstacles: the predicted obstacle set O^k for k = 0..N.

    eq:obs_prop: p_{i,k+1} = p_{i,k} + dt v_i (velocity held constant over the horizon), i.e.
    p_{i,k} = p_{i,0} + k dt v_i.
    eq:cov_prop: Sigma_{i,k+1} = Sigma_{i,k} + q_{Sigma,i} dt I_2, i.e.
    Sigma_{i,k} = Sigma_{i,0} + k q_{Sigma,i} dt I_2.
    ``q_sigma`` is a scalar or one value per obstacle (M,) [m^2/s]. Returns p (N+1, M, 2) [m] and
    cov (N+1, M, 2, 2) [m^2]; velocities and radii are unchanged along the horizon (eq:predicted_obstacles).
    """
    m = len(obstacles)
    k = np.arange(N + 1, dtype=float)
    p = obstacles.p[None, :, :] + (k * dt)[:, None, None] * obstacles.v[None, :, :]
    q = np.broadcast_to(np.asarray(q_sigma, float), (m,))
    if np.any(q < 0):
        raise ValueError("q_sigma must be >= 0 (eq:cov_prop)")
    growth = (k * dt)[:, None] * q[None, :]                       # (N+1, M)
    cov = obstacles.cov[None, :, :, :] + growth[:, :, None, None] * np.eye(2)[None, None, :, :]
    return p, cov


def age_obstacles(obstacles: Obstacles, age_s: float, fresh_s: float, unc: UncertaintyParams) -> Obstacles:
    """The estimates of a scan ``age_s`` seconds old, brought to now: the center moved with its velocity over the
    whole age (``eq:obs_prop``, one step of dt = age), and, when the age exceeds ``fresh_s`` (one period of
    the sensor: scans went missing), the covariance grown by ``eq:cov_prop`` over the excess,
    Sigma + q_Sigma,i (age - fresh) I_2 with q_Sigma,i of :func:`q_sigma_for`. Within one sensor period the
    covariance is the perception's own (its model covers the sensor's normal rate). docs/fidelity.md: "Missing
    scans". Returns ``obstacles`` itself when the age is not positive or there is none.
    """
    if age_s <= 0 or len(obstacles) == 0:
        return obstacles
    stale = age_s - fresh_s
    p, cov = kernels.advance_obstacles(obstacles.p, obstacles.v, obstacles.cov, q_sigma_for(obstacles, unc), age_s,
                                       grow_s=stale if stale > 1e-9 else 0.0)
    return Obstacles(p, obstacles.v, cov, obstacles.r, obstacles.static, obstacles.ids)
