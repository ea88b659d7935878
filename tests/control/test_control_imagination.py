"""eq:behavior_rollout (12), eq:behavior_terms (13), eq:behavior_cost (14), eq:behavior_acceptance (22),
eq:analytic_workload (24): the vectorized imagination against a per-behavior reference loop and by hand."""
import dataclasses
import math

import numpy as np
import pytest

from bigcbf.control.behaviors import BEHAVIORS, behavior_command, obstacle_groups
from bigcbf.control.governor import govern_c, obstacle_sigma_term
from bigcbf.control.imagination import imagine, rollout_paths
from bigcbf.control.prediction import predict_obstacles, q_sigma_for
from bigcbf.control.uncertainty import inflated_radius, uncertainty_radius
from bigcbf.params import PHYSICAL, SIMULATION, ExecutionModel, UncertaintyParams
from bigcbf.params.stack import PAPER_RULES, PlusRules
from bigcbf.types import Obstacles, RobotState

MODES7 = BEHAVIORS + ("REVERSE",)


def rot(th):
    return np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])


def reference(state, obs, goal, params, modes, shared, current, rules=PAPER_RULES):
    """Straightforward loops over behaviors, steps and obstacles, built from the scalar helpers."""
    unc, ex = params.uncertainty, params.uncertainty.execution
    N, dt = params.N, params.dt_s
    A, d = np.array(ex.A), np.array(ex.d)
    Pp, cov = predict_obstacles(obs, N, dt, q_sigma_for(obs, unc))
    if rules.prediction_cap:             # the rule prediction_cap: Sigma_k held at k_cap, for its scope's obstacles
        k_cap = int(round(rules.prediction_cap_s / dt))
        for i in range(len(obs)):
            if rules.prediction_cap_scope == "all" or math.hypot(*obs.v[i]) < params.v_max_mps:
                for k in range(k_cap + 1, N + 1):
                    cov[k, i] = cov[k_cap, i]
    dyn = bool(np.any(~obs.static & (obs.ids >= 0)))
    kap = unc.kappa_img if (unc.kappa_img_static is None or dyn) else unc.kappa_img_static
    groups = obstacle_groups(obs.p, obs.r, params)     # the groups of the obstacles at k = 0, as imagine() does
    out = []
    for b in modes:
        x, th = np.array([state.px, state.py]), state.theta
        xs, us, hs, W = [x.copy()], [], [], 0.0

        def h_of(x, th, u, k):
            vals = []
            for i in range(len(obs)):
                q = x - Pp[k, i]
                if shared:
                    D = inflated_radius(obs.r[i], uncertainty_radius(th, u, obs.v[i], cov[k, i], unc), kap, unc)
                else:
                    D = unc.r_robot_m + obs.r[i] + unc.d0_m + params.noshared_margin_m
                vals.append(q @ q - D * D)
            return vals

        for k in range(N):
            o_k = Obstacles(Pp[k], obs.v, cov[k], obs.r, obs.static, obs.ids)
            u = behavior_command(b, RobotState(x[0], x[1], th), o_k, goal, params, groups, rules=rules)
            move = None
            if rules.speed_governor and b not in ("YIELD", "REVERSE") and len(obs):   # governor.py, per state
                s, w = govern_c(np.array([complex(*x)]), np.array([np.exp(1j * th)]), np.array([complex(*u[:2])]),
                                Pp[k, :, 0] + 1j * Pp[k, :, 1], obs.v[:, 0] + 1j * obs.v[:, 1],
                                obstacle_sigma_term(cov[k], params), obs.r, params)
                u, move = u * s[0], np.array([w[0].real, w[0].imag])
            us.append(u)
            vreal = rot(th) @ (A[:2] @ u + d[:2])
            hk = h_of(x, th, u, k)
            hs += hk
            for i in range(len(obs)):
                q = x - Pp[k, i]
                gamma = 2 * q @ (vreal - obs.v[i]) + params.alpha_per_s * hk[i]
                grad = 2 * A[:2].T @ rot(th).T @ q
                W += max(-gamma, 0.0) ** 2 / (grad @ grad + params.w_eps)
            x = x + dt * (vreal if move is None else move)
            th = th + dt * (A[2] @ u + d[2])
            xs.append(x.copy())
        hs += h_of(x, th, us[-1], N)
        g = np.asarray(goal)
        Pr = np.linalg.norm(xs[0] - g) - np.linalg.norm(xs[N] - g)
        F = np.mean([np.linalg.norm(us[k][:2]) < params.v_freeze_mps and np.linalg.norm(xs[k] - g) > params.eps_g_m
                     for k in range(N)])
        S = sum(np.sum((us[k] - us[k - 1]) ** 2) for k in range(1, N)) + np.sum(us[0] ** 2)
        C = float(current is not None and b != current)
        J = params.w_W * W - params.w_P * Pr + params.w_F * F + params.w_sw * C + params.w_S * S
        out.append(dict(p=np.array(xs), u=np.array(us), h_min=min(hs, default=math.inf), W=W, P=Pr, F=F, S=S, J=J))
    return out


