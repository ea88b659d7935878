"""The saturating execution model: eq:execution (1) below the robot's wheel limits, and what the firmware does
above them.

Every real base's firmware limits its wheels. A linear model v = A u + d (eq:execution (1)) fitted across a
limit absorbs it into A and d (a gain that reads low, a bias that predicts motion at rest, cross gains of the wrong
sign), so the limits are identified with the model they break, and A, d on the samples below them:

    p(t) = A u(t - L) + d                          eq:execution (1) without residual, inputs delayed per axis (L_j)
    s(t) = p(t) min(1, v_max / max|R p(t)|)        wheel-speed saturation, all wheels scaled together
    x'   = the step toward s limited so that max|R dx| <= a_max dt     wheel-acceleration limit
    y'   = (x - y) / T                              the drive's first-order response
    v(t) = mean of y over [t - P, t]                the odometry's twist: encoder counts over its period P

R (4x3) gives the wheel rim speeds of a twist, vx -+ vy -+ k wz (``rim_matrix``; for a differential drive, whose
log never commands vy, the rows are its two wheels vx -+ k wz), with the yaw lever arm k (half wheelbase + half
track of a Mecanum base, half the track of a differential drive) identified with the limit. The same model drives
the simulated robot (bigcbf.sim.firmware.WheelLimiter, robot profile keys wheel_speed_max_mps, wheel_yaw_lever_m,
wheel_accel_max_mps2), which is what ``bigcbf replay`` uses.

Identification (:func:`fit_static`, :func:`fit_dynamic`):

1. static part, on the settled samples (command held, response converged): A, d by least squares; then for each k
   on a grid (0.05 to 0.6 m; fixed when the log does not move both translation and yaw) and v_max on a grid of the
   samples' rim demands max|R p|, the squared error of the saturating model (per axis, scaled by the command's
   spread); the best pair, the samples that ask more than 95 % of the limit left out (near the kink a small error in
   the limit would bias the gains), A and d refitted, three times; then A, d, the limit and the lever together by
   one least-squares fit of the saturating model on every settled sample (:func:`_refine_jointly`: the
   alternation can stop where neither half alone improves). The limit is reported
   when it saturates at least ``min_saturated`` samples (and ``min_saturated_fraction`` of them), cuts the error of
   those samples against the linear law of the samples below it (A u + d) by ``improvement``, and cuts the total
   error against a linear model fitted on every settled sample by at least 30 times the mean error per sample (a
   change the noise cannot make); otherwise the log does not reach one. A's diagonal gets a 90 % interval by a
   one-step block bootstrap of this same fit on the same samples (:func:`gain_intervals`).
2. dynamic part, on every sample of the calibration blocks: the model simulated on a 10 ms grid (the commands
   box-averaged over each step and the prediction interpolated to the odometry times, so that the fit moves
   smoothly with L) for a batch of candidates at once: a common dead time L and lag T without acceleration limit;
   then a_max (geometric grid, and none) with L and T around that; then finer; then L and T per axis (each axis
   by its own error, the others held at the common values). The candidates' error for the common parts is the
   geometric mean over the axes of each axis's summed squared error (the maximum-likelihood choice when each
   axis has its own noise variance, :func:`_best`): a plain sum let the noisiest axis choose them for all (on
   the simulated X3 the yaw rate's error, rocked by the rollers, was 12 times the others' and chose a 50 ms lag
   with a 45 ms dead time for vx, whose own best is 85 ms and 13 ms). An acceleration limit is reported when it
   lowers that error by ``accel_gain`` against none. The yaw lever is the static part's: choosing it again among
   those the static part leaves plausible by the transients (``lever_by_transients``, off by default) traded the
   lever against the yaw's own dead time, since that choice is made at a dead time common to the axes: a yaw that
   responds later than the translation read as a shorter lever (0.05-0.15 m for the simulated base's 0.1645 m), and
   its dead time then came out up to 46 ms off. On 50 dev profiles (seed 5101) the static lever gave the yaw
   latency a z-score spread of 0.94 against 1.57 (docs/twin.md). Finally each axis's dead time and lag are searched again near their values
   on a 2.5 ms grid (:func:`refine_dynamic`, dead time every 1.25 ms): on the 10 ms grid an acceleration-limited
   ramp can only start on a grid point, so a limited response's dead times came out in 10 ms steps. Each axis's
   delay to half a step (L + T ln 2: dead time and lag trade off, their sum is what a log pins down) gets a 5-95 %
   interval by bootstrap over the calibration blocks (the error of each candidate summed per block). In that last
   search the prediction is the mean over ``residual_draws`` draws (antithetic pairs) of a residual redrawn with
   every command and added before the limits, its size per translation axis from the settled errors
   (:func:`residual_sd`): behind an acceleration limit a residual adds its own wheel changes to every step's and
   slows the ramps on average, which the noiseless model reads as dead time (docs/twin.md).

The dead time L is the command-to-wheel latency (what the robot profile's latency_s is in the simulator); T and the
acceleration limit are the response after it.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from bigcbf.control.jit import kernel

from .execution import least_squares
from .signals import expanded_levels

AXES = ("vx", "vy", "wz")


@dataclass(frozen=True)
class LimitOptions:
    lever_min_m: float = 0.05           # yaw lever arm grid lever_min_m..lever_max_m [m] (no base has its wheels
    lever_max_m: float = 0.6            # closer than 5 cm to its centre)
    lever_steps: int = 56
    speed_steps: int = 80               # rim-speed limit grid (quantiles of the demands)
    min_saturated: int = 20             # samples beyond the limit, at least [-]
    min_saturated_fraction: float = 0.01
    improvement: float = 0.3            # the saturating model cuts the linear model's error by this fraction [-]
    kink_margin: float = 0.05           # A, d are fitted on samples asking at most (1 - this) of the limit [-]
    step_s: float = 0.01                # simulation grid of the dynamic fit [s]
    max_delay_s: float = 1.0            # dead-time search range [s]
    lags_s: tuple[float, ...] = (0.0, 0.01, 0.02, 0.035, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3)
    accel_min: float = 0.2              # acceleration-limit grid [m/s^2 of rim]
    accel_max: float = 40.0
    accel_gain: float = 0.03            # a limit is reported when it lowers the error by this fraction [-]
    bootstrap: int = 400
    fine_step_s: float = 0.0025         # grid of the final per-axis search (refine_dynamic; = step_s: none) [s]
    fine_dead_s: float = 0.00125        # its dead-time step [s]
    fine_span_s: float = 0.01           # ... within this of the coarse search's [s]
    fine_accel_rel: tuple[float, ...] = (0.97, 1.03)   # acceleration limits beside the coarse fit's that the
    #                                     fine search chooses among, point and resamples alike (relative; () none) [-]
    residual_draws: int = 8             # the fine search's prediction: its mean over this many draws (antithetic
    #                                     pairs) of a residual before the wheel limits (residual_sd; 0: none) [-]
    lever_by_transients: bool = False   # step 3b: the yaw lever re-chosen among the plausible ones by the
    #                                     transients at a common dead time (False: the static fit's lever) [-]


def rim_matrix(lever_m: float) -> np.ndarray:
    """R (4x3): wheel rim speeds = R (vx, vy, wz) (module docstring; as bigcbf.sim.firmware.rim_matrix)."""
    k = float(lever_m)
    return np.array([[1.0, -1.0, -k], [1.0, 1.0, k], [1.0, 1.0, -k], [1.0, -1.0, k]])


def rim_demand(p: np.ndarray, lever_m) -> np.ndarray:
    """max |R p| per row of p (n, 3): the fastest wheel's rim speed. The four wheels are the four sign combinations
    of vx +- vy +- k wz, so (k >= 0) max|R p| = |vx| + |vy| + k |wz|; ``lever_m`` may be one value per row."""
    p = np.asarray(p, float)
    return np.abs(p[..., 0]) + np.abs(p[..., 1]) + np.asarray(lever_m, float) * np.abs(p[..., 2])


def saturate(p: np.ndarray, v_max: float | None, lever_m: float) -> np.ndarray:
    """p scaled by min(1, v_max / max|R p|) per row (no limit: p)."""
    p = np.asarray(p, float)
    if v_max is None:
        return p
    D = rim_demand(p, lever_m)
    return p * np.minimum(1.0, v_max / np.maximum(D, 1e-12))[..., None]


def _scale(u: np.ndarray, axes: np.ndarray) -> np.ndarray:
    s = np.ones(3)
    s[axes] = np.maximum(np.asarray(u, float)[:, axes].std(axis=0), 1e-3)
    return s


@dataclass
class StaticFit:
    """The static part of the saturating model (step 1 of the module docstring)."""
    A: np.ndarray
    d: np.ndarray
    v_max: float | None                 # rim-speed limit [m/s] (None: not reached by the log)
    lever_m: float                      # yaw lever arm of the limit [m]
    lever_range_m: tuple[float, float]  # levers within 4 noise variances of the best error (wide: not identified) [m]
    lever_identified: bool
    demand_max: float                   # the largest rim demand max|R (A u + d)| of the settled samples [m/s]
    n_saturated: int                    # settled samples beyond the limit
    cost_linear: float                  # error of A, d fitted on every settled sample (no limit)
    cost_saturating: float              # error of this model
    A_linear: np.ndarray                # the linear fit across the limit (what a linear model would claim)
    d_linear: np.ndarray
    lever_grid: np.ndarray = field(default_factory=lambda: np.zeros(0))     # the levers tried [m]
    v_max_by_lever: np.ndarray = field(default_factory=lambda: np.zeros(0))  # the best limit at each [m/s]
    cost_by_lever: np.ndarray = field(default_factory=lambda: np.zeros(0))   # and its error
    n_samples: int = 0

    def plausible_levers(self, sigmas: float = 5.0, most: int = 7) -> np.ndarray:
        """Levers whose static error is within ``sigmas``^2 noise variances of the best (at most ``most``, evenly
        spread): the candidates the dynamic fit chooses among (a ramp's rate depends on the lever too)."""
        if self.v_max is None or len(self.cost_by_lever) == 0:
            return np.array([self.lever_m])
        c = self.cost_by_lever
        ok = np.flatnonzero(np.isfinite(c) & (c <= np.nanmin(c) * (1 + sigmas ** 2 / max(self.n_samples, 1))))
        if len(ok) > most:
            ok = ok[np.linspace(0, len(ok) - 1, most).round().astype(int)]
        return np.unique(np.r_[self.lever_grid[ok], self.lever_m])

    def at_lever(self, k: float) -> "StaticFit":
        """This fit with the lever k and the limit that goes with it (from the static profile)."""
        import dataclasses
        if self.v_max is None or len(self.lever_grid) == 0:
            return self
        i = int(np.argmin(np.abs(self.lever_grid - k)))
        vm = self.v_max_by_lever[i] if abs(self.lever_grid[i] - k) < 1e-9 else self.v_max
        return dataclasses.replace(self, lever_m=float(k), v_max=float(vm))

    def predict(self, u: np.ndarray) -> np.ndarray:
        """The settled response: sat(A u + d)."""
        return saturate(np.asarray(u, float) @ self.A.T + self.d, self.v_max, self.lever_m)

    def demand(self, u: np.ndarray) -> np.ndarray:
        return rim_demand(np.asarray(u, float) @ self.A.T + self.d, self.lever_m)

    def near_limit(self, u: np.ndarray, margin: float) -> np.ndarray:
        """True where the command asks more than (1 - margin) of the rim-speed limit: the samples :func:`fit_static`
        leaves out of A, d (its ``kink_margin``); all False without a limit."""
        if self.v_max is None:
            return np.zeros(len(u), bool)
        return self.demand(u) > self.v_max * (1 - margin)

    def saturated(self, u: np.ndarray) -> np.ndarray:
        """True where the command asks more than the rim-speed limit (by 2 %)."""
        if self.v_max is None:
            return np.zeros(len(u), bool)
        return self.demand(u) > 1.02 * self.v_max


def _lever_grid(axes: np.ndarray, opt: LimitOptions) -> tuple[np.ndarray, bool]:
    """(levers to try, whether the lever can be identified): both translation and yaw must be excited."""
    trans, yaw = bool(axes[0] or axes[1]), bool(axes[2])
    if trans and yaw:
        return np.linspace(opt.lever_min_m, opt.lever_max_m, opt.lever_steps), True
    return np.array([0.0 if trans else 1.0]), False


def fit_static(u: np.ndarray, v: np.ndarray, axes: np.ndarray, opt: LimitOptions = LimitOptions()) -> StaticFit:
    """Step 1 of the module docstring on settled samples: aligned commands u (n, 3), measured twists v (n, 3).

    Length: to be split (issue 22): the alternating search (limit and lever, then A and d) and the significance test of
    the limit are separate stages."""
    u, v = np.asarray(u, float), np.asarray(v, float)
    axes = np.asarray(axes, bool)
    idx = np.flatnonzero(axes)
    sc = _scale(u, axes)

    def cost(pred, w=None):
        e = ((v[:, idx] - pred[..., idx]) / sc[idx]) ** 2
        return e.sum(axis=(-1, -2)) if w is None else (e.sum(axis=-1) * w).sum(axis=-1)

    A_lin, d_lin = least_squares(u, v, axes)
    cost_lin = float(cost(u @ A_lin.T + d_lin))
    levers, lever_id = _lever_grid(axes, opt)
    A, d = A_lin, d_lin
    best = (None, float(levers[0]), cost_lin)
    prof = np.full(len(levers), np.inf)
    cands = [(None, float(k), np.inf) for k in levers]
    for _ in range(3):
        p = u @ A.T + d
        prof = np.full(len(levers), np.inf)
        cands = []
        for i, k in enumerate(levers):
            D = rim_demand(p, k)
            grid = np.unique(np.quantile(D, np.linspace(0.3, 1.0, opt.speed_steps)))
            for _ in range(2):                      # the quantile grid, then 41 values between its neighbours
                ratio = np.minimum(1.0, grid[:, None] / np.maximum(D[None, :], 1e-12))  # (G, n)
                c = cost(p[None, :, :] * ratio[:, :, None])                             # (G,)
                g = int(np.argmin(c))
                vm_best, c_best = float(grid[g]), float(c[g])
                grid = np.linspace(grid[max(g - 1, 0)], grid[min(g + 1, len(grid) - 1)], 41)
            prof[i] = c_best
            cands.append((vm_best, float(k), c_best))
        vm, k, c = cands[int(np.argmin(prof))]
        # A, d from the samples clearly below the limit: near the kink a small error in the limit or the lever
        # would count saturated samples as linear ones and pull the gains down
        sat = rim_demand(p, k) > vm * (1 - opt.kink_margin)
        if (~sat).sum() <= len(idx) + 1:
            break
        A_new, d_new = least_squares(u[~sat], v[~sat], axes)
        best = (vm, k, c)
        if np.allclose(A_new, A, atol=1e-6) and np.allclose(d_new, d, atol=1e-7):
            break
        A, d = A_new, d_new
    vm, k, _ = best
    if vm is not None:
        A, d, vm, k = _refine_jointly(u, v, axes, sc, A, d, vm, k, lever_id, levers)
    p = u @ A.T + d
    D = rim_demand(p, k)
    beyond = D > 1.02 * vm if vm is not None else np.zeros(len(u), bool)
    n_sat = int(beyond.sum())
    pred = saturate(p, vm, k) if vm is not None else p
    cost_sat = float(cost(pred)) if vm is not None else cost_lin
    # the limit must explain the samples beyond it (their error against the linear law of the samples below it,
    # A u + d, cut by ``improvement``) and be significant against the noise of the rest (the cut of the total error
    # against a linear model fitted on every sample at least 30 times the mean error per sample). The linear law
    # of the beyond samples is the one below the kink, not the fit across it: that fit lowers its gains to meet the
    # saturated samples half-way, and against it a limit that 15 % of the samples reach (a 0.86 m/s limit, wheels
    # asked up to 0.99 m/s) cut their error by only 21 %
    sc_idx = sc[idx]
    e_lin_b = float((((v[beyond][:, idx] - p[beyond][:, idx]) / sc_idx) ** 2).sum())
    e_sat_b = float((((v[beyond][:, idx] - pred[beyond][:, idx]) / sc_idx) ** 2).sum())
    noise = cost_sat / max(len(u), 1)
    reached = (vm is not None and n_sat >= max(opt.min_saturated, opt.min_saturated_fraction * len(u))
               and e_sat_b <= (1 - opt.improvement) * e_lin_b and cost_lin - cost_sat > 30 * noise)
    # levers whose error is within 4 noise variances (the error per sample) of the best: an interval of about 2 sigma
    near = levers[prof <= np.min(prof) * (1 + 4.0 / max(len(u), 1))] if np.isfinite(prof).any() else levers
    lever_range = (float(near.min()), float(near.max()))
    lever_ok = lever_id and reached and (lever_range[1] - lever_range[0]) <= 0.25 * opt.lever_max_m
    if not reached:
        A, d = A_lin, d_lin
        vm, n_sat, cost_sat = None, 0, cost_lin
    return StaticFit(A, d, vm, float(k), lever_range, bool(lever_ok), float(rim_demand(u @ A.T + d, k).max())
                     if len(u) else 0.0, n_sat, cost_lin, cost_sat, A_lin, d_lin, levers,
                     np.array([np.nan if c[0] is None else c[0] for c in cands]) if reached else np.zeros(0),
                     np.array([c[2] for c in cands]) if reached else np.zeros(0), len(u))


class _StaticLSQ:
    """The least squares of the saturating model's static part on samples u, v (n, 3): its parameter vector x = (A's
    identified block row by row, d's identified entries, [the limit if ``limit``], [the lever if ``lever``]) and
    the scaled residual (v - sat(A u + d)) / sc on the identified axes, (n, m). The rest of A, d (the identity rows
    of axes not identified) and a lever not fitted come from ``A``, ``d``, ``k``."""

    def __init__(self, u, v, axes, sc, A, d, k, limit: bool, lever: bool):
        self.u, self.v, self.sc = u, v, sc
        self.idx = np.flatnonzero(axes)
        self.A, self.d, self.k = A, d, k
        self.limit, self.lever = limit, lever

    def pack(self, A, d, vm, k) -> np.ndarray:
        idx = self.idx
        return np.r_[A[np.ix_(idx, idx)].ravel(), d[idx], [vm] if self.limit else [], [k] if self.lever else []]

    def unpack(self, x):
        """(A, d, the limit or None, the lever)"""
        idx, m = self.idx, len(self.idx)
        A_, d_ = self.A.copy(), self.d.copy()
        A_[np.ix_(idx, idx)] = x[:m * m].reshape(m, m)
        d_[idx] = x[m * m:m * m + m]
        vm = float(x[m * m + m]) if self.limit else None
        return A_, d_, vm, float(x[m * m + m + 1]) if self.lever else float(self.k)

    def residual(self, x) -> np.ndarray:
        A_, d_, vm, k = self.unpack(x)
        idx = self.idx
        return (self.v[:, idx] - saturate(self.u @ A_.T + d_, vm, k)[:, idx]) / self.sc[idx]


def _refine_jointly(u, v, axes, sc, A, d, vm, k, lever_id: bool, levers: np.ndarray):
    """A, d, the limit and the lever by one least-squares fit of the saturating model on every settled sample (the
    Gaussian maximum-likelihood fit of step 1), started from the alternating search's answer. The alternation
    (limit on a grid, then A, d on the samples below the kink) stops where neither half alone improves: with a
    gain above 1 on an axis that often saturates (a 1.14 vx gain, half the samples beyond a 0.53 m/s limit) the
    samples left below the kink were the small commands, and it stopped at a vx gain of 1.22 and a lever of 0.16 m
    whose error the truth (1.14, 0.165 m) beat by 6 %; the joint fit reached 1.134. The lever stays inside the
    grid's range (fixed when the log cannot identify it); a fit that does not lower the error is not taken. Only
    the identified axes' block of A and d is fitted: the other rows keep what ``least_squares`` gave them (identity)."""
    from scipy.optimize import least_squares as nls
    lsq = _StaticLSQ(u, v, axes, sc, A, d, k, True, lever_id)
    m = len(lsq.idx)
    lo = np.r_[np.full(m * m + m, -np.inf), 1e-3, [levers.min()] if lever_id else []]
    hi = np.r_[np.full(m * m + m, np.inf), np.inf, [levers.max()] if lever_id else []]
    x0 = np.clip(lsq.pack(A, d, vm, k), lo, hi)

    def res(x):
        return lsq.residual(x).ravel()
    r0 = res(x0)
    try:
        r = nls(res, x0, bounds=(lo, hi), method="trf", x_scale="jac", max_nfev=200)
    except (ValueError, np.linalg.LinAlgError):
        return A, d, vm, k
    if not np.isfinite(r.x).all() or float(r.fun @ r.fun) >= float(r0 @ r0):
        return A, d, vm, k
    return lsq.unpack(r.x)


def _block_normal_equations(residual, x0: np.ndarray, block: np.ndarray, nb: int) -> tuple[np.ndarray, np.ndarray]:
    """Per block b of the samples: J_b^T J_b (nb, p, p) and J_b^T r_b (nb, p) of ``residual`` (x -> (n, m)) at x0,
    summed over the block's samples and the m axes; J by central differences (the saturating model is piecewise
    linear: exact away from the kink)."""
    r0 = residual(x0)
    J = np.empty(r0.shape + (len(x0),))                                                # (n, m, p)
    for i in range(len(x0)):
        h = 1e-6 * max(1.0, abs(x0[i]))
        xp, xm = x0.copy(), x0.copy()
        xp[i] += h
        xm[i] -= h
        J[..., i] = (residual(xp) - residual(xm)) / (2 * h)
    G = np.zeros((nb, len(x0), len(x0)))
    g = np.zeros((nb, len(x0)))
    np.add.at(G, block, np.einsum("nap,naq->npq", J, J))
    np.add.at(g, block, np.einsum("nap,na->np", J, r0))
    return G, g


def gain_intervals(t: np.ndarray, u: np.ndarray, v: np.ndarray, axes: np.ndarray, st: StaticFit,
                   block_s: float = 2.0, resamples: int = 400, level: float = 0.90, seed: int = 0) -> np.ndarray:
    """(3, 2): the ``level`` interval of the diagonal of ``st.A`` (eq:execution (1)), nan where an axis is not
    identified, by a one-step block bootstrap of the fit that gave it.

    ``st`` is the static part fitted on the samples at times t (commands u, twists v; ``SaturatingModel.static_use``
    and ``static_u``): with a limit, the saturating model's least squares on every one of them (its parameters A, d
    of the identified axes, the limit and, where identified, the lever: :func:`_refine_jointly`), else A, d by
    linear least squares. The samples are cut into consecutive blocks of ``block_s`` seconds (the residuals are
    correlated over a held command's response and the drive's steps); each of ``resamples`` resamples draws as many
    blocks with replacement and takes one Gauss-Newton step of the same weighted least squares from the reported
    parameters (the k-step bootstrap of Davidson and MacKinnon, with k = 1; for the linear model it is exact: the
    refit itself). Its percentile interval, expanded for the number of blocks
    (:func:`twin.signals.expanded_levels`), is that of the reported estimate itself: an interval bootstrapped from
    another estimator (the linear fit on the samples below the limit, as before) and shifted onto the reported A
    had the other's spread (in vx 0.9 % apart from it, one profile in 50 by 3.5 %). Fewer than 6 blocks: nan."""
    t, u, v = np.asarray(t, float), np.asarray(u, float), np.asarray(v, float)
    axes = np.asarray(axes, bool)
    out = np.full((3, 2), np.nan)
    idx = np.flatnonzero(axes)
    m = len(idx)
    if len(t) == 0 or m == 0:
        return out
    block = np.floor((t - t[0]) / block_s).astype(int)
    _, block = np.unique(block, return_inverse=True)
    nb = int(block.max()) + 1
    if nb < 6:
        return out
    limit = st.v_max is not None
    lsq = _StaticLSQ(u, v, axes, _scale(u, axes), st.A, st.d, st.lever_m, limit, limit and st.lever_identified)
    x0 = lsq.pack(st.A, st.d, st.v_max, st.lever_m)
    G, g = _block_normal_equations(lsq.residual, x0, block, nb)
    rng = np.random.default_rng(seed)
    counts = rng.multinomial(nb, np.full(nb, 1.0 / nb), size=resamples).astype(float)    # (B, nb)
    H = np.einsum("bk,kpq->bpq", counts, G)
    rhs = counts @ g
    diag_at = np.array([i * m + i for i in range(m)])             # A[idx[i], idx[i]] in x
    est = np.full((resamples, m), np.nan)
    for b in range(resamples):
        try:
            step = -np.linalg.solve(H[b], rhs[b])                  # r(x0 + s) ~ r0 + J s: its weighted minimum
        except np.linalg.LinAlgError:
            continue
        est[b] = x0[diag_at] + step[diag_at]
    est = est[np.isfinite(est).all(axis=1)]
    if len(est) < resamples // 2:
        return out
    out[idx] = np.quantile(est, expanded_levels(level, nb), axis=0).T
    return out


# --- the dynamic part ------------------------------------------------------------------------------------------
class _Integral:
    """The running integral of the held commands, for box averages over a grid step at any delay."""

    def __init__(self, t_cmd: np.ndarray, u_cmd: np.ndarray):
        self.t = np.asarray(t_cmd, float)
        self.u = np.asarray(u_cmd, float)
        dt = np.diff(self.t)
        self.I = np.vstack([np.zeros((1, 3)), np.cumsum(self.u[:-1] * dt[:, None], axis=0)])

    def at(self, t: np.ndarray, j: int) -> np.ndarray:
        """Integral of u_j from t_cmd[0] to t (u_j = its first value before, the last one after)."""
        t = np.asarray(t, float)
        k = np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 1)
        return self.I[k, j] + self.u[k, j] * (t - self.t[k])

    def box(self, tg: np.ndarray, h: float, delay: float, j: int) -> np.ndarray:
        """Mean of u_j(s - delay) over s in [tg - h, tg]."""
        return (self.at(tg - delay, j) - self.at(tg - h - delay, j)) / h


