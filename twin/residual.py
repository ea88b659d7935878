"""The command-dependent residual bound behind e_exec(u) of eq:uncertainty_margin (21), with a stated coverage.

Residual r_xy = measured (vx, vy) - the model's (A u + d)_xy, against the commanded speed s = ||u_xy||.

- Validation split: the log is cut into n >= 4 equal time blocks (about 1 s each, the length of a command
  hold); every fourth block is held out, so the held-out part samples every kind of motion in the log (longer
  blocks put whole manoeuvres on one side, and the held-out coverage then measures which manoeuvres fell
  where rather than the bound). A held-out 1 s block sits between calibration blocks, which makes that check
  optimistic; so the final ``tail_fraction`` of the log is held out too, as one contiguous time block, and its
  coverage is reported on its own (``coverage_tail``). The model and the bound are computed on the other
  blocks, the coverage is measured on the held-out ones.
- Conformal bound with a speed-dependent scale (normalised split conformal): bins of s with equal sample
  counts (at least ``min_bin`` samples each, at most ``max_bins``) give the residual's q-quantile per bin; a
  scale curve sigma(s) runs piecewise-linearly through knots at the bin edges (first knot 0), each interior knot
  the mean of its two bins' quantiles, clamped beyond the last knot. The scores r / sigma(s) of the calibration
  samples give one conformal quantile k (the ceil((n + 1) q)-th smallest of n), and the bound is k sigma(s): the
  same knots scaled by k, exactly the piecewise-linear form ``ExecutionModel`` holds. It covers a new exchangeable
  sample with probability >= q whatever the shape of the spread over speed, and, unlike a per-bin quantile held
  flat over each bin, it does not over-cover where the spread grows within a bin. (sigma has a handful of
  parameters fitted on the same samples; the held-out blocks check the coverage that results.)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .signals import quantile_upper


@dataclass(frozen=True)
class ResidualOptions:
    coverage: float = 0.95          # stated coverage q of the bound [-]
    block_s: float = 1.0            # target length of a validation block [s]
    holdout_every: int = 4          # every n-th block is held out [-]
    tail_fraction: float = 0.15     # the final part of the log held out as one contiguous block [-]
    max_bins: int = 6
    min_bin: int = 200              # samples per speed bin, at least (larger bins: a less conservative quantile)


@dataclass
class ResidualBound:
    speed_knots: np.ndarray          # residual_speed_mps, first 0, strictly increasing
    bound_knots: np.ndarray          # residual_bound_mps
    coverage: float                  # stated
    coverage_calibration: float      # measured on the calibration blocks
    coverage_heldout: float          # measured on the held-out blocks (nan if none)
    n_calibration: int
    n_heldout: int
    coverage_tail: float = float("nan")   # measured on the contiguous final block alone (nan if none)

    def __call__(self, speed) -> np.ndarray:
        """The bound on ||r_xy|| [m/s] at command speed ||u_xy|| (interpolated, clamped beyond the last knot)."""
        return np.interp(speed, self.speed_knots, self.bound_knots)


def tail_mask(t: np.ndarray, opt: ResidualOptions = ResidualOptions()) -> np.ndarray:
    """True for samples in the final ``tail_fraction`` of the log's time span."""
    t = np.asarray(t, float)
    t0, t1 = float(t.min()), float(t.max())
    return t > t1 - opt.tail_fraction * (t1 - t0)


def holdout_mask(t: np.ndarray, opt: ResidualOptions = ResidualOptions()) -> np.ndarray:
    """True for held-out samples: every ``holdout_every``-th of n >= 4 equal blocks before the tail, and the tail
    (:func:`tail_mask`)."""
    t = np.asarray(t, float)
    tail = tail_mask(t, opt)
    t0, t1 = float(t.min()), float(t[~tail].max()) if (~tail).any() else float(t.max())
    n = max(opt.holdout_every, int((t1 - t0) // opt.block_s))
    block = np.minimum(((t - t0) / max(t1 - t0, 1e-9) * n).astype(int), n - 1)
    return (block % opt.holdout_every == opt.holdout_every - 1) | tail


def conformal_quantile(x, q: float) -> float:
    """Split-conformal bound: the ceil((n + 1) q)-th smallest of n scores (the largest if that exceeds n)."""
    x = np.sort(np.asarray(x, float))
    k = int(np.ceil((len(x) + 1) * q))
    return float(x[min(k, len(x)) - 1])


def speed_bins(speed: np.ndarray, opt: ResidualOptions = ResidualOptions()) -> np.ndarray:
    """Bin edges (first 0, last the largest speed) with about equal counts of at least ``min_bin`` each."""
    s = np.asarray(speed, float)
    top = float(s.max()) if len(s) else 0.0
    n_bins = int(np.clip(len(s) // opt.min_bin, 1, opt.max_bins))
    edges = np.unique(np.concatenate([[0.0], np.quantile(s, np.linspace(0, 1, n_bins + 1)[1:-1]), [top]]))
    # a bin with fewer than min_bin samples is merged with its right neighbour (the last bin with its left)
    while len(edges) > 2:
        counts = np.bincount(_bin_of(s, edges), minlength=len(edges) - 1)
        small = np.flatnonzero(counts < opt.min_bin)
        if len(small) == 0:
            break
        b = int(small[0])
        edges = np.delete(edges, b + 1 if b + 1 < len(edges) - 1 else b)
    if len(edges) < 2 or edges[-1] <= 0.0:
        edges = np.array([0.0, max(top, 1e-3)])
    return edges


def _bin_of(s: np.ndarray, edges: np.ndarray) -> np.ndarray:
    return np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(edges) - 2)


def fit_bound(speed: np.ndarray, resid: np.ndarray, opt: ResidualOptions = ResidualOptions()):
    """(speed_knots, bound_knots) of the residual bound behind e_exec(u) of eq:uncertainty_margin (21), from calibration
    samples (module docstring)."""
    speed = np.asarray(speed, float)
    resid = np.asarray(resid, float)
    edges = speed_bins(speed, opt)
    b = _bin_of(speed, edges)
    m = np.array([quantile_upper(resid[b == k], opt.coverage) if np.any(b == k) else 0.0
                  for k in range(len(edges) - 1)])
    scale = np.empty(len(edges))
    scale[0], scale[-1] = m[0], m[-1]
    scale[1:-1] = 0.5 * (m[:-1] + m[1:])
    scale = np.maximum(scale, 1e-9 + 1e-3 * scale.max())
    scores = resid / np.interp(speed, edges, scale)
    return edges, conformal_quantile(scores, opt.coverage) * scale


def calibrate_bound(t, speed, resid, opt: ResidualOptions = ResidualOptions(), held=None) -> ResidualBound:
    """The residual bound of e_exec(u), eq:uncertainty_margin (21), from the calibration blocks, and its coverage on
    both parts (``held``: the held-out mask, default :func:`holdout_mask`)."""
    held = holdout_mask(t, opt) if held is None else np.asarray(held, bool)
    speed, resid = np.asarray(speed, float), np.asarray(resid, float)
    cal = ~held
    ks, bs = fit_bound(speed[cal], resid[cal], opt)
    bound = np.interp(speed, ks, bs)
    inside = resid <= bound
    cov_h = float(inside[held].mean()) if held.any() else float("nan")
    tail = held & tail_mask(t, opt)
    cov_t = float(inside[tail].mean()) if tail.any() else float("nan")
    return ResidualBound(ks, bs, opt.coverage, float(inside[cal].mean()), cov_h, int(cal.sum()), int(held.sum()),
                         cov_t)
