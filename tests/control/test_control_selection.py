"""Behavior selection: hand-built situations in closed loop, dwell time, switching threshold, fallback, timing."""
import dataclasses
import math

import numpy as np
import pytest

from bigcbf.control import METHODS, BigCbfPlanner, CbfFilter, behavior_command
from bigcbf.control.big_cbf import BigCbfPlusPlanner
from bigcbf.control.imagination import Imagination
from bigcbf.control.selection import BehaviorSelector
from bigcbf.params import SIMULATION
from bigcbf.params.stack import PlusRules
from bigcbf.types import Obstacles, RobotState

P = SIMULATION
GOV = SIMULATION
GOVR = PlusRules(speed_governor=True)     # big-cbf-plus with the liveness option (governor.py)
PLUS = PlusRules()                        # big-cbf-plus as it ships (the rules that were big-cbf's before issue 24)
GOAL = np.array([5.0, 0.0])


def closed_loop(planner, obstacles_at, goal, seconds, state=RobotState(0.0, 0.0, 0.0)):
    """Kinematic closed loop at T_C: plan, filter, integrate u_safe exactly as commanded."""
    filt = CbfFilter(P)
    selections, min_h = [], math.inf
    for k in range(int(round(seconds / P.T_C_s))):
        t = k * P.T_C_s
        obs = obstacles_at(t)
        u_in, info = planner.plan(t, state, obs, goal)
        u, finfo = filt.filter(state, obs, u_in)
        assert np.all(np.isfinite(u)) and not finfo.infeasible
        min_h = min(min_h, finfo.h_min)
        if info.planned:
            selections.append(info.mode)
        c, s = math.cos(state.theta), math.sin(state.theta)
        v = np.array([c * u[0] - s * u[1], s * u[0] + c * u[1]])
        state = RobotState(state.px + P.T_C_s * v[0], state.py + P.T_C_s * v[1], state.theta + P.T_C_s * u[2], *u)
    return selections, state, min_h


def side(mode):
    return mode[-1] if mode.startswith(("PASS", "SIDE")) else None


def test_static_obstacle_dead_ahead_pass_kept_without_chattering():
    obs = Obstacles.from_lists([[2.0, 0.0]], r=0.3)
    sel, state, min_h = closed_loop(BigCbfPlanner(P), lambda t: obs, GOAL, 10 * P.T_B_s)
    assert len(sel) == 10
    assert sel[0].startswith(("PASS", "SIDE"))
    assert len({side(m) for m in sel} - {None}) == 1          # one side only: no left/right chattering
    # the filter slides the governed PASS along the post (governor.py): the discrete loop dips 0.009 m^2 into h < 0
    assert np.linalg.norm(state.p - obs.p[0]) > 0.45 and min_h > -P.eps_h_m2
    # it does get past the obstacle and on to the goal
    sel, state, _ = closed_loop(BigCbfPlanner(P), lambda t: obs, GOAL, 10.0)
    assert np.linalg.norm(state.p - GOAL) <= P.eps_g_m


def pedestrian(t):
    """Crossing right to left (+y) at 1 m/s, 1.5 m ahead, about to cut the robot's path."""
    return Obstacles.from_lists([[1.5, -1.0 + 1.0 * t]], v=[[0.0, 1.0]], r=0.25, cov=np.eye(2) * 0.01, static=False)


def test_crossing_pedestrian_yield_or_pass_behind():
    planner = BigCbfPlanner(P)
    planner.plan(0.0, RobotState(0, 0, 0), pedestrian(0.0), GOAL)
    assert planner.mode in ("YIELD", "PASS-R", "SIDE-R")     # behind it = on its right (where it comes from)
    img = planner.last_imagination
    assert not img.accepted[img.index("GOAL")]               # straight on would cut in front of it
    _, state, min_h = closed_loop(BigCbfPlanner(P), pedestrian, GOAL, 8.0)
    assert min_h > -P.eps_h_m2 and np.linalg.norm(state.p - GOAL) <= P.eps_g_m


def test_open_space_goal():
    sel, _, _ = closed_loop(BigCbfPlanner(P), lambda t: Obstacles.empty(), GOAL, 3.0)
    assert set(sel) == {"GOAL"}


