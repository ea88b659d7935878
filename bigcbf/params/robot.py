"""The robot profile: hardware imperfections between the body-twist command and the wheels, and the sensor models.

A TOML robot profile (all keys optional; the defaults of the dataclasses are an *ideal* robot: ``RobotProfile()``)::

    latency_s = 0.08                 # fixed command latency (s)
    latency_jitter_s = 0.02          # extra latency, uniform in [0, jitter] per command (s)
    gain = [[0.9, 0, 0], [0, 0.85, 0], [0, 0, 0.95]]   # execution gain A over (vx, vy, wz)
    bias = [0.02, 0.0, 0.0]          # execution bias d over (vx [m/s], vy [m/s], wz [rad/s])
    residual_max = [0.03, 0.03, 0.05]  # bounded residual noise r, uniform in [-max, max] per axis
    residual_hold_s = 0.05           # the residual is redrawn every residual_hold_s (zero-order hold)
    slip_max = 0.05                  # lateral slip: up to this fraction of ||u_xy||, across the motion [-]
    slip_hold_s = 0.5                # the slip fraction is redrawn every slip_hold_s (s)
    floor_friction = 0.35            # sliding friction of the floor; unset = the model's own
    wheel_speed_max_mps = 0.6        # wheel rim-speed limit of the firmware (m/s); unset = no limit
    wheel_accel_max_mps2 = 2.0       # wheel rim-acceleration limit of the firmware (m/s^2); unset = no limit
    wheel_yaw_lever_m = 0.1645       # yaw lever arm of those limits (m); unset = the model's lx + ly

    [lidar]                          # the 2-D LiDAR (sensor_msgs/LaserScan)
    n_beams = 360                    # beams per revolution (angular resolution 2 pi / n_beams)
    rate_hz = 10.0                   # scans per second
    range_min_m = 0.15
    range_max_m = 12.0
    range_noise_std_m = 0.005        # Gaussian range noise: std = range_noise_std_m + range_noise_frac * range
    range_noise_frac = 0.005

    [odometry]                       # wheel odometry (encoders)
    encoder_counts_per_rev = 1320    # counts per wheel revolution (0: exact wheel angles)
    scale_error = 0.01               # bias: the odometry's wheel radius is off by this fraction [-]
    wheel_noise_density_radps_rthz = 0.0   # noise: white noise on each wheel's measured speed [rad/s/sqrt(Hz)]

    [imu]                            # the gyro whose yaw rate the odometry uses for the heading
    gyro_noise_density_radps_rthz = 1.75e-4   # noise: white rate noise [rad/s/sqrt(Hz)]
    gyro_bias_max_radps = 8.7e-4     # bias: residual bias after start-up calibration, uniform in [-max, max] per
                                     # episode [rad/s]
    gyro_bias_radps = 0.0            # bias: a fixed bias on top of it (the heading drifts by this rate) [rad/s]

    [faults]                         # LiDAR dropout and blanked sectors, command latency spikes: every fault off by
                                     # default; keys, units and ranges in bigcbf/params/faults.py
    blanked_sectors_deg = []
    [faults.scan_dropout]
    rate_per_s = 0.0
    [faults.latency_spikes]
    rate_per_s = 0.0

The executed body twist is ``A u + d + r + s`` (the paper's eq:execution (1), with A extended to 3x3 to cover yaw rate;
``s`` the lateral slip, perpendicular to the commanded translation), applied ``latency`` after the command was issued;
the wheels then realise it through the Mecanum inverse kinematics and the floor contact. Every random source draws
from its own stream (``bigcbf.sim.world``), so that e.g. LiDAR noise does not change the execution residuals.
Wheel limits, as a base's firmware has them (``bigcbf.sim.firmware.WheelLimiter``): the wheel rim speeds of the
twist, ``vx -+ vy -+ k wz`` for the four wheels (k = ``wheel_yaw_lever_m``, by default half wheelbase + half
track of the model), are scaled down *together* when the fastest exceeds ``wheel_speed_max_mps`` (the direction
of motion is kept; the axes are coupled: a turn takes speed from a straight run), and the twist ramps toward its
target in a straight line, continuously in time, so that no wheel accelerates faster than ``wheel_accel_max_mps2``
(each physics block holds the ramp's mean over it). ``wheel_yaw_lever_m`` lets the model imitate another base's geometry (a differential
drive's half track, as ``bigcbf replay`` identifies it).

Documented ranges (the calibration drive, ``bigcbf record calibration``, is checked on them): latency_s 0-0.3,
latency_jitter_s 0-0.05, gain diagonal 0.7-1.2 with off-diagonal terms within +-0.1, bias within +-0.05 m/s
(vx, vy) and +-0.1 rad/s (wz), residual_max up to 0.05, floor_friction 0.3-2, wheel_speed_max_mps 0.3-1.2,
wheel_accel_max_mps2 0.5-10.
Faults (``[faults]``, ``bigcbf.params.faults``) are part of the profile too, each with its own stream.

The simulated X3 used by every scenario by default is ``bigcbf/profiles/x3_sim.toml`` (its comments give the
source of every value); scenario files override its keys in a ``[robot_profile]`` table.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from .faults import RobotFaults
from .checks import check_field_ranges, ranged

Vec3 = tuple[float, float, float]
Mat3 = tuple[Vec3, Vec3, Vec3]
IDENTITY3: Mat3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


def _nonneg(obj, *names: str) -> None:
    for name in names:
        v = getattr(obj, name)
        if not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {v}")


@dataclass(frozen=True)
class LidarModel:
    """A rotating 2-D LiDAR: beams evenly spaced over 360 degrees, one scan every 1/rate_hz.

    Range noise is Gaussian with standard deviation ``range_noise_std_m + range_noise_frac * range`` [m]
    (triangulation LiDARs lose accuracy with range). The defaults are the ideal sensor of the original model.
    """

    n_beams: int = ranged(360, 8, 8192)  # beams per scan [-]
    rate_hz: float = ranged(10.0, 1, 100)  # scan rate [Hz]
    range_min_m: float = ranged(0.12, 0, 10)  # shorter returns are dropped [m]
    range_max_m: float = ranged(8.0, 0.1, 100)  # longer returns are dropped [m]
    range_noise_std_m: float = ranged(0.0, 0, 1)  # constant part of the range noise std [m]
    range_noise_frac: float = ranged(0.0, 0, 0.5)  # part of the range noise std proportional to the range [-]

    def __post_init__(self):
        check_field_ranges(self)
        if self.n_beams < 1 or not (math.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError("n_beams must be >= 1 and rate_hz > 0")
        if not (0 <= self.range_min_m < self.range_max_m and math.isfinite(self.range_max_m)):
            raise ValueError("need 0 <= range_min_m < range_max_m")
        _nonneg(self, "range_noise_std_m", "range_noise_frac")

    def range_sigma(self, r):
        """The range noise's standard deviation at range r [m]."""
        return self.range_noise_std_m + self.range_noise_frac * r


