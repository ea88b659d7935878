"""The hard CBF filter, eq:cbf_condition (25) and eq:hard_cbf_qp (26): hand values, and property tests against a
brute-force exact solver."""
import dataclasses
import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bigcbf.control.cbf import SLACK_TOL_MPS, CbfFilter, cbf_rows, select_constraints
from bigcbf.control.uncertainty import barrier, inflated_radius, uncertainty_radius
from bigcbf.params import PHYSICAL, SIMULATION, ExecutionModel
from bigcbf.types import Obstacles, RobotState

P = SIMULATION
LO, HI = np.array(P.u_min), np.array(P.u_max)


def eq18(state, obs, u, D, params):
    """eq:cbf_condition (25) evaluated literally: 2 q_i^T [R(theta)(A u + d) - v_i] + alpha h_i, per obstacle."""
    ex = params.uncertainty.execution
    A, d = np.array(ex.A), np.array(ex.d)
    c, s = math.cos(state.theta), math.sin(state.theta)
    v = np.array([[c, -s], [s, c]]) @ (A[:2] @ u + d[:2])
    q = state.p - obs.p
    h = np.sum(q * q, axis=1) - D ** 2
    return 2 * np.sum(q * (v - obs.v), axis=1) + params.alpha_per_s * h


def brute_force_qp(C, l, u_in, Hd, lo, hi):
    """min (u-u_in)^T H (u-u_in) s.t. C u >= l, lo <= u <= hi, by enumerating every set of <= 3 active
    constraints (the KKT point of each equality-constrained problem); None if infeasible."""
    G = np.vstack([C, np.eye(3), -np.eye(3)])
    g = np.concatenate([l, lo, -hi])
    Hinv = 1.0 / Hd
    best, best_f = None, math.inf
    for k in range(4):
        for S in itertools.combinations(range(len(g)), k):
            S = list(S)
            if k:
                GS = G[S]
                K = (GS * Hinv) @ GS.T
                with np.errstate(divide="ignore", invalid="ignore"):   # a singular K is skipped, not warned of
                    singular = not abs(np.linalg.det(K)) >= 1e-12
                if singular:
                    continue
                lam = np.linalg.solve(K, g[S] - GS @ u_in)
                u = u_in + Hinv * (GS.T @ lam)
            else:
                u = u_in.copy()
            if np.all(G @ u >= g - 1e-9):
                f = float(np.sum(Hd * (u - u_in) ** 2))
                if f < best_f:
                    best, best_f = u, f
    return best, best_f


def test_eq_18_row_by_hand():
    """Robot (0,0), theta 0; static obstacle (1,0), r 0.2, no covariance; u_in = (0.7, 0.3, 0).
    m = 0.1 |(0.7, 0.3)| + 0 + 0.15 bound(0.76158) + 0.025
      = 0.076158 + 0.15 (0.02 + 0.76158/0.8 * 0.02) + 0.025 = 0.076158 + 0.005856 + 0.025 = 0.107014
    D = 0.15 + 0.2 + 0.1 + m = 0.557014; h = 1 - D^2 = 0.689736.
    eq:cbf_condition (25): 2 (-1, 0).(u_x, u_y) + 1.5 h >= 0  <=>  u_x <= 0.75 h = 0.517302.
    H = I: the minimum intervention only lowers u_x: u_safe = (0.517302, 0.3, 0)."""
    state = RobotState(0.0, 0.0, 0.0)
    obs = Obstacles.from_lists([[1.0, 0.0]], r=0.2)
    u_in = np.array([0.7, 0.3, 0.0])
    speed = math.hypot(0.7, 0.3)
    m = 0.1 * speed + 0.15 * (0.02 + speed / 0.8 * 0.02) + 0.025
    D = 0.45 + m
    h = 1 - D ** 2
    rows = cbf_rows(state, obs, u_in, P)
    assert rows.D[0] == pytest.approx(D) and rows.h[0] == pytest.approx(h)
    np.testing.assert_allclose(rows.a[0], [-2.0, 0.0, 0.0])
    assert rows.b[0] == pytest.approx(-1.5 * h)
    u, info = CbfFilter(P).filter(state, obs, u_in)
    np.testing.assert_allclose(u, [0.75 * h, 0.3, 0.0], atol=1e-7)
    assert info.active and not info.infeasible and info.fallback is None and info.n_constraints == 1
    # a command that is already safe passes unchanged
    u2, info2 = CbfFilter(P).filter(state, obs, np.array([0.4, 0.3, 0.0]))
    assert np.array_equal(u2, [0.4, 0.3, 0.0]) and not info2.active