@dataclass
class Candidates:
    L: np.ndarray       # (C, 3) dead times per input axis [s]
    T: np.ndarray       # (C,) lags, or (C, 3) one per axis [s]
    a: np.ndarray       # (C,) acceleration limits [m/s^2 of rim] (inf: none)
    k: np.ndarray | None = None      # (C,) yaw levers (None: the static fit's) [m]
    v_max: np.ndarray | None = None  # (C,) rim-speed limits that go with them [m/s]

    @staticmethod
    def grid(L, T, a) -> "Candidates":
        L = np.atleast_2d(np.asarray(L, float))
        if L.shape[1] == 1:
            L = np.repeat(L, 3, axis=1)
        iL, iT, ia = np.meshgrid(np.arange(len(L)), np.arange(len(T)), np.arange(len(a)), indexing="ij")
        return Candidates(L[iL.ravel()], np.asarray(T, float)[iT.ravel()], np.asarray(a, float)[ia.ravel()])

    def __len__(self):
        return len(self.T)


@dataclass
class DynamicProblem:
    """What the dynamic fit simulates against: the commands, the samples it scores, the static model."""
    t_cmd: np.ndarray
    u_cmd: np.ndarray
    ts: np.ndarray          # sample (odometry) times [s]
    vs: np.ndarray          # measured twists (M, 3)
    use: np.ndarray         # (M,) samples that count
    block: np.ndarray       # (M,) block index of each sample (bootstrap)
    axes: np.ndarray        # identified axes
    static: StaticFit
    h: float = 0.01
    avg_s: float = 0.0      # the odometry reports the mean twist over this span before its time [s]
    #: (3,) standard deviation per axis of a residual redrawn with every command and added before the wheel limits
    #: (``residual_sd``); None or zeros: the noiseless model
    resid_sd: np.ndarray | None = None
    resid_draws: int = 0    # draws of that residual the prediction averages over (LimitOptions.residual_draws)
    resid_seed: int = 0

    def __post_init__(self):
        self.integral = _Integral(self.t_cmd, self.u_cmd)
        self.scale = _scale(np.column_stack([np.interp(self.ts, self.t_cmd, self.u_cmd[:, j]) for j in range(3)]),
                            self.axes)
        t0 = max(float(self.ts[0]), float(self.t_cmd[0]))
        t1 = float(self.ts[-1])
        self.tg = t0 + self.h * np.arange(int(np.floor((t1 - t0) / self.h)) + 2)
        self.nblocks = int(self.block.max()) + 1 if len(self.block) else 1
        # samples between grid points n-1 and n are scored at step n (linear interpolation)
        ok = self.use & (self.ts > self.tg[0]) & (self.ts <= self.tg[-1])
        m = np.flatnonzero(ok)
        n = np.searchsorted(self.tg, self.ts[m], side="left")
        self._steps = {}
        for mi, ni in zip(m, n):
            self._steps.setdefault(int(ni), []).append(int(mi))

    def _tables(self, cand: Candidates):
        """What the loop reads of the candidates' dead times, per axis, padded to the most unique ones (U): the
        command box averages ``utab`` (3, N, U) and each candidate's column ``uinv`` (C, 3); the residual's draws
        (R, ncmd, 3) (R = 0: none), and for them the command in force at each step's end ``rk`` and the fraction of
        the step it covers ``rf`` (3, N, U) (the residual box-averaged over a step as the commands are)."""
        cols = [np.unique(cand.L[:, j], return_inverse=True) for j in range(3)]
        N, U = len(self.tg), max(len(uniq) for uniq, _ in cols)
        utab = np.zeros((3, N, U))
        for j, (uniq, _) in enumerate(cols):
            utab[j, :, :len(uniq)] = np.array([self.integral.box(self.tg, self.h, L, j) for L in uniq]).T
        uinv = np.ascontiguousarray(np.column_stack([inv for _, inv in cols]), dtype=np.int64)
        if self.resid_sd is None or self.resid_draws <= 0 or not np.any(np.asarray(self.resid_sd) > 0):
            return utab, uinv, np.zeros((0, 1, 3)), np.zeros((3, 1, 1), np.int64), np.zeros((3, 1, 1))
        rng = np.random.default_rng(self.resid_seed)
        half = rng.standard_normal(((self.resid_draws + 1) // 2, len(self.t_cmd), 3)) * np.asarray(self.resid_sd, float)
        draws = np.concatenate([half, -half])          # antithetic pairs (an odd count gets one more): mean 0
        rk, rf = np.zeros((3, N, U), np.int64), np.zeros((3, N, U))
        for j, (uniq, _) in enumerate(cols):
            end = self.tg[:, None] - uniq[None, :]
            k = np.clip(np.searchsorted(self.t_cmd, end, side="right") - 1, 0, len(self.t_cmd) - 1)
            rk[j, :, :len(uniq)] = k
            rf[j, :, :len(uniq)] = np.where(k > 0, np.clip((end - self.t_cmd[k]) / self.h, 0.0, 1.0), 1.0)
        return utab, uinv, draws, rk, rf

    def _constants(self, cand: Candidates):
        """Per candidate: the yaw lever and rim-speed limit, the lag's step factor (C, 3) and the acceleration
        limit's budget per step (C,); the state at the first step, the odometry's average in steps, the axes'
        weights."""
        C, st = len(cand), self.static
        kc = np.asarray(cand.k if cand.k is not None else np.full(C, st.lever_m), float)
        vmc = np.asarray(cand.v_max if cand.v_max is not None else np.full(C, np.inf if st.v_max is None else st.v_max),
                         float)
        T = cand.T if cand.T.ndim == 2 else cand.T[:, None]
        alpha = np.ascontiguousarray(np.broadcast_to(np.where(T > 0, 1.0 - np.exp(-self.h / np.maximum(T, 1e-12)),
                                                              1.0), (C, 3)))
        room = np.asarray(cand.a * self.h, float)
        v0 = np.array([np.interp(self.tg[0], self.ts, self.vs[:, j]) for j in range(3)])
        K = int(round(self.avg_s / self.h))            # the odometry's average: trapezoid over the last K steps
        wsc = np.where(self.axes, 1.0 / self.scale, 0.0)
        return kc, vmc, alpha, room, v0, K, wsc

    def simulate(self, cand: Candidates, keep: bool = False):
        """Run the candidates; returns the error per (candidate, block, axis) (C, B, 3), and with ``keep`` also the
        prediction y, the saturated target s and the delayed command u at every scored sample (each (C, M, 3)).
        The loop is compiled (:func:`_simulate_kernel`); :meth:`simulate_reference` is the same model in numpy,
        vectorised over the candidates (equal to rounding: ``tests/twin/test_twin_limits.py``)."""
        C, st = len(cand), self.static
        utab, uinv, draws, rk, rf = self._tables(cand)
        kc, vmc, alpha, room, v0, K, wsc = self._constants(cand)
        order = sorted(self._steps)
        s_n = np.array([n for n in order for _ in self._steps[n]], np.int64)
        s_m = np.array([m for n in order for m in self._steps[n]], np.int64)
        s_f = np.array([(self.ts[m] - self.tg[n - 1]) / self.h for n in order for m in self._steps[n]], float)
        M = len(self.ts)
        out = [np.zeros((C, M, 3)) if keep else np.zeros((0, 0, 3)) for _ in range(3)]
        err = _simulate_kernel(utab, uinv, np.ascontiguousarray(st.A, float), np.asarray(st.d, float), kc, vmc,
                               bool(np.isfinite(vmc).any()), bool(np.isfinite(cand.a).any()), room, alpha, v0, K,
                               s_n, s_m, s_f, np.ascontiguousarray(self.vs, float), np.asarray(self.block, np.int64),
                               wsc, self.nblocks, draws, rk, rf, keep, *out)
        return (err, *out) if keep else err

    def simulate_reference(self, cand: Candidates, keep: bool = False):
        """:meth:`simulate` in numpy (the reference its compiled loop is tested against): the state of every
        candidate (and of each of the residual's draws, a leading axis) steps together.

        Length: one vectorised time-stepping loop over all candidates: its state (x, y, the odometry-average buffer)
        carries from step to step; the setup above builds the tables the loop reads."""
        C, st = len(cand), self.static
        A, d = st.A, st.d
        utab, uinv, draws, rk, rf = self._tables(cand)
        kc, vmc, alpha, room, v0, K, wsc = self._constants(cand)
        room = room[:, None]
        R = len(draws)
        y = np.tile(v0, (C, 1))
        xs = np.broadcast_to(y, (R, C, 3)).copy() if R else y.copy()     # the limiter's state (per draw)
        err = np.zeros((C, self.nblocks, 3))
        pred, targ, inp = (np.zeros((C, len(self.ts), 3)) for _ in range(3)) if keep else (None, None, None)
        has_lim = np.isfinite(vmc).any()
        has_a = np.isfinite(cand.a).any()
        u = np.empty((C, 3))
        buf = [y.copy() for _ in range(K + 1)] if K > 0 else None
        run = sum(buf) if K > 0 else None
        ya = y.copy()
        for n in range(len(self.tg)):
            for j in range(3):
                u[:, j] = utab[j, n, uinv[:, j]]
            p = u @ A.T + d
            if R:                                 # each draw's residual, (R, C, 3); the limits act on each draw
                p = p + _residual_at(draws, rk, rf, uinv, n)
            if has_lim:
                ap = np.abs(p)
                D = ap[..., 0] + ap[..., 1] + kc * ap[..., 2]
                p = p * np.minimum(1.0, vmc / np.maximum(D, 1e-12))[..., None]
            if has_a:
                step = p - xs
                ast = np.abs(step)
                rim = (ast[..., 0] + ast[..., 1] + kc * ast[..., 2])[..., None]
                xs = xs + step * np.minimum(1.0, room / np.maximum(rim, 1e-12))
            else:
                xs = p
            x, p = (xs.mean(axis=0), p.mean(axis=0)) if R else (xs, p)   # the lag and the average are linear
            y = y + (x - y) * alpha
            ya_prev = ya
            if K > 0:
                old = buf.pop(0)
                buf.append(y)
                run = run - old + y
                ya = (run - 0.5 * (buf[0] + y)) / K
            else:
                ya = y
            ms = self._steps.get(n)
            if ms is not None:
                for mi in ms:
                    f = (self.ts[mi] - self.tg[n - 1]) / self.h
                    yi = ya_prev + (ya - ya_prev) * f
                    err[:, self.block[mi], :] += ((yi - self.vs[mi]) * wsc) ** 2
                    if keep:
                        pred[:, mi] = yi
                        targ[:, mi] = p
                        inp[:, mi] = u
        return (err, pred, targ, inp) if keep else err


@kernel
def _simulate_kernel(utab, uinv, A, d, kc, vmc, has_lim, has_a, room, alpha, v0, K, s_n, s_m, s_f, vs, block,
                     wsc, nblocks, draws, rk, rf, keep, pred, targ, inp):
    """:meth:`DynamicProblem.simulate`'s loop, one candidate after another (they are independent): ``utab`` (3, N,
    U) the command box averages per axis and unique dead time, ``uinv`` (C, 3) each candidate's column; the scored
    samples ``s_m`` at steps ``s_n`` (ascending) at fraction ``s_f`` of the step; ``draws`` (R, ncmd, 3) the
    residual's draws (R = 0: none) with ``rk``, ``rf`` (3, N, U) the command in force at each step's end and the
    fraction of the step it covers. Returns the error per (candidate, block, axis); fills ``pred``, ``targ``, ``inp``
    (C, M, 3) with ``keep``.

    Length: the model of the module docstring, step by step, in plain floats: the residual's draws (each through
    the saturation and the acceleration limit), the lag, the odometry's average and the scoring."""
    C = uinv.shape[0]
    N = utab.shape[1]
    R = draws.shape[0]
    S = s_n.shape[0]
    err = np.zeros((C, nblocks, 3))
    u = np.empty(3)
    p = np.empty(3)
    x = np.empty(3)
    y = np.empty(3)
    ya = np.empty(3)
    yp = np.empty(3)
    xm = np.empty(3)
    pm = np.empty(3)
    xr = np.empty((max(R, 1), 3))
    pr = np.empty(3)
    buf = np.empty((K + 1, 3))
    run = np.empty(3)
    for c in range(C):
        for j in range(3):
            x[j] = v0[j]
            y[j] = v0[j]
            ya[j] = v0[j]
            run[j] = 0.0
            for r in range(R):
                xr[r, j] = v0[j]
            for b in range(K + 1):
                buf[b, j] = v0[j]
        for b in range(K + 1):
            for j in range(3):
                run[j] += buf[b, j]
        head = 0
        si = 0
        for n in range(N):
            for j in range(3):
                u[j] = utab[j, n, uinv[c, j]]
            for i in range(3):
                p[i] = u[0] * A[i, 0] + u[1] * A[i, 1] + u[2] * A[i, 2] + d[i]
            if R > 0:
                for j in range(3):
                    xm[j] = 0.0
                    pm[j] = 0.0
                for r in range(R):
                    for j in range(3):
                        kk = rk[j, n, uinv[c, j]]
                        f = rf[j, n, uinv[c, j]]
                        prev = draws[r, kk - 1, j] if kk > 0 else draws[r, 0, j]
                        pr[j] = p[j] + (prev + (draws[r, kk, j] - prev) * f)
                    _limit(pr, xr[r], kc[c], vmc[c], has_lim, has_a, room[c])
                    for j in range(3):
                        xm[j] += xr[r, j]
                        pm[j] += pr[j]
                for j in range(3):
                    x[j] = xm[j] / R
                    p[j] = pm[j] / R
            else:
                _limit(p, x, kc[c], vmc[c], has_lim, has_a, room[c])
            for j in range(3):
                y[j] = y[j] + (x[j] - y[j]) * alpha[c, j]
                yp[j] = ya[j]
            if K > 0:
                for j in range(3):                  # the ring buffer: oldest out, y in
                    old = buf[head, j]
                    buf[head, j] = y[j]
                    run[j] = run[j] - old + y[j]
                head = (head + 1) % (K + 1)
                for j in range(3):
                    ya[j] = (run[j] - 0.5 * (buf[head, j] + y[j])) / K
            else:
                for j in range(3):
                    ya[j] = y[j]
            while si < S and s_n[si] == n:
                mi = s_m[si]
                f = s_f[si]
                for j in range(3):
                    yi = yp[j] + (ya[j] - yp[j]) * f
                    e = (yi - vs[mi, j]) * wsc[j]
                    err[c, block[mi], j] += e * e
                    if keep:
                        pred[c, mi, j] = yi
                        targ[c, mi, j] = p[j]
                        inp[c, mi, j] = u[j]
                si += 1
    return err


@kernel
def _limit(p, x, k, vm, has_lim, has_a, room):
    """In place: ``p`` saturated (all wheels scaled together) and ``x`` moved toward it by the acceleration
    limit's budget ``room`` (``x = p`` without one)."""
    if has_lim:
        D = abs(p[0]) + abs(p[1]) + k * abs(p[2])
        s = min(1.0, vm / max(D, 1e-12))
        for j in range(3):
            p[j] = p[j] * s
    if has_a:
        rim = abs(p[0] - x[0]) + abs(p[1] - x[1]) + k * abs(p[2] - x[2])
        s = min(1.0, room / max(rim, 1e-12))
        for j in range(3):
            x[j] = x[j] + (p[j] - x[j]) * s
    else:
        for j in range(3):
            x[j] = p[j]


def _residual_at(draws, rk, rf, uinv, n: int) -> np.ndarray:
    """(R, C, 3): each draw's residual box-averaged over grid step ``n`` at each candidate's dead times
    (:meth:`DynamicProblem._tables`)."""
    out = np.empty((draws.shape[0], uinv.shape[0], 3))
    for j in range(3):
        kn, fn = rk[j, n, uinv[:, j]], rf[j, n, uinv[:, j]]
        cur, prev = draws[:, kn, j], draws[:, np.maximum(kn - 1, 0), j]
        out[:, :, j] = prev + (cur - prev) * fn
    return out


@dataclass
class DynamicFit:
    """The dynamic part (step 2 of the module docstring)."""
    latency_s: np.ndarray               # (3,) dead time per axis [s] (nan: not identified)
    latency_ci_s: np.ndarray            # (3, 2) bootstrap 5-95 % of the dead time at the axis's lag [s]
    lag_s: float                        # the common first-order lag T (stages 1-3) [s]
    accel_max: float | None             # rim acceleration limit [m/s^2] (None: none seen)
    accel_floor: float                  # without one, the response is at least this fast [m/s^2]
    cost: float
    cost_no_accel: float
    notes: list[str] = field(default_factory=list)
    lever_m: float | None = None        # the yaw lever the transients chose among the plausible static ones
    lags_s: np.ndarray | None = None    # (3,) the first-order lag per axis (stage 4; None: lag_s on every axis) [s]

    @property
    def axis_lags_s(self) -> np.ndarray:
        """(3,) the lag of each axis [s]."""
        return np.full(3, self.lag_s) if self.lags_s is None else np.asarray(self.lags_s, float)

    def candidate(self) -> Candidates:
        L = np.where(np.isfinite(self.latency_s), self.latency_s, np.nanmax(self.latency_s))
        return Candidates(L[None, :], self.axis_lags_s[None, :],
                          np.array([np.inf if self.accel_max is None else self.accel_max]))


def _best(err: np.ndarray, axes: np.ndarray) -> tuple[int, np.ndarray]:
    """The candidate that best explains every identified axis, and each candidate's error: the geometric mean over
    the axes of their summed squared errors. Minimising it is the Gaussian maximum-likelihood fit with an unknown
    noise variance per axis (sum_j n log SSE_j, the variances concentrated out), so an axis whose measurement is
    noisier than the others (a Mecanum base's yaw rate: its rollers rock the body) does not choose the common lag
    and acceleration limit for all; it is also free of the axes' units and scales."""
    sse = err[:, :, axes].sum(axis=1)                                    # (C, identified axes)
    tot = np.exp(np.mean(np.log(np.maximum(sse, 1e-300)), axis=1))
    return int(np.argmin(tot)), tot


def fit_dynamic(prob: DynamicProblem, opt: LimitOptions = LimitOptions(), seed: int = 0,
                start: tuple[float, float, float] | None = None) -> DynamicFit:
    """Step 2 of the module docstring (``start`` = (L, T, a) skips the coarse stages).

    Length: the search stages 1-4 of step 2 in the module docstring, in order; each numbered block narrows the previous
    block's (L0, T0, a0)."""
    axes = prob.axes
    lags = np.asarray(opt.lags_s)
    acc = np.concatenate([np.geomspace(opt.accel_min, opt.accel_max, 16), [np.inf]])
    if start is None:
        # 1. common dead time and lag, no acceleration limit
        L1 = np.arange(0.0, opt.max_delay_s + 1e-9, 0.02)
        c1 = Candidates.grid(L1[:, None], lags, [np.inf])
        i, _ = _best(prob.simulate(c1), axes)
        L0, T0 = float(c1.L[i, 0]), float(c1.T[i])
        # 2. acceleration limit (and none), dead time at or below the first guess (a ramp delays the response)
        L2 = np.clip(L0 + np.arange(-0.12, 0.041, 0.02), 0.0, opt.max_delay_s)
        T2 = np.unique(np.clip([0.0, T0 / 2, T0, 0.05, 0.1], 0, None))
        c2 = Candidates.grid(np.unique(L2)[:, None], T2, acc)
        i, _ = _best(prob.simulate(c2), axes)
        L0, T0, a0 = float(c2.L[i, 0]), float(c2.T[i]), float(c2.a[i])
    else:
        L0, T0, a0 = (float(x) for x in start)
    # 3. finer, with and without the limit
    L3 = np.clip(L0 + np.arange(-0.015, 0.0151, 0.005), 0.0, opt.max_delay_s)
    T3 = np.unique(np.clip(np.r_[0.0, T0 * np.array([0.5, 0.75, 1.0, 1.33, 2.0]), T0 + 0.01], 0, None))
    a3 = np.r_[a0 * np.geomspace(0.8, 1.25, 7), np.inf] if np.isfinite(a0) else np.array([np.inf])
    c3 = Candidates.grid(np.unique(L3)[:, None], T3, a3)
    err3 = prob.simulate(c3)
    i, tot = _best(err3, axes)
    L0, T0, a0 = float(c3.L[i, 0]), float(c3.T[i]), float(c3.a[i])
    best_cost = float(tot[i])
    none = ~np.isfinite(c3.a)
    cost_none = float(tot[none].min()) if none.any() else best_cost
    if np.isfinite(a0) and cost_none <= (1 + opt.accel_gain) * best_cost:
        j = int(np.flatnonzero(none)[np.argmin(tot[none])])
        L0, T0, a0, best_cost = float(c3.L[j, 0]), float(c3.T[j]), np.inf, cost_none
    # 3b. the yaw lever among those the static limit allows (a combined step's ramp depends on it)
    lever = None
    levers = prob.static.plausible_levers() if opt.lever_by_transients else np.array([prob.static.lever_m])
    if len(levers) > 1:
        vms = np.array([prob.static.at_lever(k).v_max for k in levers])
        La = np.clip(L0 + np.array([-0.01, -0.005, 0.0, 0.005, 0.01]), 0.0, opt.max_delay_s)
        aa = a0 * np.array([0.9, 0.95, 1.0, 1.05, 1.1]) if np.isfinite(a0) else np.array([np.inf])
        iL, ia, ik = np.meshgrid(np.arange(len(La)), np.arange(len(aa)), np.arange(len(levers)), indexing="ij")
        c3b = Candidates(np.repeat(La[iL.ravel()][:, None], 3, axis=1), np.full(iL.size, T0), aa[ia.ravel()],
                         levers[ik.ravel()], vms[ik.ravel()])
        i, tot3b = _best(prob.simulate(c3b), axes)
        L0, a0, lever = float(c3b.L[i, 0]), float(c3b.a[i]), float(c3b.k[i])
        best_cost = float(tot3b[i])
        prob = DynamicProblem(prob.t_cmd, prob.u_cmd, prob.ts, prob.vs, prob.use, prob.block, prob.axes,
                              prob.static.at_lever(lever), prob.h, prob.avg_s)
    # 4. dead time and lag per axis (the others at the common ones), bootstrap over blocks: the axes of one base
    # need not respond alike (a Mecanum base's yaw, turned by its rollers' friction, follows more slowly than its
    # translation), and a lag shared with a slower axis would call that axis settled while it still moves
    offs = np.arange(-0.05, 0.0501, 0.005)
    lag_grid = np.unique(np.r_[lags, T0])
    lat, lag_axes, ci, _ = _axis_search(prob, np.full(3, L0), np.full(3, T0), a0, offs, [lag_grid] * 3, opt, seed)
    notes = []
    for j in np.flatnonzero(axes):
        if np.isfinite(lat[j]) and (abs(lat[j] - (L0 + offs[0])) < 1e-9 or abs(lat[j] - (L0 + offs[-1])) < 1e-9):
            notes.append(f"the {AXES[j]} dead time sits at the edge of its search ({lat[j]:.3f} s, common "
                         f"{L0:.3f} s +- 0.05 s): that axis responds unlike the others")
    if np.isfinite(a0) and a0 >= opt.accel_max:      # at the top of the grid: no limit the log can show
        a0 = np.inf
    floor = float(opt.accel_max) if not np.isfinite(a0) else float(a0)
    return DynamicFit(lat, ci, T0, None if not np.isfinite(a0) else a0, floor, best_cost, cost_none, notes, lever,
                      lag_axes)


def _choose_common_limit(weights: np.ndarray, groups: dict, full: dict):
    """The acceleration limit common to the axes and each axis's candidate at it, per weighting of the blocks
    (``_axis_search``). ``weights`` (R, B); ``groups[j][q]``: the candidate indices of axis j at limit q; ``full[j][q]``
    (K, B): their errors on axis j per block. The limit: the least geometric mean over the axes of each axis's best
    weighted error at it (as ``_best``); returns the limit's index (R,) and per axis the chosen candidate (R,)."""
    R, n_limits = len(weights), len(next(iter(full.values())))
    score = np.zeros((R, n_limits))
    best = {j: np.zeros((R, n_limits), int) for j in groups}
    for j in groups:
        for q, e in enumerate(full[j]):
            tot = weights @ e.T                                        # (R, K)
            k = np.argmin(tot, axis=1)
            best[j][:, q] = groups[j][q][k]
            score[:, q] += np.log(np.maximum(tot[np.arange(R), k], 1e-300))
    qs = np.argmin(score, axis=1)
    return qs, {j: best[j][np.arange(R), qs] for j in groups}


def _axis_search(prob: DynamicProblem, L_base: np.ndarray, T_base: np.ndarray, a: float, offs: np.ndarray,
                 lag_sets: list, opt: LimitOptions, seed: int = 0, accel_rel: tuple[float, ...] = ()):
    """Each identified axis's dead time (L_base[j] + offs) and lag (lag_sets[j]), the other axes at their base
    values, by that axis's own error; and the 5-95 % bootstrap interval over the blocks of its half-step delay
    (dead time + T ln 2: what the log pins down, dead time and lag trade off), given as the dead time at the
    chosen lag. Returns (dead times (3,), lags (3,), intervals (3, 2)); nan on the other axes.

    ``accel_rel``: acceleration limits a * each (with a finite ``a``) are candidates too. The limit is common to
    the axes: the point estimate and each resample choose it by the geometric mean over the axes of each axis's
    best error at that limit (as the coarse search's _best does), then each axis's dead time and lag at it; the
    chosen limit is returned fourth. Behind a ramp a slower limit reads as a later start, so an interval at a
    fixed limit leaves out the limit's own error (the recovery's latency intervals missed most at the lowest
    limits), and choosing the limit in the resamples alone moved the interval away from the point estimate."""
    axes = prob.axes
    rows, lag_rows, acc_rows, which = [], [], [], []
    accels = [a] + ([a * r for r in accel_rel] if np.isfinite(a) else [])
    for j in np.flatnonzero(axes):
        for aa in accels:
            for o in offs:
                for T in lag_sets[j]:
                    L = np.array(L_base, float)
                    L[j] = max(L_base[j] + o, 0.0)
                    Tj = np.array(T_base, float)
                    Tj[j] = T
                    rows.append(L)
                    lag_rows.append(Tj)
                    acc_rows.append(aa)
                    which.append(j)
    lat = np.full(3, np.nan)
    ci = np.full((3, 2), np.nan)
    lag_axes = np.array(T_base, float)
    if not rows:
        return lat, lag_axes, ci, a
    rng = np.random.default_rng(seed)
    acc_rows = np.array(acc_rows, float)
    c = Candidates(np.array(rows), np.array(lag_rows), acc_rows)
    err = prob.simulate(c)
    which = np.array(which)
    W = rng.multinomial(prob.nblocks, np.full(prob.nblocks, 1.0 / prob.nblocks), size=opt.bootstrap)
    step = float(np.min(np.diff(offs))) if len(offs) > 1 else 0.0
    ax = np.flatnonzero(axes)
    groups = {j: [np.flatnonzero((which == j) & (acc_rows == aa)) for aa in accels] for j in ax}
    full = {j: [err[g][:, :, j] for g in groups[j]] for j in ax}          # (K, B) per axis and limit
    q0, b0 = _choose_common_limit(np.ones((1, prob.nblocks)), groups, full)
    a_best = float(accels[int(q0[0])])
    _, picks_all = _choose_common_limit(W.astype(float), groups, full)
    for j in ax:
        best = int(b0[j][0])
        lat[j], lag_axes[j] = float(c.L[best, j]), float(c.T[best, j])
        picks = picks_all[j]
        half = c.L[picks, j] + c.T[picks, j] * np.log(2)
        # the search is on a grid (dead time every ``step`` s): every resample can pick the same point, and the
        # point itself is off the truth by up to half a step, which the resamples cannot show; so each end
        # moves out by half a step (else a 90 % interval reads [0.050, 0.050]); the quantiles are those of a 90 %
        # interval expanded for the few blocks (signals.expanded_levels: 2.1-97.9 % at 8 blocks)
        q = expanded_levels(0.90, prob.nblocks)
        ci[j] = np.quantile(half, q) - lag_axes[j] * np.log(2) + np.array([-0.5, 0.5]) * step
    return lat, lag_axes, ci, a_best


def refine_dynamic(prob: DynamicProblem, dyn: DynamicFit, opt: LimitOptions = LimitOptions(),
                   seed: int = 0) -> DynamicFit:
    """Each axis's dead time and lag again, on ``prob``'s finer grid (``LimitOptions.fine_step_s``) and near the
    values ``dyn`` has: dead time within +-``fine_span_s`` every ``fine_dead_s``, lags around its own. On the
    10 ms grid of the search an acceleration-limited ramp can only start on a grid point (the box average of a
    command that steps inside a step asks the limiter for its whole budget), so the dead times of a limited
    response come out in 10 ms steps; the intervals come from this search."""
    if not np.isfinite(dyn.latency_s).any():
        return dyn
    offs = np.arange(-opt.fine_span_s, opt.fine_span_s + 1e-9, opt.fine_dead_s)
    L = np.where(np.isfinite(dyn.latency_s), dyn.latency_s, np.nanmedian(dyn.latency_s))
    T = dyn.axis_lags_s
    lag_sets = [np.unique(np.clip(T[j] + np.arange(-0.0075, 0.00751, 0.0025), 0.0, None)) for j in range(3)]
    a = np.inf if dyn.accel_max is None else dyn.accel_max
    lat, lags, ci, a_best = _axis_search(prob, L, T, a, offs, lag_sets, opt, seed, opt.fine_accel_rel)
    return replace(dyn, latency_s=lat, latency_ci_s=ci, lags_s=lags,
                   accel_max=None if not np.isfinite(a_best) else a_best)


@dataclass
class SaturatingModel:
    """The whole saturating execution model of a log, and what it says about each sample."""
    static: StaticFit
    dynamic: DynamicFit
    y: np.ndarray            # (M, 3) the model's prediction at every sample
    target: np.ndarray       # (M, 3) the saturated target sat(A u(t - L) + d)
    u_delayed: np.ndarray    # (M, 3) the commands delayed by the dead times (box-averaged over a grid step)
    settled: np.ndarray      # (M,) the model's response has converged to its target
    saturated: np.ndarray    # (M,) the command asks more than the rim-speed limit
    scored: np.ndarray       # (M,) samples inside the simulated span
    static_use: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))   # (M,) the samples ``static`` was fitted on
    static_u: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))       # (M, 3) with these commands


