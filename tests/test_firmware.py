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