def pocket():
    """Wall points of a dead end around the robot: a wall 0.6 m ahead, side walls 0.55 m left and right."""
    front = np.c_[np.full(13, 0.6), np.linspace(-0.6, 0.6, 13)]
    x = np.linspace(-0.4, 0.6, 11)
    pts = np.r_[front, np.c_[x, np.full(11, 0.55)], np.c_[x, np.full(11, -0.55)]]
    return Obstacles.from_lists(pts, r=0.0, ids=-np.ones(len(pts), int))


def test_everything_blocked_reverse_release():
    walls = pocket()
    planner = BigCbfPlanner(P)
    u, info = planner.plan(0.0, RobotState(0, 0, 0), walls, np.array([4.0, 0.0]))
    assert info.mode == "REVERSE" and info.planned
    assert not planner.last_imagination.accepted.any()
    np.testing.assert_allclose(u, [-P.v_release_mps, 0.0, 0.0], atol=1e-9)   # straight back out of the pocket
    assert info.path.shape == (P.N + 1, 2) and info.path[-1, 0] < -0.3
    sel, _, _ = closed_loop(BigCbfPlanner(P), lambda t: walls, np.array([4.0, 0.0]), 5.0)
    assert sel[0] == "REVERSE" and sel[-1] != "REVERSE"      # released, then a regular behavior again


def test_robot_inside_margin_rejects_everything():
    # D >= r_R + r_i + d0 + e_ZOH + e_exec(0) = 0.45 + 0.025 + 0.003 = 0.478 whatever the command, so
    # h <= 0.35^2 - 0.478^2 = -0.106 < -eps_h at k = 0 for every behavior
    obs = Obstacles.from_lists([[0.35, 0.0]], r=0.2)
    u, info = BigCbfPlanner(P).plan(0.0, RobotState(0, 0, 0), obs, GOAL)
    assert info.mode == "REVERSE" and u[0] < 0


def test_release_leaves_an_approaching_pedestrian_path_not_just_a_wall():
    """The blind-corner trap: a wall corner behind-right of the robot and a pedestrian coming down across the
    robot's front. The push backs off the wall corner (up and forward, into the person's path); the release the
    imagination chooses has the least accumulated barrier deficit, and it moves away from the path (x < 0)."""
    from bigcbf.control.imagination import choose_release, release_candidates
    state = RobotState(0.0, 0.0, 0.0)
    wall = np.c_[np.linspace(-0.6, 0.0, 7), np.full(7, -0.45)]
    obs = Obstacles.from_lists(np.r_[wall, [[0.7, 0.9]]], v=np.r_[np.zeros((7, 2)), [[0.0, -1.0]]],
                               r=np.r_[np.zeros(7), 0.25], cov=np.eye(2) * 0.01,
                               static=np.r_[np.ones(7, bool), False], ids=np.r_[-np.ones(7, int), 0])
    v, img, best = choose_release(state, obs, GOAL, P, rules=PLUS)      # the fan: big-cbf-plus's rule
    cand = release_candidates(state, obs, GOAL, P, PLUS)
    assert cand[0].imag > 0                              # the push: away from the wall, towards the path
    assert v[0] < 0 and np.hypot(*v) == pytest.approx(P.v_release_mps)
    assert img.deficit[best] == img.deficit.min() < img.deficit[0]
    # by hand: the deficit is the sum over k >= 1 of the most negative h, clipped at 0
    i = best
    assert img.deficit[i] >= 0 and (img.deficit == 0).sum() < len(cand)


def test_release_from_inside_a_static_margin_backs_straight_off():
    obs = Obstacles.from_lists([[0.35, 0.0]], r=0.2)
    planner = BigCbfPlanner(P)
    u, info = planner.plan(0.0, RobotState(0, 0, 0), obs, GOAL)
    assert info.mode == "REVERSE"
    np.testing.assert_allclose(u, [-P.v_release_mps, 0.0, 0.0], atol=1e-9)
    # between selections the release velocity is kept (in the world frame; the body command follows the yaw)
    u2, info2 = planner.plan(0.05, RobotState(-0.015, 0, math.pi / 2), obs, GOAL)
    assert not info2.planned and info2.mode == "REVERSE"
    np.testing.assert_allclose(u2, [0.0, P.v_release_mps, 0.0], atol=1e-9)


