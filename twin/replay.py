"""Replay logged commands through the MuJoCo model and compare with the logged odometry (``bigcbf replay``).

The model starts at rest at the logged pose at the first command and receives every logged command at its log
time (relative to that start). At each logged odometry time the simulated wheel odometry is sampled; its twist is
the average over the interval since the previous sample (pose change in the body frame / interval), as an
encoder-based odometry reports it, so both sides are measured the same way.

Models compared:

- nominal: the ideal robot (``RobotProfile()``: no latency, A = I, d = 0);
- calibrated: the log's execution model and actuation delay, mapped onto the model's own response. The model is
  not ideal either (wheel dynamics, roller slip, the odometry's averaging), so the nominal replay is calibrated
  too, giving its own A0, d0 and delay0, and the robot profile that reproduces the log is
  latency = delay - delay0, gain G = A0^-1 A, bias b = A0^-1 (d - d0) (measured = A0 (G u + b) + d0 = A u + d).
  A, d come from ``--profile`` (an uncertainty profile) or from calibrating the log itself; the delay is always
  measured on the replayed log (an uncertainty profile holds tau95, which includes perception latency);
- fitted (``--fit``): starting from the calibrated profile, latency, the diagonal gains and the floor friction
  are tuned to minimise the replay's velocity error (Nelder-Mead on the first ``fit_window_s`` of the log).

Errors: velocity RMSE per axis over all samples; pose drift over consecutive windows of ``window_s``: the
displacement over the window in the frame of its start, simulated minus logged (m), and the heading change
difference (rad); the final position error.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from bigcbf.errors import UserError
from bigcbf.logio import LogData, OdomSeries
from bigcbf.params.robot import RobotProfile
from bigcbf.params.stack import ExecutionModel

from .calibrate import CalibrationOptions, calibrate_series
from .execution import AXES


@dataclass(frozen=True)
class ReplayOptions:
    window_s: float = 5.0           # pose-drift windows [s]
    fit: bool = False
    fit_window_s: float = 20.0      # the part of the log the fit replays [s]
    fit_evals: int = 40             # replays the fit may spend
    video_fps: float = 10.0


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

    def to_json(self) -> dict:
        return {"profile": {"latency_s": self.profile.latency_s, "gain": [list(r) for r in self.profile.gain],
                            "bias": list(self.profile.bias), "floor_friction": self.profile.floor_friction},
                "velocity_rmse": dict(zip(AXES, map(float, self.rmse))),
                "drift_mean_m": self.drift_mean_m, "drift_max_m": self.drift_max_m,
                "yaw_drift_mean_rad": self.yaw_drift_mean_rad, "yaw_drift_max_rad": self.yaw_drift_max_rad,
                "final_error_m": self.final_error_m}


@dataclass
class ReplayResult:
    log: str
    window_s: float
    runs: dict[str, ReplayRun]
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict:
        from .calibrate import jsonable
        return jsonable({"log": self.log, "window_s": self.window_s,
                         "runs": {k: r.to_json() for k, r in self.runs.items()}, "notes": self.notes})


# --- simulation ----------------------------------------------------------------------------------------------
def _wrap(a):
    return np.arctan2(np.sin(a), np.cos(a))


def scene_for(pose_xy: np.ndarray):
    """An open floor (no walls) framing the logged path (plus 30 % and 0.5 m for the replays' own paths): the
    top camera looks at its centre."""
    from bigcbf.sim.scene import SceneSpec
    lo, hi = pose_xy.min(axis=0), pose_xy.max(axis=0)
    c = (lo + hi) / 2
    extent = float(0.65 * max(hi - lo) + 0.5)
    return SceneSpec(extent=extent, robot_start=(float(c[0]), float(c[1]), 0.0))


def simulate(cmd_t: np.ndarray, cmd_u: np.ndarray, odom: OdomSeries, profile: RobotProfile, t_end: float | None = None,
             scene=None, frame: Callable | None = None, fps: float = 10.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Replay commands (log times cmd_t, twists cmd_u) from the logged odometry pose at the first command.

    Returns (t, pose (N, 3), twist (N, 3)) at the logged odometry times after the start (up to ``t_end``).
    ``frame(world, t_log)`` is called every 1/fps s of simulated time (for a video)."""
    from bigcbf.sim.world import SimWorld

    t0 = float(cmd_t[0])
    t_stop = float(odom.t[-1] if t_end is None else min(t_end, odom.t[-1]))
    sel = (odom.t >= t0) & (odom.t <= t_stop)
    ts = odom.t[sel]
    if len(ts) < 2:
        raise ValueError("fewer than two odometry messages after the first command")
    k0 = max(int(np.searchsorted(odom.t, t0, side="right")) - 1, 0)
    x0, y0, th0 = odom.pose[k0]
    world = SimWorld(scene if scene is not None else scene_for(odom.pose[:, :2]), profile=profile, seed=0)
    world.reset_pose(float(x0), float(y0), float(th0))
    dt = world.dt
    events = [(float(t), 0, i) for i, t in enumerate(cmd_t) if t <= t_stop]
    events += [(float(t), 1, i) for i, t in enumerate(ts)]
    if frame is not None:
        events += [(float(t), 2, 0) for t in np.arange(t0, t_stop, 1.0 / fps)]
    events.sort()
    pose = np.zeros((len(ts), 3))
    twist = np.zeros((len(ts), 3))
    prev = None
    for te, kind, i in events:
        n = int(round((te - t0 - world.t) / dt))
        if n > 0:
            world.step(n)
        if kind == 0:
            world.command(cmd_u[i])
        elif kind == 1:
            s = world.odom()
            pose[i] = (s.px, s.py, s.theta)
            if prev is None:
                twist[i] = (s.vx, s.vy, s.wz)
            else:
                h = te - prev[0]
                dth = float(_wrap(s.theta - prev[3]))
                mid = prev[3] + 0.5 * dth
                c, sn = np.cos(mid), np.sin(mid)
                dx, dy = s.px - prev[1], s.py - prev[2]
                twist[i] = ((c * dx + sn * dy) / h, (-sn * dx + c * dy) / h, dth / h) if h > 0 else twist[i - 1]
            prev = (te, s.px, s.py, s.theta)
        else:
            frame(world, te)
    return ts, pose, twist


def errors(run: ReplayRun, odom: OdomSeries, window_s: float) -> ReplayRun:
    """Fill the run's errors against the logged odometry (module docstring)."""
    k = np.searchsorted(odom.t, run.t)
    log_pose, log_twist = odom.pose[k], odom.twist[k]
    run.rmse = np.sqrt(np.mean((run.twist[1:] - log_twist[1:]) ** 2, axis=0))
    drifts, yaws = [], []
    a = 0
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
        a = b
    if drifts:
        run.drift_mean_m, run.drift_max_m = float(np.mean(drifts)), float(np.max(drifts))
        run.yaw_drift_mean_rad, run.yaw_drift_max_rad = float(np.mean(yaws)), float(np.max(yaws))
    run.final_error_m = float(np.linalg.norm(run.pose[-1, :2] - log_pose[-1, :2]))
    return run


def run_profile(name: str, data: LogData, profile: RobotProfile, window_s: float, t_end=None, scene=None,
                frame=None, fps: float = 10.0) -> ReplayRun:
    t, pose, twist = simulate(data.cmd.t, data.cmd.u, data.odom, profile, t_end, scene, frame, fps)
    return errors(ReplayRun(name, profile, t, pose, twist), data.odom, window_s)


# --- the calibrated model --------------------------------------------------------------------------------------
def model_profile(A, d, delay_s: float, A0, d0, delay0_s: float) -> RobotProfile:
    """The robot profile that makes the model respond like the log: latency = delay - delay0, G = A0^-1 A,
    b = A0^-1 (d - d0) (module docstring)."""
    A0inv = np.linalg.inv(np.asarray(A0, float))
    G = A0inv @ np.asarray(A, float)
    b = A0inv @ (np.asarray(d, float) - np.asarray(d0, float))
    return RobotProfile(latency_s=max(0.0, float(delay_s - delay0_s)),
                        gain=tuple(tuple(float(x) for x in row) for row in G), bias=tuple(float(x) for x in b))


def replay(data: LogData, execution: ExecutionModel | None = None, opt: ReplayOptions = ReplayOptions(),
           video: str | Path | None = None, cal_opt: CalibrationOptions = CalibrationOptions()) -> ReplayResult:
    """Replay with the nominal and the calibrated (and, with opt.fit, the fitted) profiles; optional video."""
    if data.cmd is None or data.odom is None:
        raise UserError("replay needs commands and odometry", file=str(data.path))
    if np.sum(data.odom.t >= data.cmd.t[0]) < 2:
        raise UserError(f"no odometry ({data.odom.topic}) after the first command ({data.cmd.topic}) to compare with",
                        file=str(data.path))
    notes: list[str] = []
    k0 = max(int(np.searchsorted(data.odom.t, data.cmd.t[0], side="right")) - 1, 0)
    if np.linalg.norm(data.odom.twist[k0, :2]) > 0.05:
        notes.append("the robot was moving at the first command; the replay starts it at rest")
    scene = scene_for(data.odom.pose[:, :2])
    nominal = run_profile("nominal", data, RobotProfile(), opt.window_s, scene=scene)
    # the log's own model (with a given profile only its delay is needed, so a log too weak to calibrate still
    # replays), and the nominal model's response to the same commands
    try:
        cal = calibrate_series(dataclasses.replace(data, scan=None), cal_opt)
        delay_s = cal.delay.xcorr_s
    except UserError as err:
        if execution is None:
            raise
        from .delay import estimate_delay
        axes = [j for j in range(3) if np.ptp(data.cmd.u[:, j]) > 1e-9] or [0]
        delay_s = estimate_delay(data.cmd.t, data.cmd.u, data.odom.t, data.odom.twist, axes, opt=cal_opt.delay).xcorr_s
        notes.append(f"the log could not be calibrated ({err.message}); only its actuation delay was measured")
    sim_log = dataclasses.replace(data, scan=None, odom=OdomSeries("replay", nominal.t, nominal.t, nominal.pose,
                                                                   nominal.twist))
    cal0 = calibrate_series(sim_log, cal_opt)
    if execution is None:
        A, d = cal.fit.A, cal.fit.d
    else:
        A, d = np.asarray(execution.A, float), np.asarray(execution.d, float)
        notes.append("execution model A, d from the given profile; actuation delay measured on this log")
    prof = model_profile(A, d, delay_s, cal0.fit.A, cal0.fit.d, cal0.delay.xcorr_s)
    runs = {"nominal": nominal}
    runs["calibrated"] = run_profile("calibrated", data, prof, opt.window_s, scene=scene)
    if opt.fit:
        runs["fitted"] = fit_profile(data, prof, opt, scene)
    if video is not None:
        best = runs.get("fitted", runs["calibrated"])
        write_video(data, best, runs["nominal"], video, opt, scene)
    return ReplayResult(str(data.path), opt.window_s, runs, notes)


def fit_profile(data: LogData, start: RobotProfile, opt: ReplayOptions, scene) -> ReplayRun:
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
        r = run_profile("fit", data, profile_of(x), opt.window_s, t_end=t_end, scene=scene)
        return float(np.sum(r.rmse / scale))

    simplex = np.vstack([x0, x0 + np.diag([0.05, -0.1, -0.1, -0.1, 0.3])])
    res = minimize(cost, x0, method="Nelder-Mead", options={"maxfev": opt.fit_evals, "initial_simplex": simplex})
    return run_profile("fitted", data, profile_of(res.x), opt.window_s, scene=scene)


def write_video(data: LogData, run: ReplayRun, nominal: ReplayRun, path: str | Path, opt: ReplayOptions, scene) -> None:
    """Top view of the replayed model: the logged path (green), the replayed path (cyan) and the nominal model's
    (orange). The paths are drawn on the image (the top camera is orthographic: a metre is H / fovy pixels)."""
    import cv2
    import mujoco

    from bigcbf.sim.render import Renderer, VideoWriter, put_text

    W, H = 640, 480
    state: dict = {}

    def to_px(xy, cam, scale):
        xy = np.asarray(xy, float).reshape(-1, 2)
        return np.column_stack([W / 2 + (xy[:, 0] - cam[0]) * scale, H / 2 - (xy[:, 1] - cam[1]) * scale]
                               ).round().astype(np.int32)

    def frame(world, t_log):
        if "r" not in state:
            state["r"] = Renderer(world.model, W, H)
            cid = mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_CAMERA, "top")
            state["cam"] = world.data.cam_xpos[cid].copy()
            state["scale"] = H / float(world.model.cam_fovy[cid])
        cam, scale = state["cam"], state["scale"]
        img = np.ascontiguousarray(state["r"].render(world.data, "top"))
        k = int(np.searchsorted(run.t, t_log))
        lk = min(int(np.searchsorted(data.odom.t, t_log)), len(data.odom.t) - 1)
        for xy, rgb, width in ((data.odom.pose[:, :2], (60, 220, 80), 3), (nominal.pose[:k, :2], (255, 140, 25), 2),
                               (run.pose[:k, :2], (25, 230, 230), 2)):
            if len(xy) > 1:
                cv2.polylines(img, [to_px(xy, cam, scale)], False, rgb, width, cv2.LINE_AA)
        put_text(img, [f"t = {t_log - data.cmd.t[0]:6.2f} s   replay of {Path(data.path).name}",
                       f"green: logged   cyan: {run.name} model   orange: nominal model",
                       f"logged twist ({data.odom.twist[lk, 0]:+.2f}, {data.odom.twist[lk, 1]:+.2f}, "
                       f"{data.odom.twist[lk, 2]:+.2f})"])
        state["w"].write(img)

    state["w"] = VideoWriter(path, fps=opt.video_fps)
    try:
        with state["w"]:                 # an exception drops the unfinished video (the path stays as it was)
            simulate(data.cmd.t, data.cmd.u, data.odom, run.profile, scene=scene, frame=frame, fps=opt.video_fps)
    finally:
        if "r" in state:
            state["r"].close()


def replay_log(path: str | Path, profile: str | Path | ExecutionModel | None = None, *,
               opt: ReplayOptions = ReplayOptions(), video: str | Path | None = None, cmd_topic: str | None = None,
               odom_topic: str | None = None) -> ReplayResult:
    """Read a log and :func:`replay` it (``bigcbf replay LOG`` in Python). ``profile``: a calibrated uncertainty
    profile TOML (its ``[uncertainty.execution]`` A, d) or an ExecutionModel; None: calibrate the log itself."""
    from bigcbf.params.stack import load_stack_params
    from bigcbf.params.toml_io import load_toml

    from .calibrate import read_log

    execution = profile
    if profile is not None and not isinstance(profile, ExecutionModel):
        if "execution" not in load_toml(profile).get("uncertainty", {}):
            raise UserError("has no [uncertainty.execution] table (A, d): not a calibrated profile",
                            file=str(profile), field="uncertainty.execution")
        execution = load_stack_params(profile).uncertainty.execution
    data = read_log(path, cmd_topic, odom_topic, use_scan=False)
    return replay(data, execution, opt, video=video)
