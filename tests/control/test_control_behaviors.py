"""eq:online_behavior_command (8) to eq:behavior_feedback (11): goal basis, behavior subgoals with the locally
relevant obstacle, bounded feedback; fallback."""
import math

import numpy as np
import pytest

from bigcbf.control.behaviors import (MODE_INDEX, behavior_command, closest_approach_c, feedback_velocity, goal_basis,
                                      mode_indices, obstacle_groups,
                                      policy_velocity, relevant_obstacle, release_velocity, subgoal_error)
from bigcbf.params import SIMULATION
from bigcbf.params.stack import PlusRules
from bigcbf.types import Obstacles, RobotState

P = SIMULATION
PLUS = PlusRules()      # big-cbf-plus: the by-hand tests of our PASS rules below (the paper's: test_paper_fidelity.py)
MODES7 = ("GOAL", "PASS-L", "PASS-R", "SIDE-L", "SIDE-R", "YIELD", "REVERSE")


def test_goal_basis_eq_6():
    d, n, dist = goal_basis(np.array([1.0, 1.0]), np.array([4.0, 5.0]))
    np.testing.assert_allclose(d, [0.6, 0.8])
    np.testing.assert_allclose(n, [-0.8, 0.6])          # left normal
    assert dist == pytest.approx(5.0)


def literal_eq8(e, vmax):
    """eq:behavior_feedback (11) exactly as printed: sat_vmax[ e/||e|| min(vmax, 2||e||) + 0.35 e ]."""
    e = np.asarray(e, float)
    n = np.linalg.norm(e)
    if n == 0:
        return np.zeros(2)
    v = e / n * min(vmax, 2.0 * n) + 0.35 * e
    nv = np.linalg.norm(v)
    return v if nv <= vmax else v * vmax / nv


def test_feedback_eq_8_by_hand():
    # e = (3, 4), ||e|| = 5: 0.8 + 1.75 = 2.55 > 0.8 -> saturated: 0.8 * (0.6, 0.8) = (0.48, 0.64)
    # e = (0.06, 0.08), ||e|| = 0.1: min(0.8, 0.2) + 0.035 = 0.235 -> 0.235 * (0.6, 0.8) = (0.141, 0.188)
    v = feedback_velocity(np.array([[3.0, 4.0], [0.06, 0.08], [0.0, 0.0], [1.0, 0.0]]), np.array([0.8, 0.8, 0.8, 0]))
    np.testing.assert_allclose(v, [[0.48, 0.64], [0.141, 0.188], [0, 0], [0, 0]], atol=1e-12)
    rng = np.random.default_rng(0)
    for _ in range(200):
        e, vmax = rng.normal(size=2) * rng.choice([0.05, 0.3, 3.0]), rng.uniform(0, 1)
        np.testing.assert_allclose(feedback_velocity(e[None], np.array([vmax]))[0], literal_eq8(e, vmax), atol=1e-12)


def test_subgoals_eq_7_obstacle_dead_ahead():
    """big-cbf-plus's PASS rules (in_way_band, pass_forward_beside, pass_group_reach). Robot (0,0), goal (5,0):
    d_g = (1,0), n_g = (0,1). Obstacle (2, 0.1), r 0.3: relevant (|c| = 0.1 <
    0.15 + 0.3 + 0.1 + 0.15 = 0.7). PASS forward: max(0.85, s_i = 2) = 2 (beside the obstacle).
    PASS-L: d_pass = max(0.3, 0.1 + 0.3 + 0.15 + 0.35) = 0.9, floor 0.15 + 0.3 + 0.35 = 0.8 -> offset 0.9.
    PASS-R: d_pass = max(0.3, -0.1 + 0.3 + 0.5) = 0.7 -> offset 0.8 (the floor)."""
    obs = Obstacles.from_lists([[2.0, 0.1]], r=0.3)
    p = np.zeros((7, 2))
    e = subgoal_error(mode_indices(MODES7), p, np.array([5.0, 0.0]), obs.p, obs.r, P, rules=PLUS)
    np.testing.assert_allclose(e, [[5, 0], [2.0, 0.9], [2.0, -0.8], [0.45, 0.8], [0.45, -0.8], [0, 0], [0, 0]])
    # an obstacle nearer than 0.85 m ahead: the paper's 0.85 m
    near = Obstacles.from_lists([[0.5, 0.1]], r=0.3)
    e = subgoal_error(mode_indices(("PASS-L",)), p[:1], np.array([5.0, 0.0]), near.p, near.r, P, rules=PLUS)
    np.testing.assert_allclose(e, [[0.85, 0.9]])


