"""The /odom and /imu covariances of the logs (bigcbf.logio.covariance): the formulas against values worked out by
hand, against Monte Carlo runs of the simulator's own sensor models (bigcbf.sim.firmware: Encoders, Gyro,
WheelOdometry), and a recorded MCAP read back with rosbags carrying the covariances of its robot profile."""
import math
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from bigcbf.logio import convert
from bigcbf.logio.covariance import (DeadReckoning, SensorNoise, WorldCovariances, gyro_rate_variance,
                                     wheel_speed_variance)
from bigcbf.params.robot import ImuModel, OdometryModel, RobotProfile
from bigcbf.scenario import load_robot_profile
from bigcbf.sim.firmware import Encoders, Gyro, WheelOdometry
from bigcbf.sim.kinematics import MecanumKinematics
from bigcbf.types import RobotState

KIN = MecanumKinematics()


# --- formulas against hand-computed values -------------------------------------------------------------------------
def test_wheel_speed_variance_by_hand():
    # q = 2 pi / 1320 = 4.759989e-3 rad, q^2 = 2.265749e-5 rad^2; T = 0.02 s: q^2 / (6 T^2) = 2.265749e-5 / 2.4e-3
    assert wheel_speed_variance(1320, 0.0, 0.02) == pytest.approx(9.440623e-3, rel=1e-6)
    # T = 0.01 s: four times that
    assert wheel_speed_variance(1320, 0.0, 0.01) == pytest.approx(3.776249e-2, rel=1e-6)
    # + white noise 0.05 rad/s/sqrt(Hz) over 0.02 s: 0.0025 / 0.02 = 0.125
    assert wheel_speed_variance(1320, 0.05, 0.02) == pytest.approx(0.125 + 9.440623e-3, rel=1e-6)
    assert wheel_speed_variance(0, 0.05, 0.02) == pytest.approx(0.125)          # exact angles: noise only
    assert wheel_speed_variance(1320, 0.05, 0.0) == 0.0                          # no reading yet


def test_gyro_rate_variance_by_hand():
    # the X3's MPU-9250 over a 10 ms block: (1.75e-4)^2 / 0.01 = 3.0625e-6; bias U(+-8.7e-4): 7.569e-7 / 3 = 2.523e-7
    assert gyro_rate_variance(1.75e-4, 8.7e-4, 0.01) == pytest.approx(3.3148e-6, rel=1e-12)
    assert gyro_rate_variance(1.75e-4, 8.7e-4, 0.02) == pytest.approx(1.53125e-6 + 2.523e-7, rel=1e-12)
    # x3_hardware's bias bound 1.75e-3 alone (no reading averaged yet): 3.0625e-6 / 3
    assert gyro_rate_variance(1.75e-4, 1.75e-3, 0.0) == pytest.approx(1.0208333e-6, rel=1e-6)


def test_twist_covariance_through_the_mecanum_kinematics_by_hand():
    noise = SensorNoise.from_profile(load_robot_profile("x3_sim"), KIN)
    c = noise.twist_covariance(0.02, 0.02)
    # vx = k_x r / 4 (w1 + w2 + w3 + w4): var = 4 (0.991 * 0.0425 / 4)^2 sigma_w^2 = (0.0421175)^2 / 4 * 9.440623e-3
    assert c[0, 0] == pytest.approx(4.186642e-6, rel=1e-6)
    assert c[1, 1] == pytest.approx(3.945197e-6, rel=1e-6)                 # k_y = 0.962
    assert c[5, 5] == pytest.approx(1.53125e-6 + 2.523e-7, rel=1e-12)     # the gyro's, not the wheels'
    off = c.copy()
    np.fill_diagonal(off, 0.0)
    assert np.abs(off).max() < 1e-12 * c[1, 1]   # the X3's forward rows are orthogonal; gyro independent of wheels
    assert np.all(np.diag(c)[2:5] == 0.0)      # planar: z, roll, pitch rates
    assert np.all(noise.twist_covariance(0.0, 0.0) == 0.0)     # the odometry's reset value (at rest) is exact


