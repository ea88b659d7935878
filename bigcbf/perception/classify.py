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

from ..control.jit import kernel
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
    """One update of the classification of N tracks; returns new (static, n_dyn, n_stat) arrays (compiled:
    :func:`_hysteresis`)."""
    static = np.ascontiguousarray(static, dtype=np.bool_).reshape(-1)
    N = len(static)
    out = (np.empty(N, np.bool_), np.empty(N, np.int64), np.empty(N, np.int64))
    _hysteresis(static, np.ascontiguousarray(n_dyn, dtype=np.int64).reshape(-1),
                np.ascontiguousarray(n_stat, dtype=np.int64).reshape(-1),
                np.ascontiguousarray(speed, dtype=float).reshape(-1), np.ascontiguousarray(sigma, dtype=float).reshape(-1),
                float(params.v_dynamic_mps), float(params.dynamic_sigma), float(params.v_static_mps),
                int(params.n_dynamic), int(params.n_static), *out)
    return out


@kernel
def _hysteresis(static, n_dyn, n_stat, speed, sigma, v_dynamic, dynamic_sigma, v_static, n_dynamic, n_static,
                out_static, out_dyn, out_stat):
    """The module docstring's rules, track by track: a significant speed above v_dynamic counts towards
    DYNAMIC, a speed below v_static towards STATIC; a class changes after n_dynamic / n_static such updates in a
    row (the counter then restarts at 0)."""
    for i in range(static.shape[0]):
        fast = speed[i] > v_dynamic and speed[i] > dynamic_sigma * sigma[i]
        slow = speed[i] < v_static
        nd = n_dyn[i] + 1 if static[i] and fast else 0
        ns = n_stat[i] + 1 if not static[i] and slow else 0
        to_dyn = static[i] and nd >= n_dynamic
        to_stat = not static[i] and ns >= n_static
        out_static[i] = (static[i] and not to_dyn) or to_stat
        out_dyn[i] = 0 if to_dyn else nd
        out_stat[i] = 0 if to_stat else ns