def _predict(t_cmd, u_cmd, t, v, axes, static: StaticFit, dyn: DynamicFit, h: float, avg_s: float = 0.0):
    prob = DynamicProblem(t_cmd, u_cmd, t, v, np.ones(len(t), bool), np.zeros(len(t), int), axes, static, h, avg_s)
    _, y, s, u = prob.simulate(dyn.candidate(), keep=True)
    scored = np.zeros(len(t), bool)
    for ms in prob._steps.values():
        scored[ms] = True
    return y[0], s[0], u[0], scored


def settled_by_model(y: np.ndarray, target: np.ndarray, axes: np.ndarray,
                     tol: tuple[float, float, float] = (0.02, 0.02, 0.04), rel: float = 0.03) -> np.ndarray:
    """True where the model's response is within max(tol_j, rel |target_j|) of its target on every identified
    axis (the dynamics have caught up: eq:execution (1) is a static map and holds there)."""
    lim = np.maximum(np.asarray(tol, float)[None, :], rel * np.abs(target))
    ok = np.abs(y - target) <= lim
    return np.all(ok[:, np.asarray(axes, bool)], axis=1)


def steady_samples(t: np.ndarray, v: np.ndarray, axes: np.ndarray, window_s: float = 0.3,
                   tol: tuple[float, float, float] = (0.02, 0.02, 0.04), rel: float = 0.03) -> np.ndarray:
    """True where the *measured* twist has stopped changing: on every identified axis the mean over the last half
    of a trailing ``window_s`` differs from the mean over its first half by at most max(tol_j, 4 noise standard
    errors) + rel |v_j| (the noise from the median absolute first difference). A model can call a sample settled
    because it believes the robot reached a limit it has not; the measurement cannot."""
    t, v = np.asarray(t, float), np.asarray(v, float)
    n = len(t)
    out = np.ones(n, bool)
    i_mid = np.searchsorted(t, t - window_s / 2, side="left")
    i_start = np.searchsorted(t, t - window_s, side="left")
    for j in np.flatnonzero(axes):
        c = np.r_[0.0, np.cumsum(v[:, j])]
        n_a = np.arange(n) + 1 - i_mid
        n_b = i_mid - i_start
        ok = (n_a >= 2) & (n_b >= 2)
        a = (c[np.arange(n) + 1] - c[i_mid]) / np.maximum(n_a, 1)
        b = (c[i_mid] - c[i_start]) / np.maximum(n_b, 1)
        sigma = 1.4826 * np.median(np.abs(np.diff(v[:, j]))) / np.sqrt(2) if n > 2 else 0.0
        lim = np.maximum(tol[j], 4 * sigma * np.sqrt(1 / np.maximum(n_a, 1) + 1 / np.maximum(n_b, 1))) + rel * np.abs(a)
        out &= ok & (np.abs(a - b) <= lim)
    return out