def test_subgoals_eq_7_obstacle_offset_to_one_side():
    """Obstacle (1.5, 0.45), r 0.1: in the way, 0.45 < 0.15 + 0.1 + 0.1 + 0.15 = 0.5 -> relevant; forward 1.5.
    PASS-L: d_pass = max(0.3, 0.45 + 0.1 + 0.15 + 0.35) = 1.05, floor 0.6 -> 1.05.
    PASS-R: max(0.3, -0.45 + 0.1 + 0.5) = 0.3, floor 0.6 -> 0.6.
    At (1.5, 0.6) it is not in the way (driving straight keeps the footprint 0.35 m > d0 + 0.15 m from it):
    PASS keeps its goal-directed 0.85 m."""
    obs = Obstacles.from_lists([[1.5, 0.45]], r=0.1)
    e = subgoal_error(mode_indices(("PASS-L", "PASS-R")), np.zeros((2, 2)), np.array([5.0, 0.0]), obs.p, obs.r, P, rules=PLUS)
    np.testing.assert_allclose(e, [[1.5, 1.05], [1.5, -0.6]])
    beside = Obstacles.from_lists([[1.5, 0.6]], r=0.1)
    e = subgoal_error(mode_indices(("PASS-L", "PASS-R")), np.zeros((2, 2)), np.array([5.0, 0.0]), beside.p,
                      beside.r, P, rules=PLUS)
    np.testing.assert_allclose(e, [[0.85, 0.0], [0.85, 0.0]])


def test_in_a_gap_the_relevant_obstacle_is_the_one_behind_it():
    """Staggered posts (r 0.2): a robot centred in a 0.98 m gap between (0.1, +-0.69) sees the next row's post at
    (1.5, 0.09) as the relevant one: the gap's posts are 0.69 > 0.15 + 0.2 + 0.1 + 0.15 = 0.6 off the goal line
    (with the former band d_pass_min = 0.3, 0.69 < 0.75 made a gap post relevant and PASS steered around its outside).
    PASS-R aims beside the next post: forward 1.5, offset max(0.3, -0.09 + 0.2 + 0.5) = 0.61, floor 0.7 -> 0.7."""
    obs = Obstacles.from_lists([[0.1, 0.69], [0.1, -0.69], [1.5, 0.09]], r=0.2)
    p = np.zeros((1, 2))
    d, _, _ = goal_basis(p, np.array([5.0, 0.0]))
    j, c, r = relevant_obstacle(p, d, obs.p, obs.r, P, rules=PLUS)
    assert j.tolist() == [2] and c[0] == pytest.approx(0.09)
    e = subgoal_error(mode_indices(("PASS-R",)), p, np.array([5.0, 0.0]), obs.p, obs.r, P, rules=PLUS)
    np.testing.assert_allclose(e, [[1.5, -0.7]])


def test_no_relevant_obstacle_pass_goes_for_the_goal():
    # behind the robot, beside the corridor, beyond the look-ahead: none is relevant
    obs = Obstacles.from_lists([[-1.0, 0.0], [1.0, 1.2], [4.0, 0.0]], r=0.2)
    p = np.zeros((2, 2))
    d, _, _ = goal_basis(p, np.array([5.0, 0.0]))
    j, _, _ = relevant_obstacle(p, d, obs.p, obs.r, P)
    assert j.tolist() == [-1, -1]
    e = subgoal_error(mode_indices(("PASS-L", "PASS-R")), p, np.array([5.0, 0.0]), obs.p, obs.r, P)
    np.testing.assert_allclose(e, [[0.85, 0.0], [0.85, 0.0]])
    # no obstacle at all (an empty scan): the same
    none = Obstacles.empty()
    e = subgoal_error(mode_indices(("PASS-L", "PASS-R")), p, np.array([5.0, 0.0]), none.p, none.r, P)
    np.testing.assert_allclose(e, [[0.85, 0.0], [0.85, 0.0]])
    v = behavior_command("PASS-L", RobotState(0, 0, 0), none, np.array([5.0, 0.0]), P)
    np.testing.assert_allclose(v, [0.8, 0.0, 0.0], atol=1e-12)


