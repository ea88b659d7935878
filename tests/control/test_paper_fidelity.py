"""``big-cbf`` is the paper as written (issue 24): one test per equation of Sec. III that the behaviors, the
imagination and the selection implement, by hand values, with every rule of ours off (``PAPER_RULES``); and
BIG-CBF-NoShared differs from BIG-CBF only in the imagination's margin (Sec. IV-C)."""
import dataclasses
import math

import numpy as np
import pytest

from bigcbf.control.behaviors import (BEHAVIORS, behavior_command, feedback_velocity, mode_indices, policy_velocity,
                                      subgoal_error)
from bigcbf.control.big_cbf import BigCbfPlanner, BigCbfPlusPlanner
from bigcbf.control.imagination import Imagination, imagine
from bigcbf.control.methods import make_planner
from bigcbf.control.selection import BehaviorSelector
from bigcbf.params import SIMULATION, ExecutionModel, UncertaintyParams
from bigcbf.params.stack import PAPER_RULES, PlusRules, default_stack_params
from bigcbf.types import Obstacles, RobotState

P = SIMULATION
GOAL = np.array([5.0, 0.0])
MODES7 = BEHAVIORS + ("REVERSE",)
#: no uncertainty terms and ideal execution: D_i = r_R + r_i + d0
BARE_UNC = UncertaintyParams(tau95_s=0.0, beta=0.0, e_zoh_m=0.0, execution=ExecutionModel(residual_bound_mps=(0.0, 0.0)))


def test_the_three_methods_and_their_rules():
    """big-cbf and big-cbf-noshared run every rule of ours off; big-cbf-plus its switches (the former big-cbf)."""
    big, nos, plus = (make_planner(m, P) for m in ("big-cbf", "big-cbf-noshared", "big-cbf-plus"))
    assert big.rules == nos.rules == PAPER_RULES and not any(PAPER_RULES.switches.values())
    assert big.shared and not nos.shared and big.params is nos.params is P
    assert isinstance(plus, BigCbfPlusPlanner) and plus.rules == PlusRules() and plus.shared
    assert plus.name == "big-cbf-plus" and big.name == "big-cbf"
    assert make_planner("big-cbf-plus", P, PlusRules(side_commitment=False)).rules.side_commitment is False


def test_table_i_values():
    """Table I as the stack's defaults, in the preset and in the twin-calibrated default profile (which replaces
    only tau95 and the execution model)."""
    for p in (P, default_stack_params()):
        assert (p.T_B_s, p.T_C_s, p.N, p.dt_s) == (0.5, 0.05, 15, 0.1)
        assert (p.eps_g_m, p.v_freeze_mps, p.eps_h_m2) == (0.15, 0.05, 0.10)
        assert p.weights == (1.0, 1.5, 3.0, 0.5, 0.05)
        u = p.uncertainty
        assert (u.d0_m, u.beta, u.e_zoh_m, u.kappa_img, u.kappa_exec) == (0.10, 2.0, 0.025, 1.0, 1.0)
    assert P.uncertainty.tau95_s == 0.10


