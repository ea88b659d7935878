"""Covariances of the robot's /odom and /imu messages, derived from the robot profile's sensor models, as a ROS
driver fills them from its sensors' data sheets (``bigcbf.params.robot``: ``[odometry]``, ``[imu]``).

What the robot knows, and therefore what goes into a covariance, is the *random* part of its sensors' errors:

- wheel encoders: the quantization of the counts (``encoder_counts_per_rev``, q = 2 pi / counts) and the white
  noise on each wheel's measured speed (``wheel_noise_density_radps_rthz``, N_w);
- gyro (yaw rate; the odometry's heading): the white rate noise (``gyro_noise_density_radps_rthz``, N_g) and the
  residual bias left after the start-up calibration, drawn once per episode uniform in [-b, b]
  (``gyro_bias_max_radps``): the robot knows its distribution, not its value.

Systematic errors the robot does not know are *not* in any covariance (a driver cannot publish what it does not
know; they show as a bias of the estimates against /ground_truth/odom): the odometry's wheel-radius error
(``scale_error``) and a fixed gyro bias (``gyro_bias_radps``, the fault that makes the heading drift).

Formulas (each derived in the docstring of the function that computes it):

- wheel-speed variance at averaging interval T, :func:`wheel_speed_variance`: N_w^2 / T + q^2 / (6 T^2);
- yaw-rate variance at averaging interval T, :func:`gyro_rate_variance`: N_g^2 / T + b^2 / 3;
- odometry twist (vx, vy, wz), :meth:`SensorNoise.twist_covariance`: the wheel-speed variance through the Mecanum
  forward kinematics for (vx, vy), the gyro's for wz (the odometry's heading and yaw rate come from the gyro);
- odometry pose (x, y, yaw), :class:`DeadReckoning`: the integrated twist noise propagated along the path (a
  random walk; the unknown per-episode bias makes the heading variance grow as t^2).

A profile without noise (``RobotProfile()``) gives zero covariances: the sensors are exact. Note that
sensor_msgs/Imu reads an all-zero matrix as "covariance unknown"; in these logs it means exact.

No MuJoCo here: the kinematics object is duck-typed (``forward(w)``, as ``bigcbf.sim.kinematics.MecanumKinematics``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: indices of (x, y, yaw) in the 6x6 (x, y, z, rot x, rot y, rot z) layout of geometry_msgs' covariances
PLANAR = (0, 1, 5)


def wheel_speed_variance(counts_per_rev: int, noise_density: float, interval_s: float) -> float:
    """Variance [rad^2/s^2] of one wheel's measured speed averaged over ``interval_s`` = T.

    The firmware's speed is a count difference over T: w_hat = (c1 - c0) q / T with c = floor(angle / q),
    q = 2 pi / counts_per_rev. Its error is (f0 - f1) q / T with f the fractional parts (in counts) of the wheel
    angle at both ends. Over the speeds a wheel runs at, f0 and f1 are independent and uniform on [0, 1) (for a
    given speed, with delta the fractional part of w T / q, the variance is delta (1 - delta) counts^2, whose mean
    over delta is 1/2 - 1/3 = 1/6), so the difference has variance 2 x 1/12 = 1/6 count^2:
    q^2 / (6 T^2). The white noise of density N on the speed adds N^2 / T (its angle random-walks with variance
    N^2 T over T). Together::

        sigma_w^2(T) = N^2 / T + q^2 / (6 T^2)

    counts_per_rev = 0 (exact angles) drops the second term; T <= 0 (no reading yet: the odometry reports its
    reset value, the robot at rest) gives 0.
    """
    if interval_s <= 0:
        return 0.0
    var = noise_density ** 2 / interval_s
    if counts_per_rev:
        q = 2.0 * math.pi / counts_per_rev
        var += q * q / (6.0 * interval_s ** 2)
    return var


def gyro_rate_variance(noise_density: float, bias_max: float, interval_s: float) -> float:
    """Variance [rad^2/s^2] of the yaw rate read by the gyro, averaged over ``interval_s`` = T.

    White rate noise of density N averaged over T has variance N^2 / T. The residual bias is one draw per episode,
    uniform on [-b, b]: variance (2 b)^2 / 12 = b^2 / 3 (unknown to the robot, so it is part of every reading's
    error; it does not average out). Together::

        sigma_g^2(T) = N^2 / T + b^2 / 3

    T <= 0 (no reading averaged yet) leaves only the bias: b^2 / 3.
    """
    var = bias_max ** 2 / 3.0
    if interval_s > 0:
        var += noise_density ** 2 / interval_s
    return var


@dataclass(frozen=True)
class SensorNoise:
    """The random part of the robot's odometry and gyro errors (module docstring), with the base's kinematics."""

    encoder_counts_per_rev: int = 0
    wheel_noise_density: float = 0.0      # [rad/s/sqrt(Hz)]
    gyro_noise_density: float = 0.0       # [rad/s/sqrt(Hz)]
    gyro_bias_max: float = 0.0            # [rad/s]
    forward_matrix: tuple = ((0.0,) * 4,) * 3   # 3x4: body twist (vx, vy, wz) per wheel speed [rad/s]

    @classmethod
    def from_profile(cls, profile, kinematics) -> "SensorNoise":
        """From a RobotProfile's ``odometry`` and ``imu`` models and the firmware's Mecanum kinematics; the forward
        kinematics matrix is read off ``kinematics.forward`` column by column (it is linear)."""
        F = np.column_stack([np.asarray(kinematics.forward(e), float) for e in np.eye(4)])
        o, g = profile.odometry, profile.imu
        return cls(int(o.encoder_counts_per_rev), float(o.wheel_noise_density_radps_rthz),
                   float(g.gyro_noise_density_radps_rthz), float(g.gyro_bias_max_radps),
                   tuple(tuple(float(x) for x in row) for row in F))

    @property
    def F(self) -> np.ndarray:
        return np.asarray(self.forward_matrix, float)

    def wheel_speed_variance(self, interval_s: float) -> float:
        return wheel_speed_variance(self.encoder_counts_per_rev, self.wheel_noise_density, interval_s)

    def gyro_rate_variance(self, interval_s: float) -> float:
        return gyro_rate_variance(self.gyro_noise_density, self.gyro_bias_max, interval_s)

    def twist_covariance(self, wheel_interval_s: float, gyro_interval_s: float) -> np.ndarray:
        """6x6 covariance of the odometry's body twist (nav_msgs/Odometry ``twist.covariance``, base_link frame).

        (vx, vy) = F_xy w (the forward kinematics' first two rows, ``bigcbf.sim.kinematics``) of wheel speeds with
        independent errors of variance sigma_w^2(T_w) (:func:`wheel_speed_variance`): Sigma_xy = sigma_w^2 F_xy
        F_xy^T. For the X3's kinematics F_xy's rows are orthogonal, so that is diag(k_x^2, k_y^2) r^2 / 4
        sigma_w^2 (r the rolling radius, k the effective scales). The yaw rate is the gyro's (``WheelOdometry``
        takes it from the IMU), independent of the wheels: sigma_g^2(T_g) (:func:`gyro_rate_variance`), no cross
        terms; a gyro interval <= 0 means the odometry has not integrated yet (it reports its reset zeros, exact).
        z, roll and pitch rates are zero by the planar model (base_link on a flat floor): variance 0.
        """
        F = self.F[:2]
        c = np.zeros((6, 6))
        c[:2, :2] = self.wheel_speed_variance(wheel_interval_s) * (F @ F.T)
        c[5, 5] = self.gyro_rate_variance(gyro_interval_s) if gyro_interval_s > 0 else 0.0
        return c

    def imu_covariances(self, gyro_interval_s: float) -> dict[str, list[float]]:
        """The three 3x3 row-major covariances of a sensor_msgs/Imu as ``SimWorld.imu()`` fills it.

        - orientation: none. The robot's IMU model is a gyro (``[imu]``); no orientation filter runs on it, so, as
          REP 145 asks of a sensor without an orientation estimate, element 0 is -1 and the orientation is to be
          ignored (:func:`bigcbf.logio.convert.imu_msg` writes the identity quaternion; the heading estimate is
          /odom's, the truth is /ground_truth/odom's).
        - angular velocity: z is the modelled gyro, sigma_g^2(T) (:func:`gyro_rate_variance`) at the reading's
          averaging interval T; x and y are the simulator's exact rates (the profile models no roll/pitch
          gyro): 0.
        - linear acceleration: the simulator's exact specific force (the profile models no accelerometer): 0.
        """
        ang = [0.0] * 9
        ang[8] = self.gyro_rate_variance(gyro_interval_s)
        return {"orientation": [-1.0] + [0.0] * 8, "angular_velocity": ang, "linear_acceleration": [0.0] * 9}


class DeadReckoning:
    """The odometry pose's covariance, propagated along the odometry it is fed (the dead-reckoning random walk).

    The odometry starts exact (the odom frame is the robot's start) and integrates, per interval dt, the wheels'
    body displacement d = F_xy (wheel angle change) rotated by the mid heading, and the gyro's heading change
    (``bigcbf.sim.firmware.WheelOdometry``). Error state e = (e_x, e_y, e_theta, b) with b the unknown residual
    gyro bias (a random constant: P_0 = diag(0, 0, 0, b_max^2 / 3)). Over an interval with world displacement
    (dx, dy) (from the fed poses), first order in the errors::

        e_theta' = e_theta + b dt + n_g                      n_g ~ N(0, N_g^2 dt)     (white rate noise, integrated)
        e_p'     = e_p + J (e_theta + b dt / 2 + n_g / 2) + R(theta_mid) n_d,  J = (-dy, dx)
                                                             n_d ~ N(0, N_w^2 dt F_xy F_xy^T)   (wheel white noise)
        P' = A P A^T + G G^T N_g^2 dt + [R Sigma_d R^T on (x, y)]
        A = [[1, 0, -dy, -dy dt/2], [0, 1, dx, dx dt/2], [0, 0, 1, dt], [0, 0, 0, 1]],  G = (-dy/2, dx/2, 1, 0)

    The midpoint term makes a straight run exact: driving at v along x with only the bias, e_y = v b t^2 / 2, so
    var(y) = v^2 t^4 / 4 b_max^2 / 3, var(yaw) = t^2 b_max^2 / 3 at any step size. Encoder quantization does not
    accumulate (the odometry integrates count differences, which telescope: the position is exact to one count,
    r q = 0.2 mm on the X3) and is left out of the pose.

    ``update(t, state)`` takes the odometry's RobotState at time t and returns the 6x6 pose covariance
    (nav_msgs/Odometry ``pose.covariance``, odom frame); z, roll, pitch are 0 by the planar model.
    """

    def __init__(self, noise: SensorNoise):
        self.noise = noise
        self.P = np.zeros((4, 4))
        self.P[3, 3] = noise.gyro_bias_max ** 2 / 3.0
        F = noise.F[:2]
        self._FFt = F @ F.T
        self._last: tuple[float, float, float, float] | None = None

    def update(self, t: float, state) -> np.ndarray:
        cur = (float(t), float(state.px), float(state.py), float(state.theta))
        last, self._last = self._last, cur
        if last is not None and cur[0] > last[0]:
            self._propagate(cur[0] - last[0], cur[1] - last[1], cur[2] - last[2], last[3], cur[3])
        return self.pose_covariance()

    def _propagate(self, dt: float, dx: float, dy: float, th0: float, th1: float) -> None:
        n = self.noise
        A = np.eye(4)
        A[0, 2], A[1, 2] = -dy, dx
        A[0, 3], A[1, 3] = -dy * dt / 2, dx * dt / 2
        A[2, 3] = dt
        G = np.array([-dy / 2, dx / 2, 1.0, 0.0])
        P = A @ self.P @ A.T + np.outer(G, G) * (n.gyro_noise_density ** 2 * dt)
        if n.wheel_noise_density > 0:
            mid = th0 + 0.5 * math.atan2(math.sin(th1 - th0), math.cos(th1 - th0))
            c, s = math.cos(mid), math.sin(mid)
            R = np.array([[c, -s], [s, c]])
            P[:2, :2] += R @ self._FFt @ R.T * (n.wheel_noise_density ** 2 * dt)
        self.P = 0.5 * (P + P.T)

    def pose_covariance(self) -> np.ndarray:
        c = np.zeros((6, 6))
        c[np.ix_(PLANAR, PLANAR)] = self.P[:3, :3]
        return c


class WorldCovariances:
    """The covariances of a simulated robot's /odom and /imu messages, for the loggers (``bigcbf run --log``,
    ``bigcbf record calibration``). ``world``: duck-typed as ``bigcbf.sim.world.SimWorld`` (``profile``, ``kin``,
    ``reading_intervals()``).

    ``odom(t, state)`` -> (pose 6x6, twist 6x6) of the odometry state at t: the pose's from :class:`DeadReckoning`
    (feed every odometry message, in order), the twist's at the world's current reading intervals, or at
    ``averaged_over_s`` for a twist averaged over that time from the odometry's poses (the wheels' counts and the
    gyro's heading both span it). ``imu()`` -> the covariances of ``world.imu()`` now."""

    def __init__(self, world):
        self.world = world
        self.noise = SensorNoise.from_profile(world.profile, world.kin)
        self.dead_reckoning = DeadReckoning(self.noise)

    def odom(self, t: float, state, averaged_over_s: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        pose = self.dead_reckoning.update(t, state)
        tw, tg = (self.world.reading_intervals() if averaged_over_s is None
                  else (averaged_over_s, averaged_over_s))
        return pose, self.noise.twist_covariance(tw, tg)

    def imu(self) -> dict[str, list[float]]:
        return self.noise.imu_covariances(self.world.reading_intervals()[1])


__all__ = ["SensorNoise", "DeadReckoning", "WorldCovariances", "wheel_speed_variance", "gyro_rate_variance",
           "PLANAR"]
