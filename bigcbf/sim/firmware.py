"""The robot's firmware side: command latency and execution imperfections, wheel targets, wheel odometry, and the
encoder and gyro models the odometry reads.

No MuJoCo here. The hardware-imperfection layer realises the paper's eq:execution (1) on the simulated robot: the body
twist actually sent to the wheels is ``A u + d + r + s`` (A 3x3, bias d, bounded residual r, lateral slip s), applied
after a latency ``latency_s + U(0, latency_jitter_s)``; commands never overtake one another (a FIFO, like a serial
link). The residual, the jitter and the slip each draw from their own random stream. Latency spikes (the robot
profile's ``[faults.latency_spikes]``, ``bigcbf/params/faults.py``): the link stalls during each event, and a command
issued then leaves when the stall ends (and then takes its latency).
Then, when the profile has wheel limits, :class:`WheelLimiter` saturates the wheel speeds and limits their
acceleration, as a base's firmware does (eq:execution (1) holds only below those limits).
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from ..params.robot import ImuModel, OdometryModel, RobotProfile
from ..types import RobotState
from .faults import EventProcess
from .kinematics import MecanumKinematics


class ImperfectionLayer:
    """eq:execution (1) plus latency: turns issued commands into executed body twists, in time order."""

    def __init__(self, profile: RobotProfile, rng: np.random.Generator, rng_jitter: np.random.Generator | None = None,
                 rng_slip: np.random.Generator | None = None, lever_m: float | None = None,
                 rng_spikes: np.random.Generator | None = None):
        """``lever_m``: the wheel limits' default yaw lever arm (the kinematics' half wheelbase + half track)."""
        self.profile = profile
        self.rng = rng
        self.rng_jitter = rng if rng_jitter is None else rng_jitter
        self.rng_slip = rng if rng_slip is None else rng_slip
        spikes = profile.faults.latency_spikes
        self.spikes = (EventProcess(spikes, rng_spikes if rng_spikes is not None else np.random.default_rng(0))
                       if spikes.enabled else None)
        self._slip = 0.0
        self._slip_until = -np.inf
        self._A = np.asarray(profile.gain, float)
        self._d = np.asarray(profile.bias, float)
        self._rmax = np.asarray(profile.residual_max, float)
        self._queue: deque[tuple[float, np.ndarray]] = deque()
        self._last_apply = -np.inf
        self._residual = np.zeros(3)
        self._residual_until = -np.inf
        self.current = np.zeros(3)
        #: the wheel limits (None: the profile has none, and the executed twist goes to the wheels as it is)
        if lever_m is None:
            kin = MecanumKinematics()
            lever_m = kin.half_wheelbase_m + kin.half_track_m
        self.limiter = WheelLimiter(profile, lever_m) if profile.has_wheel_limits else None

    def executed_twist(self, t: float, u) -> np.ndarray:
        """eq:execution (1) (3-axis form): A u + d + r + s, r uniform in [-residual_max, residual_max], held
        residual_hold_s; s the lateral slip: sigma * ||u_xy|| across the commanded translation (to its left for
        sigma > 0), sigma uniform in [-slip_max, slip_max], held slip_hold_s."""
        u = np.asarray(u, float)
        if np.any(self._rmax > 0):
            if t >= self._residual_until:
                self._residual = self.rng.uniform(-self._rmax, self._rmax)
                self._residual_until = t + self.profile.residual_hold_s
        out = self._A @ u + self._d + self._residual
        if self.profile.slip_max > 0:
            if t >= self._slip_until:
                self._slip = float(self.rng_slip.uniform(-self.profile.slip_max, self.profile.slip_max))
                self._slip_until = t + self.profile.slip_hold_s
            out = out + self._slip * np.array([-u[1], u[0], 0.0])
        return out

    def submit(self, t: float, u) -> float:
        """Issue command u at time t; returns the time at which the wheels will receive it: t + the latency, or,
        when a latency spike stalls the link at t, the end of the stall + the latency; never before the previous
        command."""
        delay = self.profile.latency_s
        if self.profile.latency_jitter_s > 0:
            delay += self.rng_jitter.uniform(0.0, self.profile.latency_jitter_s)
        sent = t if self.spikes is None else self.spikes.end_of_outage(t)
        apply_at = max(sent + delay, self._last_apply)
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


def rim_matrix(lever_m: float) -> np.ndarray:
    """R (4x3): wheel rim speeds [m/s] = R (vx, vy, wz) of the Mecanum inverse kinematics (wheel order fl, fr,
    rl, rr; ``lever_m`` = half wheelbase + half track), as in ``MecanumKinematics.jacobian`` times the rolling
    radius. For vy = 0 it is a differential drive's (rows vx -+ lever wz)."""
    k = float(lever_m)
    return np.array([[1.0, -1.0, -k], [1.0, 1.0, k], [1.0, 1.0, -k], [1.0, -1.0, k]])


