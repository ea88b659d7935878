"""eq:execution (1) to eq:predicted_obstacles (4) and eq:relative_position_error (15) to eq:uncertainty_margin
(21): prediction, execution model, uncertainty radius, D_i and h_i, by hand."""
import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bigcbf.control.prediction import age_obstacles, predict_obstacles, q_sigma_for
from bigcbf.control.uncertainty import (barrier, e_exec, inflated_radius, kappa_img, lambda_max_2x2,
                                        nominal_velocity, uncertainty_radius)
from bigcbf.params import PHYSICAL, SIMULATION, ExecutionModel, UncertaintyParams
from bigcbf.types import Obstacles


def test_prediction_eqs_2_to_4_by_hand():
    obs = Obstacles.from_lists([[1.0, 2.0], [0.0, 0.0]], v=[[0.5, -1.0], [0.0, 0.0]], r=[0.3, 0.0],
                               cov=[np.diag([0.01, 0.04]), np.zeros((2, 2))], static=[False, True])
    p, cov = predict_obstacles(obs, N=3, dt=0.1, q_sigma=np.array([0.2, 0.0]))
    assert p.shape == (4, 2, 2) and cov.shape == (4, 2, 2, 2)
    # eq:obs_prop (2) three times: (1, 2) + 3 * 0.1 * (0.5, -1) = (1.15, 1.7)
    np.testing.assert_allclose(p[3, 0], [1.15, 1.7])
    np.testing.assert_allclose(p[:, 1], 0.0)
    # eq:cov_prop (3) three times: diag(0.01, 0.04) + 3 * 0.2 * 0.1 I = diag(0.07, 0.10)
    np.testing.assert_allclose(cov[3, 0], np.diag([0.07, 0.10]))
    # the recursions themselves
    np.testing.assert_allclose(p[1:], p[:-1] + 0.1 * obs.v[None])
    np.testing.assert_allclose(cov[1:, 0], cov[:-1, 0] + 0.2 * 0.1 * np.eye(2))


def test_prediction_per_obstacle_growth_and_empty():
    obs = Obstacles.from_lists([[1, 0], [2, 0]], v=[[1, 0], [0, 0]])
    q = q_sigma_for(obs, SIMULATION.uncertainty)
    assert q.tolist() == [SIMULATION.uncertainty.q_sigma_m2_per_s, 0.0]     # static obstacles do not grow
    p, cov = predict_obstacles(Obstacles.empty(), 15, 0.1, 0.01)
    assert p.shape == (16, 0, 2) and cov.shape == (16, 0, 2, 2)
    with pytest.raises(ValueError):
        predict_obstacles(obs, 3, 0.1, -1.0)


def test_ageing_estimates_eqs_2_3_by_hand():
    """A scan 0.35 s old at 10 Hz (0.25 s beyond one sensor period): centres moved over the whole age (eq:obs_prop),
    covariances grown over the excess only (eq:cov_prop), q_Sigma of the dynamic / static obstacle."""
    unc = dataclasses.replace(SIMULATION.uncertainty, q_sigma_m2_per_s=0.2, q_sigma_static_m2_per_s=0.04)
    obs = Obstacles.from_lists([[1.0, 2.0], [3.0, 0.0]], v=[[0.5, -1.0], [0.0, 0.0]], r=[0.3, 0.2],
                               cov=[np.diag([0.01, 0.04]), np.diag([0.02, 0.02])], static=[False, True])
    aged = age_obstacles(obs, 0.35, 0.1, unc)
    np.testing.assert_allclose(aged.p, [[1.175, 1.65], [3.0, 0.0]])               # (1, 2) + 0.35 (0.5, -1)
    # diag(0.01, 0.04) + 0.2 * 0.25 I = diag(0.06, 0.09); diag(0.02, 0.02) + 0.04 * 0.25 I = diag(0.03, 0.03)
    np.testing.assert_allclose(aged.cov, [np.diag([0.06, 0.09]), np.diag([0.03, 0.03])])
    assert np.array_equal(aged.v, obs.v) and np.array_equal(aged.r, obs.r) and np.array_equal(aged.ids, obs.ids)
    # the same as the prediction's recursion: one step of dt = age for the centre, of dt = age - period for Sigma
    p1, _ = predict_obstacles(obs, 1, 0.35, q_sigma_for(obs, unc))
    _, c1 = predict_obstacles(obs, 1, 0.25, q_sigma_for(obs, unc))
    np.testing.assert_allclose(aged.p, p1[1]) and np.testing.assert_allclose(aged.cov, c1[1])
    # within one sensor period: moved, the perception's covariance kept; no age or no obstacle: the same object
    fresh = age_obstacles(obs, 0.08, 0.1, unc)
    np.testing.assert_allclose(fresh.p, obs.p + 0.08 * obs.v) and np.testing.assert_array_equal(fresh.cov, obs.cov)
    assert age_obstacles(obs, 0.0, 0.1, unc) is obs
    empty = Obstacles.empty()
    assert age_obstacles(empty, 1.0, 0.1, unc) is empty