def test_subgoals_eq_10_by_hand():
    """eq:behavior_subgoals (10), robot (0, 0), goal (5, 0): d_g = (1, 0), n_g = (0, 1). Obstacle (1.0, 0.1), r 0.3:
    the locally relevant one (its surface 0.7 m ahead, within v_max N dt = 1.2 m; the goal line passes 0.1 m from it,
    within r_R + r_i + d0 = 0.55 m). GOAL: p_g - p = (5, 0). PASS-sigma: 0.85 d_g + sigma max(d_pass = 0.30,
    r_R + r_i + 0.35 = 0.80) n_g = (0.85, +-0.80). SIDE-sigma: 0.45 d_g + 0.80 sigma n_g. YIELD: 0."""
    obs = Obstacles.from_lists([[1.0, 0.1]], r=0.3)
    e = subgoal_error(mode_indices(MODES7), np.zeros((7, 2)), GOAL, obs.p, obs.r, P)
    np.testing.assert_allclose(e, [[5, 0], [0.85, 0.8], [0.85, -0.8], [0.45, 0.8], [0.45, -0.8], [0, 0], [0, 0]],
                               atol=1e-12)
    # a constant d_pass larger than the floor is taken as it is (the max of eq. 10)
    wide = dataclasses.replace(P, d_pass_min_m=1.1)
    e = subgoal_error(mode_indices(("PASS-L", "PASS-R")), np.zeros((2, 2)), GOAL, obs.p, obs.r, wide)
    np.testing.assert_allclose(e, [[0.85, 1.1], [0.85, -1.1]], atol=1e-12)
    # not in the way (0.6 m off the goal line > r_R + r_i + d0 = 0.55 m), or beyond the look-ahead (surface 1.7 m
    # ahead): no relevant obstacle, PASS keeps its goal-directed 0.85 d_g
    for where in ([1.0, 0.6], [2.0, 0.1]):
        o = Obstacles.from_lists([where], r=0.3)
        e = subgoal_error(mode_indices(("PASS-L",)), np.zeros((1, 2)), GOAL, o.p, o.r, P)
        np.testing.assert_allclose(e, [[0.85, 0.0]], atol=1e-12)
    # in another frame: robot (1, 1), goal (4, 5): d_g = (0.6, 0.8), n_g = (-0.8, 0.6); an obstacle r 0.2 1 m ahead
    # on the goal line: PASS-L 0.85 d_g + 0.70 n_g = (-0.05, 1.10), SIDE-R 0.45 d_g - 0.80 n_g = (0.91, -0.12)
    o = Obstacles.from_lists([[1.6, 1.8]], r=0.2)
    e = subgoal_error(mode_indices(("PASS-L", "SIDE-R")), np.ones((2, 2)), np.array([4.0, 5.0]), o.p, o.r, P)
    np.testing.assert_allclose(e, [[-0.05, 1.10], [0.91, -0.12]], atol=1e-12)
    # the paper's 0.85 m forward and the obstacle's own offset whatever our PASS rules would do: a wall of points
    # (radius 0) across the goal line is passed at r_R + 0 + 0.35 = 0.5 m (d_pass 0.3 below it), 0.85 m ahead
    ys = np.linspace(-1.0, 1.0, 11)
    wall = Obstacles.from_lists(np.stack([np.full(11, 0.9), ys], 1), r=0.0, ids=-np.ones(11, int))
    e = subgoal_error(mode_indices(("PASS-L", "PASS-R")), np.zeros((2, 2)), GOAL, wall.p, wall.r, P)
    np.testing.assert_allclose(e, [[0.85, 0.5], [0.85, -0.5]], atol=1e-12)
    e = subgoal_error(mode_indices(("PASS-L", "PASS-R")), np.zeros((2, 2)), GOAL, wall.p, wall.r, P,
                      rules=PlusRules())                     # big-cbf-plus: past the group's end instead
    np.testing.assert_allclose(e, [[0.85, 1.5], [0.85, -1.5]], atol=1e-12)


def literal_eq_11(e, v_max):
    e = np.asarray(e, float)
    n = np.linalg.norm(e)
    v = e / n * min(v_max, 2.0 * n) + 0.35 * e
    return v if np.linalg.norm(v) <= v_max else v * (v_max / np.linalg.norm(v))


