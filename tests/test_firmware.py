"""The hardware-imperfection layer: latency, gain, bias, residual, and in the physics."""
import numpy as np
import pytest

from bigcbf.params.robot import RobotProfile
from bigcbf.sim.firmware import ImperfectionLayer
from bigcbf.sim.scene import SceneSpec
from bigcbf.sim.world import SimWorld


def test_layer_applies_after_latency_in_order():
    layer = ImperfectionLayer(RobotProfile(latency_s=0.1), np.random.default_rng(0))
    layer.submit(0.0, (0.5, 0, 0))
    assert np.all(layer.at(0.05) == 0)
    np.testing.assert_allclose(layer.at(0.1), (0.5, 0, 0))
    layer.submit(0.2, (0.0, 0.3, 0))
    np.testing.assert_allclose(layer.at(0.25), (0.5, 0, 0))
    np.testing.assert_allclose(layer.at(0.3), (0.0, 0.3, 0))


def test_jitter_never_reorders_commands():
    layer = ImperfectionLayer(RobotProfile(latency_s=0.05, latency_jitter_s=0.2), np.random.default_rng(3))
    times = [layer.submit(0.05 * k, (k, 0, 0)) for k in range(200)]
    assert np.all(np.diff(times) >= 0)
    delays = np.array(times) - 0.05 * np.arange(200)
    assert delays.min() >= 0.05 - 1e-12


def test_gain_bias_residual_eq1():
    p = RobotProfile(gain=((0.9, 0.1, 0), (0, 0.8, 0), (0, 0, 1.1)), bias=(0.02, -0.01, 0.0),
                     residual_max=(0.03, 0.03, 0.0))
    layer = ImperfectionLayer(p, np.random.default_rng(0))
    u = np.array([0.5, 0.2, 0.4])
    # A u + d = (0.45 + 0.02 + 0.02, 0.16 - 0.01, 0.44) = (0.49, 0.15, 0.44), plus r within +-0.03
    samples = np.array([layer.executed_twist(0.1 * k, u) for k in range(500)])
    mean = np.array([0.49, 0.15, 0.44])
    assert np.all(np.abs(samples - mean) <= np.array([0.03, 0.03, 0.0]) + 1e-12)
    assert np.all(np.abs(samples.mean(0) - mean) < 0.005)
    assert samples[:, 0].std() > 0.01


def _response(profile, until=1.0):
    world = SimWorld(SceneSpec(), profile=profile)
    vs = []
    while world.t < until:
        if round(world.t / world.dt) % 25 == 0:       # 20 Hz commands
            world.command((0.5, 0.0, 0.0))
        world.step(1)
        vs.append((world.t, world.true_state().vx))
    return np.array(vs)


def _crossing(resp, level):
    return resp[np.argmax(resp[:, 1] >= level), 0]


def test_injected_latency_shows_as_delay():
    base = _response(RobotProfile())
    late = _response(RobotProfile(latency_s=0.15))
    delay = _crossing(late, 0.25) - _crossing(base, 0.25)
    assert delay == pytest.approx(0.15, abs=0.01)


def test_injected_gain_scales_velocity():
    ideal = _response(RobotProfile(), until=1.5)
    slow = _response(RobotProfile(gain=((0.8, 0, 0), (0, 1, 0), (0, 0, 1))), until=1.5)
    ratio = slow[-100:, 1].mean() / ideal[-100:, 1].mean()
    assert ratio == pytest.approx(0.8, abs=0.02)


def test_low_floor_friction_makes_the_robot_slip():
    """A 0.05 friction floor cannot transmit a hard start; the robot lags an ideal floor."""
    ideal = _response(RobotProfile(), until=0.5)
    icy = _response(RobotProfile(floor_friction=0.05), until=0.5)
    assert icy[-1, 1] < 0.8 * ideal[-1, 1]