IMPERFECT = dataclasses.replace(SIMULATION, uncertainty=dataclasses.replace(
    SIMULATION.uncertainty, execution=ExecutionModel(
        A=((0.9, 0.05, 0.02), (-0.03, 0.85, 0.01), (0.0, 0.0, 0.95)), d=(0.02, -0.01, 0.05))))


@pytest.mark.parametrize("params", [SIMULATION, IMPERFECT, PHYSICAL])
def test_rows_agree_with_the_shared_uncertainty_functions(params):
    rng = np.random.default_rng(5)
    for _ in range(20):
        M = int(rng.integers(1, 9))
        L = rng.normal(0, 0.1, (M, 2, 2))
        obs = Obstacles.from_lists(rng.uniform(-2, 2, (M, 2)), v=rng.normal(0, 0.5, (M, 2)),
                                   r=rng.uniform(0, 0.4, M), cov=L @ L.transpose(0, 2, 1))
        state = RobotState(*rng.uniform(-0.5, 0.5, 2), rng.uniform(-3, 3))
        u_in = rng.uniform(-1, 1, 3)
        rows = cbf_rows(state, obs, u_in, params)
        unc = params.uncertainty
        m = uncertainty_radius(state.theta, u_in[None], obs.v, obs.cov, unc)
        D = inflated_radius(obs.r, m, unc.kappa_exec, unc)
        np.testing.assert_allclose(rows.D, D, rtol=1e-12)
        np.testing.assert_allclose(rows.h, barrier(state.p - obs.p, D), rtol=1e-10, atol=1e-12)
        for _ in range(3):
            u = rng.uniform(-1, 1, 3)
            np.testing.assert_allclose(rows.a @ u - rows.b, eq18(state, obs, u, rows.D, params), atol=1e-10)


obstacle = st.tuples(st.floats(-1.5, 1.5), st.floats(-1.5, 1.5), st.floats(-1.0, 1.0), st.floats(-1.0, 1.0),
                     st.floats(0.0, 0.4), st.floats(0.0, 0.02))


@settings(max_examples=300, deadline=None, derandomize=True)
@given(obstacles=st.lists(obstacle, min_size=0, max_size=8), theta=st.floats(-math.pi, math.pi),
       u_in=st.tuples(st.floats(-1.2, 1.2), st.floats(-1.2, 1.2), st.floats(-1.5, 1.5)),
       imperfect=st.booleans())
def test_filter_properties(obstacles, theta, u_in, imperfect):
    params = IMPERFECT if imperfect else P
    state = RobotState(0.0, 0.0, theta)
    if obstacles:
        a = np.array(obstacles)
        obs = Obstacles.from_lists(a[:, :2], v=a[:, 2:4], r=a[:, 4], cov=a[:, 5, None, None] * np.eye(2),
                                   static=False)
    else:
        obs = Obstacles.empty()
    u_in = np.array(u_in)
    filt = CbfFilter(params)
    u, info = filt.filter(state, obs, u_in)
    assert np.all(np.isfinite(u)) and np.all(u >= LO) and np.all(u <= HI)
    rows = cbf_rows(state, obs, u_in, params)
    C, l = rows.C, rows.l
    ref, f_ref = brute_force_qp(C, l, u_in, np.array(params.H_diag), LO, HI)
    if ref is None:
        assert info.infeasible and info.fallback in ("least-violation", "brake") and info.max_violation > 0
        # no point of a grid over the box violates the worst row less than the fallback does by more than the
        # tolerance within which the fallback takes the minimum-intervention command (SLACK_TOL_MPS)
        grid = np.stack(np.meshgrid(*[np.linspace(lo, hi, 21) for lo, hi in zip(LO, HI)]), -1).reshape(-1, 3)
        worst_grid = np.max(l[None] - grid @ C.T, axis=1).min()
        # (1e-4: the exact penalty trades a little worst-case violation for intervention when a row's coefficient
        # is tiny; measured 1.5e-6 m/s with a coefficient of 1.9e-6 on vx, a robot on an obstacle's centre, and
        # 3.0e-5 with a coefficient of 6.1e-5 at theta = 6.1e-5 rad, an example a clean-clone run drew under xdist)
        assert np.max(l - C @ u) <= worst_grid + SLACK_TOL_MPS + 1e-4
        return
    assert not info.infeasible and info.fallback is None
    # every eq:cbf_condition (25) constraint holds (evaluated literally) and the bounds hold
    assert np.all(eq18(state, obs, u, rows.D, params) >= -1e-6 * np.maximum(rows.norm, 1.0))
    # minimum intervention: the same optimum as the exact brute-force solver
    f = float(np.sum(np.array(params.H_diag) * (u - u_in) ** 2))
    assert f == pytest.approx(f_ref, rel=1e-6, abs=1e-8)
    np.testing.assert_allclose(u, ref, atol=1e-5)
    # a command that is already safe and inside the box is returned unchanged
    inside = np.all(u_in >= LO) and np.all(u_in <= HI)
    if inside and np.all(C @ u_in >= l):
        assert np.array_equal(u, u_in) and not info.active


