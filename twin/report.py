"""Plots of a calibration that a person reads (``bigcbf calibrate LOG --report DIR``).

Every figure has a panel per axis (vx, vy, wz); an axis the log does not identify, or a panel with nothing to
show, says so in the panel instead of staying blank.

- ``command_response.png``: per axis, the command (as sent, and delayed by the dead time) against the measured
  velocity, Eq. (1) (A u + d) and the saturating model (limits, dead time, lag), over a 20-s excerpt with the
  most command activity; saturated samples marked;
- ``delay.png``: per axis, the change-correlation curve with its peak, its bootstrap interval and a near tie
  marked; the per-edge delay histogram; the perception latency histogram, with tau95 marked;
- ``residuals.png``: ||r_xy|| against the command speed ||u_xy|| with the bound behind e_exec(u) and its stated and
  measured coverage, and per axis the residual r_j against the command u_j with the per-axis 95 % bound; samples
  in the bound (settled, unsaturated) in colour, transients in grey, saturated samples in red;
- ``limits.png``: the fastest wheel's rim speed measured against what Eq. (1) asks for (max|R (A u + d)|), with
  the identified rim-speed limit: below it the points follow the diagonal, above it they stay at the limit;
- ``calibration.json``: the numbers (as ``--json``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .calibrate import Calibration
from .execution import AXES
from .limits import rim_demand
from .signals import zoh

UNITS = ("m/s", "m/s", "rad/s")


def _busiest_window(t: np.ndarray, u: np.ndarray, length: float) -> tuple[float, float]:
    if t[-1] - t[0] <= length:
        return float(t[0]), float(t[-1])
    du = np.r_[0.0, np.abs(np.diff(u, axis=0)).sum(axis=1)]
    starts = np.arange(t[0], t[-1] - length, length / 4)
    act = [du[(t >= a) & (t < a + length)].sum() for a in starts]
    a = float(starts[int(np.argmax(act))])
    return a, a + length


def _save(fig, path: Path) -> Path:
    """Lay out, write (110 dpi) and close a figure; returns its path."""
    import matplotlib.pyplot as plt
    from bigcbf.outputs import atomic_output
    fig.tight_layout()
    try:
        with atomic_output(path, "figure") as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    return path


def _empty(ax, text: str) -> None:
    """A panel with nothing to draw says why."""
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, fontsize=9, color="0.35", wrap=True)
    ax.tick_params(left=False, labelleft=False, bottom=False, labelbottom=False)


def write_report(cal: Calibration, out_dir: str | Path, cmd_t: np.ndarray | None = None,
                 cmd_u: np.ndarray | None = None) -> list[Path]:
    """Write the plots and calibration.json into ``out_dir`` (created). Returns the files written."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bigcbf.outputs import check_output_dir, strict_json, write_text
    out = check_output_dir(out_dir, "report folder")
    files = []
    a = cal.aligned
    t, u, v = a["t"], a["u"], a["v"]
    sat, use, scored = a["saturated"], a["used"], a.get("scored", np.ones(len(t), bool))
    ident = cal.fit.identified
    model = cal.model
    lat = cal.latency_s
    not_ident = "{} is not identified: the log does not excite it"

    # 1. command vs response
    t_a, t_b = _busiest_window(t, u, 20.0)
    sel = (t >= t_a) & (t <= t_b)
    fig, axs = plt.subplots(3, 1, figsize=(13, 8.4))
    lin = cal.fit.predict(u)
    for j, ax in enumerate(axs):
        if not ident[j]:
            _empty(ax, not_ident.format(AXES[j]))
            continue
        if cmd_t is not None:
            tt = np.linspace(t_a, t_b, 2000)
            ax.step(tt - t[0], zoh(cmd_t, cmd_u[:, j], tt), where="post", color="0.6", lw=1, label="command as sent")
        ax.plot(t[sel] - t[0], u[sel, j], color="tab:blue", lw=1.0,
                label=f"command delayed by the dead time ({model.dynamic.latency_s[j] * 1e3:.0f} ms)"
                if model is not None else "command")
        ax.plot(t[sel] - t[0], v[sel, j], color="tab:orange", lw=1.2, label="measured (odometry)")
        ax.plot(t[sel] - t[0], lin[sel, j], color="tab:green", lw=0.8, ls="--", label="Eq. (1): A u + d")
        if model is not None:
            ok = sel & scored
            ax.plot(t[ok] - t[0], model.y[ok, j], color="tab:purple", lw=1.0, ls=":",
                    label="saturating model (limits, lag)")
        ss = sel & sat
        if ss.any():
            ax.plot(t[ss] - t[0], v[ss, j], "o", ms=2.5, color="tab:red", label="saturated (wheel at its limit)")
        ax.set_ylabel(f"{AXES[j]} [{UNITS[j]}]")
        ax.set_xlim(t_a - t[0], t_b - t[0])
        ax.set_xlabel("time since the start of the log [s]")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7)
    fig.suptitle("Command and response (the 20 s with the most command activity)")
    files.append(_save(fig, out / "command_response.png"))

    # 2. delays
    d = cal.delay
    fig, axs = plt.subplots(3, 3, figsize=(14, 8.4))
    for j in range(3):
        ax = axs[j, 0]
        ad = d.axes.get(j)
        if not ident[j] or ad is None:
            _empty(ax, not_ident.format(AXES[j]) if not ident[j] else f"no changes of {AXES[j]} to correlate")
        else:
            curve = ad.curve if ad.curve is not None else d.xcorr_curve
            ax.plot(d.xcorr_lags_s[:len(curve)] * 1e3, curve, color="tab:blue", lw=1)
            ax.axvline(ad.delay_s * 1e3, color="tab:red", ls="--", label=f"peak {ad.delay_s * 1e3:.0f} ms")
            ax.axvspan(ad.ci_s[0] * 1e3, ad.ci_s[1] * 1e3, color="tab:red", alpha=0.12,
                       label=f"bootstrap 90 %: {ad.ci_s[0] * 1e3:.0f}-{ad.ci_s[1] * 1e3:.0f} ms")
            if ad.tie:
                ax.axvline(ad.runner_up_s * 1e3, color="tab:orange", ls=":", label=f"near tie {ad.runner_up_s * 1e3:.0f} ms")
            if np.isfinite(lat[j]):
                ax.axvline(lat[j] * 1e3, color="tab:purple", ls="-.", label=f"latency {lat[j] * 1e3:.0f} ms")
            ax.set_ylabel(f"{AXES[j]}: correlation of changes")
            ax.legend(fontsize=7)
        ax = axs[j, 1]
        edges = d.edge_delays_s[d.edge_axes == j] if len(d.edge_delays_s) else np.zeros(0)
        if not ident[j]:
            _empty(ax, not_ident.format(AXES[j]))
        elif len(edges) == 0:
            _empty(ax, f"no clean command steps on {AXES[j]}\n(a step held 0.35 s before and after)")
        else:
            ax.hist(edges * 1e3, bins=min(30, max(5, len(edges) // 2)), color="tab:blue", alpha=0.8)
            ax.axvline(np.median(edges) * 1e3, color="tab:red", ls="--", label=f"median {np.median(edges) * 1e3:.0f} ms")
            ax.set_ylabel(f"{AXES[j]}: edges ({len(edges)})")
            ax.legend(fontsize=7)
    for ax in axs[:, 0]:
        ax.set_xlabel("lag [ms]")
    for ax in axs[:, 1]:
        ax.set_xlabel("per-edge half-way delay [ms]")
    ax = axs[0, 2]
    if len(d.perception_latency_s):
        ax.hist(d.perception_latency_s * 1e3, bins=30, color="tab:purple", alpha=0.8)
        ax.axvline(d.perception95_s * 1e3, color="tab:red", ls="--", label=f"p95 {d.perception95_s * 1e3:.0f} ms")
        ax.set_xlabel(f"perception latency [ms] ({d.perception_source})")
        ax.legend(fontsize=7)
    else:
        _empty(ax, "no scans: no perception latency\n(tau95 holds the actuation delay only)")
    ax = axs[1, 2]
    act = d.edge_delays_s[np.isin(d.edge_axes, d.tau95_axes)] if len(d.edge_delays_s) else np.zeros(0)
    if len(act):
        ax.hist(act * 1e3, bins=30, color="tab:blue", alpha=0.8)
        ax.axvline(d.actuation95_s * 1e3, color="tab:red", ls="--", label=f"actuation p95 {d.actuation95_s * 1e3:.0f} ms")
        ax.axvline(d.tau95_s * 1e3, color="k", ls="-", label=f"tau95 {d.tau95_s * 1e3:.0f} ms (with perception)")
        ax.set_xlabel(f"actuation delays of tau95 ({', '.join(AXES[j] for j in d.tau95_axes)}) [ms]")
        ax.legend(fontsize=7)
    else:
        _empty(ax, f"no clean edges: tau95 = {d.tau95_s * 1e3:.0f} ms from the\ncross-correlation delay"
               + (" and the perception latency" if len(d.perception_latency_s) else ""))
    p = cal.tau95_parts()
    _empty(axs[2, 2], f"tau95 {d.tau95_s * 1e3:.0f} ms = 95 % of actuation + perception\n"
           f"latency {p.latency_s * 1e3:.0f} ms, half-way median {p.actuation_median_s * 1e3:.0f} ms,\n"
           f"actuation p95 {p.actuation95_s * 1e3:.0f} ms, perception p95 {p.perception95_s * 1e3:.0f} ms")
    fig.suptitle("Delays per axis")
    files.append(_save(fig, out / "delay.png"))

    # 3. residuals against the bound
    b = cal.bound
    held = a["held"]
    r = a.get("r", v - lin)
    other = ~use & ~sat
    fig = plt.figure(figsize=(13, 8))
    gs = fig.add_gridspec(2, 3)
    ax = fig.add_subplot(gs[0, :])
    ax.scatter(a["speed"][other], a["resid"][other], s=3, alpha=0.25, color="0.6",
               label="transients (response not settled): not in the bound")
    if sat.any():
        ax.scatter(a["speed"][sat], a["resid"][sat], s=4, alpha=0.5, color="tab:red",
                   label="saturated: Eq. (1) does not hold, not in the bound")
    ax.scatter(a["speed"][use & ~held], a["resid"][use & ~held], s=4, alpha=0.35, color="tab:blue",
               label="calibration blocks")
    ax.scatter(a["speed"][use & held], a["resid"][use & held], s=4, alpha=0.5, color="tab:orange",
               label="held-out blocks")
    ss = np.linspace(0, max(float(a["speed"].max()), float(b.speed_knots[-1])) * 1.05, 200)
    ax.plot(ss, b(ss), color="k", lw=2, label=f"bound (stated {b.coverage:.2f}; held-out {b.coverage_heldout:.3f}, "
            f"all unsaturated {cal.coverage_heldout_transients:.3f}, all {cal.coverage_heldout_all:.3f})")
    ax.plot(b.speed_knots, b.bound_knots, "o", color="k")
    top = np.quantile(a["resid"], 0.995) if len(a["resid"]) else 1.0
    ax.set_ylim(0, max(top, 1.3 * float(b.bound_knots.max())))
    ax.set_xlabel("command speed ||u_xy|| [m/s]")
    ax.set_ylabel("residual ||r_xy|| [m/s]")
    ax.set_title(f"Execution residual; e_exec(u) = {cal.residual_horizon_s:.3f} s x bound")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    for j in range(3):
        ax = fig.add_subplot(gs[1, j])
        if not ident[j]:
            _empty(ax, not_ident.format(AXES[j]))
            continue
        ax.scatter(u[other, j], r[other, j], s=3, alpha=0.2, color="0.6")
        if sat.any():
            ax.scatter(u[sat, j], r[sat, j], s=3, alpha=0.4, color="tab:red")
        ax.scatter(u[use, j], r[use, j], s=3, alpha=0.35, color=np.where(held[use], "tab:orange", "tab:blue"))
        bj = cal.axis_bound[j]
        if np.isfinite(bj):
            ax.axhline(bj, color="k", lw=1.5, label=f"95 % bound {bj:.3f} (held-out {cal.axis_coverage[j]:.3f})")
            ax.axhline(-bj, color="k", lw=1.5)
            ax.legend(fontsize=7)
        lim = np.quantile(np.abs(r[:, j]), 0.995)
        ax.set_ylim(-max(lim, 1.5 * (bj if np.isfinite(bj) else 0)), max(lim, 1.5 * (bj if np.isfinite(bj) else 0)))
        ax.set_xlabel(f"command {AXES[j]} [{UNITS[j]}]")
        ax.set_ylabel(f"residual r_{AXES[j]} [{UNITS[j]}]")
        ax.grid(alpha=0.3)
    files.append(_save(fig, out / "residuals.png"))

    # 4. the wheel limit
    fig, ax = plt.subplots(figsize=(7, 5.5))
    if model is None or not ident.any():
        _empty(ax, "no execution model")
    else:
        st = model.static
        dem = rim_demand(u @ st.A.T + st.d, st.lever_m)
        meas = rim_demand(v, st.lever_m)
        ok = use | sat
        ax.scatter(dem[~ok], meas[~ok], s=3, alpha=0.2, color="0.6", label="transients")
        ax.scatter(dem[use], meas[use], s=4, alpha=0.4, color="tab:blue", label="settled, below the limit")
        if sat.any():
            ax.scatter(dem[sat], meas[sat], s=5, alpha=0.5, color="tab:red", label="saturated")
        top = float(max(dem.max(), meas.max())) * 1.05
        ax.plot([0, top], [0, top], color="k", lw=1, ls="--", label="Eq. (1): measured = asked")
        if st.v_max is not None:
            ax.axhline(st.v_max, color="tab:red", lw=1.5, label=f"rim-speed limit {st.v_max:.3f} m/s")
            title = (f"Wheel-speed limit {st.v_max:.3f} m/s (yaw lever {st.lever_m:.3f} m"
                     + ("" if st.lever_identified else ", not pinned down") + ")")
        else:
            title = f"No wheel-speed limit reached (asked up to {st.demand_max:.2f} m/s)"
        ax.set_xlim(0, top)
        ax.set_ylim(0, top)
        ax.set_xlabel("fastest wheel's rim speed asked, max|R (A u + d)| [m/s]")
        ax.set_ylabel("fastest wheel's rim speed measured, max|R v| [m/s]")
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    files.append(_save(fig, out / "limits.png"))

    files.append(out / "calibration.json")
    write_text(files[-1], strict_json(cal.to_json(), indent=2), "calibration.json")
    return files