def test_wheel_limiter_saturates_all_wheels_together_by_hand():
    from bigcbf.sim.firmware import WheelLimiter, rim_matrix
    # lever 0.1645 m: the twist (0.6, 0, 1.0) asks rim speeds (0.4355, 0.7645, 0.4355, 0.7645) m/s; a 0.4 m/s
    # limit scales the whole twist by 0.4 / 0.7645 (direction kept)
    lim = WheelLimiter(RobotProfile(wheel_speed_max_mps=0.4), 0.1645)
    np.testing.assert_allclose(np.abs(rim_matrix(0.1645) @ [0.6, 0.0, 1.0]), [0.4355, 0.7645, 0.4355, 0.7645])
    np.testing.assert_allclose(lim.saturate([0.6, 0.0, 1.0]), np.array([0.6, 0.0, 1.0]) * 0.4 / 0.7645)
    np.testing.assert_allclose(lim.saturate([0.3, 0.05, 0.2]), [0.3, 0.05, 0.2])        # within the limit
    # a differential drive's geometry (half track 0.08 m): pure spin 6 rad/s asks 0.48 m/s -> 5 rad/s at 0.4
    dd = WheelLimiter(RobotProfile(wheel_speed_max_mps=0.4, wheel_yaw_lever_m=0.08), 0.1645)
    np.testing.assert_allclose(dd.saturate([0.0, 0.0, 6.0]), [0.0, 0.0, 5.0])


def test_wheel_limiter_acceleration_by_hand():
    from bigcbf.sim.firmware import WheelLimiter
    # 2 m/s^2 on the rim, updates every 10 ms from rest toward vx = 1 m/s (rim 1 m/s on every wheel): 0.02 m/s
    # per update, 0.2 m/s after 0.1 s; toward (0.5, 0, 1.0) the fastest wheel (0.6645 m/s) leads: the twist
    # moves 0.02 / 0.6645 of the way per update
    lim = WheelLimiter(RobotProfile(wheel_accel_max_mps2=2.0), 0.1645)
    for k in range(11):
        out = lim.update(0.01 * k, [1.0, 0.0, 0.0])
    np.testing.assert_allclose(out, [0.2, 0.0, 0.0], atol=1e-12)
    lim = WheelLimiter(RobotProfile(wheel_accel_max_mps2=2.0), 0.1645)
    lim.update(0.0, [0.5, 0.0, 1.0])
    np.testing.assert_allclose(lim.update(0.01, [0.5, 0.0, 1.0]), np.array([0.5, 0.0, 1.0]) * 0.02 / 0.6645)


def test_wheel_limiter_block_means_do_not_depend_on_where_a_command_falls_in_a_block():
    """A step to vx = 0.5 m/s at 2 m/s^2 (rim) from rest, arriving at 0.1 s + delta, with updates on a 10 ms block grid
    cut at the arrival (as SimWorld.step cuts its blocks): the held block means integrate to the continuous ramp's
    integral, worked out by hand: the ramp takes tau = 0.25 s, so over [0, 1] s the output's integral is
    0.5 (1 - 0.1 - delta - tau / 2) m; the old limiter (the budget of the time before the command, applied to it)
    read up to a block early."""
    from bigcbf.sim.firmware import WheelLimiter
    for delta in (0.0, 0.002, 0.005, 0.008):
        t_a = 0.1 + delta
        grid = np.unique(np.round(np.r_[np.arange(0.0, 1.0, 0.01), t_a], 9))
        lim = WheelLimiter(RobotProfile(wheel_accel_max_mps2=2.0), 0.1645)
        area = 0.0
        for t0, t1 in zip(grid, np.r_[grid[1:], 1.0]):
            target = [0.5, 0.0, 0.0] if t0 >= t_a - 1e-12 else [0.0, 0.0, 0.0]
            area += lim.update(t0, target, t1 - t0)[0] * (t1 - t0)
        assert area == pytest.approx(0.5 * (1.0 - t_a - 0.25 / 2), abs=1e-12), delta


def test_default_profile_has_no_limiter_and_limits_show_in_the_physics():
    assert ImperfectionLayer(RobotProfile(), np.random.default_rng(0)).limiter is None
    world = SimWorld(SceneSpec(), profile=RobotProfile(wheel_speed_max_mps=0.3))
    for k in range(60):
        if k % 5 == 0:
            world.command((0.8, 0.0, 0.0))
        world.step(5)
    assert world.odom().vx == pytest.approx(0.3 * 0.991, abs=0.01)      # the model's effective vx scale 0.991