def test_changing_number_of_constraints_between_calls():
    rng = np.random.default_rng(11)
    filt = CbfFilter(P)
    counts = set()
    for _ in range(60):
        M = int(rng.integers(1, 9))
        ang = rng.uniform(0, 2 * np.pi, M)
        obs = Obstacles.from_lists(np.c_[np.cos(ang), np.sin(ang)] * rng.uniform(0.6, 0.9, (M, 1)), r=0.1)
        u_in = rng.uniform(-0.8, 0.8, 3)
        state = RobotState(0.0, 0.0, 0.0)
        u, info = filt.filter(state, obs, u_in)
        rows = cbf_rows(state, obs, u_in, P)
        ref, _ = brute_force_qp(rows.C, rows.l, u_in, np.ones(3), LO, HI)
        assert ref is not None and not info.infeasible
        np.testing.assert_allclose(u, ref, atol=1e-5)
        counts.add(info.n_constraints)
    assert len(counts) > 3                                   # several row counts through one filter object


def test_infeasible_least_violation():
    """Two pedestrians rush at the robot from both sides at 1.5 m/s: no command in the box satisfies both rows."""
    obs = Obstacles.from_lists([[0.6, 0.0], [-0.6, 0.0]], v=[[-1.5, 0.0], [1.5, 0.0]], r=0.25, static=False)
    u, info = CbfFilter(P).filter(RobotState(0, 0, 0), obs, np.array([0.0, 0.2, 0.3]))
    assert info.infeasible and info.fallback == "least-violation" and info.active and info.max_violation > 0
    assert np.all(np.isfinite(u)) and np.all(u >= LO) and np.all(u <= HI)
    # symmetric rows (u_in has no x part): the least worst violation stays between them, and u_y is kept; so is
    # the yaw rate, which no row constrains (a least-violation LP's vertex had put it at a bound)
    np.testing.assert_allclose(u, [0.0, 0.2, 0.3], atol=1e-6)
    # the worst violation is the least possible: x = 0 balances the two rows (by hand: any x moves one up)
    rows = cbf_rows(RobotState(0, 0, 0), obs, np.array([0.0, 0.2, 0.3]), P)
    assert info.max_violation == pytest.approx(float(np.max(rows.l - rows.C @ u)), abs=1e-9)
    for dx in (-0.05, 0.05):
        assert np.max(rows.l - rows.C @ (u + [dx, 0, 0])) > info.max_violation


def test_least_violation_takes_the_least_intervention_within_its_tolerance():
    """The least-violation command (bigcbf/control/cbf.py's docstring), by hand: two opposed rows that no vx
    satisfies, each with a yaw-rate component of 0.002 (the size the calibrated execution model's cross-coupling
    gives). Their least worst violation, over the box |wz| <= w_max, is t* = 0.5 - 0.002 w_max at vx = 0, wz = w_max
    (what the exact penalty alone commanded: the full yaw rate for 2 mm/s). Within SLACK_TOL_MPS of t*, the
    minimum-intervention command from u_in = 0 keeps wz = 0 (its violation 0.5 <= t* + 0.005), and vx = vy = 0."""
    C = np.array([[1.0, 0.0, 0.002], [-1.0, 0.0, 0.002]])
    l = np.array([0.5, 0.5])
    filt = CbfFilter(P)
    t_star, u = filt._least_violation(C, l, np.zeros(3))
    np.testing.assert_allclose(u, [0.0, 0.0, 0.0], atol=1e-9)
    assert t_star == pytest.approx(0.5, abs=1e-9)
    assert t_star <= 0.5 - 0.002 * HI[2] + SLACK_TOL_MPS + 1e-12
    # a command asked with a yaw rate keeps it: the tolerance does not move wz toward the rows' favour either
    t_star, u = filt._least_violation(C, l, np.array([0.0, 0.3, -0.4]))
    np.testing.assert_allclose(u, [0.0, 0.3, -0.4], atol=1e-9)
    assert t_star == pytest.approx(0.5 + 0.002 * 0.4, abs=1e-9) and t_star <= 0.5 - 0.002 * HI[2] + SLACK_TOL_MPS
    # the same rows with a larger yaw component: the tolerance binds, wz moves exactly as far as it must
    C2 = np.array([[1.0, 0.0, 0.02], [-1.0, 0.0, 0.02]])
    t_star, u = filt._least_violation(C2, l, np.zeros(3))
    w = (0.5 - (0.5 - 0.02 * HI[2] + SLACK_TOL_MPS)) / 0.02          # 0.02 w >= 0.5 - (t* + tol)
    np.testing.assert_allclose(u, [0.0, 0.0, w], atol=1e-7)
    assert t_star == pytest.approx(0.5 - 0.02 * HI[2] + SLACK_TOL_MPS, abs=1e-7)


