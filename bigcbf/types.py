"""Types shared by every layer: robot state, obstacle estimates, laser scans.

Frames follow ROS REP 105: ``odom`` is the world frame, ``base_link`` the body frame.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class RobotState:
    """The state available to the controller, x = [px, py, theta, vx, vy, wz] (paper Sec. II-A).

    Position and yaw in odom; velocities (vx, vy in m/s, wz in rad/s) in base_link.
    """

    px: float
    py: float
    theta: float
    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0

    @property
    def p(self) -> np.ndarray:
        return np.array([self.px, self.py])

    def as_array(self) -> np.ndarray:
        return np.array([self.px, self.py, self.theta, self.vx, self.vy, self.wz])


@dataclass(frozen=True)
class Obstacles:
    """M obstacle estimates in the odom frame, stored as arrays (one type for every method).

    p (M,2) center [m]; v (M,2) velocity [m/s]; cov (M,2,2) position covariance [m^2];
    r (M,) physical radius [m] (0 for a wall point); static (M,) bool; ids (M,) int track ids
    (-1 for wall points, which are not tracked entities).
    """

    p: np.ndarray
    v: np.ndarray
    cov: np.ndarray
    r: np.ndarray
    static: np.ndarray
    ids: np.ndarray = field(default=None)  # type: ignore[assignment]

    def __post_init__(self):
        m = len(self.r)
        if self.ids is None:
            object.__setattr__(self, "ids", np.arange(m))
        assert self.p.shape == (m, 2) and self.v.shape == (m, 2) and self.cov.shape == (m, 2, 2)

    def __len__(self) -> int:
        return len(self.r)

    @staticmethod
    def empty() -> "Obstacles":
        return Obstacles(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0),
                         np.zeros(0, bool), np.zeros(0, int))

    @staticmethod
    def from_lists(p, v=None, r=None, cov=None, static=None, ids=None) -> "Obstacles":
        """Convenience constructor (tests, ground-truth mode)."""
        p = np.asarray(p, float).reshape(-1, 2)
        m = len(p)
        v = np.zeros((m, 2)) if v is None else np.asarray(v, float).reshape(m, 2)
        r = np.zeros(m) if r is None else np.broadcast_to(np.asarray(r, float), (m,)).copy()
        cov = np.zeros((m, 2, 2)) if cov is None else np.broadcast_to(np.asarray(cov, float), (m, 2, 2)).copy()
        static = (np.linalg.norm(v, axis=1) < 1e-9) if static is None else np.broadcast_to(
            np.asarray(static, bool), (m,)).copy()
        ids = np.arange(m) if ids is None else np.asarray(ids, int)
        return Obstacles(p, v, cov, r, static, ids)

    def concat(self, other: "Obstacles") -> "Obstacles":
        return Obstacles(np.concatenate([self.p, other.p]), np.concatenate([self.v, other.v]),
                         np.concatenate([self.cov, other.cov]), np.concatenate([self.r, other.r]),
                         np.concatenate([self.static, other.static]), np.concatenate([self.ids, other.ids]))

    def subset(self, idx) -> "Obstacles":
        return Obstacles(self.p[idx], self.v[idx], self.cov[idx], self.r[idx], self.static[idx], self.ids[idx])


@dataclass(frozen=True)
class LaserScan:
    """Shaped like ROS 2 sensor_msgs/LaserScan. ranges: float32 array, inf where a beam missed."""

    stamp: float
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: np.ndarray
    frame_id: str = "laser"
    time_increment: float = 0.0
    scan_time: float = 0.1

    @property
    def angle_max(self) -> float:
        return self.angle_min + self.angle_increment * (len(self.ranges) - 1)

    @property
    def angles(self) -> np.ndarray:
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges))