@dataclass(frozen=True)
class OdometryModel:
    """Wheel odometry from quantized encoder counts, with a wheel-radius (scale) error (a bias: the odometry's
    distances are (1 + scale_error) x the true ones) and white noise on each wheel's measured speed (density in
    rad/s/sqrt(Hz): a speed averaged over dt has standard deviation density / sqrt(dt), so the wheel angle the
    odometry integrates random-walks with standard deviation density sqrt(t), whatever the integration step; wheel
    slip on the floor beyond the physics')."""

    encoder_counts_per_rev: int = ranged(0, 0, 1000000)  # encoder counts per wheel revolution; 0 = exact wheel angles [-]
    scale_error: float = ranged(0.0, -0.5, 0.5, lo_open=True, hi_open=True)  # odometry speeds are (1 + scale_error) x the wheels' true ones [-]
    wheel_noise_density_radps_rthz: float = ranged(0.0, 0, 10)  # white noise on each wheel's measured speed [rad/s/sqrt(Hz)]

    def __post_init__(self):
        check_field_ranges(self)
        if self.encoder_counts_per_rev < 0:
            raise ValueError("encoder_counts_per_rev must be >= 0")
        if not (math.isfinite(self.scale_error) and -0.5 < self.scale_error < 0.5):
            raise ValueError("scale_error must be in (-0.5, 0.5)")
        _nonneg(self, "wheel_noise_density_radps_rthz")
        if self.wheel_noise_density_radps_rthz > 10.0:
            raise ValueError("wheel_noise_density_radps_rthz must be <= 10 rad/s/sqrt(Hz)")