def test_feedback_eq_11_by_hand():
    """eq:behavior_feedback (11): v = sat_vmax[e/||e|| min(v_max, 2||e||) + 0.35 e]. e = (0.3, 0.4), v_max 0.8:
    0.8 (0.6, 0.8) + (0.105, 0.14) = (0.585, 0.78), norm 0.975 -> saturated: (0.48, 0.64). e = (0.03, 0.04):
    0.1 (0.6, 0.8) + (0.0105, 0.014) = (0.0705, 0.094) (norm 0.1175, not saturated)."""
    np.testing.assert_allclose(feedback_velocity([[0.3, 0.4]], [0.8]), [[0.48, 0.64]], atol=1e-12)
    np.testing.assert_allclose(feedback_velocity([[0.03, 0.04]], [0.8]), [[0.0705, 0.094]], atol=1e-12)
    rng = np.random.default_rng(3)
    for _ in range(100):
        e, vmax = rng.normal(size=2) * rng.choice([0.02, 0.3, 3.0]), rng.uniform(0.1, 1.0)
        np.testing.assert_allclose(feedback_velocity(e[None], [vmax])[0], literal_eq_11(e, vmax), atol=1e-12)
    # the policies pi_b: SIDE-L from (0, 0) with nothing around: e = (0.45, 0.8) at v_b^max = 0.55 (saturated);
    # the body command at yaw pi/2 is R^T v; YIELD commands zero
    v = policy_velocity(mode_indices(("SIDE-L", "YIELD")), np.zeros((2, 2)), GOAL, np.zeros((0, 2)), np.zeros(0), P)
    np.testing.assert_allclose(v[0], literal_eq_11([0.45, 0.8], 0.55), atol=1e-12)
    np.testing.assert_allclose(v[1], 0.0)
    u = behavior_command("SIDE-L", RobotState(0, 0, math.pi / 2), Obstacles.empty(), GOAL, P)
    np.testing.assert_allclose(u, [v[0, 1], -v[0, 0], 0.0], atol=1e-12)


def test_cost_eq_14_with_table_i_weights():
    """eq:behavior_cost (14) with Table I's (w_W, w_P, w_F, w_sw, w_S) = (1, 1.5, 3.0, 0.5, 0.05), N = 1, no obstacle
    (W = 0), current mode PASS-L. GOAL: u_0 = (0.8, 0), P = 0.08 m, F = 0, S = 0.64, C_sw = 1:
    J = -1.5 * 0.08 + 0.5 + 0.05 * 0.64 = 0.412. YIELD: u_0 = 0, P = 0, F = 1 (frozen outside the goal region),
    S = 0, C_sw = 1: J = 3 + 0.5 = 3.5. PASS-L (the current mode, C_sw = 0): e = (0.85, 0): u_0 = (0.8, 0), J =
    -0.12 + 0.032 = -0.088."""
    params = dataclasses.replace(P, N=1, uncertainty=BARE_UNC)
    img = imagine(RobotState(0, 0, 0), Obstacles.empty(), GOAL, params, current="PASS-L")
    g, y, pl = img.index("GOAL"), img.index("YIELD"), img.index("PASS-L")
    assert (img.P[g], img.F[g], img.S[g], img.C_sw[g], img.W[g]) == pytest.approx((0.08, 0.0, 0.64, 1.0, 0.0))
    assert img.J[g] == pytest.approx(0.412) and img.J[y] == pytest.approx(3.5) and img.J[pl] == pytest.approx(-0.088)
    w = np.array(P.weights)
    terms = np.stack([img.W, -img.P, img.F, img.C_sw, img.S])
    np.testing.assert_allclose(img.J, w @ terms, atol=1e-12)


@pytest.mark.parametrize("d2, accepted", [(0.16, True), (0.14, False)])
def test_acceptance_eq_22_eps_h(d2, accepted):
    """eq:behavior_acceptance (22) with eps_h = 0.10 m^2 (Table I): a candidate is rejected when min_{k,i} h < -eps_h.
    A static obstacle r 0.25 at distance d behind the robot (D = 0.5 without uncertainty terms; GOAL drives away,
    so the minimum is at k = 0): h = d^2 - 0.25 = -0.09 (accepted) or -0.11 (rejected)."""
    params = dataclasses.replace(P, uncertainty=BARE_UNC)
    obs = Obstacles.from_lists([[-math.sqrt(d2), 0.0]], r=0.25)
    img = imagine(RobotState(0, 0, 0), obs, GOAL, params)
    g = img.index("GOAL")
    assert img.h_min[g] == pytest.approx(d2 - 0.25)
    assert bool(img.accepted[g]) is accepted and params.eps_h_m2 == 0.10


def fake(J, accepted=(True,) * 6):
    modes = BEHAVIORS
    B = len(modes)
    z = np.zeros(B)
    return Imagination(modes, np.zeros((B, 2, 2)), np.zeros((B, 2)), np.zeros((B, 1, 3)), z, z, z, z, z, z,
                       np.array(J, float), np.ones(B, bool), np.array(accepted, bool))