def test_degenerate_and_invalid_input_never_nan():
    obs = Obstacles.from_lists([[0.0, 0.0], [1.0, 0.0]], r=0.2)   # first obstacle exactly on the robot center
    u, info = CbfFilter(P).filter(RobotState(0, 0, 0), obs, np.array([0.3, 0.0, 0.0]))
    assert info.infeasible and np.all(np.isfinite(u)) and np.all(u >= LO) and np.all(u <= HI)
    u, info = CbfFilter(P).filter(RobotState(0, 0, 0), Obstacles.from_lists([[1.0, 0.0]], r=0.2),
                                  np.array([np.nan, 0.0, 0.0]))
    assert info.fallback == "invalid-input" and np.array_equal(u, [0.0, 0.0, 0.0])


def test_solver_failures_are_recovered_or_brake(monkeypatch):
    state, obs = RobotState(0, 0, 0), Obstacles.from_lists([[1.0, 0.0]], r=0.2)
    u_in = np.array([0.7, 0.3, 0.0])
    expected, _ = CbfFilter(P).filter(state, obs, u_in)
    filt = CbfFilter(P)
    real = filt._solve_qp
    calls = []

    def fail_once(*args, **kw):
        calls.append(1)
        return None if len(calls) == 1 else real(*args, **kw)

    monkeypatch.setattr(filt, "_solve_qp", fail_once)
    u, info = filt.filter(state, obs, u_in)
    assert info.fallback == "qp-retry" and not info.infeasible
    np.testing.assert_allclose(u, expected, atol=1e-6)
    monkeypatch.setattr(filt, "_solve_qp", lambda *a, **k: None)
    monkeypatch.setattr(filt, "_least_violation", lambda *a, **k: None)
    u, info = filt.filter(state, obs, u_in)
    assert info.fallback == "brake" and info.infeasible and np.array_equal(u, [0.0, 0.0, 0.0])


def test_wall_points_sector_selection():
    """A corridor of wall points (y = +-0.8, 20 points each) plus 14 tracked obstacles: the filter keeps the
    12 tracked ones with the smallest h and the nearest wall point in each of the 8 bearing sectors."""
    xs = np.linspace(-2, 2, 20)
    walls = Obstacles.from_lists(np.r_[np.c_[xs, np.full(20, 0.8)], np.c_[xs, np.full(20, -0.8)]], r=0.0,
                                 ids=-np.ones(40, int))
    tracked = Obstacles.from_lists(np.c_[np.linspace(1.0, 4.0, 14), np.zeros(14)], r=0.1)
    obs = tracked.concat(walls)
    state = RobotState(0.0, 0.0, 0.0)
    rows = cbf_rows(state, obs, np.zeros(3), P)
    idx = select_constraints(obs, rows, P)
    assert list(idx[idx < 14]) == list(range(12))            # the 12 nearest tracked obstacles
    chosen = obs.p[idx[idx >= 14]]
    # sectors of 45 degrees: both walls are represented, by their points nearest to the robot
    assert np.any(chosen[:, 1] > 0) and np.any(chosen[:, 1] < 0)
    for y in (0.8, -0.8):
        d = np.hypot(*chosen[chosen[:, 1] == y].T)
        assert d.min() == pytest.approx(np.hypot(xs, y).min())
    bearing = np.degrees(np.arctan2(chosen[:, 1], chosen[:, 0]))
    assert len(np.unique(np.floor((bearing + 180) / 45))) == len(chosen)   # one point per sector
    u, info = CbfFilter(P).filter(state, obs, np.array([0.0, 0.8, 0.0]))  # towards the upper wall
    assert info.active and u[1] < 0.8
    top = obs.p[:, 1] == 0.8
    assert np.all(eq18(state, obs.subset(top), u, info.D[top], P) >= -1e-6)   # no wall point is violated
