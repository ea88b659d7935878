"""The five comparison methods (issue 6): open space -> towards the goal; one obstacle -> finite and inside the
bounds; determinism per seed; the formulas of each method against hand computations."""
import numpy as np
import pytest

from bigcbf.control import METHODS, PlanInfo, Planner
from bigcbf.control.baselines import BASELINES
from bigcbf.control.baselines.apf import ApfParams, attractive_velocity, repulsive_velocity
from bigcbf.control.baselines.backup_cbf import BackupCbfPlanner
from bigcbf.control.baselines.common import (Geometry, accel_limited, barrier_along, body_from_world, integrate,
                                             predict, world_velocity)
from bigcbf.control.baselines.dwa import DwaParams, window_samples
from bigcbf.control.baselines.mppi import (MppiPlanner, effective_sample_size, mppi_weights, sample_sequences,
                                           temperature)
from bigcbf.control.baselines.pl_cbf import PlCbfPlanner
from bigcbf.control.baselines.shield import rollout
from bigcbf.params import SIMULATION
from bigcbf.types import Obstacles, RobotState

P = SIMULATION
NEW = ("backup-cbf", "pl-cbf", "apf", "dwa", "mppi")
GOAL = np.array([4.0, 0.0])
LO, HI = np.asarray(P.u_min), np.asarray(P.u_max)


def test_all_eight_registered():
    assert set(METHODS.names()) == {"big-cbf", "big-cbf-noshared", "big-cbf-plus", "cbf-only", "dpcbf", *NEW}
    for name in NEW:
        pl = METHODS.get(name)(P)
        assert isinstance(pl, Planner) and pl.name == name and BASELINES[name] is type(pl)


@pytest.mark.parametrize("name", NEW)
def test_open_space_drives_toward_goal(name):
    pl = METHODS.get(name)(P)
    pl.reset(0)
    theta = 0.4
    state = RobotState(0.0, 0.0, theta, 0.5 * np.cos(theta), -0.5 * np.sin(theta))   # moving at 0.5 m/s along +x
    for k in range(3):   # MPPI: also the ticks that follow its sequence
        u, info = pl.plan(0.05 * k, state, Obstacles.empty(), GOAL)
        assert isinstance(info, PlanInfo) and u.shape == (3,)
        c, s = np.cos(theta), np.sin(theta)
        v_world = np.array([c * u[0] - s * u[1], s * u[0] + c * u[1]])
        assert v_world[0] > 0.3, (name, u)           # goal-ward speed (MPPI's first samples also wander sideways)
        assert np.all(u >= LO - 1e-12) and np.all(u <= HI + 1e-12)


@pytest.mark.parametrize("name", NEW)
def test_one_obstacle_grid_finite_and_bounded(name):
    pl = METHODS.get(name)(P)
    obs = Obstacles.from_lists([[1.0, 0.0]], v=[[-0.6, 0.3]], r=0.3, cov=np.eye(2) * 0.01)
    for x in (-0.5, 0.2, 0.5, 0.8, 1.0, 1.6):          # includes the robot on (and inside) the obstacle
        for y in (-0.6, 0.0, 0.4):
            for theta in (0.0, 2.5):
                pl.reset(1)
                st = RobotState(x, y, theta, 0.3, -0.2, 0.1)
                u, info = pl.plan(0.0, st, obs, GOAL)
                assert np.all(np.isfinite(u)), (name, x, y, u)
                assert np.all(u >= LO - 1e-12) and np.all(u <= HI + 1e-12), (name, u)
                assert np.hypot(u[0], u[1]) <= P.v_max_mps + 1e-9
                assert np.isfinite(info.planner_ms)