def test_relevant_obstacle_is_the_nearest_in_the_way():
    obs = Obstacles.from_lists([[2.5, 0.0], [1.2, -0.3], [0.8, 2.0]], r=0.2)
    p = np.array([[0.0, 0.0]])
    d, _, _ = goal_basis(p, np.array([0.0 + 5.0, 0.0]))
    j, c, r = relevant_obstacle(p, d, obs.p, obs.r, P)
    assert j.tolist() == [1] and c[0] == pytest.approx(-0.3) and r[0] == pytest.approx(0.2)


def test_goal_region_and_yield_command_zero():
    obs = Obstacles.from_lists([[1.0, 0.0]], r=0.2)
    idx = mode_indices(MODES7)
    v = policy_velocity(idx, np.tile([4.9, 0.05], (7, 1)), np.array([5.0, 0.0]), obs.p, obs.r, P)
    np.testing.assert_allclose(v, 0.0)              # 0.112 m from the goal: inside eps_g = 0.15
    v = policy_velocity(idx, np.zeros((7, 2)), np.array([5.0, 0.0]), obs.p, obs.r, P)
    np.testing.assert_allclose(v[MODE_INDEX["YIELD"]], 0.0)
    speeds = np.linalg.norm(v, axis=1)
    assert speeds[0] == pytest.approx(0.8) and speeds[3] == pytest.approx(0.55)   # per-behavior limits


def test_behavior_command_is_a_body_twist_eq_5():
    # theta = pi/2, goal straight "up" in odom: world velocity (0, 0.8) is body (0.8, 0)
    u = behavior_command("GOAL", RobotState(0, 0, math.pi / 2), Obstacles.empty(), np.array([0.0, 5.0]), P)
    np.testing.assert_allclose(u, [0.8, 0.0, 0.0], atol=1e-12)
    with pytest.raises(ValueError, match="unknown behavior"):
        behavior_command("FLY", RobotState(0, 0, 0), Obstacles.empty(), np.array([1.0, 0.0]), P)


def test_release_velocity():
    # an obstacle 0.3 m ahead (inside r_R + r_i + d0 + release_range = 0.85): pushed straight back
    v = release_velocity(np.zeros((1, 2)), np.array([5.0, 0.0]), np.array([[0.3, 0.0]]), np.array([0.1]), P)
    np.testing.assert_allclose(v, [[-0.3, 0.0]], atol=1e-12)
    # two obstacles: weights 0.85 - 0.5 = 0.35 (from +y) and 0.85 - 0.4 = 0.45 (from +x): direction -(0.45, 0.35)
    v = release_velocity(np.zeros((1, 2)), np.array([5.0, 0.0]), np.array([[0.0, 0.5], [0.4, 0.0]]),
                         np.array([0.1, 0.1]), P)
    np.testing.assert_allclose(v[0], -0.3 * np.array([0.45, 0.35]) / math.hypot(0.45, 0.35))
    # nothing close: straight back from the goal
    v = release_velocity(np.zeros((1, 2)), np.array([0.0, 5.0]), np.zeros((0, 2)), np.zeros(0), P)
    np.testing.assert_allclose(v, [[0.0, -0.3]], atol=1e-12)


