"""The robot profile from files: the shipped simulated X3, scenario overrides, sensor models, independent noise
streams, and the bench key that follows the profile file."""
import math
from dataclasses import replace

import numpy as np
import pytest

from bigcbf.errors import UserError
from bigcbf.params import RobotProfile, load
from bigcbf.params.perception import X3_LASER_MOUNT
from bigcbf.params.robot import ImuModel, LidarModel, OdometryModel
from bigcbf.scenario import (DEFAULT_ROBOT_PROFILE, load_robot_profile, load_scenario, profile_files,
                             scenario_files)
from bigcbf.sim.firmware import Encoders, Gyro, ImperfectionLayer
from bigcbf.sim.scene import SceneSpec, Wall
from bigcbf.sim.world import SimWorld

BASE = 'name = "x"\ndescription = "d"\ntime_limit_s = 10\n[robot]\nstart = [0, 0, 0]\ngoal = [5, 0]\n'


def test_python_default_is_ideal_and_shipped_x3_is_not():
    assert RobotProfile().is_ideal
    x3 = load_robot_profile(DEFAULT_ROBOT_PROFILE)
    assert not x3.is_ideal
    assert x3.latency_s > 0 and x3.slip_max > 0 and x3.lidar.range_noise_std_m > 0
    assert x3.odometry.encoder_counts_per_rev > 0 and x3.imu.gyro_noise_density_radps_rthz > 0
    assert {"x3_sim", "x3_hardware"} <= set(profile_files())


@pytest.mark.parametrize("name", sorted(scenario_files()))
def test_every_scenario_runs_the_x3_profile_by_default(name):
    sc = load_scenario(name, 0)
    assert sc.robot_profile_base.endswith("x3_sim.toml")
    x3 = load_robot_profile()
    if name == "delay_and_slip":       # harsher execution, the X3's sensors
        assert sc.robot_profile.latency_s > x3.latency_s and sc.robot_profile.slip_max > x3.slip_max
        assert sc.robot_profile.lidar == x3.lidar and sc.robot_profile.imu == x3.imu
    else:
        assert sc.robot_profile == x3


