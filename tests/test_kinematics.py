"""Mecanum inverse/forward kinematics against hand-worked values."""
import numpy as np
import pytest

from bigcbf.sim.kinematics import MecanumKinematics

K = MecanumKinematics(half_wheelbase_m=0.08, half_track_m=0.0845, rolling_radius_m=0.04,
                      max_wheel_speed_rad_s=30.0, effective_scale=(1.0, 1.0, 1.0))


def test_inverse_hand_values():
    # vx=0.4: every wheel 0.4/0.04 = 10 rad/s
    np.testing.assert_allclose(K.inverse((0.4, 0, 0)), [10, 10, 10, 10])
    # vy=0.2: fl -5, fr +5, rl +5, rr -5
    np.testing.assert_allclose(K.inverse((0, 0.2, 0)), [-5, 5, 5, -5])
    # wz=1: (lx+ly)/r = 0.1645/0.04 = 4.1125 -> fl -, fr +, rl -, rr +
    np.testing.assert_allclose(K.inverse((0, 0, 1.0)), [-4.1125, 4.1125, -4.1125, 4.1125])


def test_forward_inverts_inverse():
    rng = np.random.default_rng(1)
    for _ in range(20):
        u = rng.uniform([-0.5, -0.5, -1], [0.5, 0.5, 1])
        np.testing.assert_allclose(K.forward(K.inverse(u)), u, atol=1e-12)


def test_wheel_limit_scales_all_wheels_together():
    w = K.inverse((2.0, 0.0, 0.0))           # 50 rad/s wanted, limit 30
    np.testing.assert_allclose(w, [30, 30, 30, 30])
    w = K.inverse((1.0, 0.5, 0.0))           # fl 12.5, fr 37.5 -> scaled by 30/37.5
    np.testing.assert_allclose(w, np.array([12.5, 37.5, 37.5, 12.5]) * 30 / 37.5)
    assert np.max(np.abs(w)) == pytest.approx(30)


def test_effective_scale_is_applied_both_ways():
    k = MecanumKinematics(rolling_radius_m=0.04, effective_scale=(1.0, 0.8, 1.0))
    np.testing.assert_allclose(k.inverse((0, 0.2, 0)), [-6.25, 6.25, 6.25, -6.25])   # 0.2/0.8/0.04
    np.testing.assert_allclose(k.forward(k.inverse((0.1, 0.2, 0.3))), (0.1, 0.2, 0.3), atol=1e-12)
