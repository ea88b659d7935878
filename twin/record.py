"""Record a calibration drive in the simulator as a robot log (``bigcbf record calibration``).

The robot drives the program of :mod:`twin.drive` in an open room, through the imperfections of a RobotProfile
(latency and jitter, gain A, bias d, residual noise, floor friction / slip). This is the stand-in for the
hardware until a user brings their own log. The log is ROS 2 MCAP with the robot's topics:

    /cmd_vel 20 Hz, /odom 50 Hz (wheel odometry), /imu 50 Hz, /tf 50 Hz, /ground_truth/odom 50 Hz, /scan 10 Hz

Log time = simulation time; the command at time t is sent after the sensors of time t are logged (as a robot
whose controller runs on fresh data). The program runs closed loop (:class:`twin.drive.CalibrationDrive`: back to
the start between segments when the odometry says the robot has wandered), so that it stays in its room for any
robot profile within the documented ranges (``bigcbf.params.robot``).

The log is written to a temporary file beside ``out`` and renamed to ``out`` only when the drive is complete: a
drive that fails (it leaves the room's free space, the simulation breaks, Ctrl-C) leaves no complete-looking log
behind; the failure is a :class:`~bigcbf.errors.UserError` (one line on the command line).

A drive whose robot did not follow its commands is an error too, with no log written: when the true path or the
odometry's path is shorter than ``MIN_FOLLOW`` (25 %) of the commanded path (the sum of ||u_xy|| T_C over the
commands; checked once the commands ask for at least ``MIN_COMMANDED_M``). Such a log calibrates to something false
(a robot that never moved, its latency far beyond the drive, gives tau95 ~1 s with no word; wheels spinning on a
floor without grip give the wheels' calibration of a robot that stayed where it was), and the recorder's one job
is a log worth calibrating, so a warning beside a written log would not do.

The odometry twist is the average over the odometry period (the pose change from the previous message, in the
body frame at mid-heading, divided by the period), as a robot's driver computes it from encoder counts; the
instantaneous wheel speeds of the model jitter when rollers change contact (spikes of several tenths of rad/s in
yaw rate at rest), which no encoder-based odometry reports. /odom and /imu carry the covariances of the profile's
sensor models (:mod:`bigcbf.logio.covariance`); the averaged twist's are those at the 20 ms odometry period.
"""
from __future__ import annotations

import os
from dataclasses import asdict
from pathlib import Path

import numpy as np

from bigcbf.errors import UserError
from bigcbf.logio import LogWriter
from bigcbf.logio.covariance import WorldCovariances
from bigcbf.params.robot import RobotProfile
from bigcbf.params.toml_io import to_dict
from bigcbf.types import RobotState

from .drive import CalibrationDrive, DriveLimits

TICK_S = 0.01
CMD_EVERY, ODOM_EVERY, SCAN_EVERY = 5, 2, 10        # in ticks: 20 Hz, 50 Hz, 10 Hz
ROOM_EXTENT_M = 4.0
MIN_FOLLOW = 0.25          # the true and the odometry path at least this fraction of the commanded path [-]
MIN_COMMANDED_M = 0.5      # ... once the commanded path is at least this long [m]


