"""bigcbf.control.kernels: each equation's one implementation against values worked out by hand, the two forms of
eq:execution against each other, and the compiled copies (CBF rows, MPPI rollouts) against the kernels."""
import dataclasses
import math

import numpy as np
import pytest

from bigcbf.control import kernels as K
from bigcbf.control.baselines.mppi import _rollout_costs
from bigcbf.control.cbf import cbf_rows
from bigcbf.params import SIMULATION, ExecutionModel, UncertaintyParams
from bigcbf.types import Obstacles, RobotState

SLIP = ExecutionModel(A=((0.9, 0.1, 0.0), (0.0, 0.8, 0.0), (0.05, -0.02, 1.0)), d=(0.02, -0.01, 0.05),
                      residual_speed_mps=(0.0, 0.5, 1.0), residual_bound_mps=(0.02, 0.04, 0.1),
                      residual_horizon_s=0.15)
UNC = UncertaintyParams(r_robot_m=0.15, d0_m=0.10, tau95_s=0.2, beta=2.0, e_zoh_m=0.01, kappa_exec=0.9,
                        execution=SLIP)


def test_execution_by_hand():
    # eq:execution: A u + d = (0.9*0.5 + 0.1*0.2 + 0.02, 0.8*0.2 - 0.01) = (0.49, 0.15); R(pi/2) (x, y) = (-y, x)
    v = K.execution_velocity(np.pi / 2, np.array([0.5, 0.2, 0.3]), SLIP)
    np.testing.assert_allclose(v, [-0.15, 0.49], atol=1e-15)
    # rotational row: 0.05*0.5 - 0.02*0.2 + 1.0*0.3 + 0.05 = 0.371
    assert K.execution_yaw_rate(np.array([0.5, 0.2, 0.3]), SLIP) == pytest.approx(0.371, abs=1e-15)


def test_execution_complex_form_matches_the_real_one():
    # the complex form takes u_w = 0 (the behaviors command none); A[:2, 2] is 0 in SLIP, so both agree for any u_w
    a, b, d = K.execution_complex(SLIP)
    # (a, b) of [[0.9, 0.1], [0, 0.8]]: a = (1.7 - 0.1 i)/2, b = (0.1 + 0.1 i)/2
    assert a == pytest.approx(complex(0.85, -0.05)) and b == pytest.approx(complex(0.05, 0.05))
    assert d == complex(0.02, -0.01)
    rng = np.random.default_rng(3)
    th = rng.uniform(-np.pi, np.pi, 50)
    u = rng.uniform(-1, 1, (50, 3))
    real = K.execution_velocity(th, u, SLIP)
    cplx = K.execution_velocity_c(np.exp(1j * th), u[:, 0] + 1j * u[:, 1], a, b, d)
    np.testing.assert_allclose(np.stack([cplx.real, cplx.imag], -1), real, atol=1e-15)


def test_euler_paths_by_hand():
    # A = I, d = 0, u = (1, 0, 1) held for two steps of 0.5 s from (1, 2), yaw 0:
    # yaw 0 -> 0.5 -> 1.0; p1 = (1.5, 2), p2 = p1 + 0.5 (cos 0.5, sin 0.5)
    p, th = K.euler_paths(np.array([1.0, 2.0]), 0.0, np.tile([1.0, 0.0, 1.0], (1, 2, 1)), 0.5, ExecutionModel())
    np.testing.assert_allclose(th, [[0.0, 0.5, 1.0]])
    np.testing.assert_allclose(p[0], [[1.0, 2.0], [1.5, 2.0], [1.5 + 0.5 * math.cos(0.5), 2.0 + 0.5 * math.sin(0.5)]])
    # the step itself
    np.testing.assert_allclose(K.euler_step(np.array([1.0, 2.0]), np.array([0.5, -1.0]), 0.1), [1.05, 1.9])
    assert K.euler_step(1 + 2j, 0.5 - 1j, 0.1) == pytest.approx(1.05 + 1.9j)