def fake(J, accepted, modes=("GOAL", "PASS-L", "PASS-R", "SIDE-L", "SIDE-R", "YIELD")):
    B = len(modes)
    z = np.zeros(B)
    return Imagination(modes, np.zeros((B, 2, 2)), np.zeros((B, 2)), np.zeros((B, 1, 3)), z, z, z, z, z, z,
                       np.array(J, float), np.ones(B, bool), np.array(accepted, bool))


def test_selector_dwell_threshold_and_rejection():
    s = BehaviorSelector(P)      # dwell 1.0 s, switch when J_best < J_cur - 0.1 |J_cur| - 0.05
    acc = [True] * 6
    assert s.select(0.0, fake([0, -1, 0, 0, 0, 0], acc)).mode == "PASS-L"
    sel = s.select(0.5, fake([-5, -1, 0, 0, 0, 0], acc))       # much better, but within the dwell time
    assert (sel.mode, sel.reason) == ("PASS-L", "kept-dwell")
    sel = s.select(1.0, fake([-1.1, -1, 0, 0, 0, 0], acc))     # -1.1 > -1 - 0.1 - 0.05: not enough
    assert (sel.mode, sel.reason) == ("PASS-L", "kept-threshold")
    sel = s.select(1.5, fake([-1.2, -1, 0, 0, 0, 0], acc))     # -1.2 < -1.15: switch
    assert (sel.mode, sel.switched) == ("GOAL", True)
    sel = s.select(2.0, fake([0, 0, 0, -3, 0, 0], [False, True, True, True, True, True]))  # current rejected
    assert (sel.mode, sel.reason) == ("SIDE-L", "current-rejected")
    sel = s.select(2.5, fake([0] * 6, [False] * 6))
    assert (sel.mode, sel.reason) == ("REVERSE", "fallback")
    sel = s.select(3.0, fake([0, 2, 2, 2, 2, 2], acc))
    assert sel.mode == "GOAL" and sel.switched                  # leaving the fallback needs no dwell
    s.reset()
    assert s.select(0.0, fake([1, 1, 1, 1, 1, 1], acc)).mode == "GOAL"     # ties: the first in order


def test_selection_clock_and_eq_5_regeneration():
    planner = BigCbfPlanner(P)
    obs = Obstacles.from_lists([[2.0, 0.3]], r=0.3)
    planned = []
    t = 0.0
    for k in range(41):
        t = k * P.T_C_s                                        # 0.05 steps: not exact in floating point
        state = RobotState(0.01 * k, 0.0, 0.0)
        u, info = planner.plan(t, state, obs, GOAL)
        planned.append(info.planned)
        # eq:online_behavior_command (8): between selections the retained policy is re-evaluated at the latest state
        np.testing.assert_allclose(u, behavior_command(info.mode, state, obs, GOAL, P))
        assert info.path.shape == (P.N + 1, 2) and info.planner_ms >= 0
    assert [k for k, p in enumerate(planned) if p] == [0, 10, 20, 30, 40]


def test_deterministic_after_reset():
    planner = METHODS.get("big-cbf")(P)
    runs = []
    for _ in range(2):
        planner.reset(7)
        runs.append(closed_loop(planner, pedestrian, GOAL, 3.0)[:2])
    assert runs[0][0] == runs[1][0] and runs[0][1] == runs[1][1]


def test_noshared_variant_runs_the_same_loop():
    planner = METHODS.get("big-cbf-noshared")(P)
    assert planner.name == "big-cbf-noshared" and not planner.shared
    obs = Obstacles.from_lists([[2.0, 0.0]], r=0.3)
    _, state, _ = closed_loop(planner, lambda t: obs, GOAL, 10.0)
    assert np.linalg.norm(state.p - GOAL) <= P.eps_g_m