def scene(seed, n_dyn=3, n_static=3, n_wall=4):
    rng = np.random.default_rng(seed)
    M = n_dyn + n_static + n_wall
    p = rng.uniform([-1.0, -2.0], [3.5, 2.0], (M, 2))
    v = np.concatenate([rng.normal(0, 0.6, (n_dyn, 2)), np.zeros((n_static + n_wall, 2))])
    L = rng.normal(0, 0.08, (M, 2, 2))
    cov = L @ L.transpose(0, 2, 1)
    r = np.concatenate([rng.uniform(0.1, 0.35, n_dyn + n_static), np.zeros(n_wall)])
    static = np.array([False] * n_dyn + [True] * (n_static + n_wall))
    ids = np.concatenate([np.arange(n_dyn + n_static), -np.ones(n_wall, int)])
    state = RobotState(float(rng.uniform(-0.3, 0.3)), float(rng.uniform(-0.3, 0.3)), float(rng.uniform(-3, 3)))
    goal = rng.uniform([3.0, -2.0], [6.0, 2.0])
    return state, Obstacles(p, v, cov, r, static, ids), goal


IMPERFECT = dataclasses.replace(SIMULATION, uncertainty=dataclasses.replace(
    SIMULATION.uncertainty, execution=ExecutionModel(
        A=((0.9, 0.05, 0.02), (-0.03, 0.85, 0.0), (0.1, -0.05, 0.95)), d=(0.02, -0.01, 0.05),
        residual_speed_mps=(0.0, 0.3, 0.8), residual_bound_mps=(0.01, 0.03, 0.06))))


@pytest.mark.parametrize("params, rules", [(SIMULATION, PAPER_RULES), (IMPERFECT, PAPER_RULES), (PHYSICAL, PAPER_RULES),
                                           (SIMULATION, PlusRules()), (IMPERFECT, PlusRules()),
                                           # and with the liveness option:
                                           (SIMULATION, PlusRules(speed_governor=True)),
                                           (IMPERFECT, PlusRules(speed_governor=True))])
@pytest.mark.parametrize("shared", [True, False])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_vectorized_matches_reference(params, rules, shared, seed):
    state, obs, goal = scene(seed)
    current = ["GOAL", None, "PASS-R"][seed]
    img = imagine(state, obs, goal, params, modes=MODES7, shared=shared, current=current, rules=rules)
    ref = reference(state, obs, goal, params, MODES7, shared, current, rules)
    for b, r in enumerate(ref):
        np.testing.assert_allclose(img.p[b], r["p"], atol=1e-9)
        np.testing.assert_allclose(img.u[b], r["u"], atol=1e-9)
        for key, got in (("h_min", img.h_min), ("W", img.W), ("P", img.P), ("F", img.F), ("S", img.S),
                         ("J", img.J)):
            assert got[b] == pytest.approx(r[key], rel=1e-9, abs=1e-9), (MODES7[b], key)
    if rules == PAPER_RULES:        # rollout_paths imagines the paper's policies
        np.testing.assert_allclose(rollout_paths(state, obs, goal, params, ("REVERSE",))[0], img.p[-1], atol=1e-12)


