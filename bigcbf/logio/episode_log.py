"""Record an episode as ROS 2 MCAP (``bigcbf run --log PATH.mcap``): an observer of the episode's control steps,
laid out as a Nav2 user expects it in Foxglove.

At the start (log time 0), latched: /tf_static (map -> odom, the identity: the simulator's world is where odom
starts; base_link -> laser and imu_link, from the model's sites), /robot_description (the robot's URDF, derived
from its MJCF: :mod:`bigcbf.logio.urdf`), /goal_pose, /map (the scene's walls, boxes and cylinders as an occupancy
grid) and /scene/markers (the same as markers). At every control step (T_C): /clock, /tf (odom -> base_link and
the wheels' joint angles), /odom (the stack's state), /cmd_vel (u_safe), /cmd_vel_in (u_in), /ground_truth/odom,
/imu, /behavior and, in a scene with pedestrians, /pedestrians/markers (where they truly are); /plan (the selected
behavior's imagined path, nav_msgs/Path) and, for BIG-CBF, /plan/candidates (the six imagined paths of the
selection) whenever they change. At every new LiDAR scan: /scan, /tracked_obstacles
(markers), /obstacles (the estimates with their covariances) and /cbf/inflated_radius (the D_i rings of
eq:shared_barrier (20) the filter used at that step). /odom and /imu carry the covariances of the robot profile's sensor
models (:mod:`bigcbf.logio.covariance`); /odom's are zero when the stack runs on the ground truth
(``--perception truth``), as is /ground_truth/odom's.

Frames (REP 105): map (the simulator's world) -> odom (the world frame at the start, identical) -> base_link (the
robot on the floor) -> laser, imu_link and the four wheel links of the URDF.
Time base: simulation time (see :mod:`bigcbf.logio.writer`). The episode is duck-typed (``observers`` list,
``world`` with ``model``, ``data``, ``scene``, ``goal``, ``planner``, ``walkers``), so this module does not import
the episode layer above it.

Interrupted (Ctrl-C, SIGTERM through :func:`bigcbf.logio.interrupts.interrupts_as_keyboard_interrupt`): ``abort()``
called while a KeyboardInterrupt is handled keeps the log recorded so far as ``X.partial.mcap``
(:meth:`finish_partial`) and appends its path to the exception's ``partial_logs`` list, so that the command line
can say where it is; any other abort drops it.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from .covariance import WorldCovariances
from .interrupts import critical
from .writer import MAP_FRAME, LogWriter


class EpisodeLogger:
    """``logger = EpisodeLogger(episode, path); episode.run(); logger.close()``. ``writer``: another sink with
    LogWriter's methods instead of a file (``bigcbf.logio.live.LiveWriter`` streams to Foxglove)."""

    def __init__(self, episode, path: str | Path | None = None, *, writer: LogWriter | None = None):
        meta = {k: str(getattr(episode, k)) for k in ("method", "seed") if hasattr(episode, k)}
        scenario = getattr(episode, "scenario", None)
        if scenario is not None and hasattr(scenario, "name"):
            meta["scenario"] = scenario.name
        meta["time_base"] = ("simulation time: log times and header stamps are seconds since the episode's start; "
                             "/clock carries it")
        self.writer = writer if writer is not None else LogWriter(path, metadata=meta)
        self.path = self.writer.path
        try:                             # the start's latched messages whole, or no file (an interrupt waits)
            with critical:
                self._start(episode)
        except BaseException:
            if writer is None:           # ours: dropped (a caller's writer is the caller's to close)
                self.writer.abort()
            raise

    def _start(self, episode) -> None:
        self.world = episode.world
        # the robot's sensor covariances (bigcbf.logio.covariance); /odom is exact when the stack runs on the truth
        self._cov = (WorldCovariances(self.world) if hasattr(self.world, "reading_intervals") else None)
        self._odom_exact = getattr(episode, "perception_mode", "lidar") == "truth"
        self.planner = getattr(episode, "planner", None)
        self._last_scan_stamp: float | None = None
        self._last_path = None
        self._last_imagination = None
        w = self.writer
        self.urdf = None
        frames = getattr(self.world, "sensor_frames", None)
        static = [(MAP_FRAME, w.odom_frame, (0.0, 0.0, 0.0), 0.0)]
        if frames is not None:
            sensors = frames()
            static += [(w.base_frame, child, (x, y, z), yaw) for child, (x, y, z, yaw) in sensors.items()]
            if hasattr(self.world, "model"):
                from .urdf import robot_description
                self.urdf = robot_description(self.world.model, sensors, base=w.base_frame,
                                              name=self.world.robot.name)
        w.tf_static(0.0, static)
        if self.urdf is not None:
            w.robot_description(0.0, self.urdf.text)
        goal = getattr(episode, "goal", None)
        if goal is not None:
            w.goal_pose(0.0, goal)
        scene = getattr(self.world, "scene", None)
        if scene is not None:
            w.occupancy_grid(0.0, scene)
            w.scene_markers(0.0, scene)
        # the true pedestrians: their mocap bodies (positions) and the scene's bodies (names, radii, heights)
        self._walkers = getattr(episode, "walkers", None)
        peds = tuple(getattr(scene, "pedestrians", ())) if self._walkers is not None else ()
        self._peds = ([p.name for p in peds], [p.radius for p in peds], [p.height for p in peds]) if peds else None
        episode.observers.append(self)

    def __call__(self, rec) -> None:
        with critical:                   # an interrupt waits for the step's messages (the partial log ends whole)
            self._step(rec)

    def _step(self, rec) -> None:
        w, t = self.writer, rec.t
        w.clock(t)
        w.tf(t, rec.state, extra=() if self.urdf is None else self.urdf.wheel_transforms(self.world.data.qpos))
        if self._peds is not None:
            names, radii, heights = self._peds
            w.pedestrians(t, names, np.asarray(self._walkers.positions(), float), radii, heights)
        w.cmd_vel(t, rec.u_safe)
        w.cmd_vel_in(t, rec.u_in)
        if self._cov is not None and not self._odom_exact:
            pose_cov, twist_cov = self._cov.odom(t, rec.state)
            w.odom(t, rec.state, pose_cov=pose_cov, twist_cov=twist_cov)
        else:
            w.odom(t, rec.state)
        w.ground_truth(t, rec.true_state)
        w.imu(t, self.world.imu(), cov=None if self._cov is None else self._cov.imu())
        w.behavior(t, rec.mode)
        path = getattr(rec, "path", None)
        if path is not None and len(path) > 1 and path is not self._last_path:
            self._last_path = path
            w.plan(t, path)
        img = getattr(self.planner, "last_imagination", None)
        if img is not None and img is not self._last_imagination:
            self._last_imagination = img
            w.candidates(t, img.modes, img.p, img.accepted, rec.mode, img.available)
        scan = rec.scan
        if scan is not None and scan.stamp != self._last_scan_stamp:
            self._last_scan_stamp = scan.stamp
            w.scan(scan.stamp, scan)
            w.obstacles(t, rec.obstacles)
            w.obstacle_states(t, rec.obstacles)
            D = getattr(rec, "D", None)
            if D is not None:
                w.inflated_radii(t, rec.obstacles, D)

    def close(self) -> None:
        self.writer.close()

    def finish_partial(self) -> Path | None:
        """Keep the log recorded so far as ``X.partial.mcap`` (:meth:`bigcbf.logio.writer.LogWriter.finish_partial`);
        its path, or None for a writer that keeps nothing (a live stream: closed)."""
        finish = getattr(self.writer, "finish_partial", None)
        if finish is None:
            self.writer.close()
            return None
        return finish()

    def abort(self) -> None:
        """Drop the unfinished log, or, while a KeyboardInterrupt is handled, keep it (module docstring)."""
        exc = sys.exc_info()[1]
        if isinstance(exc, KeyboardInterrupt):
            path = self.finish_partial()
            if path is not None:
                if not isinstance(getattr(exc, "partial_logs", None), list):
                    exc.partial_logs = []
                exc.partial_logs.append(path)
            return
        self.writer.abort()