@pytest.mark.parametrize("name", NEW)
def test_deterministic_per_seed(name):
    obs = Obstacles.from_lists([[1.2, 0.1], [2.0, -0.8]], v=[[0, 0], [0, 0.8]], r=0.3, cov=np.eye(2) * 0.01)
    runs = []
    for _ in range(2):
        pl = METHODS.get(name)(P)
        pl.reset(7)
        runs.append(np.array([pl.plan(0.05 * k, RobotState(0.05 * k, 0, 0), obs, GOAL)[0] for k in range(12)]))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_mppi_seed_matters_and_rate():
    obs = Obstacles.from_lists([[1.2, 0.1]], r=0.3)
    a, b = MppiPlanner(P), MppiPlanner(P)
    a.reset(0)
    b.reset(1)
    ua, ia = a.plan(0.0, RobotState(0, 0, 0), obs, GOAL)
    ub, _ = b.plan(0.0, RobotState(0, 0, 0), obs, GOAL)
    assert ia.planned and not np.array_equal(ua, ub)
    planned = [a.plan(0.05 * k, RobotState(0, 0, 0), obs, GOAL)[1].planned for k in range(1, 21)]
    assert planned == [k % 10 == 0 for k in range(1, 21)]             # 2 Hz at a 20 Hz control rate
    # between updates the sequence is followed, time-indexed: at t = 1.0 + 0.25 (last update at 1.0) k = 2 (dt 0.1)
    u, info = a.plan(1.25, RobotState(0, 0, 0), obs, GOAL)
    assert not info.planned
    np.testing.assert_allclose(u[:2], a.V[2])


def test_mppi_weights_by_hand():
    # S = (1, 2, 3), lambda = 1: exp(0), exp(-1), exp(-2) normalized
    z = np.array([1.0, np.exp(-1), np.exp(-2)])
    np.testing.assert_allclose(mppi_weights(np.array([1.0, 2.0, 3.0]), 1.0), z / z.sum())
    np.testing.assert_allclose(mppi_weights(np.array([5.0, 5.0]), 0.1), [0.5, 0.5])


def test_apf_gradients_by_hand():
    ap = ApfParams(k_att_per_s=1.0, d_conic_m=0.8, k_rep_m3_per_s=0.01, rho0_m=0.6)
    # quadratic zone: e = (0.3, 0.4), |e| = 0.5 < 0.8 -> k_att e
    np.testing.assert_allclose(attractive_velocity([0, 0], [0.3, 0.4], ap), [0.3, 0.4])
    # conic zone: e = (3, 4), |e| = 5 -> 0.8 e / 5 = (0.48, 0.64)
    np.testing.assert_allclose(attractive_velocity([0, 0], [3, 4], ap), [0.48, 0.64])
    # obstacle at (1, 0), D = 0.5: rho = 0.5; 0.01 (1/0.5 - 1/0.6) / 0.25 = 0.01 * 0.3333 / 0.25 = 0.013333, along -x
    np.testing.assert_allclose(repulsive_velocity([0, 0], [[1.0, 0.0]], [0.5], ap), [-0.0133333333, 0.0], rtol=1e-6)
    # beyond rho_0: nothing
    np.testing.assert_allclose(repulsive_velocity([0, 0], [[2.0, 0.0]], [0.5], ap), [0.0, 0.0])


def test_dwa_window_by_hand():
    dp = DwaParams(acc_xy_mps2=2.0, acc_wz_radps2=3.0, n_xy=3, n_wz=3)
    U = window_samples(RobotState(0, 0, 0, 0.2, 0.0, 0.0), P, dp).reshape(-1, 3)
    # one control period T_C = 0.05 s (Fox): vx in [0.2 - 0.1, 0.2 + 0.1], vy in [-0.1, 0.1], wz in [-0.15, 0.15]
    assert len(U) == 27
    assert U[:, 0].min() == pytest.approx(0.1) and U[:, 0].max() == pytest.approx(0.3)
    assert U[:, 1].min() == pytest.approx(-0.1) and U[:, 2].max() == pytest.approx(0.15)
    # from 0.75 m/s forward, (0.85, 0.1) is clipped to the actuator box (0.8) and then onto the 0.8 m/s disc
    U = window_samples(RobotState(0, 0, 0, 0.75, 0.0, 0.0), P, dp).reshape(-1, 3)
    corner = U[np.argmax(U[:, 0] + U[:, 1])]
    np.testing.assert_allclose(corner[:2], np.array([0.8, 0.1]) * 0.8 / np.hypot(0.8, 0.1))


