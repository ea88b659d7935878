"""Plots of a calibration that a person reads (``bigcbf calibrate LOG --report DIR``), and an index page.

Only the axes the log identifies get panels; an axis it does not identify (a differential robot's vy), or a panel
with nothing to show (no clean command steps, no scans, no execution model), is left out and said in one line
under the figure and on the index page (e.g. "vy: not identified (no lateral command)"). No figure has an empty
panel.

- ``index.md``: what the calibration found (tau95, A and d, e_exec, e_ZOH, with units, and where each enters the
  paper's ``eq:uncertainty_margin`` and ``eq:execution``), in plain words, the figures with what each shows, what
  was left out, and calibrate's notes;
- ``command_response.png``: per identified axis, the command (as sent, and delayed by the dead time) against the
  measured velocity, eq:execution (1) (A u + d) and the saturating model (limits, dead time, lag), over a 20-s excerpt
  with the most command activity; saturated samples marked;
- ``delay.png``: per identified axis, the change-correlation curve with its peak, its bootstrap interval and a
  near tie marked, and (where the log has clean command steps) the per-edge delay histogram; the perception latency
  histogram and the actuation delays behind tau95 (where there are any), with tau95 marked;
- ``residuals.png``: ||r_xy|| against the command speed ||u_xy|| with the bound behind e_exec(u) and its stated and
  measured coverage, and per identified axis the residual r_j against the command u_j with the per-axis 95 % bound;
  samples in the bound (settled, unsaturated) in colour, transients in grey, saturated samples in red;
- ``limits.png`` (with an execution model): the fastest wheel's rim speed measured against what eq:execution (1) asks
  for (max|R (A u + d)|), with the identified rim-speed limit: below it the points follow the diagonal, above it they
  stay at the limit;
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


#: What each axis's command is called in a "not identified" line.
COMMAND_NAME = ("forward", "lateral", "turning")


def not_identified_lines(cal: Calibration, cmd_u: np.ndarray | None = None) -> list[str]:
    """One line per axis the log does not identify, e.g. "vy: not identified (no lateral command)"; with the
    commands, an axis that is commanded but too little says how much (the rule of twin.execution)."""
    from .execution import ExecutionOptions
    lim = ExecutionOptions().excite_min
    out = []
    for j in np.flatnonzero(~np.asarray(cal.fit.identified, bool)):
        if cmd_u is None or not np.any(np.abs(cmd_u[:, j]) > 1e-9):
            why = f"no {COMMAND_NAME[j]} command"
        else:
            why = (f"too little {COMMAND_NAME[j]} command: std {np.std(cmd_u[:, j]):.3g} {UNITS[j]}, "
                   f"identification needs {lim[j]:g}")
        out.append(f"{AXES[j]}: not identified ({why})")
    return out


def _footer(fig, lines: list[str]) -> None:
    """Lines under a figure's panels (what was left out, and why)."""
    if lines:
        fig.text(0.01, 0.005, "\n".join(lines), ha="left", va="bottom", fontsize=8, color="0.25")


def _save(fig, path: Path, footer: list[str] = ()) -> Path:
    """Lay out (room for the footer), write (110 dpi) and close a figure; returns its path."""
    import matplotlib.pyplot as plt
    from bigcbf.outputs import atomic_output
    _footer(fig, list(footer))
    bottom = (len(footer) * 8 * 1.35 / 72 + 0.12) / fig.get_figheight() if footer else 0.0   # 8-pt lines [in]
    fig.tight_layout(rect=(0, bottom, 1, 1))
    try:
        with atomic_output(path, "figure") as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
    return path