def test_scenario_overrides_merge_key_by_key(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text(BASE + "[robot_profile]\nlatency_s = 0.2\n[robot_profile.lidar]\nrate_hz = 5.0\n")
    p = load_scenario(f, 0).robot_profile
    x3 = load_robot_profile()
    assert p.latency_s == 0.2 and p.lidar.rate_hz == 5.0
    assert p.lidar.n_beams == x3.lidar.n_beams and p.gain == x3.gain and p.imu == x3.imu


def test_scenario_may_name_another_base_profile(tmp_path):
    prof = tmp_path / "ideal.toml"
    prof.write_text("# an ideal robot\n")
    f = tmp_path / "s.toml"
    f.write_text('robot_profile_base = "ideal.toml"\n' + BASE)
    assert load_scenario(f, 0).robot_profile.is_ideal
    f.write_text('robot_profile_base = "x3_hardware"\n' + BASE)
    assert load_scenario(f, 0).robot_profile == load_robot_profile("x3_hardware")


@pytest.mark.parametrize("text, file_is_profile, field, words", [
    ("[lidar]\nbeams = 10\n", True, "lidar.beams", "unknown key"),
    ("[imu]\ngyro_bias_max_radps = -1.0\n", True, "imu.gyro_bias_max_radps", ">= 0"),
    ("[odometry]\nencoder_counts_per_rev = 1.5\n", True, "odometry.encoder_counts_per_rev", "integer"),
    ("slip_max = 2.0\n", True, None, "slip_max"),
])
def test_bad_sensor_tables_name_file_and_field(tmp_path, text, file_is_profile, field, words):
    f = tmp_path / "robot.toml"
    f.write_text(text)
    with pytest.raises(UserError) as err:
        load(RobotProfile, f)
    msg = str(err.value)
    assert str(f) in msg and words in msg
    if field:
        assert f"'{field}'" in msg
    # the same mistake in a base profile a scenario refers to names the profile file
    s = tmp_path / "s.toml"
    s.write_text('robot_profile_base = "robot.toml"\n' + BASE)
    with pytest.raises(UserError, match="robot.toml"):
        load_scenario(s, 0)


def test_scenario_override_errors_name_the_scenario(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text(BASE + "[robot_profile.lidar]\nrate = 5.0\n")
    with pytest.raises(UserError) as err:
        load_scenario(f, 0)
    assert str(f) in str(err.value) and "'robot_profile.lidar.rate'" in str(err.value)
    f.write_text('robot_profile_base = "no_such_robot"\n' + BASE)
    with pytest.raises(UserError, match="robot_profile_base"):
        load_scenario(f, 0)


# --- the models -------------------------------------------------------------------------------------------------

def test_lidar_range_noise_grows_with_range():
    m = LidarModel(range_noise_std_m=0.005, range_noise_frac=0.005)
    assert m.range_sigma(0.0) == 0.005 and m.range_sigma(2.0) == pytest.approx(0.015)
    world = SimWorld(SceneSpec(walls=(Wall(1, -3, 1, 3), Wall(-4.0, -3, -4.0, 3))),
                     profile=RobotProfile(lidar=m), seed=2)
    laser_x = X3_LASER_MOUNT[0]
    errs_near, errs_far = [], []
    for _ in range(20):
        s = world.scan()
        a = s.angles
        front, back = np.abs(a) < 0.2, np.abs(np.abs(a) - np.pi) < 0.2
        errs_near += list(s.ranges[front] - (0.95 - laser_x) / np.cos(a[front]))
        errs_far += list(s.ranges[back] - (3.95 + laser_x) / np.abs(np.cos(a[back])))
    # sigma 0.0095 m at 0.9 m, 0.025 m at 4 m (20 scans x ~23 beams each: the std is within ~10 %)
    assert np.std(errs_near) == pytest.approx(0.005 + 0.005 * 0.92, rel=0.15)
    assert np.std(errs_far) == pytest.approx(0.005 + 0.005 * 4.0, rel=0.15)


def test_encoders_count_and_scale():
    enc = Encoders(OdometryModel(encoder_counts_per_rev=100, scale_error=0.02), n=1)
    q = 2 * math.pi / 100
    out = [enc.increment([3.0], 0.01)[0] for _ in range(1000)]
    # every block's speed is a whole number of counts; over 10 s the distance is exact to one count, times 1.02
    assert np.allclose(np.array(out) * 0.01 / 1.02 / q, np.round(np.array(out) * 0.01 / 1.02 / q))
    assert sum(out) * 0.01 == pytest.approx(1.02 * 30.0, abs=1.02 * q)
    assert enc.speed([3.0])[0] == pytest.approx(1.02 * 3.0, abs=1.02 * q / 0.01)
    exact = Encoders(OdometryModel())
    w = np.array([1.0, 2.0, 3.0, 4.0])
    assert exact.increment(w, 0.01) is w and exact.speed(w) is w


def test_gyro_bias_bounded_and_noise_density():
    g = Gyro(ImuModel(gyro_noise_density_radps_rthz=1e-3, gyro_bias_max_radps=0.01),
             np.random.default_rng(0), np.random.default_rng(1))
    assert abs(g.bias) <= 0.01
    x = np.array([g.measure(0.5, 0.01) for _ in range(4000)]) - 0.5 - g.bias
    assert x.std() == pytest.approx(1e-3 / math.sqrt(0.01), rel=0.05) and abs(x.mean()) < 5e-4
    assert Gyro(ImuModel(), np.random.default_rng(0), np.random.default_rng(0)).measure(0.3, 0.01) == 0.3


def test_lateral_slip_is_across_the_motion_and_bounded():
    layer = ImperfectionLayer(RobotProfile(slip_max=0.05, slip_hold_s=0.1), np.random.default_rng(0),
                              rng_slip=np.random.default_rng(5))
    u = np.array([0.6, 0.0, 0.0])
    v = np.array([layer.executed_twist(0.05 * k, u) for k in range(400)])
    assert np.allclose(v[:, 0], 0.6) and np.all(np.abs(v[:, 1]) <= 0.05 * 0.6 + 1e-12)
    assert v[:, 1].std() > 0.01 and len(np.unique(v[:, 1])) > 100


def _drive(profile, seed=3, t_end=1.5):
    world = SimWorld(SceneSpec(walls=(Wall(2, -3, 2, 3),)), profile=profile, seed=seed)
    scans = []
    while world.t < t_end:
        if round(world.t / world.dt) % 25 == 0:
            world.command((0.4, 0.2, 0.0))
        if round(world.t / world.dt) % 50 == 0:
            scans.append(world.scan().ranges.copy())
        world.step(5)
    return world, np.array(scans)


def test_noise_streams_are_independent():
    """Switching the LiDAR and gyro noise on changes the scans and the odometry, not the execution residuals,
    the jitter, the slip nor the physics."""
    x3 = load_robot_profile()
    quiet = replace(x3, lidar=replace(x3.lidar, range_noise_std_m=0.0, range_noise_frac=0.0),
                    imu=ImuModel())
    a, scans_a = _drive(x3)
    b, scans_b = _drive(quiet)
    assert a.true_state() == b.true_state()
    assert not np.array_equal(scans_a, scans_b)
    assert a.odom() != b.odom()


def test_bench_key_follows_the_base_profile_file(tmp_path):
    """Editing the robot profile a scenario starts from gives new episode keys (and the task carries it)."""
    from bigcbf.bench.runner import BenchConfig, plan

    prof = tmp_path / "robot.toml"
    prof.write_text("latency_s = 0.02\n")
    f = tmp_path / "s.toml"
    f.write_text('robot_profile_base = "robot.toml"\n' + BASE)
    cfg = BenchConfig(out=tmp_path / "out", methods=("cbf-only",), scenarios=(str(f),), seeds=(0,))
    before = plan(cfg)[0][0]
    prof.write_text("latency_s = 0.03\n")
    after = plan(cfg)[0][0]
    assert before.scenario_sha != after.scenario_sha and after.robot_profile_toml == "latency_s = 0.03\n"
    from bigcbf.bench.tasks import _scenario
    assert _scenario(after).robot_profile.latency_s == 0.03
