"""Replay logged commands through the MuJoCo model and compare with the logged odometry (``bigcbf replay``).

The log is read as calibrate reads it (twin.timebase: the odometry on its best time base, its own twist). The model
starts at rest at the logged pose at the first command and receives every logged command at its log time (relative
to that start). At each logged odometry time the simulated wheel odometry is sampled; its twist is the average over
the log's nominal odometry period before that time (the pose change over that period in the body frame), as an
encoder-based odometry reports it, so both sides are measured alike, and bursts of messages (several within a
millisecond) cannot turn into meaningless velocities.

Models compared, always the first two:

- nominal: the ideal robot (``RobotProfile()``: no latency, A = I, d = 0, no wheel limits);
- calibrated: the log's saturating execution model (twin.limits: A, d, the dead time, the wheel-speed and
  acceleration limits) mapped onto the model's own response. The model is not ideal either (wheel dynamics,
  roller slip, the odometry's averaging), so the nominal replay is calibrated too, giving its own A0, d0 and dead
  time L0, and the robot profile that reproduces the log is latency = L - L0 (the median over the identified
  axes), gain G = A0^-1 A, bias b = A0^-1 (d - d0) (measured = A0 (G u + b) + d0 = A u + d), the wheel-speed limit
  v_max / a0 (a0: A0's mean translational gain, the limit acts before it) with the log's yaw lever, and the log's
  acceleration limit when it is clearly (20 %) below the model's own. A, d (and the limits) come from ``--profile`` (an
  uncertainty profile) or from calibrating the log itself; the dead time is always measured on the replayed log
  (an uncertainty profile holds tau95, which includes perception latency). Then one correction step: the latency
  is moved by the lag that best aligns the replayed twist with the logged one (the correlation of their changes:
  both answer the same commands, so their shapes match, where the model's own response does not simply add to
  the log's: a lag, a latency jitter or an acceleration ramp trade against the dead time differently on each side);
- fitted (``--fit``): starting from the calibrated profile, latency, the diagonal gains and the floor friction
  are tuned to minimise the replay's velocity error (Nelder-Mead on the first ``fit_window_s`` of the log);
- model (``--model``, or ``--robot DIR``): the MuJoCo model itself fitted with ``mujoco.sysid`` behind the
  calibrated command layer (twin.model_fit), or a robot folder so fitted, behind its own command layer.

Held out (``holdout`` > 0; ``--model`` holds out 0.4 by default): the calibration and the model fit see only the
log before the split, every run simulates the whole log, and every score counts from the split on.

Errors: velocity RMSE per axis over all samples; pose drift over consecutive windows of ``window_s``: the
displacement over the window in the frame of its start, simulated minus logged (m), and the heading change
difference (rad); the final position error.

The verdict (:func:`compare`) weighs every score the table prints -- the velocity RMSE of each identified axis, the
mean and largest pose drift, the mean heading drift and the final error -- and says for each which model is better
(lower is better; within 1 % of each other, or within half the printed resolution, they are "about equal"). The
result carries that verdict as its first note, a ``WORSE:`` warning for each score on which the calibrated replay
is worse than the nominal one (with what the calibration and the drift windows say about why), then every note
calibrate has about the log.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from bigcbf.errors import UserError
from bigcbf.logio import LogData, OdomSeries
from bigcbf.params.checks import check_field_ranges, ranged
from bigcbf.params.robot import RobotProfile
from bigcbf.params.stack import ExecutionModel

from .calibrate import CalibrationOptions, calibrate_series
from .execution import AXES
from .timebase import prepare


#: the documented range of the pose-drift and fit windows [s] (a shorter window than a tenth of a second holds no
#: odometry period of a real base; 1e-300 made a replay count windows forever)
MIN_WINDOW_S = 0.1
MAX_WINDOW_S = 3600.0
#: the longest span a replay simulates, from the first command to the last odometry [s] (4 h of robot time: about
#: 6 min of computing; a log's times shifted by 2^63 ns asked for 292 years and never ended, a fuzzer's case)
MAX_REPLAY_S = 4 * 3600.0


@dataclass(frozen=True)
class ReplayOptions:
    window_s: float = ranged(5.0, MIN_WINDOW_S, MAX_WINDOW_S)  # pose-drift windows [s]
    fit: bool = False
    fit_window_s: float = ranged(20.0, MIN_WINDOW_S, MAX_WINDOW_S)  # the part of the log the fit replays [s]
    fit_evals: int = ranged(40, 1, 10000)  # replays the fit may spend
    holdout: float = ranged(0.0, 0.0, 0.9)  # score on this last fraction of the log; calibrate on the rest
    model: bool = False                     # also fit the MuJoCo model (twin.model_fit, mujoco.sysid)
    video_fps: float = ranged(10.0, 1, 120)

    def __post_init__(self):
        check_field_ranges(self)


@dataclass
class ReplayRun:
    """One replay: the profile used, the simulated odometry at the logged times, and its errors."""
    name: str
    profile: RobotProfile
    t: np.ndarray                    # logged odometry times [s]
    pose: np.ndarray                 # (N, 3) simulated odometry pose
    twist: np.ndarray                # (N, 3) simulated odometry twist (interval average)
    rmse: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    drift_mean_m: float = float("nan")
    drift_max_m: float = float("nan")
    yaw_drift_mean_rad: float = float("nan")
    yaw_drift_max_rad: float = float("nan")
    final_error_m: float = float("nan")
    #: the pose-drift windows: (K, 3) rows of (start [s after the first command], drift [m], heading drift [rad])
    windows: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def to_json(self) -> dict:
        p = self.profile
        return {"profile": {"latency_s": p.latency_s, "gain": [list(r) for r in p.gain], "bias": list(p.bias),
                            "floor_friction": p.floor_friction, "wheel_speed_max_mps": p.wheel_speed_max_mps,
                            "wheel_yaw_lever_m": p.wheel_yaw_lever_m, "wheel_accel_max_mps2": p.wheel_accel_max_mps2},
                "velocity_rmse": dict(zip(AXES, map(float, self.rmse))),
                "drift_mean_m": self.drift_mean_m, "drift_max_m": self.drift_max_m,
                "yaw_drift_mean_rad": self.yaw_drift_mean_rad, "yaw_drift_max_rad": self.yaw_drift_max_rad,
                "final_error_m": self.final_error_m}


# --- the verdict --------------------------------------------------------------------------------------------
#: The scores the replay's table prints (its column headers), their ReplayRun attribute, unit and printed
#: resolution; the velocity RMSE columns come first, one per axis.
POSE_SCORES = (("drift mean", "drift_mean_m", "m", 1e-3), ("drift max", "drift_max_m", "m", 1e-3),
               ("yaw mean", "yaw_drift_mean_rad", "rad", 1e-3), ("final err", "final_error_m", "m", 1e-3))
RMSE_UNITS = ("m/s", "m/s", "rad/s")
RMSE_RESOLUTION = 1e-4
TIE_REL = 0.01              # within 1 % of each other (or half the printed resolution) two scores are about equal


@dataclass(frozen=True)
class Score:
    """One score of the replay's table for a model and for the nominal one (lower is better)."""
    label: str              # the table's column header: "rmse vx", "drift max", ...
    unit: str
    model: float            # the compared model's (calibrated or fitted)
    nominal: float
    resolution: float       # the table's printed resolution
    identified: bool = True  # False: an RMSE on an axis the log does not identify (not compared)

    @property
    def better(self) -> str:
        """'model', 'nominal', 'equal', or 'not compared' (an axis not identified, or a score that is nan)."""
        if not self.identified or not (np.isfinite(self.model) and np.isfinite(self.nominal)):
            return "not compared"
        if abs(self.model - self.nominal) <= max(TIE_REL * max(abs(self.model), abs(self.nominal)),
                                                 self.resolution / 2):
            return "equal"
        return "model" if self.model < self.nominal else "nominal"

    def to_json(self, name: str) -> dict:
        b = self.better
        return {"score": self.label, "unit": self.unit, name: self.model, "nominal": self.nominal,
                "better": name if b == "model" else b}


