"""The robot profile: hardware imperfections between the body-twist command and the wheels.

A TOML robot profile (all keys optional; defaults are an ideal robot)::

    latency_s = 0.08                 # fixed command latency (s)
    latency_jitter_s = 0.02          # extra latency, uniform in [0, jitter] per command (s)
    gain = [[0.9, 0, 0], [0, 0.85, 0], [0, 0, 0.95]]   # execution gain A over (vx, vy, wz)
    bias = [0.02, 0.0, 0.0]          # execution bias d over (vx [m/s], vy [m/s], wz [rad/s])
    residual_max = [0.03, 0.03, 0.05]  # bounded residual noise r, uniform in [-max, max] per axis
    residual_hold_s = 0.05           # the residual is redrawn every residual_hold_s (zero-order hold)
    floor_friction = 0.35            # sliding friction of the floor (slip); unset = the model's own
    wheel_speed_max_mps = 0.6        # wheel rim-speed limit of the firmware (m/s); unset = no limit
    wheel_accel_max_mps2 = 2.0       # wheel rim-acceleration limit of the firmware (m/s^2); unset = no limit
    wheel_yaw_lever_m = 0.1645       # yaw lever arm of those limits (m); unset = the model's lx + ly

The executed body twist is ``A u + d + r`` (paper Eq. (1), with A extended to 3x3 to cover yaw rate),
applied ``latency`` after the command was issued; the wheels then realise it through the Mecanum
inverse kinematics and the floor contact (where slip comes from).

Wheel limits, as a base's firmware has them (``bigcbf.sim.firmware.WheelLimiter``): the wheel rim speeds of the
twist, ``vx -+ vy -+ k wz`` for the four wheels (k = ``wheel_yaw_lever_m``, by default half wheelbase + half
track of the model), are scaled down *together* when the fastest exceeds ``wheel_speed_max_mps`` (the direction
of motion is kept; the axes are coupled: a turn takes speed from a straight run), and the change of the wheel
speeds per firmware tick (10 ms) is scaled down together so that no wheel accelerates faster than
``wheel_accel_max_mps2``. ``wheel_yaw_lever_m`` lets the model imitate another base's geometry (a differential
drive's half track, as ``bigcbf replay`` identifies it).

Documented ranges (the calibration drive, ``bigcbf record calibration``, is checked on them): latency_s 0-0.3,
latency_jitter_s 0-0.05, gain diagonal 0.7-1.2 with off-diagonal terms within +-0.1, bias within +-0.05 m/s
(vx, vy) and +-0.1 rad/s (wz), residual_max up to 0.05, floor_friction 0.3-2, wheel_speed_max_mps 0.3-1.2,
wheel_accel_max_mps2 0.5-10.
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
    wheel_speed_max_mps: float | None = None
    wheel_accel_max_mps2: float | None = None
    wheel_yaw_lever_m: float | None = None

    def __post_init__(self):
        if self.latency_s < 0 or self.latency_jitter_s < 0:
            raise ValueError("latency_s and latency_jitter_s must be >= 0")
        if any(x < 0 for x in self.residual_max):
            raise ValueError("residual_max must be >= 0 on every axis")
        if self.residual_hold_s <= 0:
            raise ValueError("residual_hold_s must be > 0")
        if self.floor_friction is not None and not (0 < self.floor_friction <= 5):
            raise ValueError("floor_friction must be in (0, 5]")
        for name in ("wheel_speed_max_mps", "wheel_accel_max_mps2", "wheel_yaw_lever_m"):
            v = getattr(self, name)
            if v is not None and not (0 < v < 1e6):
                raise ValueError(f"{name} must be > 0 (or left out: no limit)")

    @property
    def has_wheel_limits(self) -> bool:
        """Whether the firmware limits the wheel speeds or accelerations."""
        return self.wheel_speed_max_mps is not None or self.wheel_accel_max_mps2 is not None

    @property
    def is_ideal(self) -> bool:
        return self == RobotProfile(floor_friction=self.floor_friction)

    def merged(self, **overrides) -> "RobotProfile":
        """A copy with some keys replaced (used by scenario files' robot-profile overrides)."""
        from dataclasses import replace
        return replace(self, **overrides)