class WheelLimiter:
    """The firmware's wheel-speed saturation and acceleration limit (robot profile keys ``wheel_speed_max_mps``,
    ``wheel_accel_max_mps2``, ``wheel_yaw_lever_m``).

    - saturation: a target twist whose fastest wheel rim speed max|R v| exceeds the limit is scaled by
      limit / max|R v| (all wheels together: the direction of motion is kept, the axes are coupled);
    - acceleration: the output twist moves toward the (saturated) target in a straight line, continuously in time,
      its largest wheel change max|R dv| growing at ``wheel_accel_max_mps2``. :meth:`update` ``(t, target,
      hold_s)`` first moves it over the time since the previous call toward the target in force then, and returns
      its mean over the coming ``hold_s`` toward the new one: the physics holds one value per block, and the
      block's mean keeps the wheels' response independent of where in a block a command arrives. (Moving toward
      the new target by the budget of the time *before* it arrived, as this limiter once did, started every ramp
      up to a block early when a command met a block's start, and less when it fell inside one: a 0-10 ms timing
      error that the twin read as latency.)
    """

    def __init__(self, profile: RobotProfile, default_lever_m: float):
        lever = profile.wheel_yaw_lever_m if profile.wheel_yaw_lever_m is not None else default_lever_m
        self.R = rim_matrix(lever)
        self.v_max = profile.wheel_speed_max_mps
        self.a_max = profile.wheel_accel_max_mps2
        self.out = np.zeros(3)
        self._goal = np.zeros(3)
        self._t = None

    def saturate(self, twist) -> np.ndarray:
        v = np.asarray(twist, float)
        if self.v_max is None:
            return v
        peak = float(np.max(np.abs(self.R @ v)))
        return v * (self.v_max / peak) if peak > self.v_max else v

    def _ramp(self, goal: np.ndarray) -> tuple[np.ndarray, float]:
        """The step from the output to ``goal`` and how long the limit takes over it [s]."""
        step = goal - self.out
        return step, float(np.max(np.abs(self.R @ step))) / self.a_max

    def update(self, t: float, target, hold_s: float = 0.0) -> np.ndarray:
        """The limited twist to hold from t for ``hold_s`` (its mean over that span; 0: its value at t) for the
        executed (pre-limit) twist ``target``, in force from t on; call with increasing t."""
        goal = self.saturate(target)
        if self.a_max is None:
            self.out = goal
            return goal
        if self._t is not None:                 # the robot starts at rest: the first call moves nothing
            step, tau = self._ramp(self._goal)
            dt = max(t - self._t, 0.0)
            self.out = self._goal.copy() if dt >= tau else self.out + step * (dt / tau)
        self._goal, self._t = goal, t
        step, tau = self._ramp(goal)
        if hold_s <= 0.0 or tau <= 0.0:
            return self.out.copy()
        # the mean over [0, H] of min(1, s / tau): the ramp's part, then the goal held
        frac = hold_s / (2.0 * tau) if hold_s <= tau else 1.0 - tau / (2.0 * hold_s)
        return self.out + step * frac


class WheelOdometry:
    """Odometry as the robot computes it: body velocity from the measured wheel speeds (forward kinematics),
    heading from the IMU's yaw rate when one is given (wheel + IMU fusion, as on the paper's robot: Mecanum
    rollers slip in yaw, which the wheels cannot see), position integrated in that heading."""

    def __init__(self, kin: MecanumKinematics, x: float = 0.0, y: float = 0.0, theta: float = 0.0):
        self.kin = kin
        # MecanumKinematics.forward's constants, for the same arithmetic in plain floats (_forward); None: another
        # kinematics class, whose own forward is called
        self._fk = ((kin.rolling_radius_m, kin.half_wheelbase_m + kin.half_track_m,
                     *(float(e) for e in kin.effective_scale)) if type(kin) is MecanumKinematics else None)
        self.reset(x, y, theta)

    def _forward(self, w) -> np.ndarray:
        """``self.kin.forward(w)``: for MecanumKinematics the same operations in the same order on Python floats
        (the same bits, without numpy's per-scalar overhead: this runs twice per physics block)."""
        if self._fk is None:
            return self.kin.forward(w)
        r, k, ex, ey, ez = self._fk
        w0, w1, w2, w3 = np.asarray(w, float).tolist()
        return np.array([ex * (r * (w0 + w1 + w2 + w3) / 4.0), ey * (r * (-w0 + w1 + w2 - w3) / 4.0),
                         ez * (r * (-w0 + w1 - w2 + w3) / (4.0 * k))])

    def reset(self, x: float, y: float, theta: float) -> None:
        self.x, self.y, self.theta = float(x), float(y), float(theta)
        self.twist = np.zeros(3)

    def update(self, wheel_speeds, dt: float, gyro_z: float | None = None, measured=None) -> None:
        """Integrate over dt with the wheel speeds (and yaw rate) ``wheel_speeds`` (e.g. the mean over dt, for a
        trapezoidal step); the reported twist is that of ``measured`` (the latest reading; default: the same)."""
        twist = self._forward(wheel_speeds)
        if gyro_z is not None:
            twist[2] = gyro_z
        vx, vy, wz = twist.tolist()
        self.twist = twist if measured is None else self._forward(measured)
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