def test_pass_clears_the_whole_group_of_a_wide_obstacle():
    """A wall 2 m wide across the goal line, seen as points of radius 0 every 0.2 m from y = -1 to 1 at x = 2:
    one group (gaps 0.2 < 2 (0.15 + 0.1) + 0.1). PASS-L aims past its left end: extent 1.0 (the point at y = 1),
    d_pass = 1.0 + 0.15 + 0.35 = 1.5; PASS-R likewise -1.5; forward 0.85 (a group). A lone point would give only
    max(0.3, 0.5, 0.5), forward max(0.85, 2) = 2."""
    ys = np.linspace(-1.0, 1.0, 11)
    wall = Obstacles.from_lists(np.stack([np.full(11, 2.0), ys], 1), r=0.0, ids=-np.ones(11, int))
    e = subgoal_error(mode_indices(("PASS-L", "PASS-R")), np.zeros((2, 2)), np.array([5.0, 0.0]), wall.p, wall.r, P, rules=PLUS)
    np.testing.assert_allclose(e, [[0.85, 1.5], [0.85, -1.5]])   # a group: the paper's 0.85 m forward
    lone = wall.subset([5])
    e1 = subgoal_error(mode_indices(("PASS-L",)), np.zeros((1, 2)), np.array([5.0, 0.0]), lone.p, lone.r, P, rules=PLUS)
    np.testing.assert_allclose(e1, [[2.0, 0.5]])                  # a lone point: beside it, 2 m ahead


def test_obstacle_groups_split_at_passable_gaps():
    """Gaps: 0.3 (< 0.6: same group), then 1.0 (>= 0.6: a new group); radii count against the gap."""
    labels = obstacle_groups(np.array([[0, 0], [0, 0.3], [0, 1.3], [3, 0]]), np.array([0, 0, 0, 0.2]), P)
    assert labels[0] == labels[1] and labels[1] != labels[2] and len(set(labels)) == 3


def test_release_from_a_moving_obstacle_is_sideways():
    """A pedestrian 0.4 m to the robot's left walking in -y (towards the robot), weight 0.85 - 0.4 = 0.45:
    backing away would mean -y, along its path; the release goes out of its path instead. Its velocity (0, -1):
    right-hand normal (-1, 0); the robot (q = (0, -0.4)) is exactly on the path line -> to the pedestrian's right,
    i.e. -x at 0.3 m/s. A pedestrian at q = (0.2, -0.4) (robot to its left of the line) -> +x."""
    v = release_velocity(np.zeros((1, 2)), np.array([5.0, 0.0]), np.array([[0.0, 0.4]]), np.array([0.25]), P,
                         obs_v=np.array([[0.0, -1.0]]))
    np.testing.assert_allclose(v, [[-0.3, 0.0]], atol=1e-12)
    v = release_velocity(np.zeros((1, 2)), np.array([5.0, 0.0]), np.array([[-0.2, 0.4]]), np.array([0.25]), P,
                         obs_v=np.array([[0.0, -1.0]]))
    np.testing.assert_allclose(v, [[0.3, 0.0]], atol=1e-12)


def test_the_closest_approach_by_hand():
    """q(t) = q0 - v t, t in [0, H]: a walker 2 m ahead coming head-on at 1.3 m/s passes through the robot at
    t = 1.54 s (0 m within 2.5 s, 0.05 m short of it within 1.5 s: 2 - 1.95); one passing 0.5 m to the side is
    closest at 0.5 m; a receding or static one is closest now."""
    q = np.array([[-2.0 + 0j, -2.0 - 0.5j, -2.0 + 0j, 1.0 + 1.0j]])          # p - p_i for walkers at (2, 0), ...
    v = np.array([-1.3 + 0j, -1.3 + 0j, 1.3 + 0j, 0j])
    np.testing.assert_allclose(closest_approach_c(q, v, 2.5), [[0.0, 0.5, 2.0, math.sqrt(2)]], atol=1e-12)
    np.testing.assert_allclose(closest_approach_c(q, v, 1.5)[0, 0], 2.0 - 1.3 * 1.5, atol=1e-12)