def test_one_step_by_hand_eqs_10_16_17():
    """N = 1, no uncertainty terms: D = 0.15 + 0.25 + 0.10 = 0.5. Robot (0,0), goal (5,0), static obstacle (0.7,0).
    GOAL: u_0 = (0.8, 0, 0); q = (-0.7, 0), h = 0.49 - 0.25 = 0.24;
    gamma = 2 q.(v - 0) + alpha h = -1.12 + 1.5 * 0.24 = -0.76; |grad|^2 = 4 * 0.49 = 1.96;
    W = 0.76^2 / (1.96 + 0.001) = 0.294544; P = 5 - 4.92 = 0.08; F = 0; S = |u_0|^2 = 0.64; C_sw = 0;
    J = 0.294544 - 1.5 * 0.08 + 0.05 * 0.64 = 0.206544. States k = 0, 1: h = 0.24 and 0.62^2 - 0.25 = 0.1344."""
    unc = UncertaintyParams(tau95_s=0.0, beta=0.0, e_zoh_m=0.0, execution=ExecutionModel(
        residual_bound_mps=(0.0, 0.0)))
    # eq:behavior_feedback (11) literally
    params = dataclasses.replace(SIMULATION, N=1, uncertainty=unc)
    obs = Obstacles.from_lists([[0.7, 0.0]], r=0.25)
    img = imagine(RobotState(0, 0, 0), obs, np.array([5.0, 0.0]), params, current="GOAL")
    g = img.index("GOAL")
    np.testing.assert_allclose(img.u[g, 0], [0.8, 0.0, 0.0])
    assert img.W[g] == pytest.approx(0.76 ** 2 / 1.961)
    assert img.P[g] == pytest.approx(0.08)
    assert img.F[g] == 0.0 and img.S[g] == pytest.approx(0.64) and img.C_sw[g] == 0.0
    assert img.J[g] == pytest.approx(0.76 ** 2 / 1.961 - 0.12 + 0.032)
    assert img.h_min[g] == pytest.approx(0.1344)
    assert img.accepted[g]
    assert img.C_sw.tolist() == [0, 1, 1, 1, 1, 1]
    assert not img.available[img.index("YIELD")]          # static scene: YIELD is no candidate


@pytest.mark.parametrize("dist, accepted", [(math.sqrt(0.25 - 0.05), True), (math.sqrt(0.25 - 0.15), False)])
def test_barrier_acceptance_eq_16(dist, accepted):
    """With the robot at the goal (every command 0) and D = 0.5 (no uncertainty terms), h_min = dist^2 - 0.25:
    -0.05 >= -eps_h = -0.1 is accepted, -0.15 is rejected."""
    unc = UncertaintyParams(tau95_s=0.0, beta=0.0, e_zoh_m=0.0, execution=ExecutionModel(
        residual_bound_mps=(0.0, 0.0)))
    params = dataclasses.replace(SIMULATION, uncertainty=unc)
    obs = Obstacles.from_lists([[dist, 0.0]], r=0.25)
    img = imagine(RobotState(0, 0, 0), obs, np.array([0.05, 0.0]), params)
    np.testing.assert_allclose(img.h_min[:5], dist ** 2 - 0.25)
    assert img.accepted[:5].tolist() == [accepted] * 5
    assert img.F.tolist() == [0.0] * 6                    # standing still at the goal is not freezing