def test_execution_model_eq_1_by_hand():
    ex = ExecutionModel(A=((0.9, 0.0, 0.0), (0.0, 0.8, 0.0), (0.0, 0.0, 1.0)), d=(0.1, 0.0, 0.0))
    # body: (0.9 * 1 + 0.1, 0.8 * 0.5) = (1.0, 0.4); R(pi/2) (1.0, 0.4) = (-0.4, 1.0)
    np.testing.assert_allclose(nominal_velocity(math.pi / 2, [1.0, 0.5, 0.0], ex), [-0.4, 1.0], atol=1e-12)


def test_e_exec_interpolation_by_hand():
    ex = ExecutionModel(residual_speed_mps=(0.0, 0.5, 1.0), residual_bound_mps=(0.02, 0.04, 0.10),
                        residual_horizon_s=0.15)
    # ||u_xy|| 0.25 -> 0.03 m/s; 0.75 -> 0.07; 2.0 -> clamped 0.10; (0.3, 0.4) -> 0.5 -> 0.04; times 0.15 s
    got = e_exec(np.array([[0.25, 0, 0], [0, 0.75, 0.3], [2.0, 0, 0], [0.3, 0.4, 1.0]]), ex)
    np.testing.assert_allclose(got, [0.0045, 0.0105, 0.015, 0.006])


def test_lambda_max_matches_eigvalsh():
    # [[0.04, 0.01], [0.01, 0.01]]: tr/2 = 0.025, sqrt(0.015^2 + 0.01^2) = 0.0180278 -> 0.0430278
    c = np.array([[0.04, 0.01], [0.01, 0.01]])
    assert lambda_max_2x2(c) == pytest.approx(0.025 + math.sqrt(0.015 ** 2 + 0.01 ** 2))
    rng = np.random.default_rng(1)
    L = rng.normal(size=(50, 2, 2))
    covs = L @ L.transpose(0, 2, 1)
    np.testing.assert_allclose(lambda_max_2x2(covs), np.linalg.eigvalsh(covs)[:, -1], rtol=1e-10)