def test_dwell_and_threshold_rule():
    """"The lowest-cost accepted candidate is selected subject to a minimum dwell time and a relative
    switching-improvement threshold" (dwell 1 s, J_best < J_cur - 0.1 |J_cur| - 0.05: paper silent values); all
    rejected: the reverse-release fallback. No side commitment in big-cbf: after the dwell PASS-R replaces PASS-L by
    the threshold alone; big-cbf-plus's rule side_commitment asks for w_sw more."""
    paper, plus = BehaviorSelector(P, PAPER_RULES), BehaviorSelector(P, PlusRules())
    for s in (paper, plus):
        assert s.select(0.0, fake([0, -1, 0, 0, 0, 0])).mode == "PASS-L"
        sel = s.select(0.5, fake([0, -1, -9, 0, 0, 0]))                  # within the dwell time
        assert (sel.mode, sel.reason) == ("PASS-L", "kept-dwell")
        sel = s.select(1.0, fake([0, -1, -1.14, 0, 0, 0]))              # -1.14 > -1 - 0.1 - 0.05
        assert sel.mode == "PASS-L"
    assert paper.select(1.5, fake([0, -1, -1.2, 0, 0, 0])).mode == "PASS-R"     # -1.2 < -1.15: switch
    assert plus.select(1.5, fake([0, -1, -1.2, 0, 0, 0])).mode == "PASS-L"      # needs < -1.65
    assert plus.select(2.0, fake([0, -1, -1.7, 0, 0, 0])).mode == "PASS-R"
    assert paper.select(2.0, fake([0] * 6, [False] * 6)).mode == "REVERSE"


def record_states(monkeypatch, scenario, seconds):
    """The (state, obstacles, goal) of every behavior selection of a short real big-cbf episode."""
    from bigcbf.episode import Episode
    from bigcbf.scenario import load_scenario

    seen = []
    real = BigCbfPlanner.select

    def spy(self, t, state, obstacles, goal):
        seen.append((state, obstacles, np.array(goal, float)))
        return real(self, t, state, obstacles, goal)

    monkeypatch.setattr(BigCbfPlanner, "select", spy)
    Episode(load_scenario(scenario, 0), "big-cbf", 0, P, time_limit_s=seconds).run()
    monkeypatch.setattr(BigCbfPlanner, "select", real)
    return seen


def test_noshared_differs_only_in_the_margin(monkeypatch):
    """Sec. IV-C: NoShared "retains the same behavior library, feedback policies, horizon, switching logic, and
    final hard CBF as BIG-CBF, but replaces [eq:uncertainty_margin (21)] with a fixed 0.30-m geometric margin". With
    the uncertainty terms made a constant (tau95 = beta = e_exec = 0, e_ZOH = 0.3 m, kappa_img 1: kappa_img m_i =
    0.3 m for every obstacle and command) the two margins are equal, and on states recorded from real episodes
    (a crowd and the sidestepping scene) the two imagine the same scores and select the same behaviors, cycle
    after cycle. With the default margins they differ (the test can fail)."""
    states = record_states(monkeypatch, "crowd_crossing", 3.0) + record_states(monkeypatch, "required_sidestepping",
                                                                               3.0)
    assert len(states) >= 10 and any(len(o) for _, o, _ in states)
    equal = dataclasses.replace(P, noshared_margin_m=0.3, uncertainty=dataclasses.replace(
        BARE_UNC, e_zoh_m=0.3))
    big, nos = BigCbfPlanner(equal, shared=True), BigCbfPlanner(equal, shared=False)
    differ = False
    for k, (state, obs, goal) in enumerate(states):
        t = 0.5 * k
        a, b = big.select(t, state, obs, goal), nos.select(t, state, obs, goal)
        assert a == b, k
        ia, ib = big.last_imagination, nos.last_imagination
        np.testing.assert_allclose(ia.margin, ib.margin, rtol=0, atol=1e-12)
        np.testing.assert_allclose(ia.J, ib.J, rtol=1e-12, atol=1e-12)
        assert (ia.accepted == ib.accepted).all()
        da = imagine(state, obs, goal, P, shared=True)
        db = imagine(state, obs, goal, P, shared=False)
        differ |= len(obs) > 0 and not np.allclose(da.h_min, db.h_min)
    assert differ
