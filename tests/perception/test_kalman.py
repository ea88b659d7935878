"""The constant-velocity Kalman filter against values worked out by hand."""
import numpy as np
import pytest

from bigcbf.perception.kalman import cv_process_noise, cv_transition, kf_predict, kf_update, mahalanobis2


def test_transition_is_eq2_constant_velocity():
    # eq:obs_prop (2): p_{k+1} = p_k + dt v_k. From p = (1, 2), v = (0.5, -1), dt = 0.2: p = (1.1, 1.8), v unchanged.
    x = np.array([[1.0, 2.0, 0.5, -1.0]])
    x1, _ = kf_predict(x, np.zeros((1, 4, 4)), 0.2, 0.0)
    assert x1[0] == pytest.approx([1.1, 1.8, 0.5, -1.0])
    assert cv_transition(0.2) @ x[0] == pytest.approx([1.1, 1.8, 0.5, -1.0])


def test_process_noise_white_acceleration():
    # q = 2, dt = 0.1: dt^3/3 q = 0.001/3*2 = 6.6667e-4, dt^2/2 q = 0.01, dt q = 0.2
    Q = cv_process_noise(0.1, 2.0)
    assert Q[0, 0] == pytest.approx(2 * 0.001 / 3) and Q[1, 1] == pytest.approx(2 * 0.001 / 3)
    assert Q[0, 2] == pytest.approx(0.01) and Q[2, 0] == pytest.approx(0.01) and Q[1, 3] == pytest.approx(0.01)
    assert Q[2, 2] == pytest.approx(0.2) and Q[0, 1] == 0 and Q[0, 3] == 0


def test_predict_then_update_hand_values():
    # P0 = diag(0.01, 0.01, 1, 1), dt = 0.1, q = 2. Prediction (per axis, by hand):
    #   Ppp = 0.01 + dt^2 * 1 + q dt^3/3 = 0.01 + 0.01 + 0.00066667 = 0.02066667
    #   Ppv = dt * 1 + q dt^2/2        = 0.1 + 0.01                = 0.11
    #   Pvv = 1 + q dt                 = 1.2
    P0 = np.diag([0.01, 0.01, 1.0, 1.0])[None]
    x0 = np.array([[0.0, 0.0, 0.0, 0.0]])
    x1, P1 = kf_predict(x0, P0, 0.1, 2.0)
    Ppp, Ppv, Pvv = 0.01 + 0.01 + 2 * 0.001 / 3, 0.11, 1.2
    assert P1[0, 0, 0] == pytest.approx(Ppp) and P1[0, 0, 2] == pytest.approx(Ppv) and P1[0, 2, 2] == pytest.approx(Pvv)
    assert P1[0, 0, 1] == pytest.approx(0.0) and P1[0, 1, 1] == pytest.approx(Ppp)
    # Update with z = (0.1, 0), R = 0.05^2 = 0.0025. Axis x: S = Ppp + R = 0.02316667,
    #   Kp = Ppp/S = 0.892086, Kv = Ppv/S = 4.748201; x = (0.0892086, 0, 0.4748201, 0)
    #   Ppp' = Ppp (1 - Kp) = 0.00223022, Ppv' = Ppv (1 - Kp) = 0.01187050, Pvv' = Pvv - Ppv^2/S = 0.677698
    x2, P2 = kf_update(x1, P1, np.array([[0.1, 0.0]]), 0.0025)
    S = Ppp + 0.0025
    Kp, Kv = Ppp / S, Ppv / S
    assert Kp == pytest.approx(0.892086, abs=1e-6) and Kv == pytest.approx(4.748201, abs=1e-6)
    assert x2[0] == pytest.approx([0.0892086, 0.0, 0.4748201, 0.0], abs=1e-6)
    assert P2[0, 0, 0] == pytest.approx(0.00223022, abs=1e-8)
    assert P2[0, 0, 2] == pytest.approx(0.01187050, abs=1e-8)
    assert P2[0, 2, 2] == pytest.approx(0.677698, abs=1e-6)
    # y is untouched by an x-only innovation and keeps its own (identical) numbers
    assert P2[0, 1, 1] == pytest.approx(0.00223022, abs=1e-8) and x2[0, 1] == 0.0
    assert np.allclose(P2[0], P2[0].T)


def test_batched_update_matches_single():
    rng = np.random.default_rng(3)
    A = rng.normal(size=(5, 4, 4))
    P = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(4)
    x = rng.normal(size=(5, 4))
    z = rng.normal(size=(5, 2))
    xb, Pb = kf_update(x, P, z, 0.01)
    for i in range(5):
        xi, Pi = kf_update(x[i:i + 1], P[i:i + 1], z[i:i + 1], 0.01)
        assert np.allclose(xi[0], xb[i]) and np.allclose(Pi[0], Pb[i])


def test_mahalanobis_hand_value():
    # y = (1, 2), S = [[2, .5], [.5, 1]]: S^-1 = [[1, -.5], [-.5, 2]] / 1.75, y^T S^-1 y = (1 - 2 + 8) / 1.75 = 4
    assert mahalanobis2(np.array([1.0, 2.0]), np.array([[2.0, 0.5], [0.5, 1.0]])) == pytest.approx(4.0)


def test_update_with_one_covariance_per_measurement():
    """R may be a covariance per measurement (N, 2, 2): R = r I equals the scalar form, and a diagonal R =
    diag(a, b) gives each axis its own gain, by hand K_p = P_pp / (P_pp + a) on x and P_pp / (P_pp + b) on y."""
    P = np.diag([0.02, 0.02, 1.0, 1.0])[None]
    x = np.zeros((1, 4))
    z = np.array([[0.1, 0.1]])
    xs, Ps = kf_update(x, P, z, 0.0025)
    xm, Pm = kf_update(x, P, z, 0.0025 * np.eye(2)[None])
    assert np.array_equal(xs, xm) and np.allclose(Ps, Pm, rtol=0, atol=1e-15)
    xa, Pa = kf_update(x, P, z, np.diag([0.0025, 0.02])[None])
    assert xa[0, 0] == pytest.approx(0.1 * 0.02 / 0.0225) and xa[0, 1] == pytest.approx(0.1 * 0.02 / 0.04)
    assert Pa[0, 0, 0] == pytest.approx(0.02 * 0.0025 / 0.0225) and Pa[0, 1, 1] == pytest.approx(0.02 * 0.02 / 0.04)