def residual_sd(t_cmd: np.ndarray, t: np.ndarray, err: np.ndarray, use: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(3,) standard deviation of the part of the model's error ``err`` (measured - predicted, (M, 3)) that changes
    with each command and holds between commands, on the translation axes (0 on the yaw and on unidentified axes).

    A residual held for one command period Tc, sampled as means over the odometry period P < Tc, has the
    autocovariance sigma^2 (1 - P / Tc) between consecutive samples; noise that changes faster than P has about
    none. So sigma^2 = the lag-one autocovariance of the samples in ``use`` / (1 - P / Tc). The yaw's is left at 0:
    on a Mecanum base its settled error is the rollers' rocking after the wheels (sd 0.09 rad/s on the simulated X3
    where its residual is <= 0.04), correlated over a sample too, and a residual in the yaw moves a ramp's rim
    demand by only the lever (about 0.2 m) times it."""
    sd = np.zeros(3)
    if len(t) < 3 or len(t_cmd) < 2:
        return sd
    P, Tc = float(np.median(np.diff(t))), float(np.median(np.diff(t_cmd)))
    if not (0 < P < Tc):
        return sd
    pair = use[:-1] & use[1:] & (np.diff(t) < 1.5 * P)
    if pair.sum() < 20:
        return sd
    for j in (0, 1):
        if not axes[j]:
            continue
        a, b = err[:-1, j][pair], err[1:, j][pair]
        cov = float(np.mean((a - a.mean()) * (b - b.mean())))
        var = float(np.var(err[use, j]))
        sd[j] = np.sqrt(min(max(cov, 0.0) / (1.0 - P / Tc), var))
    return sd


def fit_model(t_cmd, u_cmd, t, v, axes, cal: np.ndarray, block: np.ndarray, u_init: np.ndarray,
              settled_init: np.ndarray, opt: LimitOptions = LimitOptions(), min_settled: int = 100,
              avg_s: float = 0.0, rounds: int = 3) -> SaturatingModel:
    """Steps 1-2 of the module docstring, iterated: the static part on the settled samples of the calibration blocks
    (``cal``; at first those of ``settled_init``, with the commands ``u_init``), the dynamic part on every sample of
    the calibration blocks; then, up to ``rounds`` times until the static part stops changing, the static part again
    on the samples the model says have settled (and, where the model saturates, whose measured twist has stopped
    changing: :func:`steady_samples`), with the commands delayed by the dead times, and the dynamic part refined;
    last, each axis's dead time and lag on the finer grid (:func:`refine_dynamic`)."""
    axes = np.asarray(axes, bool)
    steady_meas = steady_samples(t, v, axes)

    def predict(st: StaticFit, dyn: DynamicFit, h: float):
        """The model's prediction, target, delayed commands and scored samples, and the samples it calls settled:
        where it has its target saturated, the measurement must agree that the robot stopped changing."""
        y, s, u, scored = _predict(t_cmd, u_cmd, t, v, axes, st, dyn, h, avg_s)
        return y, s, u, scored, settled_by_model(y, s, axes) & scored & (steady_meas | ~st.saturated(u))

    st_use, st_u = cal & settled_init, np.asarray(u_init, float)
    st = fit_static(u_init[st_use], v[st_use], axes, opt)
    dyn = None
    for r in range(rounds + 1):
        prob = DynamicProblem(t_cmd, u_cmd, t, v, cal, block, axes, st, opt.step_s, avg_s)
        if dyn is None:
            dyn = fit_dynamic(prob, opt)
        else:
            a = np.inf if dyn.accel_max is None else dyn.accel_max
            dyn = fit_dynamic(prob, opt, start=(float(np.nanmedian(dyn.latency_s)), dyn.lag_s, a))
        if dyn.lever_m is not None:
            st = st.at_lever(dyn.lever_m)
        y, s, u, scored, settled = predict(st, dyn, opt.step_s)
        use = cal & settled
        if r == rounds or use.sum() < min_settled:
            break
        new = fit_static(u[use], v[use], axes, opt)
        same = ((new.v_max is None) == (st.v_max is None)
                and (new.v_max is None or abs(new.v_max / st.v_max - 1) < 0.01)
                and np.allclose(new.A, st.A, atol=0.005))
        st, st_use, st_u = new, use, u
        if same and r >= 1:
            break
    if opt.fine_step_s < opt.step_s:
        sd = residual_sd(t_cmd, t, v - y, cal & settled, axes) if opt.residual_draws > 0 else None
        prob = DynamicProblem(t_cmd, u_cmd, t, v, cal, block, axes, st, opt.fine_step_s, avg_s, sd,
                              opt.residual_draws)
        dyn = refine_dynamic(prob, dyn, opt)
        y, s, u, scored, settled = predict(st, dyn, opt.fine_step_s)
    return SaturatingModel(st, dyn, y, s, u, settled, st.saturated(u) & scored, scored, st_use, st_u)
