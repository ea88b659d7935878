"""Static/dynamic classification with hysteresis (paper Sec. V: "static/dynamic classification hysteresis").

Two speed thresholds form a band, v_static_mps < v_dynamic_mps, and two dwell counts debounce the switch:

* a STATIC track becomes DYNAMIC after n_dynamic consecutive measurement updates whose speed estimate exceeds both
  v_dynamic_mps and dynamic_sigma standard deviations of the speed estimate: the speed must be significant, so
  neither the large velocity uncertainty of a young track nor the jitter of a far object's fitted centre (whose
  measurement covariance says how poor it is, ``geometry.circle_fit_covariance``) can flip it. dynamic_sigma = 2:
  the speed estimate of a static object (a 2-D zero-mean Gaussian velocity error: |v| is Rayleigh distributed)
  exceeds 2 of its standard deviations in exp(-2) = 14 % of the updates, 1 in exp(-1/2) = 61 %, and consecutive
  updates are correlated (the filter smooths), so n_dynamic does not multiply these odds;
* a DYNAMIC track becomes STATIC after n_static consecutive updates with speed below v_static_mps;
* a speed inside the band resets both counters; a track starts STATIC (velocity 0 is its prior).

A static track is reported with zero velocity (its KF velocity is jitter of a fixed object); a dynamic one with its
KF velocity. Counters only change on measurement updates: a coasting track keeps its class.
"""
from __future__ import annotations

import numpy as np

from ..params.perception import PerceptionParams


def speed_sigma(v: np.ndarray, Pv: np.ndarray) -> np.ndarray:
    """Standard deviation of the speed estimate |v|: sqrt(u^T Pv u) with u = v/|v| (first order); for |v| = 0 the
    largest standard deviation sqrt(lambda_max(Pv)). v (N,2), Pv (N,2,2)."""
    sp = np.linalg.norm(v, axis=1)
    u = np.where(sp[:, None] > 1e-12, v / np.maximum(sp, 1e-12)[:, None], 0.0)
    along = np.einsum("ni,nij,nj->n", u, Pv, u)
    lmax = np.linalg.eigvalsh(Pv)[:, -1]
    return np.sqrt(np.maximum(np.where(sp > 1e-12, along, lmax), 0.0))


def hysteresis_step(static: np.ndarray, n_dyn: np.ndarray, n_stat: np.ndarray, speed: np.ndarray,
                    sigma: np.ndarray, params: PerceptionParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One update of the classification of N tracks; returns new (static, n_dyn, n_stat) arrays."""
    fast = (speed > params.v_dynamic_mps) & (speed > params.dynamic_sigma * sigma)
    slow = speed < params.v_static_mps
    n_dyn = np.where(static & fast, n_dyn + 1, 0)
    n_stat = np.where(~static & slow, n_stat + 1, 0)
    to_dyn = static & (n_dyn >= params.n_dynamic)
    to_stat = ~static & (n_stat >= params.n_static)
    static = (static & ~to_dyn) | to_stat
    n_dyn = np.where(to_dyn, 0, n_dyn)
    n_stat = np.where(to_stat, 0, n_stat)
    return static, n_dyn, n_stat