def test_advance_obstacles_by_hand():
    # eq:obs_prop over t = 0.4: (1, 2) + 0.4 (0.5, -1) = (1.2, 1.6); eq:cov_prop: diag(0.01, 0.02) + 0.1*0.4 I
    p0, v0 = np.array([[1.0, 2.0]]), np.array([[0.5, -1.0]])
    cov0, q = np.diag([0.01, 0.02])[None], np.array([0.1])
    p, cov = K.advance_obstacles(p0, v0, cov0, q, 0.4)
    np.testing.assert_allclose(p, [[1.2, 1.6]])
    np.testing.assert_allclose(cov, [np.diag([0.05, 0.06])])
    _, cov = K.advance_obstacles(p0, v0, cov0, q, 0.4, grow_s=0.1)       # grown over 0.1 s only
    np.testing.assert_allclose(cov, [np.diag([0.02, 0.03])])
    _, cov = K.advance_obstacles(p0, v0, cov0, q, 0.4, grow_s=0.0)       # not grown: the same array
    assert cov is cov0


def test_goal_region_by_hand():
    # eq:goal_region: ||(1.3, 2.4) - (1, 2)|| = 0.5
    d = K.goal_distance(np.array([[1.3, 2.4], [1.0, 2.0]]), np.array([1.0, 2.0]))
    np.testing.assert_allclose(d, [0.5, 0.0], atol=1e-15)
    assert K.in_goal_region(0.5, 0.5) and not K.outside_goal_region(0.5, 0.5)
    assert not K.in_goal_region(0.5 + 1e-12, 0.5) and K.outside_goal_region(0.5 + 1e-12, 0.5)
    assert not K.in_goal_region(math.nan, 0.5) and not K.outside_goal_region(math.nan, 0.5)


def test_uncertainty_margin_terms_by_hand():
    # e_exec: knots (0, 0.5, 1) -> (0.02, 0.04, 0.1); at 0.25 m/s halfway: 0.03 m/s * 0.15 s = 0.0045 m; clamped
    np.testing.assert_allclose(K.e_exec_speed(np.array([0.0, 0.25, 0.75, 3.0]), SLIP),
                               [0.003, 0.0045, 0.0105, 0.015])
    # lambda_max([[2, 1], [1, 2]]) = 3; beta sqrt(3)
    assert K.lambda_max_2x2(np.array([[2.0, 1.0], [1.0, 2.0]])) == pytest.approx(3.0)
    assert K.prediction_term(np.array([[2.0, 1.0], [1.0, 2.0]]), UNC) == pytest.approx(2.0 * math.sqrt(3.0))
    # eq:uncertainty_margin: 0.2 s * 1.5 m/s + 0.1 + (0.02 + 0.01) = 0.43 m
    assert K.uncertainty_radius(1.5, 0.1, 0.02, UNC) == pytest.approx(0.43, abs=1e-15)


def test_shared_barrier_by_hand():
    # eq:shared_barrier: D = 0.15 + 0.3 + 0.10 + 0.9*0.43 = 0.937; h = ||(1, 0.5)||^2 - D^2 = 1.25 - 0.877969
    D = K.inflated_radius(0.3, 0.9 * 0.43, UNC)
    assert D == pytest.approx(0.937, abs=1e-15)
    assert K.barrier(K.squared_norm(np.array([1.0, 0.5])), D) == pytest.approx(1.25 - 0.937 ** 2, abs=1e-15)


