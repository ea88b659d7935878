"""The robot's firmware side: command latency and execution imperfections, wheel targets, wheel odometry.

No MuJoCo here. The hardware-imperfection layer realises paper Eq. (1) on the simulated robot: the body twist
actually sent to the wheels is ``A u + d + r`` (A 3x3, bias d, bounded residual r), applied after a latency
``latency_s + U(0, latency_jitter_s)``; commands never overtake one another (a FIFO, like a serial link).
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from ..params.robot import RobotProfile
from ..types import RobotState
from .kinematics import MecanumKinematics


class ImperfectionLayer:
    """Eq. (1) plus latency: turns issued commands into executed body twists, in time order."""

    def __init__(self, profile: RobotProfile, rng: np.random.Generator):
        self.profile = profile
        self.rng = rng
        self._A = np.asarray(profile.gain, float)
        self._d = np.asarray(profile.bias, float)
        self._rmax = np.asarray(profile.residual_max, float)
        self._queue: deque[tuple[float, np.ndarray]] = deque()
        self._last_apply = -np.inf
        self._residual = np.zeros(3)
        self._residual_until = -np.inf
        self.current = np.zeros(3)

    def executed_twist(self, t: float, u) -> np.ndarray:
        """Eq. (1) (3-axis form): A u + d + r, r uniform in [-residual_max, residual_max], held residual_hold_s."""
        if np.any(self._rmax > 0):
            if t >= self._residual_until:
                self._residual = self.rng.uniform(-self._rmax, self._rmax)
                self._residual_until = t + self.profile.residual_hold_s
        return self._A @ np.asarray(u, float) + self._d + self._residual

    def submit(self, t: float, u) -> float:
        """Issue command u at time t; returns the time at which the wheels will receive it."""
        delay = self.profile.latency_s
        if self.profile.latency_jitter_s > 0:
            delay += self.rng.uniform(0.0, self.profile.latency_jitter_s)
        apply_at = max(t + delay, self._last_apply)
        self._last_apply = apply_at
        self._queue.append((apply_at, self.executed_twist(t, u)))
        return apply_at

    def next_apply_time(self) -> float | None:
        """When the oldest queued command reaches the wheels (None when none is queued)."""
        return self._queue[0][0] if self._queue else None

    def at(self, t: float) -> np.ndarray:
        """The executed twist in force at time t (the newest command whose apply time has come)."""
        q = self._queue
        while q and q[0][0] <= t + 1e-12:
            self.current = q.popleft()[1]
        return self.current


class WheelOdometry:
    """Odometry as the robot computes it: body velocity from the measured wheel speeds (forward kinematics),
    heading from the IMU's yaw rate when one is given (wheel + IMU fusion, as on the paper's robot: Mecanum
    rollers slip in yaw, which the wheels cannot see), position integrated in that heading."""

    def __init__(self, kin: MecanumKinematics, x: float = 0.0, y: float = 0.0, theta: float = 0.0):
        self.kin = kin
        self.reset(x, y, theta)

    def reset(self, x: float, y: float, theta: float) -> None:
        self.x, self.y, self.theta = float(x), float(y), float(theta)
        self.twist = np.zeros(3)

    def update(self, wheel_speeds, dt: float, gyro_z: float | None = None, measured=None) -> None:
        """Integrate over dt with the wheel speeds (and yaw rate) ``wheel_speeds`` (e.g. the mean over dt, for a
        trapezoidal step); the reported twist is that of ``measured`` (the latest reading; default: the same)."""
        twist = self.kin.forward(wheel_speeds)
        if gyro_z is not None:
            twist[2] = gyro_z
        vx, vy, wz = (float(x) for x in twist)
        self.twist = twist if measured is None else self.kin.forward(measured)
        if gyro_z is not None:
            self.twist[2] = gyro_z
        mid = self.theta + 0.5 * wz * dt          # midpoint heading (second order)
        c, s = math.cos(mid), math.sin(mid)
        self.x += (c * vx - s * vy) * dt
        self.y += (s * vx + c * vy) * dt
        th = self.theta + wz * dt
        self.theta = math.atan2(math.sin(th), math.cos(th))

    def state(self) -> RobotState:
        return RobotState(self.x, self.y, self.theta, *map(float, self.twist))
