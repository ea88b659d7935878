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