def test_noshared_uses_fixed_margin():
    obs = Obstacles.from_lists([[1.0, 0.0]], v=[[0.0, 0.5]], r=0.2, cov=np.eye(2) * 0.01, static=False)
    state, goal = RobotState(0, 0, 0), np.array([0.0, 0.1])   # at the goal: the robot stays at the origin
    img = imagine(state, obs, goal, SIMULATION, shared=False)
    # the obstacle moves 0.75 m in +y over 1.5 s; min h at k = 0: 1 - (0.15 + 0.2 + 0.1 + 0.3)^2
    assert img.h_min[0] == pytest.approx(1.0 - 0.75 ** 2)
    shared = imagine(state, obs, goal, SIMULATION, shared=True)
    # shared, u = 0: m_k = 0.5 * 0.1 + 2 sqrt(0.01 + 0.01 * 0.1 k) + 0.15 * 0.02 + 0.025 (eq:cov_prop (3),
    # eq:uncertainty_margin (21)),
    # D_k = 0.45 + m_k, ||q_k||^2 = 1 + (0.05 k)^2; e.g. k = 0: D = 0.728, h = 0.470016; the minimum is at k = 3:
    # D = 0.45 + 0.05 + 2 sqrt(0.013) + 0.028 = 0.756035, h = 1.0225 - 0.571589 = 0.450911
    k = np.arange(16)
    h = 1 + (0.05 * k) ** 2 - (0.45 + 0.05 + 2 * np.sqrt(0.01 + 0.001 * k) + 0.003 + 0.025) ** 2
    assert h[0] == pytest.approx(1.0 - 0.728 ** 2) and int(np.argmin(h)) == 3
    assert shared.h_min[0] == pytest.approx(h.min()) == pytest.approx(0.450911, abs=1e-6)


@pytest.mark.parametrize("cap_s, k_cap", [(0.0, 0), (0.5, 5), (1.5, 15)])
def test_prediction_cap_holds_the_covariance_growth_by_hand(cap_s, k_cap):
    """The rule prediction_cap (PlusRules, issue 25): eq:cov_prop (3) grows Sigma_k = Sigma_0 + q dt k I up to k_cap =
    cap_s / dt and holds it there, in the imagination's margins (eq:uncertainty_margin (21)); the scene of
    test_noshared_uses_fixed_margin (Sigma_0 = 0.01 I, q 0.01 m^2/s, dt 0.1 s, u = 0): m_k = 0.05 + 2 sqrt(0.01 +
    0.001 min(k, k_cap)) + 0.003 + 0.025, D_k = 0.45 + m_k, ||q_k||^2 = 1 + (0.05 k)^2. A cap at the horizon (1.5 s)
    changes nothing; the paper's big-cbf never holds it."""
    obs = Obstacles.from_lists([[1.0, 0.0]], v=[[0.0, 0.5]], r=0.2, cov=np.eye(2) * 0.01, static=False)
    state, goal = RobotState(0, 0, 0), np.array([0.0, 0.1])
    rules = dataclasses.replace(PAPER_RULES, prediction_cap=True, prediction_cap_s=cap_s)
    img = imagine(state, obs, goal, SIMULATION, rules=rules)
    k = np.arange(16)
    m = 0.05 + 2 * np.sqrt(0.01 + 0.001 * np.minimum(k, k_cap)) + 0.003 + 0.025
    np.testing.assert_allclose(img.margin[0, :, 0], m, rtol=1e-12)
    h = 1 + (0.05 * k) ** 2 - (0.45 + m) ** 2
    assert img.h_min[0] == pytest.approx(h.min(), abs=1e-12)
    paper = imagine(state, obs, goal, SIMULATION)
    assert (img.margin[0, -1, 0] < paper.margin[0, -1, 0]) == (k_cap < 15)