@dataclass(frozen=True)
class ImuModel:
    """The gyro's yaw rate: true rate + bias + white noise (noise density in rad/s/sqrt(Hz), so a reading averaged
    over dt has standard deviation density / sqrt(dt)); the bias is ``gyro_bias_radps`` (fixed: the heading
    drifts at that rate) plus a draw once per episode, uniform in [-gyro_bias_max_radps, gyro_bias_max_radps]
    (what is left after the start-up calibration)."""

    gyro_noise_density_radps_rthz: float = ranged(0.0, 0, 1)  # white rate-noise density [rad/s/sqrt(Hz)]
    gyro_bias_max_radps: float = ranged(0.0, 0, 1)  # bound of the residual bias drawn per episode [rad/s]
    gyro_bias_radps: float = ranged(0.0, -1, 1)  # fixed bias [rad/s]

    def __post_init__(self):
        check_field_ranges(self)
        _nonneg(self, "gyro_noise_density_radps_rthz", "gyro_bias_max_radps")
        for name in ("gyro_noise_density_radps_rthz", "gyro_bias_max_radps"):
            if getattr(self, name) > 1.0:
                raise ValueError(f"{name} must be <= 1 (rad/s)")
        if not (math.isfinite(self.gyro_bias_radps) and abs(self.gyro_bias_radps) <= 1.0):
            raise ValueError("gyro_bias_radps must be in [-1, 1] rad/s")


@dataclass(frozen=True)
class RobotProfile:
    """Hardware imperfections and sensor models (keys documented in the module docstring and the README)."""

    latency_s: float = ranged(0.0, 0, 2)
    latency_jitter_s: float = ranged(0.0, 0, 1)
    gain: Mat3 = ranged(IDENTITY3, -2, 2)
    bias: Vec3 = ranged((0.0, 0.0, 0.0), -1, 1)
    residual_max: Vec3 = ranged((0.0, 0.0, 0.0), 0, 1)
    residual_hold_s: float = ranged(0.05, 0, 60, lo_open=True)
    slip_max: float = ranged(0.0, 0, 1, hi_open=True)  # lateral slip bound, fraction of ||u_xy|| [-]
    slip_hold_s: float = ranged(0.5, 0, 60, lo_open=True)  # the slip fraction is redrawn every slip_hold_s [s]
    floor_friction: float | None = ranged(None, 0, 5, lo_open=True)
    lidar: LidarModel = field(default_factory=LidarModel)
    odometry: OdometryModel = field(default_factory=OdometryModel)
    imu: ImuModel = field(default_factory=ImuModel)
    wheel_speed_max_mps: float | None = ranged(None, 0, 10, lo_open=True)
    wheel_accel_max_mps2: float | None = ranged(None, 0, 100, lo_open=True)
    wheel_yaw_lever_m: float | None = ranged(None, 0, 2, lo_open=True)
    faults: RobotFaults = field(default_factory=RobotFaults)

    def __post_init__(self):
        check_field_ranges(self)
        if self.latency_s < 0 or self.latency_jitter_s < 0:
            raise ValueError("latency_s and latency_jitter_s must be >= 0")
        if any(x < 0 for x in self.residual_max):
            raise ValueError("residual_max must be >= 0 on every axis")
        if self.residual_hold_s <= 0:
            raise ValueError("residual_hold_s must be > 0")
        if not (0 <= self.slip_max < 1):
            raise ValueError("slip_max must be in [0, 1)")
        if self.slip_hold_s <= 0:
            raise ValueError("slip_hold_s must be > 0")
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
        """No execution imperfection and ideal sensors (the floor's friction is not an imperfection)."""
        return self == RobotProfile(floor_friction=self.floor_friction)

    def merged(self, **overrides) -> "RobotProfile":
        """A copy with some keys replaced (used by scenario files' robot-profile overrides)."""
        from dataclasses import replace
        return replace(self, **overrides)


def merge_tables(base: dict, over: dict) -> dict:
    """``over`` on top of ``base``, table by table (a nested table's keys are merged, not replaced)."""
    out = dict(base)
    for k, v in over.items():
        out[k] = merge_tables(base[k], v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
    return out


__all__ = ["RobotProfile", "LidarModel", "OdometryModel", "ImuModel", "IDENTITY3", "Mat3", "Vec3",
           "merge_tables"]