def test_governed_static_obstacle_dead_ahead_one_side():
    obs = Obstacles.from_lists([[2.0, 0.0]], r=0.3)
    sel, state, min_h = closed_loop(BigCbfPlusPlanner(GOV, GOVR), lambda t: obs, GOAL, 10 * P.T_B_s)
    assert len(sel) == 10
    # the governed GOAL slows down in front of the post (governor.py) and is kept while it progresses; a sided
    # maneuver takes over before the post, on one side only: no left/right chattering
    assert any(m.startswith(("PASS", "SIDE")) for m in sel)
    assert len({side(m) for m in sel} - {None}) == 1
    # the filter slides the governed PASS along the post (governor.py): the discrete loop dips 0.009 m^2 into h < 0
    assert np.linalg.norm(state.p - obs.p[0]) > 0.45 and min_h > -P.eps_h_m2
    # it does get past the obstacle and on to the goal
    sel, state, _ = closed_loop(BigCbfPlusPlanner(GOV, GOVR), lambda t: obs, GOAL, 10.0)
    assert np.linalg.norm(state.p - GOAL) <= P.eps_g_m


def test_governed_crossing_pedestrian_pass_behind():
    planner = BigCbfPlusPlanner(GOV, GOVR)
    planner.plan(0.0, RobotState(0, 0, 0), pedestrian(0.0), GOAL)
    assert planner.mode in ("YIELD", "PASS-R", "SIDE-R")     # behind it = on its right (where it comes from)
    img = planner.last_imagination
    # straight on (governed: it slows down in front of the person) scores worse than going behind
    assert img.J[img.index("GOAL")] > img.J[img.index(planner.mode)]
    _, state, min_h = closed_loop(BigCbfPlusPlanner(GOV, GOVR), pedestrian, GOAL, 8.0)
    assert min_h > -P.eps_h_m2 and np.linalg.norm(state.p - GOAL) <= P.eps_g_m


def test_progress_along_the_maneuver_open_space_by_hand():
    """Imagination.along, sum_k dt e_k^T w_k (e_k the direction of the behavior's command at step k): in open space
    with ideal execution every step moves along its own command. GOAL from (0, 0) to (5, 0) at 0.8 m/s for
    N dt = 1.5 s: along = P = 1.2 m. SIDE-L, e = d_g (0.45 + 0.8 i), |e| = 0.917878, at v_side = 0.55 m/s:
    along = 0.55 * 1.5 = 0.825 m, while the goal distance shrinks by about 0.825 * 0.45 / 0.917878 = 0.404 m
    (less the second-order term 15 (0.055)^2 (0.8 / 0.917878)^2 / (2 * 5) = 0.0035 m)."""
    ideal = dataclasses.replace(GOV, uncertainty=dataclasses.replace(
        GOV.uncertainty, execution=dataclasses.replace(GOV.uncertainty.execution, A=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0),
                                                                                   (0.0, 0.0, 1.0)), d=(0.0, 0.0, 0.0))))
    from bigcbf.control.imagination import imagine
    img = imagine(RobotState(0, 0, 0), Obstacles.empty(), np.array([5.0, 0.0]), ideal, rules=GOVR)
    g, sl = img.index("GOAL"), img.index("SIDE-L")
    assert img.along[g] == pytest.approx(1.2) and img.P[g] == pytest.approx(1.2)
    assert img.along[sl] == pytest.approx(0.825)
    assert img.P[sl] == pytest.approx(0.825 * 0.45 / math.hypot(0.45, 0.8) - 0.0035, abs=5e-4)
    assert img.viable[:5].all()
    # without the option the Imagination carries no such field (the defaults keep the paper's reading)
    assert imagine(RobotState(0, 0, 0), Obstacles.empty(), np.array([5.0, 0.0]), P).along is None


