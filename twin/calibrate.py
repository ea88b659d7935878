"""Calibrate the shared-uncertainty terms of eq:uncertainty_margin (21) from a robot log (``bigcbf calibrate``).

    cal = calibrate_log("drive.mcap")            # topics found by type, or named
    write_profile(cal, "robot.toml")              # the uncertainty profile `bigcbf run --profile` reads
    cal.to_json()                                 # tau95_s, A, d, e_exec, e_zoh_m, coverage, sample counts

Steps (each module documents its method):
0. the log as it comes (twin.timebase): the odometry on its best time base (header stamps on the log's clock, or
   mapped from a second clock, or a robust envelope of bursty receive times), its own twist (or pose differences
   when it has none), the command stream's publication (periodic, or on change: the held command is the input
   either way; what is required is excitation, not a message count), gaps;
1. delay (twin.delay): cross-correlation, per axis with a bootstrap confidence interval and a warning when two
   candidate delays nearly tie; per-edge actuation delays; perception latency from scan times; tau95 = 95th
   percentile of their sum, with its parts;
2. the saturating execution model (twin.limits): the robot's wheel-speed limit, acceleration limit and
   command-to-wheel latency (dead time per axis, with a confidence interval) identified with the model they break;
   A, d of eq:execution (1) by least squares on the samples the model says have settled below the limits
   (twin.execution for the axes: those the log does not excite are reported as not identified). When the log reaches a
   limit the summary says plainly what a linear model fitted across it would claim;
3. residual bound (twin.residual): conformal quantile of ||r_xy|| per command-speed bin on the settled,
   unsaturated samples of the calibration blocks, coverage checked on the held-out time blocks (the error right
   after a command change is the delay's, which the relative-motion delay term of eq:uncertainty_margin (21)
   covers); the coverage is also reported on every unsaturated held-out sample (transients included) and on every
   held-out sample (saturated ones too, which eq:execution (1) does not describe), and a held-out coverage more than 3
   points below the stated one is a warning;
4. e_ZOH (:func:`zoh_displacement`) from the log's command period (the stack's T_C when commands are published
   on change) and measured speeds.

Commands are held between messages, as most drivers do (a TurtleBot3 holds its last cmd_vel). A robot whose
firmware stops on a command timeout is told by ``max_command_age_s`` (``--cmd-timeout``): samples whose command is
older than that when it should act are left out of every step but the delay's (holding the last command there
would pair it with a stopped robot). Without it, gaps over 0.5 s in a periodic command stream are a note.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bigcbf.errors import UserError
from bigcbf.logio import CMD, ODOM, SCAN, LogData, find_topic, open_log, read_series
from bigcbf.params.stack import ExecutionModel, StackParams, Tau95Parts
from bigcbf.params.toml_io import from_dict, to_dict

from .delay import DelayEstimate, DelayOptions, estimate_delay
from .execution import (AXES, ExecutionFit, ExecutionOptions, identified_axes, input_condition,
                        saturated_samples, settled_samples)
from .limits import LimitOptions, SaturatingModel, fit_model, gain_intervals
from .residual import ResidualBound, ResidualOptions, calibrate_bound, conformal_quantile, holdout_mask
from .signals import intervals, quantile_upper, zoh
from .timebase import OdomTiming, TimebaseOptions, command_publication, prepare

MIN_MESSAGES = 20          # odometry messages, and usable samples for the residual bound, at least
MIN_CHANGES = 2            # command changes on the identified axes, at least (the delay needs edges)
UNITS = ("m/s", "m/s", "rad/s")


@dataclass(frozen=True)
class CalibrationOptions:
    delay: DelayOptions = DelayOptions()
    execution: ExecutionOptions = ExecutionOptions()
    residual: ResidualOptions = ResidualOptions()
    limits: LimitOptions = LimitOptions()
    timebase: TimebaseOptions = TimebaseOptions()
    period_quantile: float = 0.95     # T_C: this quantile of the intervals between commands [-]
    speed_quantile: float = 0.99      # v of e_ZOH: this quantile of the measured ||v_xy|| [-]
    max_command_age_s: float | None = None   # the robot's command timeout, if it has one (module docstring) [s]
    coverage_warn: float = 0.03       # a held-out coverage this far below the stated one is a warning [-]
    condition_warn: float = 30.0      # the input condition number above which the axes are not separable [-]
    block_s: float = 10.0             # blocks of the latency bootstrap [s]


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
    aligned: dict[str, np.ndarray]   # t, u, v, held, saturated, settled, used, speed, resid, pred (for the report)
    warnings: list[str] = field(default_factory=list)
    model: SaturatingModel | None = None     # the saturating execution model (limits, latency)
    timing: OdomTiming | None = None         # the odometry's time base
    publication: str = "periodic"            # of the commands: "periodic" or "on change"
    coverage_heldout_all: float = float("nan")   # the bound's coverage on every held-out sample (saturated too)
    rmse_saturating: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # (3,) held-out, the model
    axis_bound: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))   # (3,) per-axis residual bound
    axis_coverage: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # (3,) its held-out coverage
    rmse_all: dict[str, np.ndarray] = field(default_factory=dict)   # every held-out sample: nominal, identity,
    #                                                                 linear (eq:execution (1)), saturating
    gain_ci: np.ndarray = field(default_factory=lambda: np.full((3, 2), np.nan))  # (3, 2) 90 % interval of diag A

    @property
    def latency_s(self) -> np.ndarray:
        """The command-to-wheel latency per axis: the model's dead time plus the time its first-order lag takes to
        half a small step (T ln 2), i.e. the median delay of the response before any limit acts; nan where not
        identified [s]. (Dead time and lag trade off against each other, against a latency jitter and behind an
        acceleration ramp; their sum is what the log pins down.)"""
        if self.model is None:
            return np.full(3, np.nan)
        return self.model.dynamic.latency_s + self.model.dynamic.axis_lags_s * math.log(2)

    @property
    def latency_ci_s(self) -> np.ndarray:
        """(3, 2): the 90 % bootstrap interval of :attr:`latency_s` [s]."""
        if self.model is None:
            return np.full((3, 2), np.nan)
        return self.model.dynamic.latency_ci_s + self.model.dynamic.axis_lags_s[:, None] * math.log(2)

    def tau95_parts(self) -> Tau95Parts:
        d = self.delay
        lat = self.latency_s[list(d.tau95_axes)] if d.tau95_axes else self.latency_s
        lat = float(np.nanmax(lat)) if np.isfinite(lat).any() else 0.0
        return Tau95Parts(latency_s=lat, actuation_median_s=float(d.actuation_median_s),
                          actuation95_s=float(d.actuation95_s), perception95_s=float(d.perception95_s))

    def execution_model(self) -> ExecutionModel:
        st = self.model.static if self.model is not None else None
        dyn = self.model.dynamic if self.model is not None else None
        return ExecutionModel(
            A=tuple(tuple(float(x) for x in row) for row in self.fit.A), d=tuple(float(x) for x in self.fit.d),
            residual_speed_mps=tuple(float(x) for x in self.bound.speed_knots),
            residual_bound_mps=tuple(float(x) for x in self.bound.bound_knots),
            residual_horizon_s=float(self.residual_horizon_s), residual_coverage=float(self.bound.coverage),
            identified=tuple(bool(x) for x in self.fit.identified),
            wheel_speed_max_mps=None if st is None or st.v_max is None else float(st.v_max),
            wheel_yaw_lever_m=None if st is None or st.v_max is None else float(st.lever_m),
            wheel_accel_max_mps2=None if dyn is None or dyn.accel_max is None else float(dyn.accel_max))

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
        for k in ("wheel_speed_max_mps", "wheel_yaw_lever_m", "wheel_accel_max_mps2"):
            if k in ex:
                ex[k] = round(ex[k], 4)
        parts = {k: round(v, 5) for k, v in to_dict(self.tau95_parts()).items()}
        return {"uncertainty": {"tau95_s": up(self.delay.tau95_s), "e_zoh_m": up(self.e_zoh_m), "execution": ex,
                                "tau95_parts": parts}}

    def limits_json(self) -> dict:
        if self.model is None:
            return {}
        st, dyn = self.model.static, self.model.dynamic
        return {"wheel_speed_max_mps": st.v_max, "wheel_yaw_lever_m": st.lever_m if st.v_max is not None else None,
                "wheel_yaw_lever_range_m": list(st.lever_range_m) if st.v_max is not None else None,
                "wheel_yaw_lever_identified": bool(st.lever_identified),
                "rim_demand_max_mps": st.demand_max, "saturated_settled_samples": int(st.n_saturated),
                "wheel_accel_max_mps2": dyn.accel_max, "accel_floor_mps2": dyn.accel_floor,
                "lag_s": dyn.lag_s, "lag_axes_s": dyn.axis_lags_s.tolist(), "linear_fit_across_limit": {"A": st.A_linear.tolist(), "d": st.d_linear.tolist()}}

    def to_json(self) -> dict:
        d = self.delay
        lat = self.latency_s
        ci = self.latency_ci_s
        dead = self.model.dynamic.latency_s if self.model is not None else np.full(3, np.nan)
        lags = self.model.dynamic.axis_lags_s if self.model is not None else np.full(3, np.nan)
        return jsonable({
            "log": self.log, "topics": self.topics, "duration_s": self.duration_s,
            "tau95_s": d.tau95_s, "tau95_parts": to_dict(self.tau95_parts()),
            "tau95_axes": [AXES[j] for j in d.tau95_axes],
            "latency_s": {AXES[j]: {"latency": float(lat[j]), "ci90": ci[j].tolist(), "dead_time": float(dead[j]),
                                    "lag": float(lags[j])}
                          for j in range(3) if np.isfinite(lat[j])},
            "lag_s": self.model.dynamic.lag_s if self.model is not None else None,
            "delay": {"xcorr_s": d.xcorr_s, "actuation_median_s": d.actuation_median_s,
                      "actuation95_s": d.actuation95_s, "perception95_s": d.perception95_s,
                      "perception_source": d.perception_source, "edges": int(len(d.edge_delays_s)),
                      "axes": {AXES[j]: {"xcorr_s": a.delay_s, "ci90": list(a.ci_s), "peak": a.peak,
                                         "near_tie_s": a.runner_up_s if a.tie else None, "edges": a.edges,
                                         "edge_median_s": a.edge_median_s} for j, a in d.axes.items()}},
            "A": self.fit.A.tolist(), "d": self.fit.d.tolist(),
            "gain_ci90": {AXES[j]: self.gain_ci[j].tolist() for j in range(3) if np.isfinite(self.gain_ci[j]).all()},
            "identified": {a: bool(x) for a, x in zip(AXES, self.fit.identified)},
            "limits": self.limits_json(),
            "e_exec": {"residual_speed_mps": self.bound.speed_knots.tolist(),
                       "residual_bound_mps": self.bound.bound_knots.tolist(),
                       "residual_horizon_s": self.residual_horizon_s,
                       "coverage": self.bound.coverage, "coverage_calibration": self.bound.coverage_calibration,
                       "coverage_heldout": self.bound.coverage_heldout,
                       "coverage_heldout_final_block": self.bound.coverage_tail,
                       "coverage_heldout_transients": self.coverage_heldout_transients,
                       "coverage_heldout_all": self.coverage_heldout_all,
                       "axis_bound": dict(zip(AXES, map(float, self.axis_bound))),
                       "axis_coverage_heldout": dict(zip(AXES, map(float, self.axis_coverage)))},
            "e_zoh_m": self.e_zoh_m, "control_period_s": self.control_period_s, "speed_mps": self.speed_mps,
            "commands": self.publication, "odometry_times": None if self.timing is None else self.timing.source,
            "rmse_heldout": {"nominal": dict(zip(AXES, map(float, self.rmse_nominal))),
                             "identity": dict(zip(AXES, map(float, self.rmse_identity))),
                             "model": dict(zip(AXES, map(float, self.rmse_model))),
                             "saturating": dict(zip(AXES, map(float, self.rmse_saturating)))},
            "rmse_heldout_all_samples": {k: dict(zip(AXES, map(float, v))) for k, v in self.rmse_all.items()},
            "samples": self.counts, "warnings": self.notes(),
        })

    def notes(self) -> list[str]:
        """Every note about the log and the calibration (what the summary prints and replay carries)."""
        out = []
        for n in self.warnings + self.delay.notes + (self.model.dynamic.notes if self.model is not None else []):
            if n not in out:
                out.append(n)
        return out


def zoh_displacement(t_cmd, v_xy, period_quantile: float = 0.95, speed_quantile: float = 0.99,
                     period_s: float | None = None):
    """e_ZOH of eq:uncertainty_margin (21): the distance the robot can cover while one command is held, T_C * v.

    T_C = the ``period_quantile`` of the intervals between consecutive commands (messages of one burst merged),
    or ``period_s`` when given (commands published on change have no period: the stack's T_C), v = the
    ``speed_quantile`` of the measured translational speed ||v_xy||. Returns (e_zoh_m, T_C, v).
    """
    if period_s is None:
        dt = intervals(t_cmd)
        if len(dt) == 0:
            raise ValueError("need at least two commands at different times")
        T = quantile_upper(dt, period_quantile)
    else:
        T = float(period_s)
    v = quantile_upper(np.hypot(v_xy[:, 0], v_xy[:, 1]), speed_quantile)
    return T * v, T, v


def _rmse(err: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(err ** 2, axis=0)) if len(err) else np.full(3, np.nan)


def _changes(u: np.ndarray, axes: np.ndarray) -> int:
    if len(u) < 2:
        return 0
    tol = np.array([1e-3, 1e-3, 2e-3])
    return int(np.sum(np.any((np.abs(np.diff(u, axis=0)) > tol)[:, axes], axis=1)))


def _limits_notes(model: SaturatingModel, v_stack: float) -> list[str]:
    """What the saturating model says, in plain words (module docstring, step 2)."""
    st, dyn = model.static, model.dynamic
    axes = np.zeros(3, bool)
    out = []
    if st.v_max is not None:
        k = st.lever_m
        alone = [f"vx or vy alone {st.v_max:.3f} m/s"]
        if k > 0:
            alone.append(f"wz alone {st.v_max / k:.2f} rad/s")
        lever = (f"yaw lever {k:.3f} m" if st.lever_identified else
                 f"yaw lever {k:.3f} m, not pinned down: {st.lever_range_m[0]:.2f}-{st.lever_range_m[1]:.2f} m fit "
                 "as well")
        Al, dl = st.A_linear, st.d_linear
        worst = [f"A[{AXES[i]},{AXES[j]}] {Al[i, j]:+.3f} (below the limit {st.A[i, j]:+.3f})"
                 for i in range(3) for j in range(3) if abs(Al[i, j] - st.A[i, j]) > 0.05]
        worst += [f"d[{AXES[i]}] {dl[i]:+.3f} {UNITS[i]} (below {st.d[i]:+.3f})" for i in range(3)
                  if abs(dl[i] - st.d[i]) > (0.02 if i < 2 else 0.05)]
        out.append(f"the robot saturates: its wheels reach a rim speed of {st.v_max:.3f} m/s ({', '.join(alone)}; "
                   f"{lever}); {st.n_saturated} settled samples asked for more (up to {st.demand_max:.2f} m/s). "
                   "A linear model v = A u + d is wrong above the limit" +
                   (": fitted across it, it would claim " + ", ".join(worst[:6]) if worst else "") +
                   ". A and d here are fitted below the limit")
        if st.v_max < v_stack:
            out.append(f"the stack commands up to {v_stack} m/s, more than this robot's wheels realise "
                       f"({st.v_max:.3f} m/s rim speed): give the stack v_max_mps <= {st.v_max:.2f}, or its "
                       "commands above that are not executed as eq:execution (1) says")
    if dyn.accel_max is not None:
        out.append(f"the wheels' acceleration is limited to {dyn.accel_max:.2f} m/s^2 (rim), after a dead time and a "
                   f"{dyn.lag_s * 1e3:.0f} ms lag")
    return out


NEVER_MOVED = 0.05          # the odometry's path below this fraction of the commanded one: the robot never moved [-]


def _check_moved(cmd, odom, path: str) -> None:
    """A UserError when the odometry shows (next to) no motion while the commands ask for some: the path length
    and the summed heading change (of the pose, or of the twist integrated, whichever is larger) under ``NEVER_MOVED`` of the commanded ones (||u_xy|| and |wz| held over the
    odometry's span), each where the commands ask for at least 0.2 m or 0.2 rad."""
    t = odom.t[odom.t >= cmd.t[0]]
    if len(t) < 2:
        return
    u = zoh(cmd.t, cmd.u, t[:-1])
    dt = np.diff(t)
    want_xy = float(np.sum(np.hypot(u[:, 0], u[:, 1]) * dt))
    want_yaw = float(np.sum(np.abs(u[:, 2]) * dt))
    pose = odom.pose[odom.t >= cmd.t[0]]
    v = odom.twist[odom.t >= cmd.t[0]][:-1]            # a log may carry only one of pose and twist: either moving
    got_xy = max(float(np.sum(np.hypot(*np.diff(pose[:, :2], axis=0).T))),
                 float(np.sum(np.hypot(v[:, 0], v[:, 1]) * dt)))
    got_yaw = max(float(np.sum(np.abs(np.diff(np.unwrap(pose[:, 2]))))), float(np.sum(np.abs(v[:, 2]) * dt)))
    asked = [(g, w) for g, w in ((got_xy, want_xy), (got_yaw, want_yaw)) if w >= 0.2]
    if asked and all(g < NEVER_MOVED * w for g, w in asked):
        raise UserError(f"the robot never moved: the commands on {cmd.topic} ask for {want_xy:.2f} m and "
                        f"{want_yaw:.2f} rad, the odometry ({odom.topic}) shows {got_xy:.3f} m and {got_yaw:.3f} "
                        "rad; nothing to calibrate", file=path)


def calibrate_series(data: LogData, opt: CalibrationOptions = CalibrationOptions()) -> Calibration:
    """Calibrate from extracted series (commands and odometry required, scan stamps optional).

    Length: to be split (issue 22): the input checks, the delay alignment, the fits, the warnings and the result are
    separate stages in one body."""
    path = str(data.path)
    cmd, odom, scan = data.cmd, data.odom, data.scan
    if cmd is None or len(cmd.t) < 2:
        raise UserError(f"too few commands to calibrate ({0 if cmd is None else len(cmd.t)}; the held command is "
                        "the input, but it has to change)", file=path, field=None if cmd is None else cmd.topic)
    if odom is None or len(odom.t) < MIN_MESSAGES:
        raise UserError(f"too few odometry messages to calibrate ({0 if odom is None else len(odom.t)}, need "
                        f"{MIN_MESSAGES})", file=path, field=None if odom is None else odom.topic)
    data, timing, log_notes = prepare(data, opt.timebase)
    odom = data.odom
    if min(cmd.t[-1], odom.t[-1]) - max(cmd.t[0], odom.t[0]) < 2.0:
        raise UserError(f"the commands ({cmd.topic}) and the odometry ({odom.topic}) overlap for less than 2 s",
                        file=path)
    _check_moved(cmd, odom, path)
    held_cmd = zoh(cmd.t, cmd.u, odom.t[(odom.t >= cmd.t[0])])
    axes = identified_axes(held_cmd, opt.execution)
    if not axes.any():
        raise UserError(f"the commands on {cmd.topic} do not excite any axis (std of the held command vx, vy, wz: "
                        f"{', '.join(f'{x:.3g}' for x in held_cmd.std(axis=0))}); nothing to calibrate", file=path)
    n_changes = _changes(cmd.u, axes)
    if n_changes < MIN_CHANGES:
        raise UserError(f"the commands on {cmd.topic} change {n_changes} time(s) on the excited axes: not enough "
                        "excitation to measure a delay (a step up and back at least)", file=path)
    publication, med_interval = command_publication(cmd.t)
    ax = np.flatnonzero(axes)
    delay = estimate_delay(cmd.t, cmd.u, odom.t, odom.twist, ax,
                           None if scan is None else scan.t, None if scan is None else scan.stamp, opt.delay)
    # delay-aligned samples at the odometry times: each axis at its own cross-correlation delay
    tau = np.full(3, delay.xcorr_s)
    for j, a in delay.axes.items():
        tau[j] = a.delay_s
    lo, hi = float(tau[axes].min()), float(tau[axes].max())
    keep = (odom.t - hi >= cmd.t[0]) & (odom.t - lo <= cmd.t[-1] + opt.delay.max_gap_s)
    last_cmd = cmd.t[np.clip(np.searchsorted(cmd.t, odom.t - lo, side="right") - 1, 0, len(cmd.t) - 1)]
    age = odom.t - lo - last_cmd
    stale = keep & (age > opt.max_command_age_s) if opt.max_command_age_s is not None else np.zeros_like(keep)
    keep &= ~stale
    gaps = intervals(cmd.t)
    t = odom.t[keep]
    v = odom.twist[keep]
    u0 = zoh(cmd.t, cmd.u, t - delay.xcorr_s)
    held = holdout_mask(t, opt.residual)
    settled0 = settled_samples(cmd.t, cmd.u, t - delay.xcorr_s, opt.execution)
    if not (settled0 & ~held).any():
        raise UserError("no odometry sample in the calibration blocks follows a held command long enough to "
                        "settle: "
                        f"the commands on {cmd.topic} change faster than the robot can follow (or their order is "
                        "scrambled)", file=path)
    nb = max(6, int(round((t[-1] - t[0]) / opt.block_s)))
    block = np.minimum(((t - t[0]) / max(t[-1] - t[0], 1e-9) * nb).astype(int), nb - 1)
    model = fit_model(cmd.t, cmd.u, t, v, axes, ~held, block, u0, settled0, opt.limits,
                      min_settled=opt.execution.min_settled, avg_s=timing.period_s)
    # from here on the command in force is the one the model says acts: delayed by its dead time per axis
    u = np.where(model.scored[:, None], model.u_delayed, u0)
    st = model.static
    settled = model.settled
    settled_only = bool((settled & ~held).sum() >= opt.execution.min_settled)
    if not settled_only:
        settled = settled0 if (settled0 & ~held).sum() >= opt.execution.min_settled else np.ones(len(t), bool)
    sat = model.saturated.copy()
    # falling short of the command where the wheel model sees no limit: left out too, and said
    short = saturated_samples(t, u, v, st.A, st.d, axes, opt.execution) & ~sat & settled
    use = settled & ~sat & ~short & model.scored
    if int((use & ~held).sum()) < MIN_MESSAGES:
        raise UserError(f"too few usable samples for the residual bound ({int((use & ~held).sum())} settled, "
                        f"unsaturated samples in the calibration blocks, need {MIN_MESSAGES})", file=path)
    fit = ExecutionFit(st.A, st.d, axes, sat[~held] | short[~held], int((use & ~held).sum()), settled_only)
    # A's interval: a bootstrap of the fit that gave it, on its samples (limits.gain_intervals)
    su = model.static_use
    gain_ci = gain_intervals(t[su], model.static_u[su], v[su], axes, st, opt.execution.gain_block_s,
                             opt.execution.gain_bootstrap, opt.execution.gain_level)
    r = v - fit.predict(u)
    speed = np.hypot(u[:, 0], u[:, 1])
    resid = np.hypot(r[:, 0], r[:, 1])
    bound = calibrate_bound(t[use], speed[use], resid[use], opt.residual, held=held[use])
    inside = resid <= bound(speed)
    unsat_held = held & ~sat & model.scored
    cov_unsat = float(inside[unsat_held].mean()) if unsat_held.any() else float("nan")
    all_held = held & model.scored
    cov_all = float(inside[all_held].mean()) if all_held.any() else float("nan")
    # per-axis residual bounds (informational: the report draws them)
    axis_bound, axis_cov = np.full(3, np.nan), np.full(3, np.nan)
    for j in ax:
        ra = np.abs(r[:, j])
        if (use & ~held).sum() >= MIN_MESSAGES:
            axis_bound[j] = conformal_quantile(ra[use & ~held], opt.residual.coverage)
            if (use & held).any():
                axis_cov[j] = float((ra[use & held] <= axis_bound[j]).mean())
    v_stack = StackParams().v_max_mps
    period = None if publication == "periodic" else StackParams().T_C_s
    if period is None and len(intervals(cmd.t)) == 0:
        raise UserError(f"all commands on {cmd.topic} carry the same log time: no control period", file=path)
    e_zoh, T_C, v_q = zoh_displacement(cmd.t, odom.twist, opt.period_quantile, opt.speed_quantile, period)
    ho = held & use
    warnings = list(data.warnings) + log_notes
    if publication == "on change":
        warnings.append(f"{cmd.topic} is published on change ({len(cmd.t)} messages, median interval "
                        f"{med_interval:.2f} s): the held command is the input; the log has no control period, so "
                        f"e_ZOH uses the stack's T_C {T_C} s")
    if stale.any():
        warnings.append(f"{int(stale.sum())} odometry samples left out: their command was older than the command "
                        f"timeout {opt.max_command_age_s} s (gaps in {cmd.topic})")
    elif (opt.max_command_age_s is None and publication == "periodic" and len(gaps) and gaps.max() > 0.5):
        warnings.append(f"{cmd.topic} has gaps of up to {gaps.max():.2f} s; the last command was held through them "
                        "(if the robot stops on a command timeout, give it: --cmd-timeout)")
    warnings += _limits_notes(model, v_stack)
    if short.sum() > 0.05 * max(settled.sum(), 1):
        warnings.append(f"{int(short.sum())} settled samples fall short of the command without reaching the "
                        "identified wheel limit (a per-axis limit? slip?); they are left out of A, d and the bound")
    for name, cov in (("held-out blocks", bound.coverage_heldout), ("final held-out block", bound.coverage_tail)):
        if cov < bound.coverage - opt.coverage_warn:
            warnings.append(f"the residual bound covers {cov:.3f} of the {name}, below the stated {bound.coverage}: "
                            "the log's residuals are not stationary; calibrate on a longer or steadier log")
    if sat.any() and cov_all < bound.coverage - opt.coverage_warn:
        warnings.append(f"on every held-out sample, saturated ones included, the bound covers {cov_all:.3f}: "
                        "eq:execution (1) does not describe the robot above its wheel limit")
    cond = input_condition(u0[~held & settled], axes)          # the commands as sent: collinear or not
    if cond > opt.condition_warn:
        warnings.append(f"the commanded axes {', '.join(a for a, x in zip(AXES, axes) if x)} move together "
                        f"(condition number {cond:.0f}): each is excited, but their cross gains in A cannot be "
                        "told apart; excite them independently for a full A")
    u_top = quantile_upper(np.hypot(cmd.u[:, 0], cmd.u[:, 1]), opt.speed_quantile)
    if u_top < v_stack - 0.05:
        warnings.append(f"the log commands at most {u_top:.2f} m/s (the {opt.speed_quantile:.0%} quantile), the "
                        f"stack up to {v_stack} m/s: e_ZOH = T_C v (v measured, {v_q:.2f} m/s) and the residual "
                        f"bound above {bound.speed_knots[-1]:.2f} m/s are extrapolated from slower driving")
    if not settled_only:
        warnings.append(f"only {int((model.settled & ~held).sum())} samples whose response has settled in the "
                        "calibration blocks: A and d were fitted on fewer or transient samples (gains may read low)")
    for j in np.flatnonzero(~axes):
        warnings.append(f"{AXES[j]} is not identified: the log does not excite it (identity row kept in A, no bias)")
    rmse_nom = _rmse((v - zoh(cmd.t, cmd.u, t))[ho])
    rmse_model = _rmse(r[ho])
    for j in ax:
        if rmse_model[j] > rmse_nom[j]:
            warnings.append(f"on {AXES[j]} the fitted model predicts the settled held-out samples worse than the "
                            f"nominal v = u ({rmse_model[j]:.4f} vs {rmse_nom[j]:.4f} {UNITS[j]}): the log's "
                            "residuals are not stationary or the axis barely moves")
    sc = model.scored & held
    counts = {"stale": int(stale.sum()), "commands": int(len(cmd.t)), "odometry": int(len(odom.t)),
              "scans": int(0 if scan is None else len(scan.t)), "aligned": int(len(t)), "settled": int(settled.sum()),
              "calibration": int((~held & use).sum()), "heldout": int(ho.sum()), "saturated": int(sat.sum()),
              "short": int(short.sum()), "fit": int(fit.n_used), "edges": int(len(delay.edge_delays_s))}
    return Calibration(
        log=path, topics={"commands": cmd.topic, "odometry": odom.topic, "scans": None if scan is None else scan.topic},
        duration_s=float(t[-1] - t[0]), delay=delay, fit=fit, bound=bound, control_period_s=T_C, speed_mps=v_q,
        e_zoh_m=e_zoh, residual_horizon_s=T_C + delay.tau95_s, coverage_heldout_transients=cov_unsat,
        rmse_nominal=rmse_nom, rmse_identity=_rmse((v - u0)[ho]), rmse_model=rmse_model, counts=counts,
        aligned={"t": t, "u": u, "v": v, "held": held, "saturated": sat, "settled": settled, "used": use,
                 "speed": speed, "resid": resid, "r": r, "pred": model.y, "scored": model.scored},
        warnings=warnings, model=model, timing=timing, publication=publication, coverage_heldout_all=cov_all,
        rmse_saturating=_rmse((v - model.y)[sc]), axis_bound=axis_bound, axis_coverage=axis_cov,
        rmse_all={"nominal": _rmse((v - zoh(cmd.t, cmd.u, t))[sc]), "identity": _rmse((v - u0)[sc]),
                  "linear": _rmse(r[sc]), "saturating": _rmse((v - model.y)[sc])}, gain_ci=gain_ci)


def read_log(path: str | Path, cmd_topic: str | None = None, odom_topic: str | None = None,
             scan_topic: str | None = None, use_scan: bool = True) -> LogData:
    """Open a log, find the command, odometry and (optional) scan topics, extract their series."""
    with open_log(path) as log:
        c = find_topic(log, CMD, cmd_topic)
        o = find_topic(log, ODOM, odom_topic)
        s = find_topic(log, SCAN, scan_topic, required=scan_topic is not None) if use_scan else None
        data = read_series(log, cmd=c, odom=o, scan=s)
        if log.format == "mcap" and not log.recovered and data.cmd is not None:
            data = _commands_in_file_order(data, log.path, c)
        return data


def _commands_in_file_order(data: LogData, path: Path, topic: str) -> LogData:
    """The commands checked against the order of the messages in the MCAP file (twin.timebase, Order): the reader
    sorts on the log time, which scrambles a topic whose log times were permuted."""
    import dataclasses

    from mcap.reader import make_reader

    from .timebase import command_order
    try:
        with open(path, "rb") as fh:
            rows = [(m.log_time, m.publish_time, m.sequence)
                    for _, _, m in make_reader(fh).iter_messages(topics=[topic], log_time_order=False)]
    except Exception:            # noqa: BLE001 - the reader read it; a file this one cannot index keeps its order
        return data
    if any(x > np.iinfo(np.int64).max for row in rows for x in row):   # times past 2262: the order is not checked
        return data                                                   # here (the reader's notes say what it saw)
    a = np.array(rows, np.int64).reshape(-1, 3)
    how, note = command_order(a[:, 0], a[:, 1], a[:, 2], topic, str(data.path))
    if how == "as is":
        return data
    cmd = data.cmd
    if how == "file order":
        if len(a) != len(cmd.t):      # the reader dropped messages (NaN): the file's order no longer maps onto them
            raise UserError(f"{topic}: its log times go back in the file's order and some messages were dropped; "
                            "the true order cannot be restored", file=str(data.path), field=topic)
        rank = np.argsort(np.argsort(a[:, 0], kind="stable"), kind="stable")   # each file message's place by time
        cmd = dataclasses.replace(cmd, t=np.sort(cmd.t), u=cmd.u[rank])
    return dataclasses.replace(data, cmd=cmd, warnings=list(data.warnings) + [note])


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
    ident = [j for j in range(3) if f.identified[j]]
    lines = [f"log            {cal.log}  ({cal.duration_s:.1f} s; commands {cal.topics['commands']} "
             f"({cal.publication}), odometry {cal.topics['odometry']} "
             f"({cal.timing.source if cal.timing is not None else 'receive times'}), scans {cal.topics['scans']})"]
    if cal.model is not None:
        dyn = cal.model.dynamic
        lat, ci = cal.latency_s, cal.latency_ci_s
        lines.append("latency        command to wheel (90 % interval): " + ", ".join(
            f"{AXES[j]} {lat[j]:.3f} s [{ci[j, 0]:.3f}, {ci[j, 1]:.3f}]" for j in ident)
            + f"  (dead time {', '.join(f'{dyn.latency_s[j]:.3f}' for j in ident)} s, then a lag of "
            f"{', '.join(f'{dyn.axis_lags_s[j] * 1e3:.0f}' for j in ident)} ms: + T ln 2 to half a step)")
    lines.append("delays         cross-correlation (90 % interval): " + ", ".join(
        f"{AXES[j]} {a.delay_s:.3f} s [{a.ci_s[0]:.3f}, {a.ci_s[1]:.3f}]" + (" NEAR TIE" if a.tie else "")
        for j, a in d.axes.items()) + f"; all axes {d.xcorr_s:.3f} s")
    p = cal.tau95_parts()
    act = (f"actuation on {', '.join(AXES[j] for j in d.tau95_axes)} from {len(d.edge_delays_s)} edges (latency "
           f"{p.latency_s:.3f} s, half-way median {d.actuation_median_s:.3f} s, p95 {d.actuation95_s:.3f} s)"
           if len(d.edge_delays_s) >= DelayOptions().min_edges else
           f"actuation = the cross-correlation delay {d.xcorr_s:.3f} s (too few clean edges; latency {p.latency_s:.3f} s)")
    lines.append(f"tau95          {d.tau95_s:.3f} s = 95 % of (actuation + perception): {act}; "
                 f"perception p95 {d.perception95_s:.3f} s from {d.perception_source}")
    if cal.model is not None:
        st, dyn = cal.model.static, cal.model.dynamic
        lim = (f"wheel rim speed {st.v_max:.3f} m/s (yaw lever {st.lever_m:.3f} m" +
               ("" if st.lever_identified else f", {st.lever_range_m[0]:.2f}-{st.lever_range_m[1]:.2f} fit as well")
               + f"), {cal.counts['saturated']} samples saturated" if st.v_max is not None else
               f"no wheel-speed limit reached (rim demand up to {st.demand_max:.2f} m/s realised)")
        acc = (f"acceleration {dyn.accel_max:.2f} m/s^2 (rim)" if dyn.accel_max is not None else
               f"no acceleration limit seen (at least {dyn.accel_floor:.0f} m/s^2)")
        lines.append(f"limits         {lim}; {acc}")
    for j, a in enumerate(AXES):
        ci = cal.gain_ci[j]
        gain = f" (gain 90 % [{ci[0]:.3f}, {ci[1]:.3f}])" if np.isfinite(ci).all() else ""
        lines.append(f"A[{a}]          {fmt(f.A[j])}   d {f.d[j]:+.4f}   "
                     + ("identified" + gain if f.identified[j] else "NOT identified (not excited by the log)"))
    lines += [f"e_exec         horizon {cal.residual_horizon_s:.3f} s x bound(|u_xy|): "
              + ", ".join(f"{s:.2f} m/s -> {v:.4f}" for s, v in zip(b.speed_knots, b.bound_knots)),
              f"coverage       stated {b.coverage:.3f}; settled unsaturated: calibration {b.coverage_calibration:.3f}, "
              f"held-out {b.coverage_heldout:.3f} (final block {b.coverage_tail:.3f}); every unsaturated held-out "
              f"sample {cal.coverage_heldout_transients:.3f}; every held-out sample {cal.coverage_heldout_all:.3f}",
              f"e_ZOH          {cal.e_zoh_m:.4f} m  (T_C {cal.control_period_s:.3f} s x v {cal.speed_mps:.3f} m/s)",
              "held-out RMSE  settled: nominal v=u(t) " + fmt(cal.rmse_nominal) + "   v=u(t-delay) "
              + fmt(cal.rmse_identity) + "   fitted " + fmt(cal.rmse_model)]
    if cal.rmse_all:
        ra = cal.rmse_all
        lines.append("               every sample: nominal " + fmt(ra["nominal"]) + "   linear " + fmt(ra["linear"])
                     + "   saturating model " + fmt(ra["saturating"]))
    lines.append("samples        " + ", ".join(f"{k} {v}" for k, v in cal.counts.items()))
    lines += [f"note           {w}" for w in cal.notes()]
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