def test_scale_error_and_fixed_gyro_bias_are_not_covariances():
    """Systematic errors the robot does not know: the odometry's wheel-radius error and a fixed gyro bias."""
    p = load_robot_profile("x3_sim")
    base = SensorNoise.from_profile(p, KIN)
    biased = SensorNoise.from_profile(p.merged(odometry=OdometryModel(1320, scale_error=0.04),
                                               imu=ImuModel(1.75e-4, 8.7e-4, gyro_bias_radps=0.01)), KIN)
    assert biased == base


def test_zero_noise_profile_gives_zero_covariances():
    noise = SensorNoise.from_profile(RobotProfile(), KIN)
    assert np.all(noise.twist_covariance(0.01, 0.01) == 0.0)
    cov = noise.imu_covariances(0.01)
    assert cov["angular_velocity"] == [0.0] * 9 and cov["linear_acceleration"] == [0.0] * 9
    assert cov["orientation"] == [-1.0] + [0.0] * 8       # REP 145: no orientation estimate, whatever the noise
    dr = DeadReckoning(noise)
    for k in range(50):
        P = dr.update(0.02 * k, RobotState(0.01 * k, 0.002 * k * k, 0.05 * k))
    assert np.all(P == 0.0)


def test_imu_message_without_orientation_estimate_carries_the_identity():
    imu = {"orientation": (0.9, 0.1, 0.2, 0.3), "angular_velocity": (0.0, 0.0, 0.4),
           "linear_acceleration": (0.0, 0.0, 9.81)}
    m = convert.imu_msg(1.0, imu, cov=SensorNoise(gyro_noise_density=1e-3).imu_covariances(0.01))
    assert m["orientation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    assert m["orientation_covariance"][0] == -1.0
    assert m["angular_velocity_covariance"][8] == pytest.approx(1e-4)
    assert convert.imu_msg(1.0, imu)["orientation"]["w"] == 0.9      # no covariances given: as before


def test_dead_reckoning_straight_run_by_hand():
    """Driving at v along x for t: the bias b alone tilts the heading by b t and the path by v b t^2 / 2, at any step
    size: var(yaw) = t^2 b^2/3, var(y) = v^2 t^4 / 4 b^2/3, cov(y, yaw) = v t^3 / 2 b^2/3. The wheels' white noise N
    random-walks x and y: var(x) = 4 (k_x r / 4)^2 N^2 t, var(y) += 4 (k_y r / 4)^2 N^2 t. The gyro's white noise
    N_g: var(yaw) += N_g^2 t and, summing the midpoint weights (K - k - 1/2)^2 over K steps,
    var(y) += v^2 N_g^2 (t^3/3 - t dt^2/12)."""
    v, t_end, b, N, Ng = 0.4, 6.0, 1e-3, 0.02, 2e-3
    for dt in (0.05, 0.2):
        dr = DeadReckoning(SensorNoise(0, N, Ng, b, tuple(map(tuple, _F()))))
        K = int(round(t_end / dt))
        for k in range(K + 1):
            P = dr.update(k * dt, RobotState(v * k * dt, 0.0, 0.0))
        b2 = b * b / 3
        assert P[5, 5] == pytest.approx(t_end ** 2 * b2 + Ng ** 2 * t_end, rel=1e-9)
        assert P[1, 1] == pytest.approx(v ** 2 * t_end ** 4 / 4 * b2 + v ** 2 * Ng ** 2 * (t_end ** 3 / 3 - t_end * dt ** 2 / 12)
                                        + (0.962 * 0.0425) ** 2 / 4 * N ** 2 * t_end, rel=1e-9)
        assert P[1, 5] == pytest.approx(v * t_end ** 3 / 2 * b2 + v * Ng ** 2 * t_end ** 2 / 2, rel=1e-9)
        assert P[0, 0] == pytest.approx((0.991 * 0.0425) ** 2 / 4 * N ** 2 * t_end, rel=1e-9)
        assert P[0, 1] == pytest.approx(0.0, abs=1e-15)


def _F():
    return np.column_stack([KIN.forward(e) for e in np.eye(4)])


# --- formulas against the simulator's sensor models (Monte Carlo) -------------------------------------------------
def test_wheel_speed_variance_matches_the_encoder_model():
    """bigcbf.sim.firmware.Encoders read over one 10 ms window at speeds of 5-15 rad/s, after a first block at a
    random speed (a random count phase at the window's start, as after any drive): the error's variance is
    q^2 / (6 T^2) (+ N^2 / T with wheel noise)."""
    rng = np.random.default_rng(0)
    for N in (0.0, 0.05):
        model = OdometryModel(encoder_counts_per_rev=1320, wheel_noise_density_radps_rthz=N)
        err = []
        for i in range(3000):
            w = rng.uniform(5.0, 15.0, 4)
            enc = Encoders(model, rng=np.random.default_rng(i))
            enc.increment(rng.uniform(0.0, 50.0, 4), 0.01)
            for _ in range(2):
                enc.increment(w, 0.01)
            assert enc.speed_interval_s == pytest.approx(0.01)
            err.append(enc.speed(w) - w)
        var = np.var(np.concatenate(err))
        assert var == pytest.approx(wheel_speed_variance(1320, N, 0.01), rel=0.06), N


def test_gyro_rate_variance_matches_the_gyro_model():
    model = ImuModel(gyro_noise_density_radps_rthz=1.75e-4, gyro_bias_max_radps=8.7e-4)
    err = []
    for i in range(4000):
        g = Gyro(model, np.random.default_rng(i), np.random.default_rng(10_000 + i))
        err.append(g.measure(0.3, 0.01) - 0.3)
    assert np.var(err) == pytest.approx(gyro_rate_variance(1.75e-4, 8.7e-4, 0.01), rel=0.06)


def test_dead_reckoning_matches_the_odometry_model():
    """WheelOdometry fed by noisy Encoders and Gyro on a curved run (vx 0.3, vy 0.1, wz 0.4 for 2 s), 300 seeds:
    the pose errors' sample covariance against DeadReckoning fed the odometry at 20 Hz."""
    u, dt, n_steps, seeds = np.array([0.3, 0.1, 0.4]), 0.01, 200, 300
    odo_model = OdometryModel(encoder_counts_per_rev=1320, wheel_noise_density_radps_rthz=0.05)
    imu_model = ImuModel(gyro_noise_density_radps_rthz=0.01, gyro_bias_max_radps=0.01)
    w = KIN.jacobian @ (u / np.asarray(KIN.effective_scale))        # wheel speeds whose forward twist is u
    ref = WheelOdometry(KIN)
    dr = DeadReckoning(SensorNoise.from_profile(RobotProfile(odometry=odo_model, imu=imu_model), KIN))
    for k in range(n_steps + 1):
        if k % 5 == 0:
            P = dr.update(k * dt, ref.state())
        if k < n_steps:
            ref.update(w, dt, u[2])
    errs = []
    for i in range(seeds):
        enc = Encoders(odo_model, rng=np.random.default_rng(i))
        gyro = Gyro(imu_model, np.random.default_rng(50_000 + i), np.random.default_rng(90_000 + i))
        odo = WheelOdometry(KIN)
        for _ in range(n_steps):
            odo.update(enc.increment(w, dt), dt, gyro.measure(u[2], dt))
        errs.append((odo.x - ref.x, odo.y - ref.y, math.remainder(odo.theta - ref.theta, 2 * math.pi)))
    S = np.cov(np.array(errs).T)
    Pp = P[np.ix_((0, 1, 5), (0, 1, 5))]
    assert np.diag(S) == pytest.approx(np.diag(Pp), rel=0.15)      # measured: within 2 %
    corr = lambda C: C / np.sqrt(np.outer(np.diag(C), np.diag(C)))
    assert np.abs(corr(S) - corr(Pp)).max() < 0.06                 # measured: 0.016


# --- a recorded MCAP, read back --------------------------------------------------------------------------------------
def _read(path: Path, topics):
    out = {t: [] for t in topics}
    with AnyReader([path]) as reader:
        for con, t, raw in reader.messages():
            if con.topic in out:
                out[con.topic].append((t * 1e-9, reader.deserialize(raw, con.msgtype)))
    return out


@pytest.mark.parametrize("name", ["x3_hardware", "ideal"])
def test_recorded_calibration_drive_carries_the_profiles_covariances(tmp_path, name):
    """``bigcbf record calibration`` (twin.record) for 3 s, read back with rosbags: /odom's twist covariance is the
    profile's at the 20 ms odometry period, its pose covariance DeadReckoning's along the logged odometry (the yaw
    variance growing from 0), /imu's yaw-rate variance the gyro's at a block's interval (2-10 ms), no orientation
    (REP 145), /ground_truth/odom exact; the ideal profile's are all zero."""
    from twin.record import record_calibration
    profile = RobotProfile() if name == "ideal" else load_robot_profile(name)
    path = tmp_path / "drive.mcap"
    record_calibration(profile, path, seed=1, duration_s=3.0)
    msgs = _read(path, ("/odom", "/imu", "/ground_truth/odom"))
    noise = SensorNoise.from_profile(profile, KIN)
    dr = DeadReckoning(noise)
    assert len(msgs["/odom"]) == 150
    yaw_var = []
    for k, (t, m) in enumerate(msgs["/odom"]):
        twist = np.array(m.twist.covariance).reshape(6, 6)
        expect = noise.twist_covariance(0.02, 0.02) if k else np.zeros((6, 6))   # the first: at rest, exact
        assert twist == pytest.approx(expect, rel=1e-12, abs=0.0)
        pose = np.array(m.pose.covariance).reshape(6, 6)
        assert pose == pytest.approx(dr.update(t, convert.odometry_state(m)), rel=1e-12, abs=1e-30)
        yaw_var.append(pose[5, 5])
    allowed = [gyro_rate_variance(noise.gyro_noise_density, noise.gyro_bias_max, 0.002 * j) for j in range(1, 6)]
    first = msgs["/imu"].pop(0)[1]                # t = 0: no reading averaged yet, the bias only
    assert first.angular_velocity_covariance[8] == pytest.approx(noise.gyro_bias_max ** 2 / 3, rel=1e-12)
    for _, m in msgs["/imu"]:
        assert m.orientation_covariance[0] == -1.0 and (m.orientation.w, m.orientation.z) == (1.0, 0.0)
        assert min(abs(m.angular_velocity_covariance[8] - a) for a in allowed) <= 1e-12 * allowed[0]
        assert list(m.angular_velocity_covariance[:8]) == [0.0] * 8
        assert list(m.linear_acceleration_covariance) == [0.0] * 9
    for _, m in msgs["/ground_truth/odom"]:
        assert not np.any(m.pose.covariance) and not np.any(m.twist.covariance)
    if name == "ideal":
        assert all(a == 0.0 for a in allowed) and max(yaw_var) == 0.0
        assert not any(np.any(m.twist.covariance) for _, m in msgs["/odom"])
    else:
        # x3_hardware: gyro bias bound 1.75e-3 rad/s; after 3 s the yaw std is at least 3 * 1.75e-3 / sqrt(3)
        assert yaw_var[0] == 0.0 and np.all(np.diff(yaw_var) >= 0)
        assert yaw_var[-1] == pytest.approx(2.98 ** 2 * 1.75e-3 ** 2 / 3 + 1.75e-4 ** 2 * 2.98, rel=1e-9)
        assert msgs["/odom"][1][1].twist.covariance[0] == pytest.approx(4.186642e-6, rel=1e-6)


def test_world_covariances_use_the_readings_intervals():
    class World:                                   # duck-typed SimWorld
        profile, kin = load_robot_profile("x3_sim"), KIN

        def reading_intervals(self):
            return 0.014, 0.004

    wc = WorldCovariances(World())
    _, twist = wc.odom(0.0, RobotState(0.0, 0.0, 0.0))
    assert twist[0, 0] == pytest.approx((0.991 * 0.0425) ** 2 / 4 * wheel_speed_variance(1320, 0.0, 0.014))
    assert twist[5, 5] == pytest.approx(gyro_rate_variance(1.75e-4, 8.7e-4, 0.004))
    assert wc.imu()["angular_velocity"][8] == twist[5, 5]