def _grid(plt, n: int, width: float = 14.0, row_h: float = 3.4, max_cols: int = 3):
    """A figure with exactly n panels (rows of up to max_cols; the last row's unused cells removed)."""
    cols = min(n, max_cols)
    rows = -(-n // cols)
    fig, axs = plt.subplots(rows, cols, figsize=(width, row_h * rows + 1.0), squeeze=False)
    flat = list(axs.ravel())
    for ax in flat[n:]:
        fig.delaxes(ax)
    return fig, flat[:n]


def figures(cal: Calibration, cmd_t: np.ndarray | None = None,
            cmd_u: np.ndarray | None = None) -> tuple[dict, list[str]]:
    """The report's figures, ({file name: (matplotlib figure, footer lines)}, what was left out and why): a panel
    per identified axis and per thing to show, never an empty one; a figure with nothing to show is left out.

    Length: to be split (issue 22): four figures in numbered blocks that share only the aligned series; each block could
    be its own function."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figs: dict = {}
    left_out: list[str] = []
    a = cal.aligned
    t, u, v = a["t"], a["u"], a["v"]
    sat, use, scored = a["saturated"], a["used"], a.get("scored", np.ones(len(t), bool))
    ident = np.asarray(cal.fit.identified, bool)
    axes_ids = [int(j) for j in np.flatnonzero(ident)]
    not_ident = not_identified_lines(cal, cmd_u)
    model = cal.model
    lat = cal.latency_s

    # 1. command vs response: one panel per identified axis
    t_a, t_b = _busiest_window(t, u, 20.0)
    sel = (t >= t_a) & (t <= t_b)
    fig, axs = plt.subplots(len(axes_ids), 1, figsize=(13, 2.8 * len(axes_ids) + 1.2), squeeze=False)
    lin = cal.fit.predict(u)
    for ax, j in zip(axs[:, 0], axes_ids):
        if cmd_t is not None:
            tt = np.linspace(t_a, t_b, 2000)
            ax.step(tt - t[0], zoh(cmd_t, cmd_u[:, j], tt), where="post", color="0.6", lw=1, label="command as sent")
        ax.plot(t[sel] - t[0], u[sel, j], color="tab:blue", lw=1.0,
                label=f"command delayed by the dead time ({model.dynamic.latency_s[j] * 1e3:.0f} ms)"
                if model is not None else "command")
        ax.plot(t[sel] - t[0], v[sel, j], color="tab:orange", lw=1.2, label="measured (odometry)")
        ax.plot(t[sel] - t[0], lin[sel, j], color="tab:green", lw=0.8, ls="--", label="eq:execution (1): A u + d")
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
    figs["command_response.png"] = (fig, not_ident)

    # 2. delays: a panel per thing to show
    d = cal.delay
    panels, missing = [], []
    for j in axes_ids:
        ad = d.axes.get(j)
        if ad is None:
            missing.append(f"{AXES[j]}: no command changes to correlate (no correlation curve)")
            continue

        def corr(ax, j=j, ad=ad):
            curve = ad.curve if ad.curve is not None else d.xcorr_curve
            ax.plot(d.xcorr_lags_s[:len(curve)] * 1e3, curve, color="tab:blue", lw=1)
            ax.axvline(ad.delay_s * 1e3, color="tab:red", ls="--", label=f"peak {ad.delay_s * 1e3:.0f} ms")
            ax.axvspan(ad.ci_s[0] * 1e3, ad.ci_s[1] * 1e3, color="tab:red", alpha=0.12,
                       label=f"bootstrap 90 %: {ad.ci_s[0] * 1e3:.0f}-{ad.ci_s[1] * 1e3:.0f} ms")
            if ad.tie:
                ax.axvline(ad.runner_up_s * 1e3, color="tab:orange", ls=":",
                           label=f"near tie {ad.runner_up_s * 1e3:.0f} ms")
            if np.isfinite(lat[j]):
                ax.axvline(lat[j] * 1e3, color="tab:purple", ls="-.", label=f"latency {lat[j] * 1e3:.0f} ms")
            ax.set_title(f"{AXES[j]}: correlation of command and response changes", fontsize=9)
            ax.set_xlabel("lag [ms]")
            ax.set_ylabel("correlation")
            ax.legend(fontsize=7)
        panels.append(corr)
    for j in axes_ids:
        edges = d.edge_delays_s[d.edge_axes == j] if len(d.edge_delays_s) else np.zeros(0)
        if len(edges) == 0:
            missing.append(f"{AXES[j]}: no clean command steps (a step held 0.35 s before and after), so no "
                           "per-edge delay histogram")
            continue

        def hist(ax, j=j, edges=edges):
            ax.hist(edges * 1e3, bins=min(30, max(5, len(edges) // 2)), color="tab:blue", alpha=0.8)
            ax.axvline(np.median(edges) * 1e3, color="tab:red", ls="--",
                       label=f"median {np.median(edges) * 1e3:.0f} ms")
            ax.set_title(f"{AXES[j]}: per-edge half-way delays ({len(edges)} edges)", fontsize=9)
            ax.set_xlabel("delay [ms]")
            ax.set_ylabel("edges")
            ax.legend(fontsize=7)
        panels.append(hist)
    if len(d.perception_latency_s):
        def perception(ax):
            ax.hist(d.perception_latency_s * 1e3, bins=30, color="tab:purple", alpha=0.8)
            ax.axvline(d.perception95_s * 1e3, color="tab:red", ls="--", label=f"p95 {d.perception95_s * 1e3:.0f} ms")
            ax.set_title(f"perception latency of the scans ({d.perception_source})", fontsize=9)
            ax.set_xlabel("perception latency [ms]")
            ax.set_ylabel("scans")
            ax.legend(fontsize=7)
        panels.append(perception)
    else:
        missing.append("no scans: no perception latency (tau95 holds the actuation delay only)")
    act = d.edge_delays_s[np.isin(d.edge_axes, d.tau95_axes)] if len(d.edge_delays_s) else np.zeros(0)
    if len(act):
        def actuation(ax):
            ax.hist(act * 1e3, bins=30, color="tab:blue", alpha=0.8)
            ax.axvline(d.actuation95_s * 1e3, color="tab:red", ls="--",
                       label=f"actuation p95 {d.actuation95_s * 1e3:.0f} ms")
            ax.axvline(d.tau95_s * 1e3, color="k", ls="-", label=f"tau95 {d.tau95_s * 1e3:.0f} ms (with perception)")
            ax.set_xlim(right=max(ax.get_xlim()[1], d.tau95_s * 1e3 * 1.05))       # tau95 inside, not on the edge
            ax.set_title(f"actuation delays behind tau95 ({', '.join(AXES[j] for j in d.tau95_axes)})", fontsize=9)
            ax.set_xlabel("delay [ms]")
            ax.legend(fontsize=7)
        panels.append(actuation)
    else:
        missing.append(f"no clean command steps on any axis: tau95's actuation part is the cross-correlation delay "
                       f"({d.xcorr_s * 1e3:.0f} ms)")
    pt = cal.tau95_parts()
    fig, axs = _grid(plt, len(panels))
    for draw, ax in zip(panels, axs):
        draw(ax)
    fig.suptitle(f"Delays: tau95 = {d.tau95_s * 1e3:.0f} ms (95 % of actuation + perception; latency "
                 f"{pt.latency_s * 1e3:.0f} ms, actuation p95 {pt.actuation95_s * 1e3:.0f} ms, perception p95 "
                 f"{pt.perception95_s * 1e3:.0f} ms)", fontsize=11)
    figs["delay.png"] = (fig, not_ident + missing)

    # 3. residuals against the bound: the speed panel, then one per identified axis
    b = cal.bound
    held = a["held"]
    r = a.get("r", v - lin)
    other = ~use & ~sat
    fig = plt.figure(figsize=(13, 8))
    gs = fig.add_gridspec(2, len(axes_ids))
    ax = fig.add_subplot(gs[0, :])
    ax.scatter(a["speed"][other], a["resid"][other], s=3, alpha=0.25, color="0.6",
               label="transients (response not settled): not in the bound")
    if sat.any():
        ax.scatter(a["speed"][sat], a["resid"][sat], s=4, alpha=0.5, color="tab:red",
                   label="saturated: eq:execution (1) does not hold, not in the bound")
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
    for col, j in enumerate(axes_ids):
        ax = fig.add_subplot(gs[1, col])
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
    figs["residuals.png"] = (fig, not_ident)

    # 4. the wheel limit (only with an execution model)
    if model is None:
        left_out.append("limits.png: no execution model (the wheel limits were not identified)")
    else:
        fig, ax = plt.subplots(figsize=(7, 5.5))
        st = model.static
        dem = rim_demand(u @ st.A.T + st.d, st.lever_m)
        meas = rim_demand(v, st.lever_m)
        ok = use | sat
        ax.scatter(dem[~ok], meas[~ok], s=3, alpha=0.2, color="0.6", label="transients")
        ax.scatter(dem[use], meas[use], s=4, alpha=0.4, color="tab:blue", label="settled, below the limit")
        if sat.any():
            ax.scatter(dem[sat], meas[sat], s=5, alpha=0.5, color="tab:red", label="saturated")
        top = float(max(dem.max(), meas.max())) * 1.05
        ax.plot([0, top], [0, top], color="k", lw=1, ls="--", label="eq:execution (1): measured = asked")
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
        figs["limits.png"] = (fig, [])
    return figs, left_out + missing


def write_report(cal: Calibration, out_dir: str | Path, cmd_t: np.ndarray | None = None,
                 cmd_u: np.ndarray | None = None) -> list[Path]:
    """Write the plots, calibration.json and index.md into ``out_dir`` (created). Returns the files written."""
    from bigcbf.outputs import check_output_dir, strict_json, write_text
    out = check_output_dir(out_dir, "report folder")
    figs, left_out = figures(cal, cmd_t, cmd_u)
    files = [_save(fig, out / name, footer) for name, (fig, footer) in figs.items()]
    files.append(out / "calibration.json")
    write_text(files[-1], strict_json(cal.to_json(), indent=2), "calibration.json")
    files.append(out / "index.md")
    write_text(files[-1], index_page(cal, [p.name for p in files[:-1]], not_identified_lines(cal, cmd_u), left_out),
               "report index")
    return files


def index_page(cal: Calibration, files: list[str], not_ident: list[str], left_out: list[str]) -> str:
    """The report's index (Markdown): what the calibration found and what the terms mean, the figures, what was
    left out, calibrate's notes.

    Length: one Markdown page's text, mostly the literal rows of its table of terms; splitting it would scatter one
    document."""
    d, f, b = cal.delay, cal.fit, cal.bound
    pt = cal.tau95_parts()
    ident = [AXES[j] for j in range(3) if f.identified[j]]
    knots = ", ".join(f"{s:.2f} m/s -> {x:.4f} m/s" for s, x in zip(b.speed_knots, b.bound_knots))
    e_exec = [cal.residual_horizon_s * float(x) for x in (b.bound_knots.min(), b.bound_knots.max())]
    mat = lambda row: "[" + ", ".join(f"{x:+.3f}" for x in row) + "]"      # noqa: E731
    lines = [f"# Calibration report: {Path(cal.log).name}", "",
             f"Log `{cal.log}`: {cal.duration_s:.1f} s aligned; commands `{cal.topics['commands']}` "
             f"({cal.publication}), odometry `{cal.topics['odometry']}`, scans `{cal.topics['scans']}`. "
             f"Identified axes: {', '.join(ident)}." + (" " + "; ".join(not_ident) + "." if not_ident else ""),
             "", "## What the calibration found", "",
             "These are the robot-dependent terms of the paper's shared uncertainty radius, `eq:uncertainty_margin` "
             "(21):",
             "m_i = ||R(theta)(A u + d) - v_i|| tau95 + beta sqrt(lambda_max(Sigma_i)) + e_exec(u) + e_ZOH, "
             "the distance [m] by which the robot's and an obstacle's relative position may be off. "
             "`bigcbf run --profile` reads them from the profile `calibrate --out` writes.", "",
             "| term | value | unit | what it is |", "|---|---|---|---|",
             f"| tau95 | {d.tau95_s:.3f} | s | the perception-to-actuation delay: the 95th percentile of (actuation "
             f"delay + perception latency). In `eq:uncertainty_margin` it multiplies the relative speed: the distance "
             f"the robot and an obstacle close while a scan becomes a wheel motion. Here: command-to-wheel latency "
             f"{pt.latency_s:.3f} s, actuation p95 {pt.actuation95_s:.3f} s, perception p95 {pt.perception95_s:.3f} s "
             f"({d.perception_source}). |",
             f"| A | {' '.join(mat(f.A[j]) for j in range(3))} | - (rows vx, vy, wz) | the gain of the execution "
             "model `eq:execution` (1), v_real = R(theta)(A u + d + r): what the robot realises of a "
             "command u; A = I is a perfect robot. An axis not identified keeps its identity row. |",
             f"| d | {mat(f.d)} | m/s, m/s, rad/s | the constant bias of `eq:execution`: motion the robot adds to "
             "every command. |",
             f"| e_exec(u) | {e_exec[0]:.4f} to {e_exec[1]:.4f} | m | the displacement the execution residual r of "
             f"`eq:execution` can cause (the robot-execution term of `eq:uncertainty_margin`): horizon "
             f"{cal.residual_horizon_s:.3f} s (T_C + tau95) x the bound on ||r_xy|| at the command speed ||u_xy|| "
             f"({knots}); the bound covers {b.coverage:.2f} of the residuals by construction and "
             f"{b.coverage_heldout:.3f} of the held-out ones. |",
             f"| e_ZOH | {cal.e_zoh_m:.4f} | m | the distance the robot covers while one command is held between "
             f"control updates (zero-order hold; the sampled-data term of `eq:uncertainty_margin`): T_C "
             f"{cal.control_period_s:.3f} s x v {cal.speed_mps:.3f} m/s (the 99th percentile of the measured "
             "speed). |"]
    if cal.model is not None:
        st, dyn = cal.model.static, cal.model.dynamic
        lines += ["", "Wheel limits (not in the paper's model; the twin's saturating model): "
                  + (f"rim speed {st.v_max:.3f} m/s" if st.v_max is not None else "no wheel-speed limit reached")
                  + "; " + (f"acceleration {dyn.accel_max:.2f} m/s^2" if dyn.accel_max is not None
                            else "no acceleration limit seen") + "."]
    desc = {"command_response.png": "the command (as sent and delayed by the dead time) against the measured "
                                    "velocity, eq:execution (1) and the saturating model, per identified axis, "
                                    "over the 20 s with the most command activity",
            "delay.png": "how the delays were measured: per identified axis the correlation of command and response "
                         "changes (its peak is the delay), the per-edge delays where the log has clean command "
                         "steps, and the perception latency and actuation delays behind tau95",
            "residuals.png": "the execution residual ||r_xy|| against the command speed with the bound behind "
                             "e_exec, and per identified axis the residual against its command",
            "limits.png": "the fastest wheel's rim speed measured against what eq:execution (1) asks, with the "
                          "identified rim-speed limit",
            "calibration.json": "every number (as `bigcbf calibrate --json`)"}
    lines += ["", "## Files", ""] + [f"- [{name}]({name}): {desc.get(name, '')}" for name in files]
    if not_ident or left_out:
        lines += ["", "## Left out", ""] + [f"- {x}" for x in not_ident + left_out]
    notes = cal.notes()
    if notes:
        lines += ["", "## Notes from the calibration", ""] + [f"- {n}" for n in notes]
    return "\n".join(lines) + "\n"
