"""The execution model eq:execution (1), v = A u + d + r, identified from delay-aligned commands and odometry.

Samples are the odometry messages; each is paired with the command in force one actuation delay earlier.

- Axes: an axis (vx, vy, wz) is identified when the log excites it: its command has a standard deviation of at
  least ``excite_min`` and at least ``min_samples`` samples beyond that magnitude. A differential-drive robot
  never commands vy, so vy is reported as not identified; its row of A stays the identity row and its bias 0,
  and the identified rows get no coefficient on it (the log holds no information about them). Never guessed.
- A and d by least squares: for each identified output axis j, v_j = sum_k A_jk u_k + d_j over the identified
  inputs k (scipy.linalg.lstsq), on the *settled* samples: those whose command (delay-aligned) has been held,
  within ``hold_tol`` per axis, for at least ``settle_s``. eq:execution (1) is a static map; right after a command
  change the velocity is still on its way (the wheels' acceleration is limited, more so in combined motions),
  and fitting those samples would bias the gains low. The residual bound uses the same settled samples (see
  twin.calibrate: right after a change the error is the delay's, which eq:uncertainty_margin (21)'s relative-motion
  delay term covers); the coverage on every held-out sample, transients included, is reported beside it. Fewer than
  ``min_settled`` settled samples (a log from a planner whose command never rests): all samples are used, with
  a note.
- Saturated samples are left out: where the drive could not realise the command (a wheel at its limit), the
  measured velocity falls short of the model's prediction along the predicted direction. With the prediction p
  and measurement m scaled per axis by the command's spread, the shortfall is |p| - (p . m)/|p|; a sample is
  saturated when its shortfall exceeds max(4 robust sigma, 10 % of |p|), |p| is in the upper half of the
  log's demands, and it belongs to a run of such samples lasting at least 0.3 s (a drive at its limit stays
  there while the command does; a brief dip, e.g. wheel slip or odometry noise, is not saturation). The fit is
  repeated without them (twice).
- Intervals of A's diagonal: ``twin.limits.gain_intervals``, a block bootstrap (blocks of ``gain_block_s`` seconds:
  the residuals are correlated over the execution residual's hold and the drive's steps; resampling single samples
  would treat them as independent and read too narrow) of the fit that gave the reported A (``bigcbf calibrate``'s
  A is the saturating model's static part, ``twin.limits``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import lstsq

AXES = ("vx", "vy", "wz")


@dataclass(frozen=True)
class ExecutionOptions:
    excite_min: tuple[float, float, float] = (0.05, 0.05, 0.1)   # (m/s, m/s, rad/s)
    min_samples: int = 50
    saturation_sigmas: float = 4.0
    saturation_fraction: float = 0.10
    saturation_min_s: float = 0.3
    settle_s: float = 0.3                                         # [s]
    hold_tol: tuple[float, float, float] = (0.02, 0.02, 0.04)     # (m/s, m/s, rad/s)
    min_settled: int = 200
    passes: int = 2
    gain_block_s: float = 2.0                                     # blocks of the gains' bootstrap [s]
    gain_bootstrap: int = 400                                     # its resamples
    gain_level: float = 0.90                                      # its interval's level [-]


@dataclass
class ExecutionFit:
    A: np.ndarray              # (3, 3)
    d: np.ndarray              # (3,)
    identified: np.ndarray     # (3,) bool
    saturated: np.ndarray      # (n,) bool over the samples given to fit_execution
    n_used: int                # samples the least squares used (settled, not saturated)
    settled_only: bool         # False when too few settled samples and every sample was used

    def predict(self, u: np.ndarray) -> np.ndarray:
        """eq:execution (1) without the residual: A u + d for commands u (n, 3)."""
        return np.asarray(u, float) @ self.A.T + self.d


def settled_samples(t_cmd: np.ndarray, u_cmd: np.ndarray, t_aligned: np.ndarray,
                    opt: ExecutionOptions = ExecutionOptions()) -> np.ndarray:
    """True where the command in force at each (delay-aligned) time ``t_aligned`` has been held within ``hold_tol``
    on every axis over the preceding ``settle_s`` (commands t_cmd (N,), u_cmd (N, 3))."""
    t_cmd = np.asarray(t_cmd, float)
    ta = np.asarray(t_aligned, float)
    i1 = np.searchsorted(t_cmd, ta, side="right") - 1
    i0 = np.searchsorted(t_cmd, ta - opt.settle_s, side="right") - 1
    tol = np.asarray(opt.hold_tol, float)
    out = np.zeros(len(ta), bool)
    for k in np.flatnonzero(i0 >= 0):
        seg = u_cmd[i0[k]:i1[k] + 1]
        out[k] = bool(np.all(seg.max(axis=0) - seg.min(axis=0) <= tol))
    return out


def identified_axes(u: np.ndarray, opt: ExecutionOptions = ExecutionOptions()) -> np.ndarray:
    """Which axes the commands u (n, 3) excite (rule in the module docstring)."""
    u = np.asarray(u, float)
    lim = np.asarray(opt.excite_min, float)
    return (u.std(axis=0) >= lim) & ((np.abs(u) >= lim).sum(axis=0) >= opt.min_samples)


def input_condition(u: np.ndarray, axes: np.ndarray) -> float:
    """Condition number of the standardised regressors [u_k for identified k, 1]: large (> ~30) when the log moves
    two axes together (e.g. vx and wz always in the same proportion), so that their cross gains cannot be told
    apart even though each axis is excited. Rows with an unknown command (NaN: odometry before the first command
    once delayed) are left out."""
    idx = np.flatnonzero(axes)
    if len(idx) == 0:
        return 1.0
    x = np.asarray(u, float)[:, idx]
    x = x[np.isfinite(x).all(axis=1)]
    x = (x - x.mean(axis=0)) / np.maximum(x.std(axis=0), 1e-12)
    return float(np.linalg.cond(x)) if len(x) > len(idx) else float("inf")


def least_squares(u: np.ndarray, v: np.ndarray, axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """eq:execution (1): A, d minimising sum ||v - (A u + d)||^2 over the identified axes (identity rows elsewhere)."""
    A, d = np.eye(3), np.zeros(3)
    idx = np.flatnonzero(axes)
    if len(idx) == 0 or len(u) <= len(idx):          # nothing to fit, or fewer samples than unknowns per row
        return A, d
    X = np.column_stack([u[:, idx], np.ones(len(u))])
    beta, *_ = lstsq(X, v[:, idx])
    for col, j in enumerate(idx):
        A[j, :] = 0.0
        A[j, idx] = beta[:-1, col]
        d[j] = beta[-1, col]
    return A, d


def runs_at_least(flag: np.ndarray, t: np.ndarray, min_s: float) -> np.ndarray:
    """``flag`` kept only on runs of consecutive True samples spanning at least ``min_s`` seconds."""
    flag = np.asarray(flag, bool)
    out = np.zeros_like(flag)
    edges = np.diff(np.concatenate([[0], flag.astype(int), [0]]))
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        if t[b - 1] - t[a] >= min_s:
            out[a:b] = True
    return out


def saturated_samples(t: np.ndarray, u: np.ndarray, v: np.ndarray, A: np.ndarray, d: np.ndarray, axes: np.ndarray,
                      opt: ExecutionOptions = ExecutionOptions()) -> np.ndarray:
    """Samples (times t) where the measured velocity stays short of A u + d along its direction (module
    docstring)."""
    idx = np.flatnonzero(axes)
    if len(idx) == 0:
        return np.zeros(len(u), bool)
    scale = np.maximum(u[:, idx].std(axis=0), 1e-6)
    p = (u @ A.T + d)[:, idx] / scale
    m = v[:, idx] / scale
    norm = np.linalg.norm(p, axis=1)
    safe = np.maximum(norm, 1e-12)
    short = norm - np.sum(p * m, axis=1) / safe
    sigma = 1.4826 * np.median(np.abs(short - np.median(short)))
    thresh = np.maximum(opt.saturation_sigmas * sigma, opt.saturation_fraction * norm)
    flag = (short > thresh) & (norm >= np.median(norm)) & (norm > 1e-9)
    return runs_at_least(flag, np.asarray(t, float), opt.saturation_min_s)


def fit_execution(t: np.ndarray, u: np.ndarray, v: np.ndarray, opt: ExecutionOptions = ExecutionOptions(),
                  axes: np.ndarray | None = None, settled: np.ndarray | None = None) -> ExecutionFit:
    """Identify A, d of eq:execution (1) from aligned commands u (n, 3) and measured body twists v (n, 3) at times t.

    ``settled`` (n,) marks the samples the least squares may use (default: all)."""
    u = np.asarray(u, float)
    v = np.asarray(v, float)
    axes = identified_axes(u, opt) if axes is None else np.asarray(axes, bool)
    settled = np.ones(len(u), bool) if settled is None else np.asarray(settled, bool)
    settled_only = bool(settled.sum() >= opt.min_settled)
    if not settled_only:
        settled = np.ones(len(u), bool)
    sat = np.zeros(len(u), bool)
    A, d = least_squares(u[settled], v[settled], axes)
    for _ in range(opt.passes):
        sat = saturated_samples(t, u, v, A, d, axes, opt)
        use = settled & ~sat
        A, d = least_squares(u[use], v[use], axes)
    return ExecutionFit(A, d, axes, sat, int((settled & ~sat).sum()), settled_only)