def test_release_ahead_pushes_out_of_the_path_of_a_walker_still_far_away():
    """The rule release_ahead: a walker 2 m ahead (r 0.25), coming at 1.3 m/s straight at the robot, the goal
    beyond it. Now it is beyond r_R + r_i + d0 + release_range_m = 0.15 + 0.25 + 0.10 + 0.5 = 1.0 m: no push,
    straight back from the goal (-x, along its path). Within 2.5 s it comes through the robot (closest 0), weight
    1.0, and the push is sideways (release_sideways: the robot on its path line -> the walker's right, (0, +1)
    for a walker heading -x); at 0.3 m/s. A walker going away pushes nothing either way."""
    p0, goal = np.zeros((1, 2)), np.array([5.0, 0.0])
    obs, r, vel = np.array([[2.0, 0.0]]), np.array([0.25]), np.array([[-1.3, 0.0]])
    np.testing.assert_allclose(release_velocity(p0, goal, obs, r, P, obs_v=vel), [[-0.3, 0.0]], atol=1e-12)
    np.testing.assert_allclose(release_velocity(p0, goal, obs, r, P, obs_v=vel, ahead_v=vel, ahead_s=2.5),
                               [[0.0, 0.3]], atol=1e-12)
    np.testing.assert_allclose(release_velocity(p0, goal, obs, r, P, obs_v=-vel, ahead_v=-vel, ahead_s=2.5),
                               [[-0.3, 0.0]], atol=1e-12)


def test_release_ahead_is_a_plus_rule_off_by_default_and_reads_the_rollout_horizon():
    from bigcbf.control.imagination import release_candidates
    assert PlusRules().release_ahead is False
    state = RobotState(0.0, 0.0, 0.0)
    walker = Obstacles.from_lists([[2.0, 0.0]], v=[[-1.3, 0.0]], r=0.25, static=False, ids=[0])
    on = PlusRules(release_ahead=True)
    assert release_candidates(state, walker, np.array([5.0, 0.0]), P, PLUS)[0] == pytest.approx(-0.3)
    assert release_candidates(state, walker, np.array([5.0, 0.0]), P, on)[0] == pytest.approx(0.3j)
    # the horizon: long_horizon_s (2.5 s) with long_horizon, N dt (1.5 s) without: a walker 4 m away comes within
    # 0.75 m of the robot in 2.5 s (weight 0.25: sideways), within 2.05 m in 1.5 s (no weight: straight back)
    short = PlusRules(release_ahead=True, long_horizon=False)
    far = Obstacles.from_lists([[4.0, 0.0]], v=[[-1.3, 0.0]], r=0.25, static=False, ids=[0])
    assert release_candidates(state, far, np.array([5.0, 0.0]), P, on)[0] == pytest.approx(0.3j)     # 4 - 3.25
    assert release_candidates(state, far, np.array([5.0, 0.0]), P, short)[0] == pytest.approx(-0.3)  # 4 - 1.95


def test_the_in_way_band_is_a_plus_rule_and_noshared_keeps_the_paper_s():
    """big-cbf-plus (rule in_way_band): an obstacle is in the way within r_R + r_i + d0 + 0.15 m of the goal line;
    big-cbf and big-cbf-noshared (the paper's rules): within r_R + r_i + d0, the same for both (NoShared differs only
    in the imagination margin). An obstacle (1.0, 0.45), r 0.1 (within both look-aheads): 0.45 < 0.15 + 0.1 + 0.1 + 0.15 = 0.5 for plus, not
    < 0.35 for the paper's; (1.0, 0.3): in the way for all."""
    from bigcbf.control.big_cbf import BigCbfPlanner, BigCbfPlusPlanner

    shared, noshared, plus = BigCbfPlanner(P), BigCbfPlanner(P, shared=False), BigCbfPlusPlanner(P)
    assert shared.params is noshared.params is P and shared.rules == noshared.rules
    p = np.zeros((1, 2))
    d, _, _ = goal_basis(p, np.array([5.0, 0.0]))
    for y, paper_in_way in ((0.45, False), (0.3, True)):
        obs = Obstacles.from_lists([[1.0, y]], r=0.1)
        assert relevant_obstacle(p, d, obs.p, obs.r, P, plus.rules)[0].tolist() == [0]
        for planner in (shared, noshared):
            assert relevant_obstacle(p, d, obs.p, obs.r, P, planner.rules)[0].tolist() == [0 if paper_in_way else -1]

def test_alone_in_group_by_hand():
    """Groups [0, 0, 1, 2, 2, 3]: obstacles 2 and 5 are alone; an empty scan has none."""
    from bigcbf.control.behaviors import alone_in_group

    assert alone_in_group([0, 0, 1, 2, 2, 3]).tolist() == [False, False, True, False, False, True]
    assert alone_in_group(np.zeros(0, int)).shape == (0,)