class Encoders:
    """Quadrature wheel encoders: the wheels' angles counted in steps of 2 pi / encoder_counts_per_rev, speeds from
    count differences, scaled by (1 + scale_error) (the odometry's wheel radius is off by that fraction). With
    ``wheel_noise_density_radps_rthz`` N > 0, each increment adds white noise of standard deviation N / sqrt(dt) to
    every wheel's speed (drawn from ``rng``, the odometry's own stream) before it is counted.

    ``increment(w_mean, dt)`` -> the wheels' mean speeds over dt as the counts show them (the distance the
    odometry integrates is exact to one count); ``speed()`` -> the speeds over the last ``window_s`` (at least one
    block), what a firmware reports as the wheel speeds. With ``encoder_counts_per_rev = 0`` both are exact.
    """

    def __init__(self, model: OdometryModel, n: int = 4, window_s: float = 0.01,
                 rng: np.random.Generator | None = None):
        self.model = model
        self.noise_density = model.wheel_noise_density_radps_rthz
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.last_noise = np.zeros(n)
        self.quantum = 2 * math.pi / model.encoder_counts_per_rev if model.encoder_counts_per_rev else 0.0
        self.scale = 1.0 + model.scale_error
        self.window_s = window_s
        self.angle = np.zeros(n)
        self.count = np.zeros(n)
        self.t = 0.0
        self.last_dt = 0.0                 # the last increment's dt [s]
        self._hist: deque[tuple[float, np.ndarray]] = deque([(0.0, self.count.copy())])

    @property
    def exact(self) -> bool:
        return self.quantum == 0.0

    def increment(self, w_mean, dt: float) -> np.ndarray:
        w_mean = np.asarray(w_mean, float)
        self.last_dt = dt
        if self.noise_density > 0:
            self.last_noise = self.rng.standard_normal(len(self.angle)) * (self.noise_density / math.sqrt(dt))
            w_mean = w_mean + self.last_noise
        if self.exact:
            return w_mean * self.scale if self.scale != 1.0 else w_mean
        self.angle += w_mean * dt
        c = np.floor(self.angle / self.quantum)
        dc, self.count = c - self.count, c
        self.t += dt
        h = self._hist
        h.append((self.t, c))
        while len(h) > 2 and h[1][0] <= self.t - self.window_s + 1e-12:
            h.popleft()
        return dc * (self.quantum / dt) * self.scale

    def speed(self, w_now) -> np.ndarray:
        """The reported wheel speeds: exact encoders report the current speeds ``w_now``."""
        if self.exact:
            w = np.asarray(w_now, float)
            if self.noise_density > 0:
                w = w + self.last_noise
            return w * self.scale if self.scale != 1.0 else w
        (t0, c0), (t1, c1) = self._hist[0], self._hist[-1]
        return (c1 - c0) * (self.quantum / max(t1 - t0, 1e-9)) * self.scale

    @property
    def speed_interval_s(self) -> float:
        """The interval [s] ``speed()`` averages over now: the count window, or for exact encoders the last
        increment's (whose noise it carries); 0 before the first increment."""
        if self.exact:
            return self.last_dt
        return self._hist[-1][0] - self._hist[0][0]


class Gyro:
    """The yaw-rate gyro: mean true rate over dt + bias + white noise of density N (std N / sqrt(dt)); the bias is
    gyro_bias_radps plus a draw made once, uniform in [-gyro_bias_max_radps, gyro_bias_max_radps], from its own
    stream."""

    def __init__(self, model: ImuModel, rng_noise: np.random.Generator, rng_bias: np.random.Generator):
        self.model = model
        self.rng = rng_noise
        self.bias = (float(rng_bias.uniform(-model.gyro_bias_max_radps, model.gyro_bias_max_radps))
                     if model.gyro_bias_max_radps > 0 else 0.0)
        if model.gyro_bias_radps:
            self.bias += model.gyro_bias_radps
        self.last_noise = 0.0
        self.last_dt = 0.0                 # the averaging interval of the last reading [s]; 0 before the first

    def measure(self, rate_mean: float, dt: float) -> float:
        self.last_dt = dt
        if self.model.gyro_noise_density_radps_rthz > 0:
            self.last_noise = float(self.rng.standard_normal()) * self.model.gyro_noise_density_radps_rthz / math.sqrt(dt)
        elif self.bias == 0.0:
            return rate_mean
        return rate_mean + self.bias + self.last_noise