def test_integrate_and_barrier_by_hand():
    # u = (0.5, 0, 0) at theta = pi/2 for 2 steps of 0.1 s: +y by 0.05 m per step
    p, th = integrate(RobotState(1.0, 2.0, np.pi / 2), np.tile([0.5, 0.0, 0.0], (1, 2, 1)), 0.1, P)
    np.testing.assert_allclose(p[0], [[1.0, 2.0], [1.0, 2.05], [1.0, 2.10]], atol=1e-12)
    # the method's barrier at k = 0 against a static obstacle at (1, 3), r = 0.2: D = 0.15 + 0.2 + d0 0.1 + margin 0.1
    # = 0.55 (no shared uncertainty m_i: that is the common CBF's); h = 1 - D^2; with scale 1.01: D = 1.01 * 0.35 + 0.1
    assert P.uncertainty.d0_m == 0.10
    obs = Obstacles.from_lists([[1.0, 3.0]], r=0.2)
    h = barrier_along(p, predict(obs, P, 2, 0.1), P, Geometry(0.1))
    assert h[0, 0, 0] == pytest.approx(1.0 - 0.55 ** 2)
    assert h[0, 2, 0] == pytest.approx(0.9 ** 2 - 0.55 ** 2)
    h = barrier_along(p, predict(obs, P, 2, 0.1), P, Geometry(0.0, 1.01))
    assert h[0, 0, 0] == pytest.approx(1.0 - (1.01 * 0.35 + 0.1) ** 2)


def test_accel_limited_and_brake_rollout_by_hand():
    # from 0.8 m/s towards 0 with 2 m/s^2 over 0.1 s: 0.6 m/s
    np.testing.assert_allclose(accel_limited(np.array([[0.8, 0.0]]), np.zeros((1, 2)), 2.0, 0.1), [[0.6, 0.0]])
    # braking from 0.8 m/s: speeds 0.6, 0.4, 0.2, 0 -> positions 0.06, 0.10, 0.12, 0.12, ...
    ro = rollout(np.zeros((1, 2)), np.array([[0.8, 0.0]]), 0.0, lambda k, p, o: np.zeros_like(p),
                 predict(Obstacles.empty(), P, 6, 0.1), P, 2.0)
    np.testing.assert_allclose(ro.p[0, :, 0], [0.0, 0.06, 0.10, 0.12, 0.12, 0.12, 0.12], atol=1e-12)
    assert ro.h_min[0] == np.inf
    # with an execution gain the state is the realized velocity and commands go through eq:execution (1) once:
    # A_xx = 0.5, bias 0.1 m/s; commanding 1.0 m/s asks for 0.5 * 1.0 + 0.1 = 0.6 m/s, which the robot already
    # does: it keeps 0.6 m/s (positions 0.06 k), and commanding 0 asks for the bias 0.1 m/s
    import dataclasses
    from bigcbf.params.stack import ExecutionModel
    ex = ExecutionModel(A=((0.5, 0, 0), (0, 1, 0), (0, 0, 1)), d=(0.1, 0.0, 0.0))
    Pg = dataclasses.replace(P, uncertainty=dataclasses.replace(P.uncertainty, execution=ex))
    pred = predict(Obstacles.empty(), Pg, 4, 0.1)
    ro = rollout(np.zeros((1, 2)), np.array([[0.6, 0.0]]), 0.0, lambda k, p, o: np.tile([1.0, 0.0], (len(p), 1)),
                 pred, Pg, 2.0)
    np.testing.assert_allclose(ro.p[0, :, 0], [0.0, 0.06, 0.12, 0.18, 0.24], atol=1e-12)
    ro = rollout(np.zeros((1, 2)), np.array([[0.3, 0.0]]), 0.0, lambda k, p, o: np.zeros_like(p), pred, Pg, 2.0)
    np.testing.assert_allclose(ro.p[0, :, 0], [0.0, 0.01, 0.02, 0.03, 0.04], atol=1e-12)   # 0.3 -> 0.1 in 0.1 s


