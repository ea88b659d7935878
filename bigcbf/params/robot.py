"""The robot profile: hardware imperfections between the body-twist command and the wheels.

A TOML robot profile (all keys optional; defaults are an ideal robot)::

    latency_s = 0.08                 # fixed command latency (s)
    latency_jitter_s = 0.02          # extra latency, uniform in [0, jitter] per command (s)
    gain = [[0.9, 0, 0], [0, 0.85, 0], [0, 0, 0.95]]   # execution gain A over (vx, vy, wz)
    bias = [0.02, 0.0, 0.0]          # execution bias d over (vx [m/s], vy [m/s], wz [rad/s])
    residual_max = [0.03, 0.03, 0.05]  # bounded residual noise r, uniform in [-max, max] per axis
    residual_hold_s = 0.05           # the residual is redrawn every residual_hold_s (zero-order hold)
    floor_friction = 0.35            # sliding friction of the floor (slip); unset = the model's own

The executed body twist is ``A u + d + r`` (paper Eq. (1), with A extended to 3x3 to cover yaw rate),
applied ``latency`` after the command was issued; the wheels then realise it through the Mecanum
inverse kinematics and the floor contact (where slip comes from).
"""
from __future__ import annotations

from dataclasses import dataclass

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]
IDENTITY3: Mat3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


@dataclass(frozen=True)
class RobotProfile:
    """Hardware imperfections (keys documented in the module docstring and the README)."""

    latency_s: float = 0.0
    latency_jitter_s: float = 0.0
    gain: Mat3 = IDENTITY3
    bias: Vec3 = (0.0, 0.0, 0.0)
    residual_max: Vec3 = (0.0, 0.0, 0.0)
    residual_hold_s: float = 0.05
    floor_friction: float | None = None

    def __post_init__(self):
        if self.latency_s < 0 or self.latency_jitter_s < 0:
            raise ValueError("latency_s and latency_jitter_s must be >= 0")
        if any(x < 0 for x in self.residual_max):
            raise ValueError("residual_max must be >= 0 on every axis")
        if self.residual_hold_s <= 0:
            raise ValueError("residual_hold_s must be > 0")
        if self.floor_friction is not None and not (0 < self.floor_friction <= 5):
            raise ValueError("floor_friction must be in (0, 5]")

    @property
    def is_ideal(self) -> bool:
        return self == RobotProfile(floor_friction=self.floor_friction)

    def merged(self, **overrides) -> "RobotProfile":
        """A copy with some keys replaced (used by scenario files' robot-profile overrides)."""
        from dataclasses import replace
        return replace(self, **overrides)