def record_calibration(profile: RobotProfile, out: str | Path, seed: int = 0, duration_s: float = 60.0,
                       limits: DriveLimits = DriveLimits(), robot: str | None = None) -> dict:
    """Drive the calibration program on a robot with ``profile``; write the log to ``out`` (module docstring).
    ``robot``: the robot (a registered name or a robot folder's path, ``bigcbf/robots.py``; None: the default).
    Returns a summary (messages per topic, duration, the largest distance from the start, the re-centrings).

    Length: one tick loop writing each topic at its own rate from the same world state, inside the temporary-file try
    that deletes a partial log on any error."""
    from bigcbf.sim.scene import open_room
    from bigcbf.sim.world import SimWorld

    out = Path(out)
    if out.is_dir():
        raise UserError("is a directory, expected an .mcap file path", file=str(out))
    drive = CalibrationDrive(duration_s, limits, seed, dt=CMD_EVERY * TICK_S)
    room = open_room(extent=ROOM_EXTENT_M)
    if robot is not None:
        from dataclasses import replace
        room = replace(room, robot=str(robot))
    world = SimWorld(room, profile=profile, seed=seed)
    cov = WorldCovariances(world)
    steps = int(round(TICK_S / world.dt))
    n_ticks = int(round(duration_s / TICK_S))
    meta = {"kind": "calibration drive", "seed": seed, "duration_s": duration_s,
            "robot_profile": repr(to_dict(profile)), "limits": repr(asdict(limits))}
    reach = 0.0
    commanded = true_path = odom_path = 0.0
    last_truth = last_odom = None
    prev: RobotState | None = None
    tmp = out.with_name(f".{out.name}.part{os.getpid()}")
    try:
        with LogWriter(tmp, metadata=meta) as w:
            for k in range(n_ticks):
                t = world.t
                if k % ODOM_EVERY == 0:
                    odom, truth = world.odom(), world.true_state()
                    averaged = prev is not None
                    if averaged:
                        odom = averaged_twist(prev, odom, ODOM_EVERY * TICK_S)
                    prev = odom
                    pose_cov, twist_cov = cov.odom(t, odom, ODOM_EVERY * TICK_S if averaged else None)
                    w.odom(t, odom, pose_cov=pose_cov, twist_cov=twist_cov)
                    w.tf(t, odom)
                    w.ground_truth(t, truth)
                    w.imu(t, world.imu(), cov=cov.imu())
                    reach = max(reach, float(np.hypot(truth.px, truth.py)))
                    if last_truth is not None:
                        true_path += float(np.hypot(truth.px - last_truth.px, truth.py - last_truth.py))
                        odom_path += float(np.hypot(odom.px - last_odom.px, odom.py - last_odom.py))
                    last_truth, last_odom = truth, odom
                    if reach > ROOM_EXTENT_M - 0.6 or not np.isfinite(reach):
                        raise UserError(f"the calibration drive left the room's free space at t = {t:.1f} s "
                                        f"(|p| = {reach:.2f} m, seed {seed}); no log written: is the robot profile "
                                        "within the documented ranges (bigcbf/params/robot.py)?", file=str(out))
                if k % SCAN_EVERY == 0:
                    scan = world.scan()      # None: the profile's scan dropout lost it (nothing is logged)
                    if scan is not None:
                        w.scan(t, scan)
                if k % CMD_EVERY == 0:
                    o = world.odom()
                    u = drive.command(t, (o.px, o.py, o.theta))
                    world.command(u)
                    w.cmd_vel(t, u)
                    commanded += float(np.hypot(u[0], u[1])) * CMD_EVERY * TICK_S
                world.step(steps)
            moved = min(true_path, odom_path)
            if commanded >= MIN_COMMANDED_M and moved < MIN_FOLLOW * commanded:
                raise UserError(f"the robot did not follow the calibration drive: it was commanded along "
                                f"{commanded:.2f} m and moved {true_path:.2f} m (odometry {odom_path:.2f} m), under "
                                f"{MIN_FOLLOW:.0%}; no log written: is the robot profile within the documented ranges "
                                "(latency, floor friction: bigcbf/params/robot.py)?", file=str(out))
            counts = dict(w.counts)
        os.replace(tmp, out)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return {"path": str(out), "duration_s": duration_s, "messages": counts, "max_distance_m": reach,
            "commanded_path_m": commanded, "true_path_m": true_path, "odometry_path_m": odom_path,
            "recentrings": drive.recentrings, "warnings": world.warnings()}


def random_profile(rng: np.random.Generator) -> RobotProfile:
    """A random robot profile with wheel limits, inside the documented ranges of bigcbf/params/robot.py, for
    recovery checks (tests/twin/test_twin_recovery.py, scripts/twin_recovery.py): latency U(0, 0.25) s, jitter
    U(0, 0.04) s, diagonal gains U(0.75, 1.15), bias U(+-0.04) m/s and U(+-0.08) rad/s, residual U(0, 0.04), wheel
    rim-speed limit U(0.35, 0.9) m/s, wheel acceleration limit log-uniform in [0.8, 8] m/s^2."""
    gains = rng.uniform(0.75, 1.15, 3)
    return RobotProfile(
        latency_s=float(rng.uniform(0.0, 0.25)), latency_jitter_s=float(rng.uniform(0.0, 0.04)),
        gain=tuple(tuple(float(gains[i]) if i == j else 0.0 for j in range(3)) for i in range(3)),
        bias=(float(rng.uniform(-0.04, 0.04)), float(rng.uniform(-0.04, 0.04)), float(rng.uniform(-0.08, 0.08))),
        residual_max=tuple(float(x) for x in rng.uniform(0.0, 0.04, 3)),
        wheel_speed_max_mps=float(rng.uniform(0.35, 0.9)),
        wheel_accel_max_mps2=float(np.exp(rng.uniform(np.log(0.8), np.log(8.0)))))


def averaged_twist(prev: RobotState, cur: RobotState, dt: float) -> RobotState:
    """``cur`` with its twist replaced by the average body twist since ``prev`` (dt seconds earlier): the pose
    change rotated into the body frame at the mid heading, divided by dt (encoder-count odometry)."""
    dth = float(np.arctan2(np.sin(cur.theta - prev.theta), np.cos(cur.theta - prev.theta)))
    mid = prev.theta + 0.5 * dth
    c, s = np.cos(mid), np.sin(mid)
    dx, dy = cur.px - prev.px, cur.py - prev.py
    return RobotState(cur.px, cur.py, cur.theta, (c * dx + s * dy) / dt, (-s * dx + c * dy) / dt, dth / dt)