def test_backup_cbf_keeps_nominal_far_and_intervenes_near():
    pl = BackupCbfPlanner(P)
    far = Obstacles.from_lists([[5.0, 3.0]], r=0.3)
    u, info = pl.plan(0.0, RobotState(0, 0, 0), far, GOAL)
    assert info.mode == "NOMINAL"
    np.testing.assert_allclose(u, [0.8, 0.0, 0.0])
    # obstacle 0.9 m ahead, r 0.3: D = r_R + r_i + d0 = 0.55 m, 0.35 m of room. Full speed then braking covers
    # 0.04 + 0.16 m but shrinks the backup trajectory's end value faster than alpha allows: the QP slows the robot
    near = Obstacles.from_lists([[0.9, 0.0]], r=0.3)
    u, info = pl.plan(0.0, RobotState(0, 0, 0), near, GOAL)
    assert info.mode == "BACKUP-CBF"
    assert 0.0 <= u[0] < 0.8 and abs(u[1]) < 1e-3


def test_pl_cbf_keeps_nominal_far_and_picks_a_certified_policy_near():
    pl = PlCbfPlanner(P)
    u, info = pl.plan(0.0, RobotState(0, 0, 0), Obstacles.from_lists([[3.0, 0.0]], r=0.3), GOAL)
    assert info.mode == "NOMINAL"
    np.testing.assert_allclose(u, [0.8, 0.0, 0.0])
    # a pedestrian 1 m ahead walking at the robot at 1 m/s: continuing the nominal cannot be certified
    obs = Obstacles.from_lists([[1.0, 0.0]], v=[[-1.0, 0.0]], r=0.25)
    u, info = pl.plan(0.0, RobotState(0, 0, 0), obs, GOAL)
    assert info.mode != "NOMINAL"
    assert not (u[0] > 0.5 and abs(u[1]) < 0.1)      # not driving on towards it


def test_mppi_temperature_hits_the_target_effective_sample_size():
    # two costs 0 and 1: w = (1, e^-1/l) / (1 + e^-1/l); ESS = (1 + z)^2 / (1 + z^2) = 1.5 at z = 2 - sqrt(3)
    # (by hand: (1 + z)^2 = 1.5 (1 + z^2) <=> z^2 - 4 z + 1 = 0), i.e. lambda = -1 / ln(2 - sqrt(3))
    lam = temperature(np.array([0.0, 1.0]), 1.5)
    assert lam == pytest.approx(-1.0 / np.log(2.0 - np.sqrt(3.0)), rel=1e-6)
    S = np.random.default_rng(0).normal(60.0, 3.0, 512)
    assert effective_sample_size(mppi_weights(S, temperature(S, 51.2))) == pytest.approx(51.2, rel=1e-6)
    assert temperature(np.full(4, 7.0), 2.0) == 1.0                    # equal costs: uniform weights anyway


def test_mppi_open_floor_command_is_smooth():
    """The weighted update averages out the sampling noise: on an empty floor the command heading for the goal
    stays within a few cm/s of the goal line (a too-cold temperature executed one noisy sample: 0.2 m/s std)."""
    pl = MppiPlanner(P)
    pl.reset(0)
    state, us = RobotState(0.0, 0.0, 0.0), []
    for k in range(40):
        u, _ = pl.plan(0.05 * k, state, Obstacles.empty(), np.array([8.0, 0.0]))
        us.append(u)
        state = RobotState(state.px + 0.05 * u[0], state.py + 0.05 * u[1], 0.0, *u)
    us = np.array(us)
    assert np.std(us[:, 1]) < 0.08 and np.mean(us[:, 0]) > 0.4
    # a non-finite estimate never latches a NaN into the warm start
    bad = Obstacles.from_lists([[np.nan, 0.0]], r=0.2)
    u, _ = pl.plan(2.0, state, bad, np.array([8.0, 0.0]))
    assert np.all(np.isfinite(pl.V)) and np.all(np.isfinite(u))