def scores(model: ReplayRun, nominal: ReplayRun, identified) -> list[Score]:
    """Every score the table prints for ``model`` and the nominal run, in the table's order."""
    ident = np.ones(3, bool) if identified is None else np.asarray(identified, bool)
    out = [Score(f"rmse {AXES[j]}", RMSE_UNITS[j], float(model.rmse[j]), float(nominal.rmse[j]), RMSE_RESOLUTION,
                 bool(ident[j])) for j in range(3)]
    out += [Score(label, unit, float(getattr(model, attr)), float(getattr(nominal, attr)), res)
            for label, attr, unit, res in POSE_SCORES]
    return out


def _fmt(x: float, res: float) -> str:
    return f"{x:.4f}" if res < 1e-3 else f"{x:.3f}"


def verdict_line(name: str, sc: list[Score]) -> str:
    """One line: per score, which model is better, with both numbers (``name`` vs nominal)."""
    parts = []
    for s in sc:
        if s.better == "not compared":
            if not s.identified:
                parts.append(f"{s.label} not compared ({s.label.split()[-1]} not identified)")
            continue
        nums = f"{name} {_fmt(s.model, s.resolution)}, nominal {_fmt(s.nominal, s.resolution)} {s.unit}"
        which = "about equal" if s.better == "equal" else f"{name if s.better == 'model' else 'nominal'} better"
        parts.append(f"{s.label}: {which} ({nums})")
    worse = [s.label for s in sc if s.better == "nominal"]
    head = (f"verdict, {name} vs nominal (lower is better): "
            + (f"{name} WORSE on {', '.join(worse)}; " if worse else f"{name} no worse on any score; "))
    return head + "; ".join(parts)


def why_pose_worse(label: str, model: ReplayRun, nominal: ReplayRun, window_s: float) -> str:
    """What the drift windows say about why ``model`` is worse than the nominal run on a pose score (measured)."""
    w, wn = model.windows, nominal.windows
    out = []
    if label == "final err":
        out.append("the final error is one sample: the position error after the whole log, where every heading "
                   "error on the way has turned into a displacement")
    if len(w) and len(w) == len(wn):
        col = 2 if label.startswith("yaw") else 1
        more = int(np.sum(w[:, col] > wn[:, col]))
        unit = "rad" if col == 2 else "m"
        k = int(np.argmax(w[:, col]))
        out.append(f"the {'heading ' if col == 2 else ''}drift is larger on {more} of {len(w)} {window_s:g}-s "
                   f"windows; the largest is in the window {w[k, 0]:.1f}-{w[k, 0] + window_s:.1f} s after the first "
                   f"command ({w[k, col]:.3f} {unit}, nominal {wn[k, col]:.3f} {unit})"
                   + (f", where the replayed heading departs {w[k, 2]:.3f} rad from the log's (a heading error turns "
                      "into position drift over the rest of the window)" if col == 1 else ""))
    out.append("the pose scores integrate the velocity error where the RMSE weighs each sample alone: a brief "
               "yaw-rate error the RMSE hardly sees (a wheel slip, a transient the model does not share) turns the "
               "rest of the path")
    return "; ".join(out)


