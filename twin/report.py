"""Plots of a calibration that a person reads (``bigcbf calibrate LOG --report DIR``).

- ``command_response.png``: per identified axis, the command (as sent, and shifted by the delay) against the
  measured velocity, over a 20-s excerpt with the most command activity;
- ``delay.png``: the cross-correlation curve, the per-edge delay histogram and the perception latency
  histogram, with the delay estimates and tau95 marked;
- ``residuals.png``: ||r_xy|| against the command speed ||u_xy||, calibration and held-out samples, with the bound
  and its stated and measured coverage;
- ``calibration.json``: the numbers (as ``--json``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .calibrate import Calibration
from .execution import AXES
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
    tau = cal.delay.xcorr_s
    axes = np.flatnonzero(cal.fit.identified)

    # 1. command vs response
    t_a, t_b = _busiest_window(t, u, 20.0)
    sel = (t >= t_a) & (t <= t_b)
    fig, axs = plt.subplots(len(axes), 1, figsize=(10, 2.6 * len(axes)), sharex=True, squeeze=False)
    for ax, j in zip(axs[:, 0], axes):
        if cmd_t is not None:
            tt = np.linspace(t_a, t_b, 2000)
            ax.step(tt - t[0], zoh(cmd_t, cmd_u[:, j], tt), where="post", color="0.6", lw=1, label="command as sent")
        ax.plot(t[sel] - t[0], u[sel, j], color="tab:blue", lw=1.2, label=f"command shifted by {tau * 1e3:.0f} ms")
        ax.plot(t[sel] - t[0], v[sel, j], color="tab:orange", lw=1.0, label="measured (odometry)")
        ax.plot(t[sel] - t[0], cal.fit.predict(u[sel])[:, j], color="tab:green", lw=0.8, ls="--",
                label="model A u + d")
        ax.set_ylabel(f"{AXES[j]} [{UNITS[j]}]")
        ax.grid(alpha=0.3)
    axs[0, 0].legend(loc="upper right", fontsize=8, ncol=2)
    axs[-1, 0].set_xlabel("time since the start of the log [s]")
    fig.suptitle("Command and response, delay-aligned")
    files.append(_save(fig, out / "command_response.png"))

    # 2. delays
    d = cal.delay
    fig, axs = plt.subplots(1, 3, figsize=(13, 3.6))
    axs[0].plot(d.xcorr_lags_s * 1e3, d.xcorr_curve, color="tab:blue")
    axs[0].axvline(d.xcorr_s * 1e3, color="tab:red", ls="--", label=f"delay {d.xcorr_s * 1e3:.0f} ms")
    axs[0].set_xlabel("lag [ms]")
    axs[0].set_ylabel("correlation of changes (sum over axes)")
    axs[0].legend(fontsize=8)
    if len(d.edge_delays_s):
        axs[1].hist(d.edge_delays_s * 1e3, bins=30, color="tab:blue", alpha=0.8)
    axs[1].axvline(d.actuation95_s * 1e3, color="tab:red", ls="--", label=f"p95 {d.actuation95_s * 1e3:.0f} ms")
    axs[1].set_xlabel(f"per-edge actuation delay [ms] ({len(d.edge_delays_s)} edges)")
    axs[1].legend(fontsize=8)
    if len(d.perception_latency_s):
        axs[2].hist(d.perception_latency_s * 1e3, bins=30, color="tab:purple", alpha=0.8)
    axs[2].axvline(d.tau95_s * 1e3, color="tab:red", ls="--", label=f"tau95 {d.tau95_s * 1e3:.0f} ms (sum)")
    axs[2].set_xlabel(f"perception latency [ms] ({d.perception_source})")
    axs[2].legend(fontsize=8)
    fig.suptitle("Delays")
    files.append(_save(fig, out / "delay.png"))

    # 3. residuals against the bound
    b = cal.bound
    use = a["used"]
    held = a["held"] & use
    calib = ~a["held"] & use
    fig, ax = plt.subplots(figsize=(8, 4.5))
    other = ~use
    ax.scatter(a["speed"][other], a["resid"][other], s=3, alpha=0.25, color="0.6",
               label="transients (command just changed) and saturated: not in the bound")
    ax.scatter(a["speed"][calib], a["resid"][calib], s=4, alpha=0.35, color="tab:blue", label="calibration blocks")
    ax.scatter(a["speed"][held], a["resid"][held], s=4, alpha=0.5, color="tab:orange", label="held-out blocks")
    ss = np.linspace(0, max(float(a["speed"].max()), float(b.speed_knots[-1])) * 1.05, 200)
    ax.plot(ss, b(ss), color="tab:red", lw=2,
            label=f"bound (stated {b.coverage:.2f}; held-out {b.coverage_heldout:.3f})")
    ax.plot(b.speed_knots, b.bound_knots, "o", color="tab:red")
    ax.set_xlabel("command speed ||u_xy|| [m/s]")
    ax.set_ylabel("residual ||r_xy|| [m/s]")
    ax.set_title(f"Execution residual; e_exec(u) = {cal.residual_horizon_s:.3f} s x bound")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    files.append(_save(fig, out / "residuals.png"))

    files.append(out / "calibration.json")
    write_text(files[-1], strict_json(cal.to_json(), indent=2), "calibration.json")
    return files