def test_governed_pocket_goal_stalls_lateral_maneuvers_still_viable():
    """0.35 m from the pocket's end wall the governed behaviors are accepted (they stop short of the wall). GOAL gains
    less than v_freeze N dt = 0.05 * 15 * 0.1 = 0.075 m, along its own direction too: not viable. PASS and SIDE gain
    less than that in goal distance but move ~0.2 m along their own (sideways) direction before the side wall stops
    them: viable (this is what lets a sidestep in front of a wide obstacle be kept, docs/fidelity.md "Liveness";
    its cost, measured there: in a pocket the robot then shuttles sideways)."""
    walls = pocket()
    planner = BigCbfPlusPlanner(GOV, GOVR)
    u, info = planner.plan(0.0, RobotState(0.25, 0, 0), walls, np.array([4.0, 0.0]))
    img = planner.last_imagination
    stall = GOV.v_freeze_mps * GOV.N * GOV.dt_s
    assert img.accepted[:5].all() and np.all(img.P[:5] < stall)
    assert img.along[0] == pytest.approx(img.P[0]) and not img.viable[0]    # GOAL moves straight at the goal
    assert np.all(img.along[1:5] > 0.15) and img.viable[1:5].all()
    assert info.mode in ("PASS-L", "PASS-R", "SIDE-L", "SIDE-R")


def test_release_from_inside_a_static_margin_backs_off_towards_a_viable_maneuver():
    """Inside the post's margin every behavior is rejected. Straight back (the push) leaves the robot on the goal
    line behind the post; a diagonal back-off leaves it where a PASS is viable sooner: the release is chosen by the
    lowest J of a viable behavior imagined T_B after it (release_outlook)."""
    from bigcbf.control.imagination import choose_release, release_candidates, release_outlook
    obs = Obstacles.from_lists([[0.35, 0.0]], r=0.2)
    planner = BigCbfPlusPlanner(GOV, GOVR)
    u, info = planner.plan(0.0, RobotState(0, 0, 0), obs, GOAL)
    assert info.mode == "REVERSE"
    v, img, best = choose_release(RobotState(0, 0, 0), obs, GOAL, GOV, rules=GOVR)
    cand = release_candidates(RobotState(0, 0, 0), obs, GOAL, GOV, GOVR)
    J_after = release_outlook(img, obs, GOAL, GOV, rules=GOVR)
    assert np.isfinite(J_after).any() and J_after[best] == J_after.min()
    assert v == pytest.approx([cand[best].real, cand[best].imag])
    np.testing.assert_allclose(u[:2], v, atol=1e-9)                # body = world at yaw 0
    assert u[0] < 0 and np.hypot(*v) == pytest.approx(P.v_release_mps)
    # between selections the release velocity is kept (in the world frame; the body command follows the yaw)
    u2, info2 = planner.plan(0.05, RobotState(-0.015, 0, math.pi / 2), obs, GOAL)
    assert not info2.planned and info2.mode == "REVERSE"
    np.testing.assert_allclose(u2, [v[1], -v[0], 0.0], atol=1e-9)


def test_viable_is_accepted_and_progressing():
    """Imagination.viable: accepted (eq:behavior_acceptance (22)) and, for GOAL/PASS/SIDE, progress P
    (eq:behavior_terms (13)) of at least
    v_freeze N dt = 0.075 m unless the rollout ends in the goal region; YIELD is exempt. A frozen behavior is not
    retained; when nothing is viable the selector falls back to REVERSE."""
    modes = ("GOAL", "PASS-L", "PASS-R", "SIDE-L", "SIDE-R", "YIELD")
    B = len(modes)
    z = np.zeros(B)

    def img(P, accepted, reached):
        return Imagination(modes, np.zeros((B, 2, 2)), np.zeros((B, 2)), np.zeros((B, 1, 3)), z, z,
                           np.array(P, float), z, z, z, np.array([0.0, -1.0, 0.1, 0.2, 0.3, 0.4]), np.ones(B, bool),
                           np.array(accepted, bool), params_stall=(0.075, np.array(reached, bool)))

    a = img([0.2, 0.074, 0.076, 0.2, 0.2, 0.0], [True, True, True, True, False, True], [False] * 6)
    assert a.viable.tolist() == [True, False, True, True, False, True]
    b = img([0.01, 0.0, 0.0, 0.0, 0.0, 0.0], [True] * 5 + [False], [True] + [False] * 5)   # GOAL arrives
    assert b.viable.tolist() == [True, False, False, False, False, False]
    s = BehaviorSelector(P)
    assert s.select(0.0, a).mode == "GOAL"       # PASS-L has the lowest J but is frozen
    c = img([0.0] * 6, [True] * 5 + [False], [False] * 6)
    assert s.select(0.5, c).mode == "REVERSE"
