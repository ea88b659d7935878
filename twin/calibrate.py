"""Calibrate the shared-uncertainty terms of Eq. (15) from a robot log (``bigcbf calibrate``).

    cal = calibrate_log("drive.mcap")            # topics found by type, or named
    write_profile(cal, "robot.toml")              # the uncertainty profile `bigcbf run --profile` reads
    cal.to_json()                                 # tau95_s, A, d, e_exec, e_zoh_m, coverage, sample counts

Steps (each module documents its method):
1. delay (twin.delay): cross-correlation and per-edge actuation delays, perception latency from scan times,
   tau95 = 95th percentile of their sum;
2. execution model (twin.execution): commands held and shifted by the cross-correlation delay, paired with the
   odometry's body twist; A, d by least squares on the calibration blocks, saturated samples excluded, axes the
   log does not excite reported as not identified;
3. residual bound (twin.residual): conformal quantile of ||r_xy|| per command-speed bin on the settled,
   unsaturated samples of the calibration blocks, coverage checked on the held-out time blocks (the error right
   after a command change is the delay's, which the relative-motion delay term of Eq. (15) covers); the coverage
   on every held-out sample, transients included, is reported too (``coverage_heldout_transients``), and a
   held-out coverage more than 3 points below the stated one is a warning;
4. e_ZOH (:func:`zoh_displacement`) from the log's command period and measured speeds.

Commands are held between messages, as most drivers do (a TurtleBot3 holds its last cmd_vel). A robot whose
firmware stops on a command timeout is told by ``max_command_age_s`` (``--cmd-timeout``): samples whose command is
older than that when it should act are left out of every step but the delay's (holding the last command there
would pair it with a stopped robot). Without it, gaps over 0.5 s in the command stream are a note.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bigcbf.errors import UserError
from bigcbf.logio import CMD, ODOM, SCAN, LogData, find_topic, open_log, read_series
from bigcbf.params.stack import ExecutionModel, StackParams
from bigcbf.params.toml_io import from_dict, to_dict

from .delay import DelayEstimate, DelayOptions, estimate_delay
from .execution import (AXES, ExecutionFit, ExecutionOptions, fit_execution, identified_axes, input_condition,
                        saturated_samples, settled_samples)
from .residual import ResidualBound, ResidualOptions, calibrate_bound, holdout_mask
from .signals import intervals, quantile_upper, zoh

MIN_MESSAGES = 20


@dataclass(frozen=True)
class CalibrationOptions:
    delay: DelayOptions = DelayOptions()
    execution: ExecutionOptions = ExecutionOptions()
    residual: ResidualOptions = ResidualOptions()
    period_quantile: float = 0.95     # T_C: this quantile of the intervals between commands [-]
    speed_quantile: float = 0.99      # v of e_ZOH: this quantile of the measured ||v_xy|| [-]
    max_command_age_s: float | None = None   # the robot's command timeout, if it has one (module docstring) [s]
    coverage_warn: float = 0.03       # a held-out coverage this far below the stated one is a warning [-]
    condition_warn: float = 30.0      # the input condition number above which the axes are not separable [-]


@dataclass
class Calibration:
    """Everything ``bigcbf calibrate`` found; ``execution_model()``, ``profile_dict()``, ``to_json()`` present it."""

    log: str
    topics: dict[str, str | None]
    duration_s: float
    delay: DelayEstimate
    fit: ExecutionFit
    bound: ResidualBound
    control_period_s: float          # T_C [s]
    speed_mps: float                 # the speed quantile used by e_ZOH [m/s]
    e_zoh_m: float
    residual_horizon_s: float
    coverage_heldout_transients: float   # the bound's coverage on every unsaturated held-out sample
    rmse_nominal: np.ndarray         # (3,) on the held-out samples, nominal model v(t) = u(t) (no delay, A = I)
    rmse_identity: np.ndarray        # (3,) on the held-out samples, v(t) = u(t - delay) (A = I, d = 0)
    rmse_model: np.ndarray           # (3,) on the held-out samples, model v = A u + d
    counts: dict[str, int]
    aligned: dict[str, np.ndarray]   # t, u, v, held, saturated, speed, resid (for the report)
    warnings: list[str] = field(default_factory=list)

    def execution_model(self) -> ExecutionModel:
        return ExecutionModel(
            A=tuple(tuple(float(x) for x in row) for row in self.fit.A), d=tuple(float(x) for x in self.fit.d),
            residual_speed_mps=tuple(float(x) for x in self.bound.speed_knots),
            residual_bound_mps=tuple(float(x) for x in self.bound.bound_knots),
            residual_horizon_s=float(self.residual_horizon_s), residual_coverage=float(self.bound.coverage),
            identified=tuple(bool(x) for x in self.fit.identified))

    def profile_dict(self) -> dict:
        """The uncertainty profile: a StackParams TOML table holding only what the calibration measured.

        Written readable: A and d rounded to 1e-5, speed knots to 1e-4 m/s; the bounds (tau95, e_ZOH, the
        residual bound and horizon) rounded *up* to 1e-5, so that rounding never shrinks a margin."""
        up = lambda x: float(np.ceil(np.asarray(x) * 1e5 - 1e-9) / 1e5)          # noqa: E731
        ex = to_dict(self.execution_model())
        ex["A"] = [[round(x, 5) for x in row] for row in ex["A"]]
        ex["d"] = [round(x, 5) for x in ex["d"]]
        knots = [round(x, 4) for x in ex["residual_speed_mps"]]
        if all(b > a for a, b in zip(knots, knots[1:])):
            ex["residual_speed_mps"] = knots
        ex["residual_bound_mps"] = [up(x) for x in ex["residual_bound_mps"]]
        ex["residual_horizon_s"] = up(ex["residual_horizon_s"])
        return {"uncertainty": {"tau95_s": up(self.delay.tau95_s), "e_zoh_m": up(self.e_zoh_m), "execution": ex}}

    def to_json(self) -> dict:
        d = self.delay
        return jsonable({
            "log": self.log, "topics": self.topics, "duration_s": self.duration_s,
            "tau95_s": d.tau95_s,
            "delay": {"xcorr_s": d.xcorr_s, "actuation_median_s": d.actuation_median_s,
                      "actuation95_s": d.actuation95_s, "perception95_s": d.perception95_s,
                      "perception_source": d.perception_source, "edges": int(len(d.edge_delays_s))},
            "A": self.fit.A.tolist(), "d": self.fit.d.tolist(),
            "identified": {a: bool(x) for a, x in zip(AXES, self.fit.identified)},
            "e_exec": {"residual_speed_mps": self.bound.speed_knots.tolist(),
                       "residual_bound_mps": self.bound.bound_knots.tolist(),
                       "residual_horizon_s": self.residual_horizon_s,
                       "coverage": self.bound.coverage, "coverage_calibration": self.bound.coverage_calibration,
                       "coverage_heldout": self.bound.coverage_heldout,
                       "coverage_heldout_final_block": self.bound.coverage_tail,
                       "coverage_heldout_transients": self.coverage_heldout_transients},
            "e_zoh_m": self.e_zoh_m, "control_period_s": self.control_period_s, "speed_mps": self.speed_mps,
            "rmse_heldout": {"nominal": dict(zip(AXES, map(float, self.rmse_nominal))),
                             "identity": dict(zip(AXES, map(float, self.rmse_identity))),
                             "model": dict(zip(AXES, map(float, self.rmse_model)))},
            "samples": self.counts, "warnings": self.warnings + d.notes,
        })


def zoh_displacement(t_cmd, v_xy, period_quantile: float = 0.95, speed_quantile: float = 0.99):
    """e_ZOH of Eq. (15): the distance the robot can cover while one command is held, T_C * v.

    T_C = the ``period_quantile`` of the intervals between consecutive commands (messages of one burst merged),
    v = the ``speed_quantile`` of the measured translational speed ||v_xy||. Returns (e_zoh_m, T_C, v).
    """
    dt = intervals(t_cmd)
    if len(dt) == 0:
        raise ValueError("need at least two commands at different times")
    T = quantile_upper(dt, period_quantile)
    v = quantile_upper(np.hypot(v_xy[:, 0], v_xy[:, 1]), speed_quantile)
    return T * v, T, v


def _rmse(err: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(err ** 2, axis=0)) if len(err) else np.full(3, np.nan)


def calibrate_series(data: LogData, opt: CalibrationOptions = CalibrationOptions()) -> Calibration:
    """Calibrate from extracted series (commands and odometry required, scan stamps optional)."""
    path = str(data.path)
    cmd, odom, scan = data.cmd, data.odom, data.scan
    for name, s in (("commands", cmd), ("odometry", odom)):
        if s is None or len(s.t) < MIN_MESSAGES:
            n = 0 if s is None else len(s.t)
            raise UserError(f"too few {name} messages to calibrate ({n}, need {MIN_MESSAGES})", file=path,
                            field=None if s is None else s.topic)
    if min(cmd.t[-1], odom.t[-1]) - max(cmd.t[0], odom.t[0]) < 2.0:
        raise UserError(f"the commands ({cmd.topic}) and the odometry ({odom.topic}) overlap for less than 2 s",
                        file=path)
    axes = identified_axes(zoh(cmd.t, cmd.u, odom.t[(odom.t >= cmd.t[0])]), opt.execution)
    if not axes.any():
        raise UserError(f"the commands on {cmd.topic} do not excite any axis (std of vx, vy, wz: "
                        f"{', '.join(f'{x:.3g}' for x in cmd.u.std(axis=0))}); nothing to calibrate", file=path)
    ax = np.flatnonzero(axes)
    delay = estimate_delay(cmd.t, cmd.u, odom.t, odom.twist, ax,
                           None if scan is None else scan.t, None if scan is None else scan.stamp, opt.delay)
    # delay-aligned samples at the odometry times
    tau = delay.xcorr_s
    keep = (odom.t - tau >= cmd.t[0]) & (odom.t - tau <= cmd.t[-1] + opt.delay.max_gap_s)
    last_cmd = cmd.t[np.clip(np.searchsorted(cmd.t, odom.t - tau, side="right") - 1, 0, len(cmd.t) - 1)]
    age = odom.t - tau - last_cmd
    stale = keep & (age > opt.max_command_age_s) if opt.max_command_age_s is not None else np.zeros_like(keep)
    keep &= ~stale
    gaps = intervals(cmd.t)
    t = odom.t[keep]
    u = zoh(cmd.t, cmd.u, t - tau)
    v = odom.twist[keep]
    held = holdout_mask(t, opt.residual)
    settled = settled_samples(cmd.t, cmd.u, t - tau, opt.execution)
    fit = fit_execution(t[~held], u[~held], v[~held], opt.execution, axes=axes, settled=settled[~held])
    sat = np.zeros(len(t), bool)
    sat[~held] = fit.saturated
    # held-out samples: saturation judged with the calibration fit
    sat[held] = saturated_samples(t[held], u[held], v[held], fit.A, fit.d, axes, opt.execution)
    # the residual bound, like the fit, on settled samples: right after a command change the error is the delay's
    # (the relative-motion delay term of Eq. (15) covers it), not the execution residual r of Eq. (1)
    use = ~sat & (settled if fit.settled_only else True)
    if int((use & ~held).sum()) < MIN_MESSAGES:
        raise UserError(f"too few usable samples for the residual bound ({int((use & ~held).sum())} settled, "
                        f"unsaturated samples in the calibration blocks, need {MIN_MESSAGES})", file=path)
    if len(intervals(cmd.t)) == 0:
        raise UserError(f"all commands on {cmd.topic} carry the same log time: no control period", file=path)
    r = v - fit.predict(u)
    speed = np.hypot(u[:, 0], u[:, 1])
    resid = np.hypot(r[:, 0], r[:, 1])
    bound = calibrate_bound(t[use], speed[use], resid[use], opt.residual, held=held[use])
    unsat_held = held & ~sat
    cov_all = float((resid[unsat_held] <= bound(speed[unsat_held])).mean()) if unsat_held.any() else float("nan")
    e_zoh, T_C, v_q = zoh_displacement(cmd.t, odom.twist, opt.period_quantile, opt.speed_quantile)
    ho = held & use
    warnings = list(data.warnings)
    if stale.any():
        warnings.append(f"{int(stale.sum())} odometry samples left out: their command was older than the command "
                        f"timeout {opt.max_command_age_s} s (gaps in {cmd.topic})")
    elif opt.max_command_age_s is None and len(gaps) and gaps.max() > 0.5:
        warnings.append(f"{cmd.topic} has gaps of up to {gaps.max():.2f} s; the last command was held through them "
                        "(if the robot stops on a command timeout, give it: --cmd-timeout)")
    for name, cov in (("held-out blocks", bound.coverage_heldout), ("final held-out block", bound.coverage_tail)):
        if cov < bound.coverage - opt.coverage_warn:
            warnings.append(f"the residual bound covers {cov:.3f} of the {name}, below the stated {bound.coverage}: "
                            "the log's residuals are not stationary; calibrate on a longer or steadier log")
    cond = input_condition(u[~held & settled], axes)
    if cond > opt.condition_warn:
        warnings.append(f"the commanded axes {', '.join(a for a, x in zip(AXES, axes) if x)} move together "
                        f"(condition number {cond:.0f}): each is excited, but their cross gains in A cannot be "
                        "told apart; excite them independently for a full A")
    v_stack = StackParams().v_max_mps
    u_top = quantile_upper(np.hypot(cmd.u[:, 0], cmd.u[:, 1]), opt.speed_quantile)
    if u_top < v_stack - 0.05:
        warnings.append(f"the log commands at most {u_top:.2f} m/s (the {opt.speed_quantile:.0%} quantile), the "
                        f"stack up to {v_stack} m/s: e_ZOH = T_C v (v measured, {v_q:.2f} m/s) and the residual "
                        f"bound above {bound.speed_knots[-1]:.2f} m/s are extrapolated from slower driving")
    if not fit.settled_only:
        warnings.append(f"only {int(settled[~held].sum())} samples with a settled command in the calibration blocks: "
                        "A and d were fitted on every sample (transients included, gains may read low)")
    for j in np.flatnonzero(~axes):
        warnings.append(f"{AXES[j]} is not identified: the log does not excite it (identity row kept in A, no bias)")
    counts = {"stale": int(stale.sum()), "commands": int(len(cmd.t)), "odometry": int(len(odom.t)), "scans": int(0 if scan is None else len(scan.t)),
              "aligned": int(len(t)), "settled": int(settled.sum()), "calibration": int((~held & use).sum()),
              "heldout": int(ho.sum()),
              "saturated": int(sat.sum()), "fit": int(fit.n_used), "edges": int(len(delay.edge_delays_s))}
    return Calibration(
        log=path, topics={"commands": cmd.topic, "odometry": odom.topic, "scans": None if scan is None else scan.topic},
        duration_s=float(t[-1] - t[0]), delay=delay, fit=fit, bound=bound, control_period_s=T_C, speed_mps=v_q,
        e_zoh_m=e_zoh, residual_horizon_s=T_C + delay.tau95_s, coverage_heldout_transients=cov_all,
        rmse_nominal=_rmse((v - zoh(cmd.t, cmd.u, t))[ho]), rmse_identity=_rmse((v - u)[ho]),
        rmse_model=_rmse(r[ho]), counts=counts,
        aligned={"t": t, "u": u, "v": v, "held": held, "saturated": sat, "settled": settled, "used": use,
                 "speed": speed, "resid": resid},
        warnings=warnings)


def read_log(path: str | Path, cmd_topic: str | None = None, odom_topic: str | None = None,
             scan_topic: str | None = None, use_scan: bool = True) -> LogData:
    """Open a log, find the command, odometry and (optional) scan topics, extract their series."""
    with open_log(path) as log:
        c = find_topic(log, CMD, cmd_topic)
        o = find_topic(log, ODOM, odom_topic)
        s = find_topic(log, SCAN, scan_topic, required=scan_topic is not None) if use_scan else None
        return read_series(log, cmd=c, odom=o, scan=s)


def calibrate_log(path: str | Path, cmd_topic: str | None = None, odom_topic: str | None = None,
                  scan_topic: str | None = None, opt: CalibrationOptions = CalibrationOptions()) -> Calibration:
    """:func:`read_log` then :func:`calibrate_series`."""
    return calibrate_series(read_log(path, cmd_topic, odom_topic, scan_topic), opt)


def write_profile(cal: Calibration, path: str | Path) -> Path:
    """Write the uncertainty profile: a StackParams TOML with only the calibrated keys ([uncertainty] tau95_s,
    e_zoh_m and [uncertainty.execution]), validated by the dataclasses before and after writing."""
    import tomli_w

    from bigcbf.params.stack import load_stack_params
    p = Path(path)
    if p.is_dir():
        raise UserError("is a directory, expected a .toml file path", file=str(p))
    data = cal.profile_dict()
    from_dict(StackParams, data, file=str(p))
    ident = ", ".join(f"{a} {'identified' if x else 'NOT identified'}" for a, x in zip(AXES, cal.fit.identified))
    header = [f"Uncertainty profile calibrated by `bigcbf calibrate` from {cal.log}",
              f"({cal.duration_s:.1f} s, {cal.counts['aligned']} samples; {ident}).",
              "e_exec(u) = residual_horizon_s * interp(||u_xy||, residual_speed_mps, residual_bound_mps); "
              f"held-out coverage {cal.bound.coverage_heldout:.3f} (stated {cal.bound.coverage}).",
              "Use: bigcbf run ... --profile THIS.toml (overlays the stack parameters)."]
    from bigcbf.outputs import atomic_output
    with atomic_output(p, "profile") as tmp:      # written beside the path, renamed to it once checked
        tmp.write_text("".join(f"# {h}\n" for h in header) + tomli_w.dumps(data))
        load_stack_params(tmp)
    return p


def summary_lines(cal: Calibration) -> list[str]:
    """A human-readable summary (what `bigcbf calibrate` prints without --json)."""
    d, f, b = cal.delay, cal.fit, cal.bound
    fmt = lambda v: " ".join(f"{x:+.3f}" for x in v)   # noqa: E731
    lines = [f"log            {cal.log}  ({cal.duration_s:.1f} s; commands {cal.topics['commands']}, "
             f"odometry {cal.topics['odometry']}, scans {cal.topics['scans']})",
             f"tau95          {d.tau95_s:.3f} s  (actuation: xcorr {d.xcorr_s:.3f} s, median of {len(d.edge_delays_s)} "
             f"edges {d.actuation_median_s:.3f} s, p95 {d.actuation95_s:.3f} s; perception p95 {d.perception95_s:.3f} s "
             f"from {d.perception_source})"]
    for j, a in enumerate(AXES):
        lines.append(f"A[{a}]          {fmt(f.A[j])}   d {f.d[j]:+.4f}   "
                     + ("identified" if f.identified[j] else "NOT identified (not excited by the log)"))
    lines += [f"e_exec         horizon {cal.residual_horizon_s:.3f} s x bound(|u_xy|): "
              + ", ".join(f"{s:.2f} m/s -> {v:.4f}" for s, v in zip(b.speed_knots, b.bound_knots)),
              f"coverage       stated {b.coverage:.3f}, calibration {b.coverage_calibration:.3f}, held-out "
              f"{b.coverage_heldout:.3f} (final block {b.coverage_tail:.3f}; with transients "
              f"{cal.coverage_heldout_transients:.3f})",
              f"e_ZOH          {cal.e_zoh_m:.4f} m  (T_C {cal.control_period_s:.3f} s x v {cal.speed_mps:.3f} m/s)",
              "held-out RMSE  nominal v=u(t) " + fmt(cal.rmse_nominal) + "   v=u(t-delay) " + fmt(cal.rmse_identity)
              + "   fitted " + fmt(cal.rmse_model),
              "samples        " + ", ".join(f"{k} {v}" for k, v in cal.counts.items())]
    lines += [f"note           {w}" for w in cal.warnings + d.notes]
    return lines


def jsonable(x):
    """Nested dicts/lists with NaN and inf replaced by None (JSON has no NaN)."""
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x
