"""Record an episode as ROS 2 MCAP (``bigcbf run --log PATH.mcap``): an observer of the episode's control steps,
laid out as a Nav2 user expects it in Foxglove.

At the start (log time 0): /tf_static (base_link -> laser and imu_link, from the model's sites), /robot_description
(the robot's MJCF text), both latched, and /goal_pose. At every control step (T_C): /clock, /tf (odom ->
base_link), /odom (the stack's state), /cmd_vel (u_safe), /cmd_vel_in (u_in), /ground_truth/odom, /imu and
/behavior; /plan (the selected behavior's imagined path, nav_msgs/Path) and, for BIG-CBF, /plan/candidates (the
six imagined paths of the selection) whenever they change. At every new LiDAR scan: /scan, /tracked_obstacles
(markers), /obstacles (the estimates with their covariances) and /cbf/inflated_radius (the D_i rings of
Eq. (14) the filter used at that step). /odom and /imu carry the covariances of the robot profile's sensor
models (:mod:`bigcbf.logio.covariance`); /odom's are zero when the stack runs on the ground truth
(``--perception truth``), as is /ground_truth/odom's.

Frames (REP 105): odom (the world frame at the start) -> base_link (the robot on the floor) -> laser, imu_link.
Time base: simulation time (see :mod:`bigcbf.logio.writer`). The episode is duck-typed (``observers`` list,
``world``, ``goal``, ``planner``), so this module does not import the episode layer above it.
"""
from __future__ import annotations

from pathlib import Path

from .covariance import WorldCovariances
from .writer import LogWriter


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
        self.world = episode.world
        # the robot's sensor covariances (bigcbf.logio.covariance); /odom is exact when the stack runs on the truth
        self._cov = (WorldCovariances(self.world) if hasattr(self.world, "reading_intervals") else None)
        self._odom_exact = getattr(episode, "perception_mode", "lidar") == "truth"
        self.planner = getattr(episode, "planner", None)
        self._last_scan_stamp: float | None = None
        self._last_path = None
        self._last_imagination = None
        w = self.writer
        frames = getattr(self.world, "sensor_frames", None)
        if frames is not None:
            w.tf_static(0.0, [(w.base_frame, child, (x, y, z), yaw) for child, (x, y, z, yaw) in frames().items()])
        describe = getattr(self.world, "robot_description", None)
        if describe is not None:
            w.robot_description(0.0, describe())
        goal = getattr(episode, "goal", None)
        if goal is not None:
            w.goal_pose(0.0, goal)
        episode.observers.append(self)

    def __call__(self, rec) -> None:
        w, t = self.writer, rec.t
        w.clock(t)
        w.tf(t, rec.state)
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

    def abort(self) -> None:
        self.writer.abort()
