"""The perception-to-actuation delay tau95 of eq:uncertainty_margin (21), from a log of commands, odometry and
(optionally) scans.

Three measurements, all on the log's clock (the odometry on the time base of twin.timebase); scan header stamps
are used only when they are on the log's clock:

1. actuation delay by cross-correlation: commands (held between messages) and measured body velocity are put on
   a common grid; the delay is the lag that maximises the correlation of their *changes* (first differences,
   each axis normalised, summed over the excited axes), refined to below the grid step by a parabola through
   the peak. Correlating changes, not levels, gives a sharp peak at the dead time. The same per axis
   (:class:`AxisDelay`), with a confidence interval by bootstrap over segments (the log cut into ``block_s``
   blocks, the blocks resampled with replacement ``bootstrap`` times, the peak found again each time: the 5-95 %
   range), and a warning when a second peak, at least ``tie_separation_s`` away, reaches ``tie_ratio`` of the
   highest (two candidate delays nearly tie: the log cannot tell them apart).
2. per-edge actuation delays (the distribution): at each clean command step on an axis (the command held before
   and after), the time from the command to the measured response crossing half-way between its settled
   levels before and after (and staying past it for two samples, so that a noise spike is not a crossing). For a
   dead time L followed by a first-order lag T this is L + T ln 2.
3. perception latency per command: the age of the newest scan at the time the command was sent (the command can
   only be based on that scan): t_cmd - t_acq. t_acq is the scan's log time unless its header stamps are on the
   log's clock: ``scan_clock`` "auto" takes the stamps when the median of (log time - stamp) lies in
   [-0.05, ``max_stamp_offset_s``] (a driver's acquisition-to-log latency; beyond it, or negative, the stamps are
   on another clock), "stamps" and "log" force one or the other. The offset found is reported in the notes.

tau95 is the 95th percentile of (actuation delay + perception latency), the two taken as independent: every
per-edge delay is paired with every latency. The actuation delays are those of the translational axes (vx, vy)
when they have at least ``min_edges`` clean edges: eq:uncertainty_margin (21) multiplies tau95 by a translational
relative velocity, and a slower yaw response (a filtered gyro, a yaw-rate ramp) is not a delay of the robot's
translation; otherwise those of every identified axis.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .signals import interp_columns, quantile_upper, zoh

AXES = ("vx", "vy", "wz")


@dataclass(frozen=True)
class DelayOptions:
    grid_s: float = 0.005            # common time grid of the cross-correlation [s]
    max_delay_s: float = 1.0         # largest delay searched [s]
    max_gap_s: float = 0.25          # odometry gaps longer than this are not interpolated across [s]
    edge_min: tuple[float, float, float] = (0.05, 0.05, 0.1)   # smallest command step that is an edge (m/s, m/s, rad/s)
    edge_hold_s: float = 0.35        # the command must be held this long before and after an edge [s]
    settle_window_s: float = 0.1     # settled levels are averaged over this window, at least 2.5 odometry periods [s]
    min_response: float = 0.3        # the measured step must be at least this fraction of the commanded one [-]
    quantile: float = 0.95           # tau95's quantile [-]
    min_edges: int = 5               # fewer clean edges: the distribution is the cross-correlation delay alone
    scan_clock: str = "auto"         # scan acquisition times: "auto", "stamps" (header stamps) or "log" (log times)
    max_stamp_offset_s: float = 0.3  # "auto": stamps this much older than their log times are still the log's clock [s]
    block_s: float = 10.0            # bootstrap segments [s] (at least 6 segments)
    bootstrap: int = 400             # bootstrap resamples [-]
    tie_ratio: float = 0.95          # a second peak this high (of the highest) nearly ties [-]
    tie_separation_s: float = 0.04   # ... if at least this far from the highest [s]


@dataclass
class AxisDelay:
    """The cross-correlation delay of one axis (method 1 of the module docstring) and its confidence."""
    axis: int
    delay_s: float                   # the peak, parabola-refined [s]
    ci_s: tuple[float, float]        # 5-95 % of the bootstrap over segments [s]
    peak: float                      # the correlation at the peak [-]
    runner_up_s: float = float("nan")   # a second peak that nearly ties (nan: none) [s]
    runner_up_peak: float = float("nan")
    edges: int = 0                   # clean edges on this axis
    edge_median_s: float = float("nan")  # their median half-way delay [s]
    curve: np.ndarray | None = None      # the correlation curve over the lags (for the report)

    @property
    def tie(self) -> bool:
        return bool(np.isfinite(self.runner_up_s))


@dataclass
class DelayEstimate:
    xcorr_s: float                           # actuation delay by cross-correlation [s]
    xcorr_lags_s: np.ndarray                 # the correlation curve (for the report)
    xcorr_curve: np.ndarray
    edge_delays_s: np.ndarray                # per-edge actuation delays [s]
    edge_times_s: np.ndarray                 # log times of those edges [s]
    edge_axes: np.ndarray                    # axis index of each edge
    perception_latency_s: np.ndarray         # per-command scan age [s] (empty without scans)
    perception_source: str                   # "header stamps", "log times" or "no scans"
    actuation_median_s: float
    actuation95_s: float
    perception95_s: float
    tau95_s: float
    notes: list[str] = field(default_factory=list)
    axes: dict[int, AxisDelay] = field(default_factory=dict)    # per identified axis
    tau95_axes: tuple[int, ...] = ()                             # the axes whose edges make tau95

def grid_signals(t_cmd, u_cmd, t_odom, v_odom, grid_s: float, max_gap_s: float):
    """Commands (zero-order hold) and measured velocity (interpolated) on a common grid over their overlap.

    Returns (t_grid, u_grid (n,3), v_grid (n,3), valid (n,))."""
    t0 = max(float(t_cmd[0]), float(t_odom[0]))
    t1 = min(float(t_cmd[-1]), float(t_odom[-1]))
    if t1 - t0 < 10 * grid_s:
        return np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, bool)
    tg = t0 + grid_s * np.arange(int(np.floor((t1 - t0) / grid_s)) + 1)
    ug = zoh(t_cmd, u_cmd, tg)
    vg, ok = interp_columns(t_odom, v_odom, tg, max_gap_s)
    return tg, ug, vg, ok & np.all(np.isfinite(ug), axis=1)


def xcorr_delay(u_grid: np.ndarray, v_grid: np.ndarray, valid: np.ndarray, axes, grid_s: float,
                max_delay_s: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Actuation delay [s]: the lag maximising sum over ``axes`` of corr(du(t), dv(t + lag)), parabola-refined.

    Returns (delay, lags (L,), curve (L,))."""
    du = np.diff(u_grid, axis=0)
    dv = np.diff(v_grid, axis=0)
    ok = valid[1:] & valid[:-1]
    n_lag = int(round(max_delay_s / grid_s))
    lags = grid_s * np.arange(n_lag + 1)
    curve = np.zeros(n_lag + 1)
    for j in axes:
        a = np.where(ok, du[:, j], 0.0)
        b = np.where(ok, dv[:, j], 0.0)
        sa, sb = np.sqrt(np.sum(a * a)), np.sqrt(np.sum(b * b))
        if sa == 0 or sb == 0:
            continue
        n = len(a)
        for k in range(min(n_lag + 1, n - 1)):
            curve[k] += np.dot(a[:n - k], b[k:]) / (sa * sb)
    k = int(np.argmax(curve))
    frac = 0.0
    if 0 < k < n_lag:
        y0, y1, y2 = curve[k - 1], curve[k], curve[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            frac = float(np.clip(0.5 * (y0 - y2) / den, -0.5, 0.5))
    return float((k + frac) * grid_s), lags, curve


def edge_delays(t_cmd, u_cmd, t_odom, v_odom, axes, opt: DelayOptions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-edge delays [s] (method 2 of the module docstring). Returns (delays, edge log times, axis of each)."""
    t_cmd = np.asarray(t_cmd, float)
    out_d, out_t, out_a = [], [], []
    dt_odom = float(np.median(np.diff(t_odom))) if len(t_odom) > 1 else 0.0
    w = max(opt.settle_window_s, 2.5 * dt_odom)        # at least two odometry samples per settled level
    for j in axes:
        u = u_cmd[:, j]
        change = np.flatnonzero(np.abs(np.diff(u)) > 1e-9) + 1          # command indices where axis j changes
        if len(change) == 0:
            continue
        times = t_cmd[change]
        prev_times = np.concatenate([[t_cmd[0]], times[:-1]])
        next_times = np.concatenate([times[1:], [t_cmd[-1]]])
        for k, idx in enumerate(change):
            te = times[k]
            step = u[idx] - u[idx - 1]
            if abs(step) < opt.edge_min[j]:
                continue
            if te - prev_times[k] < opt.edge_hold_s or next_times[k] - te < opt.edge_hold_s:
                continue
            pre = (t_odom >= te - w) & (t_odom < te)
            t_end = next_times[k]
            post = (t_odom >= t_end - w) & (t_odom < t_end)
            if pre.sum() < 2 or post.sum() < 2:
                continue
            y0, y1 = v_odom[pre, j].mean(), v_odom[post, j].mean()
            if abs(y1 - y0) < opt.min_response * abs(step) or np.sign(y1 - y0) != np.sign(step):
                continue
            seg = (t_odom >= te) & (t_odom <= min(te + opt.max_delay_s, t_end))
            ts, ys = t_odom[seg], (v_odom[seg, j] - y0) / (y1 - y0)
            above = np.flatnonzero((ys[:-1] >= 0.5) & (ys[1:] >= 0.5))     # crossed for good, not a noise spike
            if len(above) == 0:
                continue
            i = above[0]
            if i == 0:
                tc = ts[0]
            else:
                tc = ts[i - 1] + (0.5 - ys[i - 1]) / (ys[i] - ys[i - 1]) * (ts[i] - ts[i - 1])
            out_d.append(tc - te)
            out_t.append(te)
            out_a.append(j)
    return np.array(out_d), np.array(out_t), np.array(out_a, int)


def stamp_offset(t_scan, stamp_scan) -> float:
    """The median of (log time - header stamp) of the scans [s]."""
    return float(np.median(np.asarray(t_scan, float) - np.asarray(stamp_scan, float)))


def scan_clock(t_scan, stamp_scan, max_offset_s: float = 0.3) -> str:
    """Whether scan header stamps are on the log's clock: "header stamps" if the median of (log time - stamp) is
    within [-0.05, max_offset_s] s, else "log times" (stamps on another clock, or a log written after the fact)."""
    return "header stamps" if -0.05 <= stamp_offset(t_scan, stamp_scan) <= max_offset_s else "log times"


def perception_latency(t_cmd, t_scan, stamp_scan, clock: str = "auto",
                       max_offset_s: float = 0.3) -> tuple[np.ndarray, str]:
    """Age [s] of the newest scan when each command was sent (method 3 of the module docstring); ``clock``
    "auto", "stamps" or "log" chooses the acquisition times.

    Commands before the first scan are left out. Returns (latencies, source of the acquisition times)."""
    t_scan = np.asarray(t_scan, float)
    if len(t_scan) == 0:
        return np.zeros(0), "no scans"
    if clock not in ("auto", "stamps", "log"):
        raise ValueError(f"clock must be auto, stamps or log, got {clock!r}")
    source = {"stamps": "header stamps", "log": "log times"}.get(clock) or scan_clock(t_scan, stamp_scan,
                                                                                    max_offset_s)
    acq = np.minimum(np.asarray(stamp_scan, float), t_scan) if source == "header stamps" else t_scan
    order = np.argsort(t_scan, kind="stable")
    t_recv, acq = t_scan[order], acq[order]
    idx = np.searchsorted(t_recv, np.asarray(t_cmd, float), side="right") - 1
    keep = idx >= 0
    return np.asarray(t_cmd, float)[keep] - acq[idx[keep]], source


def tau95(actuation_s, perception_s, q: float = 0.95) -> float:
    """tau95 of eq:uncertainty_margin (21): the q-quantile (``quantile_upper``) of actuation delay + perception latency,
    with every actuation sample paired with every latency sample (independent sources). No latency samples: the quantile
    of the actuation delays alone."""
    a = np.asarray(actuation_s, float).ravel()
    p = np.asarray(perception_s, float).ravel()
    if len(p) == 0:
        return quantile_upper(a, q)
    if len(p) > 4000:                       # an even subsample keeps the pairing cheap
        p = np.sort(p)[np.linspace(0, len(p) - 1, 4000).round().astype(int)]
    return quantile_upper((a[:, None] + p[None, :]).ravel(), q)


def _refine(curve: np.ndarray, k: int) -> float:
    """Sub-grid peak position (in grid steps) by a parabola through k and its neighbours."""
    if 0 < k < len(curve) - 1:
        y0, y1, y2 = curve[k - 1], curve[k], curve[k + 1]
        den = y0 - 2 * y1 + y2
        if den < 0:
            return k + float(np.clip(0.5 * (y0 - y2) / den, -0.5, 0.5))
    return float(k)


def block_correlations(u_grid, v_grid, valid, j: int, grid_s: float, max_delay_s: float, block_s: float):
    """Per-segment numerators of the change correlation of axis j: N (n_blocks, L) with sum over blocks = the
    curve of :func:`xcorr_delay` for that axis times its norms. Returns (N, norm) or (None, 0) without changes."""
    du = np.diff(u_grid[:, j])
    dv = np.diff(v_grid[:, j])
    ok = valid[1:] & valid[:-1]
    a = np.where(ok, du, 0.0)
    b = np.where(ok, dv, 0.0)
    sa, sb = np.sqrt(np.sum(a * a)), np.sqrt(np.sum(b * b))
    if sa == 0 or sb == 0:
        return None, 0.0
    n_lag = int(round(max_delay_s / grid_s))
    n = len(a)
    nb = max(6, int(round(n * grid_s / block_s)))
    edges = np.linspace(0, n, nb + 1).round().astype(int)
    bpad = np.concatenate([b, np.zeros(n_lag)])
    N = np.array([np.correlate(bpad[e0:e1 + n_lag], a[e0:e1], mode="valid") for e0, e1 in zip(edges, edges[1:])])
    return N, float(sa * sb)


def ties(curve: np.ndarray, grid_s: float, ratio: float, separation_s: float) -> tuple[float, float]:
    """A second local peak of ``curve`` at least ``separation_s`` from the highest and at least ``ratio`` of its
    height: (its lag [s], its height), or (nan, nan)."""
    k = int(np.argmax(curve))
    top = curve[k]
    if not top > 0:
        return float("nan"), float("nan")
    w = 3
    pad = np.concatenate([np.full(w, -np.inf), curve, np.full(w, -np.inf)])
    from numpy.lib.stride_tricks import sliding_window_view
    local = curve >= sliding_window_view(pad, 2 * w + 1).max(axis=1)
    far = np.abs(np.arange(len(curve)) - k) * grid_s >= separation_s
    cand = np.flatnonzero(local & far & (curve >= ratio * top))
    if len(cand) == 0:
        return float("nan"), float("nan")
    c = int(cand[np.argmax(curve[cand])])
    return _refine(curve, c) * grid_s, float(curve[c])


def axis_delays(u_grid, v_grid, valid, axes, opt: "DelayOptions", seed: int = 0) -> dict[int, AxisDelay]:
    """Method 1 per axis, with the bootstrap confidence interval and the near-tie check (module docstring)."""
    rng = np.random.default_rng(seed)
    out = {}
    for j in axes:
        N, norm = block_correlations(u_grid, v_grid, valid, j, opt.grid_s, opt.max_delay_s, opt.block_s)
        if N is None:
            continue
        curve = N.sum(axis=0) / norm
        k = int(np.argmax(curve))
        W = rng.multinomial(len(N), np.full(len(N), 1.0 / len(N)), size=opt.bootstrap).astype(float)
        boot = W @ N
        kb = np.argmax(boot, axis=1)
        d_boot = np.array([_refine(boot[i], kb[i]) for i in range(len(kb))]) * opt.grid_s
        lo, hi = np.quantile(d_boot, [0.05, 0.95])
        r_s, r_p = ties(curve, opt.grid_s, opt.tie_ratio, opt.tie_separation_s)
        out[int(j)] = AxisDelay(int(j), _refine(curve, k) * opt.grid_s, (float(lo), float(hi)), float(curve[k]),
                                r_s, r_p, curve=curve)
    return out


def estimate_delay(t_cmd, u_cmd, t_odom, v_odom, axes, t_scan=None, stamp_scan=None,
                   opt: DelayOptions = DelayOptions()) -> DelayEstimate:
    """All of the module docstring: cross-correlation, per-edge delays, perception latency, tau95."""
    notes: list[str] = []
    tg, ug, vg, ok = grid_signals(t_cmd, u_cmd, t_odom, v_odom, opt.grid_s, opt.max_gap_s)
    d_xc, lags, curve = xcorr_delay(ug, vg, ok, axes, opt.grid_s, opt.max_delay_s)
    per_axis = axis_delays(ug, vg, ok, axes, opt)
    d_edge, t_edge, a_edge = edge_delays(t_cmd, u_cmd, t_odom, v_odom, axes, opt)
    for j, ad in per_axis.items():
        ad.edges = int(np.sum(a_edge == j))
        ad.edge_median_s = float(np.median(d_edge[a_edge == j])) if ad.edges else float("nan")
        if ad.tie:
            notes.append(f"two candidate delays nearly tie on {AXES[j]}: {ad.delay_s:.3f} s (correlation "
                         f"{ad.peak:.3f}) and {ad.runner_up_s:.3f} s ({ad.runner_up_peak:.3f}); the log cannot tell "
                         f"them apart (bootstrap 5-95 %: {ad.ci_s[0]:.3f}-{ad.ci_s[1]:.3f} s)")
    trans = [j for j in axes if j in (0, 1)]
    use_axes = trans if trans and int(np.isin(a_edge, trans).sum()) >= opt.min_edges else list(axes)
    d_use = d_edge[np.isin(a_edge, use_axes)] if len(d_edge) else d_edge
    if len(d_use) >= opt.min_edges:
        actuation = d_use
    else:
        actuation = np.array([d_xc])
        notes.append(f"only {len(d_edge)} clean command steps (a step held {opt.edge_hold_s} s before and after, "
                     f"at least {opt.edge_min} on an axis): the actuation delay distribution is the "
                     f"cross-correlation delay alone, the dead time without the response's rise")
    if not 0 < d_xc < opt.max_delay_s:
        notes.append(f"the cross-correlation peaks at the edge of the search range ({d_xc:.3f} s of "
                     f"0..{opt.max_delay_s} s): the actuation delay is unreliable")
    if t_scan is not None and len(t_scan):
        lat, source = perception_latency(t_cmd, t_scan, stamp_scan, opt.scan_clock, opt.max_stamp_offset_s)
        off = stamp_offset(t_scan, stamp_scan)
        notes.append(f"scan acquisition from {source} (median log time - header stamp {off:+.3f} s"
                     + (", so the acquisition-to-log latency is not counted)" if source == "log times" else ")"))
    else:
        lat, source = np.zeros(0), "no scans"
        notes.append("no scans given: tau95 holds the actuation delay only")
    return DelayEstimate(
        xcorr_s=d_xc, xcorr_lags_s=lags, xcorr_curve=curve, edge_delays_s=d_edge, edge_times_s=t_edge,
        edge_axes=a_edge, perception_latency_s=lat, perception_source=source,
        actuation_median_s=float(np.median(actuation)), actuation95_s=quantile_upper(actuation, opt.quantile),
        perception95_s=quantile_upper(lat, opt.quantile) if len(lat) else 0.0,
        tau95_s=tau95(actuation, lat, opt.quantile), notes=notes, axes=per_axis,
        tau95_axes=tuple(int(j) for j in use_axes) if len(d_use) >= opt.min_edges else tuple(int(j) for j in axes))