def compare(runs: dict[str, ReplayRun], identified, window_s: float, cal=None) -> list[str]:
    """The verdict notes: for the calibrated run (and the fitted one), a line with every score, then a ``WORSE:``
    warning per score on which it is worse than the nominal run, with what is known about why."""
    notes = []
    nominal = runs["nominal"]
    for name in ("calibrated", "fitted", "model"):
        if name not in runs:
            continue
        run = runs[name]
        sc = scores(run, nominal, identified)
        notes.append(verdict_line(name, sc))
        for s in sc:
            if s.better != "nominal":
                continue
            nums = f"({name} {_fmt(s.model, s.resolution)}, nominal {_fmt(s.nominal, s.resolution)} {s.unit})"
            if s.label.startswith("rmse"):
                j = AXES.index(s.label.split()[-1])
                why = why_worse(j, cal, nominal, run) if name == "calibrated" else \
                    f"the {name} replay was fitted on {'the first part' if name == 'model' else 'the first seconds'} only"
                notes.append(f"WORSE: the {name} replay tracks {AXES[j]} worse than the nominal one {nums}"
                             + (f": {why}" if why else ""))
            else:
                notes.append(f"WORSE: the {name} replay's {s.label} is larger than the nominal one's {nums}: "
                             + why_pose_worse(s.label, run, nominal, window_s))
    return notes


@dataclass
class ReplayResult:
    log: str
    window_s: float
    runs: dict[str, ReplayRun]
    notes: list[str] = field(default_factory=list)
    identified: np.ndarray | None = None      # the axes the calibration identified (the comparison's axes)
    scored_from: float | None = None          # with a held-out part: its first log time (scores from there on)
    model_fit: object | None = None           # twin.model_fit.ModelFit of the "model" run (None: given or none)

    @property
    def scores(self) -> list[Score]:
        """Every score of the table, calibrated vs nominal ([] without a calibrated run)."""
        if "calibrated" not in self.runs:
            return []
        return scores(self.runs["calibrated"], self.runs["nominal"], self.identified)

    @property
    def worse_on(self) -> list[str]:
        """The scores (table headers: "rmse vx", "drift max", ...) on which the calibrated replay is worse than
        the nominal one: the velocity RMSE of the identified axes and every pose score."""
        return [s.label for s in self.scores if s.better == "nominal"]

    @property
    def worse_axes(self) -> list[str]:
        """What ``bigcbf replay`` lists after "calibrated worse than nominal on": every score of :attr:`worse_on`
        (an identified axis's velocity RMSE and the pose scores alike)."""
        return self.worse_on

    def to_json(self) -> dict:
        from .calibrate import jsonable
        verdict = {name: [s.to_json(name) for s in scores(r, self.runs["nominal"], self.identified)]
                   for name, r in self.runs.items() if name != "nominal"}
        return jsonable({"log": self.log, "window_s": self.window_s,
                         "runs": {k: r.to_json() for k, r in self.runs.items()},
                         "identified": None if self.identified is None else
                         {a: bool(x) for a, x in zip(AXES, self.identified)},
                         "verdict": verdict, "calibrated_worse_on": self.worse_on, "notes": self.notes,
                "scored_from_s": None if self.scored_from is None else self.scored_from - self._t0(),
                "model_fit": None if self.model_fit is None else self.model_fit.to_json()})

    def _t0(self) -> float:
        return float(self.runs["nominal"].t[0])


# --- simulation ----------------------------------------------------------------------------------------------
def _wrap(a):
    return np.arctan2(np.sin(a), np.cos(a))


def scene_for(pose_xy: np.ndarray, robot: str | None = None):
    """An open floor (no walls) framing the logged path (plus 30 % and 0.5 m for the replays' own paths): the
    top camera looks at its centre. ``robot``: a registered robot or a robot folder's path (default: the
    default robot)."""
    from bigcbf.sim.scene import SceneSpec
    lo, hi = pose_xy.min(axis=0), pose_xy.max(axis=0)
    c = (lo + hi) / 2
    extent = float(0.65 * max(hi - lo) + 0.5)
    spec = SceneSpec(extent=extent, robot_start=(float(c[0]), float(c[1]), 0.0))
    return spec if robot is None else dataclasses.replace(spec, robot=str(robot))