def test_prediction_cap_escapable_holds_only_the_obstacles_slower_than_v_max():
    """prediction_cap_scope "escapable" (PlusRules, issue 25): the cap holds eq:cov_prop (3) only for obstacles
    slower than v_max (0.8 m/s), which the robot can back away from. Robot at the origin; A at (1, 0.6) walking at
    0.5 m/s (held), B at (1, -0.6) at 1.2 m/s (growing as in the paper); Sigma_0 = 0.01 I, q 0.01 m^2/s, dt 0.1 s,
    cap at 0: YIELD stands still, so the margin moves only with the prediction term, 0 for A and 2 sqrt(0.01 +
    0.001 k) - 0.2 for B."""
    obs = Obstacles.from_lists([[1.0, 0.6], [1.0, -0.6]], v=[[0.5, 0.0], [-1.2, 0.0]], r=0.2,
                               cov=np.eye(2) * 0.01, static=False)
    state, goal = RobotState(0, 0, 0), np.array([0.0, 0.1])
    rules = dataclasses.replace(PAPER_RULES, prediction_cap=True, prediction_cap_s=0.0,
                                prediction_cap_scope="escapable")
    img = imagine(state, obs, goal, SIMULATION, rules=rules, modes=("YIELD",))
    paper = imagine(state, obs, goal, SIMULATION, modes=("YIELD",))
    k = np.arange(16)
    np.testing.assert_allclose(img.margin[0, :, 0] - img.margin[0, 0, 0], 0.0, atol=1e-12)
    np.testing.assert_allclose(img.margin[0, :, 1] - img.margin[0, 0, 1], 2 * np.sqrt(0.01 + 0.001 * k) - 0.2,
                               rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(img.margin[0, :, 1], paper.margin[0, :, 1])
    everyone = imagine(state, obs, goal, SIMULATION, modes=("YIELD",),
                       rules=dataclasses.replace(rules, prediction_cap_scope="all"))
    np.testing.assert_allclose(everyone.margin[0, :, 1] - everyone.margin[0, 0, 1], 0.0, atol=1e-12)


def test_prediction_cap_scope_is_checked(tmp_path):
    from bigcbf.config import load_run_config
    from bigcbf.errors import FieldError, UserError
    with pytest.raises(FieldError, match="must be one of all, escapable") as e:
        dataclasses.replace(PAPER_RULES, prediction_cap_scope="sideways")
    assert e.value.field == "prediction_cap_scope"
    f = tmp_path / "run.toml"
    f.write_text('[methods.big-cbf-plus]\nprediction_cap_scope = "sideways"\n')
    with pytest.raises(UserError, match=r"run.toml.*prediction_cap_scope.*must be one of"):
        load_run_config(f)


def test_empty_scene():
    img = imagine(RobotState(0, 0, 0), Obstacles.empty(), np.array([3.0, 0.0]), SIMULATION)
    assert np.all(np.isinf(img.h_min)) and np.all(img.W == 0)
    assert img.accepted.tolist() == [True] * 5 + [False]
    assert img.P[0] == pytest.approx(img.P.max())


@pytest.mark.parametrize("params", [IMPERFECT, PHYSICAL])
@pytest.mark.parametrize("shared", [True, False])
def test_margins_are_kappa_img_m_i_eq_14_15(params, shared):
    """Imagination.margin[b, k, i] = D_i - (r_R + r_i + d0): kappa_img m_i (eq:uncertainty_margin (21) at the imagined
    yaw, the command that moves the robot from state k (u_{N-1} at the terminal state) and the predicted covariance), or
    NoShared's fixed margin."""
    state, obs, goal = scene(4)
    img = imagine(state, obs, goal, params, modes=MODES7, shared=shared)
    unc = params.uncertainty
    N = params.N
    _, cov = predict_obstacles(obs, N, params.dt_s, q_sigma_for(obs, unc))
    dyn = bool(np.any(~obs.static & (obs.ids >= 0)))
    kap = unc.kappa_img if (unc.kappa_img_static is None or dyn) else unc.kappa_img_static
    assert img.margin.shape == (len(MODES7), N + 1, len(obs))
    for b in range(len(MODES7)):
        for k in range(N + 1):
            u = img.u[b, min(k, N - 1)]
            for i in range(len(obs)):
                want = (kap * uncertainty_radius(img.theta[b, k], u, obs.v[i], cov[k, i], unc) if shared
                        else params.noshared_margin_m)
                assert img.margin[b, k, i] == pytest.approx(float(want), rel=1e-9, abs=1e-12)
