"""Constant-velocity Kalman filter over the state [px, py, vx, vy] (odom), batched over tracks.

The paper (Sec. V) tracks obstacles "using constant-velocity Kalman filters"; its obstacle model (Sec. II) predicts
positions with constant velocity, eq:obs_prop (2), and a growing covariance, eq:cov_prop (3). The filter's position
covariance (the upper-left 2x2 block of P) is the Sigma_i handed to the stack, where eq:uncertainty_margin (21) uses
beta sqrt(lambda_max).
Process noise is the discretised continuous white-noise acceleration model (Bar-Shalom, Li & Kirubarajan 2001,
Sec. 6.2.2) with power spectral density q [m^2/s^3].
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np


def cv_transition(dt: float) -> np.ndarray:
    """F = [[I, dt I], [0, I]]: the constant-velocity motion of eq:obs_prop (2)
    (p_{k+1} = p_k + dt v_k, v_{k+1} = v_k)."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    return F


def cv_process_noise(dt: float, q: float) -> np.ndarray:
    """Q = q [[dt^3/3 I, dt^2/2 I], [dt^2/2 I, dt I]] (continuous white-noise acceleration, PSD q).

    Its position block grows linearly in dt for small dt times the velocity variance, the role
    eq:cov_prop (3)'s q_Sigma dt I_2 plays in the stack's own prediction.
    """
    I = np.eye(2)
    return q * np.block([[dt ** 3 / 3 * I, dt ** 2 / 2 * I], [dt ** 2 / 2 * I, dt * I]])


@lru_cache(maxsize=64)
def cv_model(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """(F, Q) for one (dt, q), built once: scans come at a fixed rate, so a tracker meets a few dt only (read-only
    arrays: the cache hands out the same objects; F.T stays the transposed view it always was, so the matrix
    products see the same memory layout and give the same bits)."""
    F = cv_transition(dt)
    Q = cv_process_noise(dt, q)
    for a in (F, Q):
        a.flags.writeable = False
    return F, Q


def kf_predict(x: np.ndarray, P: np.ndarray, dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Prediction over dt: x' = F x (eq:obs_prop (2) for the mean), P' = F P F^T + Q. x (N,4), P (N,4,4)."""
    F, Q = cv_model(float(dt), float(q))
    return x @ F.T, F @ P @ F.T + Q


H = np.hstack([np.eye(2), np.zeros((2, 2))])


def measurement_matrix(meas_var) -> np.ndarray:
    """R: a number r for r I, or covariances (N, 2, 2) as they are."""
    return meas_var * np.eye(2) if np.ndim(meas_var) == 0 else np.asarray(meas_var, float)


def innovation(x: np.ndarray, P: np.ndarray, z: np.ndarray, meas_var) -> tuple[np.ndarray, np.ndarray]:
    """Innovation y = z - H x and its covariance S = H P H^T + R; R = meas_var I for a number, or meas_var itself
    (N,2,2), one covariance per measurement. x (N,4), P (N,4,4), z (N,2)."""
    return z - x[:, :2], P[:, :2, :2] + measurement_matrix(meas_var)


def kf_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, meas_var) -> tuple[np.ndarray, np.ndarray]:
    """Measurement update with a position measurement z (N,2) of covariance R (``innovation``): K = P H^T S^-1,
    x' = x + K y, P' = (I - K H) P (I - K H)^T + K R K^T (Joseph form, stays symmetric positive definite)."""
    y, S = innovation(x, P, z, meas_var)
    K = P[:, :, :2] @ np.linalg.inv(S)                                   # P H^T = P[:, :, :2]
    x_new = x + np.einsum("nij,nj->ni", K, y)
    IKH = np.eye(4) - K @ H
    R = measurement_matrix(meas_var)
    P_new = IKH @ P @ IKH.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1)
    return x_new, 0.5 * (P_new + P_new.transpose(0, 2, 1))


def static_update(xs: np.ndarray, Ps: np.ndarray, x_cv: np.ndarray, P_cv: np.ndarray, z: np.ndarray, R: np.ndarray,
                  gate_chi2: float) -> tuple[np.ndarray, np.ndarray]:
    """The tracker's constant-position filter (its static tracks' position, ``perception.tracker``): the update of
    positions xs (K,2), covariances Ps (K,2,2) with measurements z (K,2) of covariances R (K,2,2) (Joseph form,
    symmetrised), then its consistency check against the CV filter's updated position x_cv (K,2) and covariance
    P_cv (K,2,2): where they disagree beyond gate_chi2 (``mahalanobis2``) it restarts from them. The numpy
    reference of the tracker's compiled update (``tracker._measurement_update``)."""
    K = Ps @ np.linalg.inv(Ps + R)
    xs = xs + np.einsum("nij,nj->ni", K, z - xs)
    IK = np.eye(2) - K
    Ps = IK @ Ps @ IK.transpose(0, 2, 1) + K @ R @ K.transpose(0, 2, 1)
    Ps = 0.5 * (Ps + Ps.transpose(0, 2, 1))
    moved = mahalanobis2(xs - x_cv, Ps + P_cv) > gate_chi2
    return np.where(moved[:, None], x_cv, xs), np.where(moved[:, None, None], P_cv, Ps)


def mahalanobis2(y: np.ndarray, S: np.ndarray) -> np.ndarray:
    """y^T S^-1 y for innovations y (..., 2) and covariances S (..., 2, 2) (closed-form 2x2 inverse)."""
    a, b, c, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
    det = a * d - b * c
    y0, y1 = y[..., 0], y[..., 1]
    return (d * y0 * y0 - (b + c) * y0 * y1 + a * y1 * y1) / det
