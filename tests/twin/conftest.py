"""Calibration drives recorded once per test session (the simulator runs ~10-20x real time)."""
import pytest

from bigcbf.params.robot import RobotProfile

#: The issue's recovery profile: latency 0.08 s, jitter 0.02 s, gains 0.9/0.85/0.95, bias 0.02 m/s, residual noise.
PROFILE = RobotProfile(latency_s=0.08, latency_jitter_s=0.02, gain=((0.9, 0.0, 0.0), (0.0, 0.85, 0.0), (0.0, 0.0, 0.95)),
                       bias=(0.02, 0.0, 0.0), residual_max=(0.03, 0.03, 0.05))


@pytest.fixture(scope="session")
def profile():
    return PROFILE


@pytest.fixture(scope="session")
def profile_drive(tmp_path_factory):
    from twin.record import record_calibration
    path = tmp_path_factory.mktemp("drives") / "profile.mcap"
    summary = record_calibration(PROFILE, path, seed=0, duration_s=80.0)
    return path, summary


@pytest.fixture(scope="session")
def ideal_drive(tmp_path_factory):
    """The same program on the ideal profile: the model's own response (its wheels, rollers and odometry)."""
    from twin.record import record_calibration
    path = tmp_path_factory.mktemp("drives") / "ideal.mcap"
    record_calibration(RobotProfile(), path, seed=0, duration_s=60.0)
    return path


#: Random profiles with wheel limits for the recovery tests: twin.record.random_profile with this seed, the first
#: LIMITED_COUNT draws (drawn once, not chosen).
LIMITED_SEED, LIMITED_COUNT = 7, 2


@pytest.fixture(scope="session")
def limited_drives(tmp_path_factory):
    """[(profile, calibration, reference calibration)]: each random profile's calibration drive, and the same drive
    on a reference robot with the same wheel limits and nothing else (the model's own response behind them)."""
    import numpy as np
    from twin.calibrate import calibrate_log
    from twin.record import random_profile, record_calibration
    rng = np.random.default_rng(LIMITED_SEED)
    d = tmp_path_factory.mktemp("limited")
    out = []
    for i in range(LIMITED_COUNT):
        prof = random_profile(rng)
        record_calibration(prof, d / f"p{i}.mcap", seed=LIMITED_SEED + 1 + i, duration_s=80.0)
        ref = RobotProfile(wheel_speed_max_mps=prof.wheel_speed_max_mps, wheel_accel_max_mps2=prof.wheel_accel_max_mps2)
        record_calibration(ref, d / f"r{i}.mcap", seed=LIMITED_SEED + 1 + i, duration_s=80.0)
        out.append((prof, calibrate_log(d / f"p{i}.mcap"), calibrate_log(d / f"r{i}.mcap")))
    return out
