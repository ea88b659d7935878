"""Mecanum-wheel kinematics of the robot's firmware (no MuJoCo here; pure numpy).

Wheel order: front-left, front-right, rear-left, rear-right. Wheel speeds w_j in rad/s, positive rolling the
robot forward. Rollers in the "X" arrangement seen from above, half wheelbase lx, half track ly, rolling
radius r. Inverse kinematics (body twist -> wheel speeds):

    w_fl = (vx - vy - (lx + ly) wz) / r        w_fr = (vx + vy + (lx + ly) wz) / r
    w_rl = (vx + vy - (lx + ly) wz) / r        w_rr = (vx - vy + (lx + ly) wz) / r

Forward kinematics is its least-squares inverse (exact for consistent wheel speeds).

Effective scale: in the MuJoCo model (straight capsule rollers, whose contact point wanders along the roller) the
achieved twist differs slightly per axis from the ideal formula, as on a real Mecanum base. The firmware corrects
with per-axis effective scales ``(kx, ky, kw)`` measured on the model (``tests/test_robot.py`` re-measures them
and fails if they drift by more than 1 %): the command ``u`` is realised by the wheel speeds ``J (u / k)``, and
odometry reports ``k * (J^+ w)``.

A robot's values come from its MJCF (``bigcbf.robots.robot(name).kinematics``: wheel positions, the rollers'
envelope, the roller angles, which must be this "X" arrangement at 45 degrees, the actuators' speed limit and the
``effective_scale`` custom numeric); the defaults below are the Rosmaster X3's (``tests/test_robot_folder.py``
checks that they equal what its MJCF gives).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MecanumKinematics:
    half_wheelbase_m: float = 0.080
    half_track_m: float = 0.0845
    rolling_radius_m: float = 0.0425
    max_wheel_speed_rad_s: float = 30.0
    #: achieved / ideal twist per axis (vx, vy, wz), measured on assets/rosmaster_x3 (see module docstring; the
    #: model's <custom><numeric name="effective_scale">)
    effective_scale: tuple[float, float, float] = (0.991, 0.962, 0.998)

    @property
    def jacobian(self) -> np.ndarray:
        """J (4x3) with w = J u, u = (vx, vy, wz)."""
        k = self.half_wheelbase_m + self.half_track_m
        return np.array([[1.0, -1.0, -k], [1.0, 1.0, k], [1.0, 1.0, -k], [1.0, -1.0, k]]) / self.rolling_radius_m

    def inverse(self, u) -> np.ndarray:
        """Body twist (vx, vy, wz) -> wheel speeds (4,), scaled down together if any exceeds the wheel limit
        (the firmware keeps the direction of motion rather than clipping one wheel)."""
        w = self.jacobian @ (np.asarray(u, float) / np.asarray(self.effective_scale))
        peak = np.max(np.abs(w))
        if peak > self.max_wheel_speed_rad_s:
            w *= self.max_wheel_speed_rad_s / peak
        return w

    def forward(self, w) -> np.ndarray:
        """Wheel speeds (4,) -> body twist (vx, vy, wz) (least squares)."""
        r = self.rolling_radius_m
        k = self.half_wheelbase_m + self.half_track_m
        w = np.asarray(w, float)
        return np.asarray(self.effective_scale) * np.array([
            r * (w[0] + w[1] + w[2] + w[3]) / 4.0,
            r * (-w[0] + w[1] + w[2] - w[3]) / 4.0,
            r * (-w[0] + w[1] - w[2] + w[3]) / (4.0 * k),
        ])
