"""Record an episode as ROS 2 MCAP (``bigcbf run --log PATH.mcap``): an observer of the episode's control steps.

At every control step (T_C): /cmd_vel (u_safe), /cmd_vel_in (u_in), /odom (the stack's state), /tf,
/ground_truth/odom, /imu and /behavior; at every new LiDAR scan: /scan and /tracked_obstacles (the estimates the
stack used at that step). Log time = simulation time. The episode is duck-typed (``observers`` list and
``world``), so this module does not import the episode layer above it.
"""
from __future__ import annotations

from pathlib import Path

from .writer import LogWriter


class EpisodeLogger:
    """``logger = EpisodeLogger(episode, path); episode.run(); logger.close()``."""

    def __init__(self, episode, path: str | Path):
        meta = {k: str(getattr(episode, k)) for k in ("method", "seed") if hasattr(episode, k)}
        scenario = getattr(episode, "scenario", None)
        if scenario is not None and hasattr(scenario, "name"):
            meta["scenario"] = scenario.name
        self.writer = LogWriter(path, metadata=meta)
        self.world = episode.world
        self._last_scan_stamp: float | None = None
        episode.observers.append(self)

    def __call__(self, rec) -> None:
        w, t = self.writer, rec.t
        w.cmd_vel(t, rec.u_safe)
        w.cmd_vel_in(t, rec.u_in)
        w.odom(t, rec.state)
        w.tf(t, rec.state)
        w.ground_truth(t, rec.true_state)
        w.imu(t, self.world.imu())
        w.behavior(t, rec.mode)
        scan = rec.scan
        if scan is not None and scan.stamp != self._last_scan_stamp:
            self._last_scan_stamp = scan.stamp
            w.scan(scan.stamp, scan)
            w.obstacles(t, rec.obstacles)

    def close(self) -> None:
        self.writer.close()

    def abort(self) -> None:
        self.writer.abort()