def simulate(cmd_t: np.ndarray, cmd_u: np.ndarray, odom: OdomSeries, profile: RobotProfile, t_end: float | None = None,
             scene=None, frame: Callable | None = None, fps: float = 10.0,
             period_s: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Replay commands (log times cmd_t, twists cmd_u) from the logged odometry pose at the first command.

    Returns (t, pose (N, 3), twist (N, 3)) at the logged odometry times after the start (up to ``t_end``); the
    twist is the average over ``period_s`` before each time (default: the median odometry interval).
    ``frame(world, t_log)`` is called every 1/fps s of simulated time (for a video)."""
    from bigcbf.sim.world import SimWorld

    t0 = float(cmd_t[0])
    t_stop = float(odom.t[-1] if t_end is None else min(t_end, odom.t[-1]))
    sel = (odom.t >= t0) & (odom.t <= t_stop)
    ts = odom.t[sel]
    if len(ts) < 2:
        raise ValueError("fewer than two odometry messages after the first command")
    if period_s is None:
        dt = np.diff(odom.t)
        period_s = float(np.median(dt[dt > 0])) if np.any(dt > 0) else 0.02
    k0 = max(int(np.searchsorted(odom.t, t0, side="right")) - 1, 0)
    x0, y0, th0 = odom.pose[k0]
    world = SimWorld(scene if scene is not None else scene_for(odom.pose[:, :2]), profile=profile, seed=0)
    world.reset_pose(float(x0), float(y0), float(th0))
    dt = world.dt
    events = [(float(t), 0, i) for i, t in enumerate(cmd_t) if t <= t_stop]
    events += [(float(t), 1, i) for i, t in enumerate(ts)]
    events += [(float(t) - period_s, 3, i) for i, t in enumerate(ts) if t - period_s > t0]
    if frame is not None:
        events += [(float(t), 2, 0) for t in np.arange(t0, t_stop, 1.0 / fps)]
    events.sort()
    pose = np.zeros((len(ts), 3))
    before = np.full((len(ts), 3), np.nan)
    twist = np.zeros((len(ts), 3))
    for te, kind, i in events:
        n = int(round((te - t0 - world.t) / dt))
        if n > 0:
            world.step(n)
        if kind == 0:
            world.command(cmd_u[i])
        elif kind == 1:
            s = world.odom()
            pose[i] = (s.px, s.py, s.theta)
            if np.isnan(before[i, 0]):              # the first period after the start: at rest before it
                before[i] = odom.pose[k0]
                h = te - t0
            else:
                h = period_s
            dth = float(_wrap(s.theta - before[i, 2]))
            mid = before[i, 2] + 0.5 * dth
            c, sn = np.cos(mid), np.sin(mid)
            dx, dy = s.px - before[i, 0], s.py - before[i, 1]
            twist[i] = ((c * dx + sn * dy) / h, (-sn * dx + c * dy) / h, dth / h) if h > 0 else (s.vx, s.vy, s.wz)
        elif kind == 3:
            s = world.odom()
            before[i] = (s.px, s.py, s.theta)
        else:
            frame(world, te)
    return ts, pose, twist


def errors(run: ReplayRun, odom: OdomSeries, window_s: float, t_from: float | None = None) -> ReplayRun:
    """Fill the run's errors against the logged odometry (module docstring); ``t_from``: score only the samples
    from that log time on (the held-out part of a log; the drift windows start there)."""
    k = np.searchsorted(odom.t, run.t)
    log_pose, log_twist = odom.pose[k], odom.twist[k]
    a = 0 if t_from is None else min(int(np.searchsorted(run.t, t_from)), len(run.t) - 1)
    run.rmse = np.sqrt(np.mean((run.twist[max(a, 1):] - log_twist[max(a, 1):]) ** 2, axis=0))
    drifts, yaws, starts = [], [], []
    while True:
        b = int(np.searchsorted(run.t, run.t[a] + window_s))
        if b >= len(run.t):
            break
        d = []
        for P in (log_pose, run.pose):
            c, s = np.cos(P[a, 2]), np.sin(P[a, 2])
            dp = P[b, :2] - P[a, :2]
            d.append((np.array([c * dp[0] + s * dp[1], -s * dp[0] + c * dp[1]]), _wrap(P[b, 2] - P[a, 2])))
        drifts.append(float(np.linalg.norm(d[1][0] - d[0][0])))
        yaws.append(float(abs(_wrap(d[1][1] - d[0][1]))))
        starts.append(float(run.t[a] - run.t[0]))
        a = b
    if drifts:
        run.drift_mean_m, run.drift_max_m = float(np.mean(drifts)), float(np.max(drifts))
        run.yaw_drift_mean_rad, run.yaw_drift_max_rad = float(np.mean(yaws)), float(np.max(yaws))
        run.windows = np.column_stack([starts, drifts, yaws])
    run.final_error_m = float(np.linalg.norm(run.pose[-1, :2] - log_pose[-1, :2]))
    return run


def run_profile(name: str, data: LogData, profile: RobotProfile, window_s: float, t_end=None, scene=None,
                frame=None, fps: float = 10.0, period_s: float | None = None, t_from: float | None = None) -> ReplayRun:
    t, pose, twist = simulate(data.cmd.t, data.cmd.u, data.odom, profile, t_end, scene, frame, fps, period_s)
    return errors(ReplayRun(name, profile, t, pose, twist), data.odom, window_s, t_from)


# --- the calibrated model --------------------------------------------------------------------------------------
def model_profile(A, d, delay_s: float, A0, d0, delay0_s: float, v_max: float | None = None,
                  lever_m: float | None = None, accel: float | None = None,
                  accel0: float | None = None) -> RobotProfile:
    """The robot profile that makes the model respond like the log: latency = delay - delay0, G = A0^-1 A,
    b = A0^-1 (d - d0), wheel-speed limit v_max / a0 (a0 = A0's mean translational gain), the log's yaw lever, and
    its acceleration limit when clearly (20 %) below the model's own ``accel0`` (module docstring)."""
    A0 = np.asarray(A0, float)
    A0inv = np.linalg.inv(A0)
    G = A0inv @ np.asarray(A, float)
    b = A0inv @ (np.asarray(d, float) - np.asarray(d0, float))
    a0 = float(np.mean(np.diag(A0)[:2]))
    return RobotProfile(latency_s=max(0.0, float(delay_s - delay0_s)),
                        gain=tuple(tuple(float(x) for x in row) for row in G), bias=tuple(float(x) for x in b),
                        wheel_speed_max_mps=None if v_max is None else float(v_max) / a0,
                        wheel_yaw_lever_m=None if v_max is None or lever_m is None or lever_m <= 0 else float(lever_m),
                        wheel_accel_max_mps2=float(accel) if accel is not None and (accel0 is None
                                                                                      or accel < 0.8 * accel0)
                        else None)


def _invertible_gain(A0, min_gain: float = 0.05) -> tuple[np.ndarray, list[str]]:
    """The model's own gain matrix A0 with each axis whose own gain is below ``min_gain`` (an axis the log barely
    drives: its fit is 0 or noise, and A0 cannot be inverted) replaced by the ideal response on that axis; the
    names of the replaced axes."""
    A0 = np.array(A0, float)
    weak = [j for j in range(3) if not np.isfinite(A0[j, j]) or abs(A0[j, j]) < min_gain]
    for j in weak:
        A0[j, :] = 0.0
        A0[:, j] = 0.0
        A0[j, j] = 1.0
    if not np.all(np.isfinite(A0)) or np.linalg.cond(A0) > 1e8:      # still degenerate: the ideal model
        return np.eye(3), ["vx", "vy", "wz"]
    return A0, [("vx", "vy", "wz")[j] for j in weak]


def _median_latency(cal) -> float:
    lat = cal.latency_s[cal.fit.identified]
    lat = lat[np.isfinite(lat)]
    return float(np.median(lat)) if len(lat) else float(cal.delay.xcorr_s)


def why_worse(j: int, cal, nominal: ReplayRun, calibrated: ReplayRun) -> str:
    """What the calibration says about why the calibrated replay is worse on axis j (best guesses, measured)."""
    reasons = []
    if cal is None:
        return "the log could not be calibrated (see the notes)"
    dyn = cal.model.dynamic if cal.model is not None else None
    ra = cal.rmse_all
    if ra and ra["saturating"][j] >= ra["nominal"][j]:
        reasons.append(f"even open loop the calibrated model does not predict {AXES[j]} better than v = u "
                       f"({ra['saturating'][j]:.3f} vs {ra['nominal'][j]:.3f}): the log's {AXES[j]} does not follow "
                       "its command as eq:execution (1) and a wheel limit describe")
    elif ra:
        reasons.append(f"open loop the calibrated model predicts {AXES[j]} better ({ra['saturating'][j]:.3f} vs "
                       f"nominal {ra['nominal'][j]:.3f}); replayed through the MuJoCo model it does not: the "
                       "simulated robot's own dynamics (Mecanum rollers, its wheel response"
                       + (f"; the log's robot adds a {dyn.axis_lags_s[j] * 1e3:.0f} ms lag on {AXES[j]} the simulator "
                          "has no key for" if dyn is not None and dyn.axis_lags_s[j] > 0.05 else "")
                       + ") differ from this robot's")
    if dyn is not None and np.isfinite(dyn.latency_ci_s[j]).all() and np.ptp(dyn.latency_ci_s[j]) > 0.05:
        reasons.append(f"its dead time is uncertain ({dyn.latency_ci_s[j, 0]:.3f}-{dyn.latency_ci_s[j, 1]:.3f} s)")
    if j in cal.delay.axes and cal.delay.axes[j].tie:
        reasons.append("two candidate delays nearly tie")
    return "; ".join(reasons)


def response_shift(run: ReplayRun, odom: OdomSeries, axes, max_s: float = 0.3, grid_s: float = 0.005) -> float:
    """The time [s] by which the replayed twist leads the logged one: the lag in [-max_s, max_s] maximising the
    correlation of their changes on a common grid (summed over ``axes``), parabola-refined; 0 without changes."""
    from .delay import _refine
    t0, t1 = max(run.t[0], odom.t[0]), min(run.t[-1], odom.t[-1])
    if t1 - t0 < 20 * grid_s:
        return 0.0
    tg = np.arange(t0, t1, grid_s)
    n = int(round(max_s / grid_s))
    lags = np.arange(-n, n + 1)
    curve = np.zeros(len(lags))
    for j in np.flatnonzero(axes):
        a = np.diff(np.interp(tg, run.t, run.twist[:, j]))
        b = np.diff(np.interp(tg, odom.t, odom.twist[:, j]))
        na, nb = np.sqrt(a @ a), np.sqrt(b @ b)
        if na == 0 or nb == 0:
            continue
        full = np.correlate(b, a, mode="full") / (na * nb)        # index len(a) - 1 is lag 0
        mid = len(a) - 1
        curve += full[mid - n:mid + n + 1]
    if not np.any(curve):
        return 0.0
    k = int(np.argmax(curve))
    return float((_refine(curve, k) - n) * grid_s)


def _checked(data: LogData, cal_opt: CalibrationOptions):
    """The replay's input checks on the log put on its analysis time base: (data, timing, time-base notes, notes)."""
    if data.cmd is None or data.odom is None:
        raise UserError("replay needs commands and odometry", file=str(data.path))
    notes: list[str] = []
    data, timing, tb_notes = prepare(data, cal_opt.timebase)
    if len(data.cmd.t) == 0 or len(data.odom.t) == 0:
        raise UserError(f"nothing to replay: {len(data.cmd.t)} commands ({data.cmd.topic}) and {len(data.odom.t)} "
                        f"odometry messages ({data.odom.topic}) left after reading the log", file=str(data.path))
    span = float(data.odom.t[-1] - data.cmd.t[0])
    if span > MAX_REPLAY_S or data.odom.t[0] > data.cmd.t[-1] or data.cmd.t[0] > data.odom.t[-1]:
        raise UserError(f"the commands ({data.cmd.topic}: {data.cmd.t[0]:.6g}-{data.cmd.t[-1]:.6g} s) and the "
                        f"odometry ({data.odom.topic}: {data.odom.t[0]:.6g}-{data.odom.t[-1]:.6g} s) "
                        + ("do not overlap in time" if span <= MAX_REPLAY_S else
                           f"span {span:.3g} s, more than a replay runs ({MAX_REPLAY_S:g} s)")
                        + ": their times look corrupt or on different clocks", file=str(data.path))
    if np.sum(data.odom.t >= data.cmd.t[0]) < 2:
        raise UserError(f"no odometry ({data.odom.topic}) after the first command ({data.cmd.topic}) to compare with",
                        file=str(data.path))
    k0 = max(int(np.searchsorted(data.odom.t, data.cmd.t[0], side="right")) - 1, 0)
    if np.linalg.norm(data.odom.twist[k0, :2]) > 0.05:
        notes.append("the robot was moving at the first command; the replay starts it at rest")
    return data, timing, tb_notes, notes


def cut(data: LogData, t_end: float | None) -> LogData:
    """``data`` (no scans) up to log time ``t_end`` (None: all of it): the part a held-out replay calibrates on."""
    if t_end is None:
        return dataclasses.replace(data, scan=None)
    c, o = data.cmd, data.odom
    kc, ko = c.t < t_end, o.t < t_end
    return dataclasses.replace(data, scan=None, cmd=dataclasses.replace(c, t=c.t[kc], u=c.u[kc]),
                               odom=dataclasses.replace(o, t=o.t[ko], stamp=o.stamp[ko], pose=o.pose[ko],
                                                        twist=o.twist[ko]))


def _head(run: ReplayRun, t_end: float | None) -> ReplayRun:
    if t_end is None:
        return run
    k = run.t < t_end
    return dataclasses.replace(run, t=run.t[k], pose=run.pose[k], twist=run.twist[k])


def command_profile(data: LogData, cal, execution, delay_s: float, nominal: ReplayRun, scene, period_s,
                    window_s: float, cal_opt: CalibrationOptions, t_split: float | None = None):
    """The calibrated robot profile (module docstring: A, d, the dead time and the limits mapped onto the
    model's own response, then the latency's correction step), measured on the log up to ``t_split``; returns
    (profile, its replay of the whole log scored from ``t_split``, notes)."""
    notes = []
    sim_log = cut(dataclasses.replace(data, warnings=[], odom=OdomSeries("replay", nominal.t, nominal.t,
                                                                         nominal.pose, nominal.twist)), t_split)
    try:
        cal0 = calibrate_series(sim_log, cal_opt)
    except UserError as err:           # the model's own response could not be measured: take it as ideal
        cal0 = None
        notes.append(f"the nominal replay could not be calibrated ({err.message}); the model's own response is "
                     "taken as ideal (A0 = I, no dead time)")
    v_max = lever = accel = None
    if execution is None:
        A, d = cal.fit.A, cal.fit.d
        st, dyn = cal.model.static, cal.model.dynamic
        v_max, lever, accel = st.v_max, st.lever_m, dyn.accel_max
    else:
        A, d = np.asarray(execution.A, float), np.asarray(execution.d, float)
        v_max, lever, accel = execution.wheel_speed_max_mps, execution.wheel_yaw_lever_m, execution.wheel_accel_max_mps2
        notes.append("execution model A, d" + (" and wheel limits" if v_max is not None or accel is not None else "")
                     + " from the given profile; dead time measured on this log")
    if cal0 is not None:
        A0, d0, L0, own_accel = cal0.fit.A, cal0.fit.d, _median_latency(cal0), cal0.model.dynamic.accel_max
        A0, weak = _invertible_gain(A0)
        if weak:
            notes.append("the nominal replay's own gain could not be measured on " + ", ".join(weak) + " (too little "
                         "motion on that axis in this log): taken as ideal (1) there")
    else:
        A0, d0, L0, own_accel = np.eye(3), np.zeros(3), 0.0, None
    prof = model_profile(A, d, delay_s, A0, d0, L0, v_max, lever, accel, own_accel)
    kw = dict(scene=scene, period_s=period_s, t_from=t_split)
    first = run_profile("calibrated", data, prof, window_s, **kw)
    # one correction step: the lag that best aligns the replayed twist with the logged one (correlation of their
    # changes; both are responses to the same commands, so their shapes match), added to the latency
    ident = cal.fit.identified if cal is not None else np.ones(3, bool)
    shift = response_shift(_head(first, t_split), cut(data, t_split).odom, ident)
    if abs(shift) > 0.002:
        prof = dataclasses.replace(prof, latency_s=max(0.0, prof.latency_s + shift))
        return prof, run_profile("calibrated", data, prof, window_s, **kw), notes
    return prof, first, notes


def _log_model(raw: LogData, data: LogData, cal_opt: CalibrationOptions, execution, t_split, notes):
    """The log's own model (calibrated up to ``t_split``; with a given profile only its dead time is needed, so a
    log too weak to calibrate still replays): (calibration or None, dead time [s]); None, None: no calibrated
    replay."""
    try:
        cal = calibrate_series(cut(raw, t_split), cal_opt)
        notes += [n for n in cal.notes() if not n.startswith("no scans given")]     # replay leaves scans out
        return cal, _median_latency(cal)
    except UserError as err:
        notes += list(data.warnings)
        if execution is None:
            notes.append(f"no calibrated replay: the log could not be calibrated ({err.message})")
            return None, None
        from .delay import estimate_delay
        axes = [j for j in range(3) if np.ptp(data.cmd.u[:, j]) > 1e-9] or [0]
        delay_s = estimate_delay(data.cmd.t, data.cmd.u, data.odom.t, data.odom.twist, axes, opt=cal_opt.delay).xcorr_s
        notes.append(f"the log could not be calibrated ({err.message}); only its actuation delay was measured")
        return None, delay_s


def replay(data: LogData, execution: ExecutionModel | None = None, opt: ReplayOptions = ReplayOptions(),
           video: str | Path | None = None, cal_opt: CalibrationOptions = CalibrationOptions(),
           robot_dir: str | Path | None = None) -> ReplayResult:
    """Replay with the nominal and the calibrated (with opt.fit, the fitted; with opt.model or ``robot_dir``, the
    model-fitted) profiles; optional video. With opt.holdout the calibrations see the first part of the log only
    and every run is scored on the rest."""
    raw = data
    data, timing, tb_notes, notes = _checked(data, cal_opt)
    t0 = float(data.cmd.t[0])
    t_split = None if opt.holdout == 0 else t0 + (1 - opt.holdout) * float(data.odom.t[-1] - t0)
    scene = scene_for(data.odom.pose[:, :2])
    P = timing.period_s
    runs = {"nominal": run_profile("nominal", data, RobotProfile(), opt.window_s, scene=scene, period_s=P,
                                   t_from=t_split)}
    cal, delay_s = _log_model(raw, data, cal_opt, execution, t_split, notes)
    if cal is None and delay_s is None:
        return ReplayResult(str(data.path), opt.window_s, runs, _dedup(notes + tb_notes), None, t_split)
    if cal is None:
        notes += tb_notes
    prof, runs["calibrated"], more = command_profile(data, cal, execution, delay_s, runs["nominal"], scene, P,
                                                     opt.window_s, cal_opt, t_split)
    notes += more
    if opt.fit:
        runs["fitted"] = fit_profile(data, prof, opt, scene, P)
    fit = None
    if opt.model or robot_dir is not None:
        from .model_fit import model_run
        runs["model"], fit, more = model_run(raw, data, prof, opt, P, t_split, robot_dir)
        notes += more
    identified = cal.fit.identified if cal is not None else np.array(
        execution.identified if execution is not None else (True, True, True))
    notes = compare(runs, identified, opt.window_s, cal) + notes      # the verdict first: what a person reads
    if video is not None:
        best = runs.get("model", runs.get("fitted", runs["calibrated"]))
        write_video(data, best, runs["nominal"], video, opt, scene)
    return ReplayResult(str(data.path), opt.window_s, runs, _dedup(notes), identified, t_split, fit)


def _dedup(notes: list[str]) -> list[str]:
    out = []
    for n in notes:
        if n not in out:
            out.append(n)
    return out


def fit_profile(data: LogData, start: RobotProfile, opt: ReplayOptions, scene, period_s=None) -> ReplayRun:
    """Tune latency, the diagonal gains and the floor friction to the log (Nelder-Mead, opt.fit_evals replays
    of the first opt.fit_window_s), then replay the whole log with the result."""
    from scipy.optimize import minimize

    t_end = float(data.cmd.t[0] + opt.fit_window_s)
    scale = np.maximum(data.odom.twist.std(axis=0), 1e-3)
    G0 = np.asarray(start.gain, float)
    x0 = np.array([start.latency_s, G0[0, 0], G0[1, 1], G0[2, 2], 1.0])
    lo = np.array([0.0, 0.3, 0.3, 0.3, 0.05])
    hi = np.array([1.0, 1.5, 1.5, 1.5, 3.0])

    def profile_of(x):
        x = np.clip(x, lo, hi)
        G = G0.copy()
        G[0, 0], G[1, 1], G[2, 2] = x[1:4]
        return dataclasses.replace(start, latency_s=float(x[0]), gain=tuple(tuple(map(float, r)) for r in G),
                                   floor_friction=float(x[4]))

    def cost(x):
        r = run_profile("fit", data, profile_of(x), opt.window_s, t_end=t_end, scene=scene, period_s=period_s)
        return float(np.sum(r.rmse / scale))

    simplex = np.vstack([x0, x0 + np.diag([0.05, -0.1, -0.1, -0.1, 0.3])])
    res = minimize(cost, x0, method="Nelder-Mead", options={"maxfev": opt.fit_evals, "initial_simplex": simplex})
    return run_profile("fitted", data, profile_of(res.x), opt.window_s, scene=scene, period_s=period_s)


#: The video's colours (RGB) per path, and the robot marker's size: the simulated robot's bumper, 0.30 x 0.20 m.
PATH_RGB = {"logged": (60, 220, 80), "nominal": (255, 140, 25), "model": (25, 230, 230)}
ROBOT_SIZE_M = (0.30, 0.20)


def scale_bar_length(max_m: float) -> float:
    """The longest 1, 2 or 5 x 10^k metres not above ``max_m``."""
    k = np.floor(np.log10(max_m))
    for m in (5, 2, 1):
        if m * 10 ** k <= max_m:
            return float(m * 10 ** k)
    return float(10 ** k)


def draw_scale_bar(img: np.ndarray, px_per_m: float) -> float:
    """A scale bar in the bottom-left corner (at most a quarter of the width); returns its length [m]."""
    import cv2
    h, w = img.shape[:2]
    length = scale_bar_length(0.25 * w / px_per_m)
    n = int(round(length * px_per_m))
    x0, y0 = 14, h - 16
    label = f"{length:g} m"
    (tw, th), _ = cv2.getTextSize(label, cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
    cv2.rectangle(img, (x0 - 6, y0 - th - 16), (x0 + max(n, tw) + 6, y0 + 8), (20, 20, 20), -1)
    cv2.line(img, (x0, y0), (x0 + n, y0), (255, 255, 255), 3)
    for x in (x0, x0 + n):
        cv2.line(img, (x, y0 - 6), (x, y0 + 4), (255, 255, 255), 2)
    cv2.putText(img, label, (x0, y0 - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return length


def draw_robot(img: np.ndarray, uv, theta: float, px_per_m: float, rgb, filled: bool = False) -> None:
    """The robot's pose marker: its footprint (ROBOT_SIZE_M, at least 16 x 11 px) in ``rgb`` over a dark edge
    (``filled``: a translucent fill, so outlines drawn over it stay visible), and a heading arrow from its front
    edge outwards (image v points down, so a heading theta points at (cos, -sin))."""
    import cv2
    L = max(ROBOT_SIZE_M[0] * px_per_m, 16.0) / 2
    W = max(ROBOT_SIZE_M[1] * px_per_m, 11.0) / 2
    c, s = np.cos(theta), -np.sin(theta)
    fwd, left = np.array([c, s]), np.array([s, -c])
    u = np.asarray(uv, float)
    box = np.array([u + fwd * L + left * W, u - fwd * L + left * W, u - fwd * L - left * W, u + fwd * L - left * W])
    pts = box.round().astype(np.int32).reshape(-1, 1, 2)
    if filled:
        layer = img.copy()
        cv2.fillPoly(layer, [pts], tuple(rgb), cv2.LINE_AA)
        cv2.addWeighted(layer, 0.55, img, 0.45, 0, dst=img)
    a0 = tuple((u + fwd * L).round().astype(int))
    a1 = tuple((u + fwd * (L + 16)).round().astype(int))
    for col, th in (((15, 15, 15), 5), (tuple(rgb), 2)):
        cv2.polylines(img, [pts], True, col, th, cv2.LINE_AA)
        cv2.arrowedLine(img, a0, a1, col, th, cv2.LINE_AA, tipLength=0.45)


def overlay(img: np.ndarray, to_px, px_per_m: float, paths: list[tuple[str, np.ndarray, np.ndarray]],
            route: np.ndarray | None = None) -> None:
    """Draw on a top-view frame: the whole logged route (thin, dark), then per path (name in PATH_RGB, its poses
    so far (N, 3)) its trail and the robot's current pose marker, then the scale bar."""
    import cv2
    if route is not None and len(route) > 1:
        cv2.polylines(img, [to_px(route[:, :2])], False, (30, 110, 40), 1, cv2.LINE_AA)
    for name, poses in paths:
        if len(poses) > 1:
            cv2.polylines(img, [to_px(poses[:, :2])], False, PATH_RGB[name], 3 if name == "logged" else 2,
                          cv2.LINE_AA)
    for name, poses in paths:
        if len(poses):
            draw_robot(img, to_px(poses[-1, :2])[0], float(poses[-1, 2]), px_per_m, PATH_RGB[name],
                       filled=name == "logged")
    draw_scale_bar(img, px_per_m)


def legend_items(model_name: str) -> list[tuple[str, tuple, str]]:
    """The legend under the video: each path's colour, the markers (box: the robot's odometry pose now, arrow: its
    heading), the thin whole logged path, and the rendered robot (the simulated body: its true pose, from which its
    wheel odometry drifts by roller slip)."""
    rgba = lambda name: tuple(c / 255 for c in PATH_RGB[name]) + (1.0,)       # noqa: E731
    return [("logged (odometry)", rgba("logged"), "thick"), (f"{model_name} model", rgba("model"), "thick"),
            ("nominal model", rgba("nominal"), "thick"),
            ("box, arrow: pose now (odometry; logged filled)", (0.85, 0.85, 0.85, 1.0), "arrow"),
            ("thin: whole logged path", (30 / 255, 110 / 255, 40 / 255, 1.0), "line"),
            (f"3D robot: the {model_name} model's true pose", (0.6, 0.6, 0.6, 1.0), "disc")]


def write_video(data: LogData, run: ReplayRun, nominal: ReplayRun, path: str | Path, opt: ReplayOptions, scene) -> None:
    """Top view of the replayed model: for the logged odometry (green), the replayed model (cyan) and the nominal
    model (orange) the path so far and the robot's current pose (its footprint and heading), the whole logged path
    thin, a scale bar in metres, the time, and a legend band below naming each colour. The paths are drawn on the
    image (the top camera is orthographic: a metre is H / fovy pixels)."""
    from bigcbf.sim.render import Renderer, VideoWriter, meters_per_pixel, project, put_text, with_legend_strip

    W, H = 640, 480
    state: dict = {}
    legend = legend_items(run.name)
    t_total = float(data.odom.t[-1] - data.cmd.t[0])

    def to_px(world, xy):
        xy = np.asarray(xy, float).reshape(-1, 2)
        uv, _ = project(world.model, world.data, "top", np.column_stack([xy, np.zeros(len(xy))]), W, H)
        return uv.round().astype(np.int32)

    def frame(world, t_log):
        if "r" not in state:
            state["r"] = Renderer(world.model, W, H)
            state["scale"] = 1.0 / meters_per_pixel(world.model, "top", H)     # the top camera is orthographic
        scale = state["scale"]
        img = np.ascontiguousarray(state["r"].render(world.data, "top"))
        k = int(np.searchsorted(run.t, t_log, side="right"))
        lk = int(np.searchsorted(data.odom.t, t_log, side="right"))
        k0 = max(int(np.searchsorted(data.odom.t, data.cmd.t[0], side="right")) - 1, 0)
        logged = data.odom.pose[k0:max(lk, k0 + 1)]
        start = data.odom.pose[k0:k0 + 1]            # both models start at the logged pose at the first command
        paths = [("logged", logged), ("nominal", nominal.pose[:k] if k else start),
                 ("model", run.pose[:k] if k else start)]
        overlay(img, lambda xy: to_px(world, xy), scale, paths, route=data.odom.pose)
        tw = data.odom.twist[min(max(lk - 1, 0), len(data.odom.t) - 1)]
        put_text(img, [f"t = {t_log - data.cmd.t[0]:6.2f} s of {t_total:.1f} s   replay of {Path(data.path).name}",
                       f"logged twist ({tw[0]:+.2f} m/s, {tw[1]:+.2f} m/s, {tw[2]:+.2f} rad/s)"], scale=0.5)
        state["w"].write(with_legend_strip(img, legend))

    state["w"] = VideoWriter(path, fps=opt.video_fps)
    try:
        with state["w"]:                 # an exception drops the unfinished video (the path stays as it was)
            simulate(data.cmd.t, data.cmd.u, data.odom, run.profile, scene=scene, frame=frame, fps=opt.video_fps)
    finally:
        if "r" in state:
            state["r"].close()


def replay_log(path: str | Path, profile: str | Path | ExecutionModel | None = None, *,
               opt: ReplayOptions = ReplayOptions(), video: str | Path | None = None, cmd_topic: str | None = None,
               odom_topic: str | None = None, robot_dir: str | Path | None = None) -> ReplayResult:
    """Read a log and :func:`replay` it (``bigcbf replay LOG`` in Python). ``profile``: a calibrated uncertainty
    profile TOML (its ``[uncertainty.execution]`` A, d) or an ExecutionModel; None: calibrate the log itself.
    ``robot_dir``: a fitted robot folder replayed as the "model" run (``bigcbf calibrate --model``)."""
    from bigcbf.params.stack import load_stack_params
    from bigcbf.params.toml_io import load_toml

    from .calibrate import read_log

    execution = profile
    if profile is not None and not isinstance(profile, ExecutionModel):
        unc = load_toml(profile).get("uncertainty", {})
        if not isinstance(unc, dict):
            raise UserError(f"expected a table, got {type(unc).__name__}", file=str(profile), field="uncertainty")
        if "execution" not in unc:
            raise UserError("has no [uncertainty.execution] table (A, d): not a calibrated profile",
                            file=str(profile), field="uncertainty.execution")
        execution = load_stack_params(profile).uncertainty.execution
    data = read_log(path, cmd_topic, odom_topic, use_scan=False)
    return replay(data, execution, opt, video=video, robot_dir=robot_dir)