def test_uncertainty_radius_eq_15_by_hand():
    unc = SIMULATION.uncertainty
    # theta 0, A = I, d = 0, u = (0.5, 0, 0), v_i = (-0.3, 0.4): relative velocity (0.8, -0.4), norm 0.894427
    #   delay term 0.1 * 0.894427 = 0.0894427
    # cov diag(0.0025, 0.0009): sqrt(lambda_max) = 0.05, beta 2 -> 0.1
    # e_exec: bound(0.5) = 0.02 + 0.5/0.8 * 0.02 = 0.0325 m/s, times 0.15 s -> 0.004875
    # e_ZOH 0.025                                  -> m = 0.2193177
    m = uncertainty_radius(0.0, [0.5, 0.0, 0.0], [-0.3, 0.4], np.diag([0.0025, 0.0009]), unc)
    assert m == pytest.approx(0.0894427191 + 0.1 + 0.004875 + 0.025)
    # eq:shared_barrier (20): D = 0.15 + 0.25 + 0.10 + 1.0 * m; h = ||q||^2 - D^2 with q = (1.0, 0.5)
    D = inflated_radius(0.25, m, unc.kappa_exec, unc)
    assert D == pytest.approx(0.5 + 0.2193177191)
    assert barrier(np.array([1.0, 0.5]), D) == pytest.approx(1.25 - (0.7193177191) ** 2)


def test_kappa_img_static_only_without_dynamic_obstacles():
    unc = PHYSICAL.uncertainty
    static = Obstacles.from_lists([[1, 0]], static=True)
    walls = Obstacles.from_lists([[1, 0]], v=[[0.5, 0]], static=False, ids=[-1])   # wall points are not tracked
    dyn = Obstacles.from_lists([[1, 0]], v=[[0.5, 0]], static=False)
    assert kappa_img(static, unc) == 1.0 and kappa_img(walls, unc) == 1.0 and kappa_img(dyn, unc) == 0.8
    assert kappa_img(static, SIMULATION.uncertainty) == 1.0


@settings(max_examples=200, deadline=None, derandomize=True)
@given(q=st.tuples(st.floats(-3, 3), st.floats(-3, 3)), ang=st.floats(0, 2 * math.pi), frac=st.floats(0, 1),
       r_i=st.floats(0, 0.5), m=st.floats(0, 0.5), kappa=st.floats(0.5, 1.5))
def test_robust_condition_eqs_11_to_13(q, ang, frac, r_i, m, kappa):
    """eq:robust_distance_condition (19): ||q|| >= D (eq:shared_barrier (20)) and ||eps_rel|| <= kappa m
    (eq:relative_error_bound (17)) imply the true clearance of eq:true_safety_requirement (6)."""
    unc = UncertaintyParams()
    q = np.array(q)
    D = inflated_radius(r_i, m, kappa, unc)
    if barrier(q, D) < 0:
        return
    eps = frac * kappa * m * np.array([math.cos(ang), math.sin(ang)])
    true_rel = q + eps                       # p_true - p_i,true = q_i + eps_rel (unlabelled (16))
    assert np.linalg.norm(true_rel) >= unc.r_robot_m + r_i + unc.d0_m - 1e-12


def test_uncertainty_radius_broadcasts_over_obstacles_and_commands():
    unc = dataclasses.replace(SIMULATION.uncertainty, execution=ExecutionModel(
        A=((0.9, 0.1, 0.0), (-0.05, 0.8, 0.02), (0.0, 0.0, 1.0)), d=(0.02, -0.01, 0.0)))
    rng = np.random.default_rng(3)
    u = rng.normal(size=(4, 1, 3))
    v = rng.normal(size=(1, 5, 2))
    L = rng.normal(size=(5, 2, 2)) * 0.1
    cov = L @ L.transpose(0, 2, 1)
    th = rng.normal(size=(4, 1))
    m = uncertainty_radius(th, u, v, cov[None], unc)
    assert m.shape == (4, 5)
    for b in range(4):
        for i in range(5):
            c, s = math.cos(th[b, 0]), math.sin(th[b, 0])
            A = np.array(unc.execution.A)
            vr = np.array([[c, -s], [s, c]]) @ (A[:2] @ u[b, 0] + np.array(unc.execution.d[:2]))
            ref = (np.linalg.norm(vr - v[0, i]) * unc.tau95_s + unc.beta * math.sqrt(np.linalg.eigvalsh(cov[i])[-1])
                   + e_exec(u[b, 0], unc.execution) + unc.e_zoh_m)
            assert m[b, i] == pytest.approx(ref)