def test_compiled_cbf_rows_match_the_kernels():
    """cbf._rows_kernel (numba) inlines eq:uncertainty_margin and eq:shared_barrier; it sums the radius as
    (r_R + d0) + r_i + kappa m, the kernel as (r_R + r_i) + d0 + kappa m: equal to rounding."""
    params = dataclasses.replace(SIMULATION, uncertainty=UNC)
    rng = np.random.default_rng(7)
    for _ in range(20):
        M = 6
        A = rng.uniform(-0.3, 0.3, (M, 2, 2))
        obs = Obstacles.from_lists(rng.uniform(-3, 3, (M, 2)), v=rng.uniform(-1, 1, (M, 2)),
                                   r=rng.uniform(0, 0.5, M), cov=A @ A.transpose(0, 2, 1) * 0.1)
        state = RobotState(*rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi))
        u = rng.uniform(-0.8, 0.8, 3)
        rows = cbf_rows(state, obs, u, params)
        rel = K.execution_velocity(state.theta, u, SLIP) - obs.v
        m = K.uncertainty_radius(np.hypot(rel[:, 0], rel[:, 1]), K.prediction_term(obs.cov, UNC),
                                 K.e_exec_speed(math.hypot(u[0], u[1]), SLIP), UNC)
        D = K.inflated_radius(obs.r, UNC.kappa_exec * m, UNC)
        np.testing.assert_allclose(rows.margin, UNC.kappa_exec * m, rtol=1e-13, atol=1e-15)
        np.testing.assert_allclose(rows.D, D, rtol=1e-13)
        np.testing.assert_allclose(rows.h, K.barrier(K.squared_norm(state.p - obs.p), D), rtol=1e-11, atol=1e-13)


def test_compiled_mppi_rollout_matches_euler_paths():
    """mppi._rollout_costs (numba) integrates eq:execution with forward Euler one step at a time; the kernel sums
    the same steps with cumsum: equal to rounding."""
    rng = np.random.default_rng(11)
    S, N, dt = 4, 15, 0.1
    Vs = rng.uniform(-0.8, 0.8, (S, N, 2))
    theta0 = 0.7
    A, d = np.asarray(SLIP.A, float), np.asarray(SLIP.d, float)
    w = np.array([dt, 1.0, 1.0, 1.0, 1.0, 0.3, 1.0, 0.0])
    _, paths = _rollout_costs(Vs, np.zeros((S, N, 2)), np.zeros((N, 2)), 0.5, -0.5, theta0, np.zeros(2),
                              np.array([5.0, 0.0]), np.zeros((N, 0, 2)), np.zeros(0), A, d, w)
    c, s = math.cos(theta0), math.sin(theta0)
    U = np.stack([c * Vs[..., 0] + s * Vs[..., 1], -s * Vs[..., 0] + c * Vs[..., 1], np.zeros((S, N))], -1)
    p, _ = K.euler_paths(np.array([0.5, -0.5]), theta0, U, dt, SLIP)
    np.testing.assert_allclose(paths, p, rtol=0, atol=1e-12)


def test_body_from_world_inverts_the_ideal_execution():
    # R(pi/2)^T (0, 1) = (1, 0); and eq:execution with A = I, d = 0 maps it back
    np.testing.assert_allclose(K.body_from_world(np.pi / 2, np.array([0.0, 1.0])), [1.0, 0.0, 0.0], atol=1e-15)
    rng = np.random.default_rng(5)
    th, v = rng.uniform(-np.pi, np.pi, 20), rng.uniform(-1, 1, (20, 2))
    np.testing.assert_allclose(K.execution_velocity(th, K.body_from_world(th, v), ExecutionModel()), v, atol=1e-15)


def test_yaw_rate_complex_form_by_hand():
    # A[2] = (0.05, -0.02, 1), d_w = 0.05: 0.05*0.5 - 0.02*0.2 + 0.05 = 0.071 (u_w = 0), as the real form gives
    A = np.asarray(SLIP.A, float)
    w = K.execution_yaw_rate_c(np.array([0.5 + 0.2j]), A[2, 0], A[2, 1], SLIP.d[2])
    np.testing.assert_allclose(w, [0.071], atol=1e-15)
    np.testing.assert_allclose(w, K.execution_yaw_rate(np.array([[0.5, 0.2, 0.0]]), SLIP), atol=1e-15)