def mppi_costs_numpy(pl: MppiPlanner, Vs, eps, state, pred, goal):
    """MPPI's cost S(V^s) written with numpy arrays over samples, steps and obstacles (the implementation before
    the compiled kernel): an independent computation of the same formulas (bigcbf.control.baselines.mppi)."""
    p, mp = pl.params, pl.mppi
    dt = p.dt_s
    U = body_from_world(state.theta, Vs)
    paths, _ = integrate(state, U, dt, p)
    dg = np.hypot(*(paths - goal).transpose(2, 0, 1))
    cost = mp.w_goal * dt * dg[:, 1:].sum(axis=1) + mp.w_term * dg[:, -1]
    if pred.M:
        h = barrier_along(paths, pred, p, Geometry(mp.margin_m))[:, 1:]
        qn = np.hypot(*(paths[:, 1:, None, :] - pred.p[None, 1:]).transpose(3, 0, 1, 2))
        d = (qn - np.sqrt(np.maximum(qn * qn - h, 0.0))).min(axis=2)
        cost += dt * (mp.w_coll * (d < 0).sum(axis=1) + mp.w_clear * np.exp(-np.maximum(d, 0.0) / mp.l_clear_m).sum(axis=1))
    v_prev = np.concatenate([np.broadcast_to(world_velocity(state), (len(Vs), 1, 2)), Vs[:, :-1]], axis=1)
    cost += mp.w_smooth * ((Vs - v_prev) ** 2).sum(axis=(1, 2))
    cost += mp.gamma * (pl.V[None] * eps).sum(axis=(1, 2)) / mp.sigma_mps ** 2
    return cost, paths


def test_mppi_compiled_costs_match_the_array_formulas():
    """The compiled rollout cost gives the array version's costs and paths to 1e-12 (relative) on random scenes:
    moving and static obstacles, a calibrated execution model (A != I, d != 0), a warm-started mean, and a
    non-finite obstacle estimate (a non-finite cost for every sample in both)."""
    import dataclasses
    rng = np.random.default_rng(3)
    ex = dataclasses.replace(P.uncertainty.execution, A=((0.95, 0.02, 0.01), (-0.03, 0.9, 0.02), (0.05, -0.04, 0.92)),
                             d=(0.01, -0.02, 0.03))
    params = [P, dataclasses.replace(P, uncertainty=dataclasses.replace(P.uncertainty, execution=ex))]
    for trial in range(24):
        pl = MppiPlanner(params[trial % 2])
        pl.reset(trial)
        pl.V = rng.normal(0.0, 0.3, pl.V.shape)
        state = RobotState(*rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi), *rng.normal(0, 0.3, 3))
        M = int(rng.integers(0, 9))
        obs = Obstacles.from_lists(rng.uniform(-3, 3, (M, 2)), v=rng.normal(0, 0.5, (M, 2)),
                                   r=rng.uniform(0.05, 0.4, M), cov=np.eye(2) * 0.01)
        if trial == 23:
            obs = Obstacles.from_lists([[np.nan, 1.0], [1.0, 1.0]], r=0.2)
        pred = predict(obs, pl.params)
        Vs, eps = sample_sequences(pl.V, pl.rng, pl.params.v_max_mps, pl.mppi)
        goal = rng.uniform(-4, 4, 2)
        S, paths = pl.costs(Vs, eps, state, pred, goal)
        S_ref, paths_ref = mppi_costs_numpy(pl, Vs, eps, state, pred, goal)
        if trial == 23:
            assert not np.isfinite(S).any() and not np.isfinite(S_ref).any()
            continue
        np.testing.assert_allclose(paths, paths_ref, rtol=0, atol=1e-12)
        np.testing.assert_allclose(S, S_ref, rtol=1e-12, atol=1e-12)
