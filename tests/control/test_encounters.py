"""Issue 25 item 1: encounters (bigcbf/control/encounters.py), big-cbf-plus's encounter commitment and executed-speed
rules, and the switches-per-encounter metric; big-cbf keeps neither."""
from __future__ import annotations

import math

import numpy as np
import pytest

from bigcbf import run_episode
from bigcbf.control.big_cbf import BigCbfPlanner, BigCbfPlusPlanner
from bigcbf.control.encounters import EncounterSideRecorder, EncounterTracker
from bigcbf.control.executed_speed import SCALES, judge_at_executed_speed, speed_params
from bigcbf.control.imagination import Imagination, imagine
from bigcbf.control.selection import BehaviorSelector
from bigcbf.params.stack import PAPER_RULES, SIMULATION, PlusRules, default_stack_params
from bigcbf.types import Obstacles, RobotState

P = SIMULATION
GOAL = (6.0, 0.0)


def _post(x, y, ident=0, r=0.2, v=(0.0, 0.0)):
    return Obstacles.from_lists([[x, y]], v=[v], r=r, ids=[ident])


def test_a_post_ahead_is_one_encounter_until_it_is_behind_the_robot():
    tr = EncounterTracker(P)
    enc = tr.update(0.0, (0.0, 0.0), GOAL, _post(2.0, 0.0))
    assert enc is not None and tr.opened == 1
    # beside it (no longer in the way: the robot moved 0.8 m left) the encounter stays current
    assert tr.update(1.0, (2.0, 0.8), GOAL, _post(2.0, 0.0)) is enc
    # 0.4 m behind: not yet behind by its clearance r_R + r + d0 = 0.45 m
    assert tr.update(1.5, (2.4, 0.5), GOAL, _post(2.0, 0.0)) is enc
    assert tr.update(2.0, (2.5, 0.3), GOAL, _post(2.0, 0.0)) is None and tr.open == []


def test_a_new_track_id_within_the_gate_of_the_predicted_position_inherits_the_encounter():
    tr = EncounterTracker(P)
    walker = _post(1.5, 0.0, ident=3, v=(0.4, 0.0))
    enc = tr.update(0.0, (0.0, 0.0), GOAL, walker)
    # one second later the walker (predicted at x = 1.9) comes back as track 7 at x = 2.0: the same encounter
    assert tr.update(1.0, (0.5, 0.0), GOAL, _post(2.0, 0.05, ident=7, v=(0.4, 0.0))) is enc
    assert enc.ids == frozenset({7})
    # a track far from every prediction is a new encounter
    far = tr.update(1.2, (0.5, 0.0), GOAL, _post(3.5, 0.0, ident=9))
    assert far is not enc and tr.opened == 2


def test_posts_the_footprint_cannot_pass_between_are_one_encounter_and_a_lost_one_ends():
    tr = EncounterTracker(P)
    pair = Obstacles.from_lists([[2.0, 0.0], [2.0, 0.55]], r=0.2, ids=[0, 1])     # gap 0.15 m
    enc = tr.update(0.0, (0.0, 0.0), GOAL, pair)
    assert enc.ids == frozenset({0, 1})
    assert tr.update(0.5, (0.2, 0.0), GOAL, Obstacles.empty()) is enc          # unseen for 0.5 s: kept
    assert tr.update(1.6, (0.4, 0.0), GOAL, Obstacles.empty()) is None         # unseen for 1.6 s: lost


def _img(accepted, J):
    modes = ("GOAL", "PASS-L", "PASS-R", "SIDE-L", "SIDE-R")
    B = len(modes)
    z = np.zeros(B)
    return Imagination(modes, np.zeros((B, 2, 2)), np.zeros((B, 2)), np.zeros((B, 1, 3)), z, z, z, z, z, z,
                       np.array(J, float), np.ones(B, bool), np.array(accepted, bool))


def test_the_committed_side_is_kept_until_infeasible_for_k_selections():
    rules = PlusRules(commit_release_selections=2)
    sel = BehaviorSelector(P, rules)
    enc = EncounterTracker(P).update(0.0, (0.0, 0.0), GOAL, _post(2.0, 0.0))
    # PASS-L is the best: selected, and the encounter commits to the left
    assert sel.select(0.0, _img([1, 1, 1, 1, 1], [1, 0, 0.5, 2, 2]), enc).mode == "PASS-L" and enc.side == 1
    # PASS-R better by 1.0 (> the threshold plus w_sw) at every selection: without the rule it would switch; with
    # it the left side is kept (the evidence, (1.0 - w_sw) T_B per selection with leak 0.7, stays below 0.84 < 1.2)
    for k in range(6):
        assert sel.select(2.0 + k, _img([1, 1, 1, 1, 1], [1, 0.5, -0.5, 2, 2]), enc).mode == "PASS-L"
    assert 0 < enc.evidence < rules.commit_evidence_js
    # the left side rejected: GOAL (neutral) rather than the right, once
    assert sel.select(9.0, _img([1, 0, 1, 0, 1], [1, 0.5, -0.5, 2, 2]), enc).mode == "GOAL"
    assert enc.blocked == 1 and enc.side == 1
    # rejected at the second consecutive selection: released, the right side is chosen and committed
    assert sel.select(10.0, _img([1, 0, 1, 0, 1], [1, 0.5, -0.5, 2, 2]), enc).mode == "PASS-R" and enc.side == -1
    # without the rule, the same selector switches to the better right side at once
    free = BehaviorSelector(P, PlusRules(encounter_commitment=False, side_commitment=False))
    enc2 = EncounterTracker(P).update(0.0, (0.0, 0.0), GOAL, _post(2.0, 0.0))
    assert free.select(0.0, _img([1, 1, 1, 1, 1], [1, 0, 0.5, 2, 2]), enc2).mode == "PASS-L"
    assert free.select(2.0, _img([1, 1, 1, 1, 1], [1, 0.5, -0.5, 2, 2]), enc2).mode == "PASS-R"


def test_a_lasting_large_advantage_of_the_other_side_releases_the_commitment_a_single_one_does_not():
    sel = BehaviorSelector(P, PlusRules())
    enc = EncounterTracker(P).update(0.0, (0.0, 0.0), GOAL, _post(2.0, 0.0))
    assert sel.select(0.0, _img([1, 1, 1, 1, 1], [1, 0, 0.5, 2, 2]), enc).mode == "PASS-L"
    big, calm = _img([1, 1, 1, 1, 1], [1, 0.5, -7.5, 2, 2]), _img([1, 1, 1, 1, 1], [1, 0.5, 0.6, 2, 2])
    # one selection with PASS-R better by 8.0: its evidence is capped, min(8.0 - w_sw, 1.0) T_B = 0.5: kept
    assert sel.select(2.0, big, enc).mode == "PASS-L" and enc.evidence == pytest.approx(0.5)
    # PASS-R worse by 0.1: 0.7 0.5 + (-0.1 - 0.5) 0.5 = 0.05
    assert sel.select(3.0, calm, enc).mode == "PASS-L" and enc.evidence == pytest.approx(0.05)
    # the advantage lasts: 0.535, 0.8745, 1.112, then 1.279 >= 1.2 releases at the fourth, and PASS-R is taken
    for k, e in enumerate((0.535, 0.8745, 1.11215)):
        assert sel.select(4.0 + k, big, enc).mode == "PASS-L" and enc.evidence == pytest.approx(e)
    assert sel.select(7.0, big, enc).mode == "PASS-R" and enc.side == -1 and enc.evidence == 0.0


def test_the_papers_big_cbf_keeps_no_encounters_and_judges_at_full_speed():
    assert not PAPER_RULES.encounter_commitment and not PAPER_RULES.executed_speed
    assert BigCbfPlanner(P).encounters is None and BigCbfPlanner(P, shared=False).encounters is None
    plus = BigCbfPlusPlanner(P)
    assert plus.encounters is not None and plus.rules.encounter_commitment and plus.rules.executed_speed
    assert BigCbfPlusPlanner(P, PlusRules(encounter_commitment=False)).encounters is None


def _corridor_walls() -> Obstacles:
    """The walls of a 2.4 m corridor along +x as wall points (every 0.25 m from x = -0.5 to 2.75)."""
    xs = np.arange(-0.5, 3.0, 0.25)
    return Obstacles.from_lists(np.r_[np.c_[xs, np.full_like(xs, 1.2)], np.c_[xs, np.full_like(xs, -1.2)]], r=0.0,
                                ids=-np.ones(2 * len(xs), int))


def test_a_candidate_rejected_at_full_speed_is_judged_again_at_a_slower_speed_over_the_same_distance():
    params = default_stack_params()
    for s in SCALES:
        slow = speed_params(params, s)
        assert slow.v_max_mps == pytest.approx(params.v_max_mps * s)
        assert slow.N == math.ceil(params.N / s - 1e-9)
        assert slow.v_max_mps * slow.N * slow.dt_s >= params.v_max_mps * params.N * params.dt_s - 1e-9
        assert speed_params(params, s) is slow                               # cached
    st = RobotState(0.0, 0.0, 0.0)
    # a slow walker (0.3 m/s, the robot's way) 0.9 m ahead, 0.15 m right of the line, in a 2.4 m corridor
    walls = _corridor_walls()
    obs = walls.concat(Obstacles.from_lists([[0.9, -0.15]], v=[[0.3, 0.0]], r=0.25, ids=[5]))
    rules = PlusRules(prediction_cap=False)          # the paper's growth of the walker's covariance (see below)
    img = imagine(st, obs, (9.0, 0.0), params, rules=rules)
    out, scale = judge_at_executed_speed(img, st, obs, (9.0, 0.0), params, shared=True, current=None,
                                         rules=rules)
    gained = ~img.accepted & out.accepted
    # rejected at full speed: GOAL (into the walker's back) and PASS-R (its free side, 0.55 m of corridor);
    # at 0.35 v_max GOAL follows it, at 0.6 v_max PASS-R passes it
    assert dict(zip(img.modes, img.accepted))["GOAL"] == dict(zip(img.modes, img.accepted))["PASS-R"] == False
    assert dict(zip(out.modes, scale)) == dict(GOAL=0.35, **{"PASS-L": 1.0, "PASS-R": 0.6, "SIDE-L": 1.0,
                                                             "SIDE-R": 1.0, "YIELD": 1.0})
    assert np.all(out.h_min[gained] >= 0.0) and np.all(img.h_min[gained] < -params.eps_h_m2)
    assert np.all(out.J[img.accepted] == img.J[img.accepted])                # full-speed rows untouched


def test_with_the_default_cap_the_slow_walkers_free_side_passes_at_full_speed():
    """The shipped big-cbf-plus (prediction_cap at 0 s for obstacles slower than v_max, PlusRules): in the corridor
    above, PASS-R on the 0.3 m/s walker's free side, rejected with the paper's growth of its covariance, is
    accepted at full speed (its h_min -0.193 -> +0.109 m^2 with the tuned stack); the same walker at 1.2 m/s, faster
    than v_max 0.8 m/s, keeps the paper's growth: every candidate the same as without the cap."""
    params = default_stack_params()
    st = RobotState(0.0, 0.0, 0.0)
    walls = _corridor_walls()
    for v, changed in ((0.3, True), (1.2, False)):
        obs = walls.concat(Obstacles.from_lists([[0.9, -0.15]], v=[[v, 0.0]], r=0.25, ids=[5]))
        cap = imagine(st, obs, (9.0, 0.0), params, rules=PlusRules())
        grown = imagine(st, obs, (9.0, 0.0), params, rules=PlusRules(prediction_cap=False))
        assert np.array_equal(cap.h_min, grown.h_min) != changed
        if changed:
            i = cap.index("PASS-R")
            assert grown.h_min[i] < -params.eps_h_m2 and cap.h_min[i] >= 0.0 and cap.accepted[i]
            assert np.all(cap.h_min >= grown.h_min)


def _recorded(modes_at):
    rec = EncounterSideRecorder(P)
    for t, x, mode in modes_at:
        rec.add(t, RobotState(x, 0.0, 0.0), _post(2.0, 0.0), GOAL, mode)
    return rec.metrics()


def test_side_switches_are_counted_per_encounter():
    # L, GOAL, R, L while the post is ahead: 2 switches in 1 encounter; once it is behind, nothing counts
    m = _recorded([(0.0, 0.0, "PASS-L"), (0.5, 0.2, "GOAL"), (1.0, 0.4, "SIDE-R"), (1.5, 0.6, "PASS-L"),
                   (2.0, 3.0, "PASS-R")])
    assert m == dict(encounters=1, encounter_side_switches=2, switches_per_encounter=2.0)
    assert _recorded([(0.0, 0.0, "GOAL")]) == dict(encounters=0, encounter_side_switches=0,
                                                    switches_per_encounter=0.0)


def test_episodes_report_switches_per_encounter_only_for_methods_with_sides():
    plus = run_episode("required_sidestepping", "big-cbf-plus", 0, time_limit_s=3.0)
    assert isinstance(plus.encounters, int) and isinstance(plus.switches_per_encounter, float)
    assert plus.encounters >= 1                     # the wide obstacle on the goal line is passed on one side
    dwa = run_episode("required_sidestepping", "dwa", 0, time_limit_s=2.0)
    assert dwa.encounters is None and dwa.encounter_side_switches is None and dwa.switches_per_encounter is None


def test_the_planner_runs_a_re_judged_mode_at_its_slower_speed():
    params = default_stack_params()
    walls = _corridor_walls()
    st = RobotState(0.0, 0.0, 0.0)
    slowed = 0
    for y in (-0.15, 0.0, 0.15):          # a slow walker 0.9 m ahead in a 2.4 m corridor (see the test above)
        obs = walls.concat(Obstacles.from_lists([[0.9, y]], v=[[0.3, 0.0]], r=0.25, ids=[5]))
        planner = BigCbfPlusPlanner(params, PlusRules(executed_speed=True, prediction_cap=False))
        u, info = planner.plan(0.0, st, obs, (9.0, 0.0))
        img = imagine(st, obs, (9.0, 0.0), params, rules=planner.rules)
        _, scale = judge_at_executed_speed(img, st, obs, (9.0, 0.0), params, shared=True, current=None,
                                           rules=planner.rules)
        s = dict(zip(img.modes, scale))[info.mode]
        limit = params.v_side_mps if info.mode.startswith("SIDE") else params.v_max_mps
        assert np.hypot(*u[:2]) <= s * limit + 1e-9
        slowed += s < 1.0
    assert slowed >= 1                    # the walker's free side or following it, at the re-judged speed


def test_the_metric_tracks_encounters_at_planning_cycles_and_mode_changes():
    rec = EncounterSideRecorder(P)
    rec.add(0.0, RobotState(0.0, 0.0, 0.0), _post(2.0, 0.0), GOAL, "GOAL", planned=True)
    assert rec.tracker.opened == 1
    rec.add(0.05, RobotState(0.0, 0.0, 0.0), _post(1.0, 3.0, ident=4), GOAL, "GOAL", planned=False)
    assert rec.tracker.open[0].t_seen == 0.0                   # a control step without a selection: skipped
    rec.add(0.1, RobotState(0.0, 0.0, 0.0), _post(2.0, 0.0), GOAL, "PASS-L", planned=False)
    assert rec.tracker.open[0].t_seen == 0.1 and rec.metrics()["encounters"] == 1   # the mode changed: counted


def test_meeting_side_is_away_from_a_person_walking_along_the_path_by_hand():
    """encounters.meeting_side, by hand: robot at the origin, goal (6, 0) (d_g = +x, n_g = +y), v_max 0.8 m/s,
    2 N dt = 3 s."""
    from bigcbf.control.encounters import meeting_side
    # head-on at 1.1 m/s, 3.7 m ahead, 0.3 m to the left: closing 0.8 + 1.1 = 1.9 m/s, 3.7 <= 3 x 1.9: right (-1)
    assert meeting_side((0, 0), GOAL, _post(3.7, 0.3, ident=2, v=(-1.1, 0.0)), P) == -1
    assert meeting_side((0, 0), GOAL, _post(3.7, -0.3, ident=2, v=(-1.1, 0.0)), P) == 1
    # 6.0 m ahead: 6.0 > 5.7, meets beyond two horizons: none
    assert meeting_side((0, 0), GOAL, _post(6.0, 0.3, ident=2, v=(-1.1, 0.0)), P) == 0
    # on the goal line within the band (|e| = 0.05 < 0.1): none; a robot that stands beside it sees the offset
    assert meeting_side((0, 0), GOAL, _post(3.0, 0.05, ident=2, v=(-1.1, 0.0)), P) == 0
    assert meeting_side((0, -0.2), (6.0, -0.2), _post(3.0, 0.05, ident=2, v=(-1.1, 0.0)), P) == -1
    # overtaking a walker at 0.4 m/s, 2 m ahead, 0.2 m to the right: closing 0.4 m/s, 2.0 <= 1.2: no; 1.0 m ahead: left
    assert meeting_side((0, 0), GOAL, _post(2.0, -0.2, ident=2, v=(0.4, 0.0)), P) == 0
    assert meeting_side((0, 0), GOAL, _post(1.0, -0.2, ident=2, v=(0.4, 0.0)), P) == 1
    # a walker faster than the robot in its direction never meets it; a crossing one (45 deg off the axis > 30 deg),
    # a standing one (0.1 < 0.2 m/s), a wall point (id -1) and one behind the robot do not count
    assert meeting_side((0, 0), GOAL, _post(1.0, -0.2, ident=2, v=(1.0, 0.0)), P) == 0
    assert meeting_side((0, 0), GOAL, _post(2.0, 0.3, ident=2, v=(-0.8, -0.8)), P) == 0
    assert meeting_side((0, 0), GOAL, _post(2.0, 0.3, ident=2, v=(-0.1, 0.0)), P) == 0
    assert meeting_side((0, 0), GOAL, _post(2.0, 0.3, ident=-1, v=(-1.0, 0.0)), P) == 0
    assert meeting_side((0, 0), GOAL, _post(-1.0, 0.3, ident=2, v=(1.0, 0.0)), P) == 0
    # the nearest one ahead decides
    two = Obstacles.from_lists([[3.0, -0.4], [2.0, 0.4]], v=[[-1.0, 0.0], [-1.0, 0.0]], r=0.25, ids=[4, 5])
    assert meeting_side((0, 0), GOAL, two, P) == -1
    assert meeting_side((0, 0), GOAL, Obstacles.empty(), P) == 0


def test_the_meeting_side_picks_the_first_side_only():
    sel = BehaviorSelector(P, PlusRules())
    # SIDE-L is the best, but the person is on the left (lean -1): the right side's best, SIDE-R, is taken
    assert sel.select(0.0, _img([1, 1, 1, 1, 1], [1, 0.9, 0.95, 0.2, 0.5]), None, lean=-1).mode == "SIDE-R"
    # once a side is held, the lean no longer decides: with lean +1, the right is kept (SIDE-L's 0.3 advantage is
    # below the threshold plus w_sw of the side commitment)
    assert sel.select(2.0, _img([1, 1, 1, 1, 1], [1, 0.9, 0.95, 0.2, 0.5]), None, lean=1).mode == "SIDE-R"
    # no accepted mode on the lean's side: the lean is ignored
    sel2 = BehaviorSelector(P, PlusRules())
    assert sel2.select(0.0, _img([1, 1, 0, 1, 0], [1, 0.9, 0.95, 0.2, 0.5]), None, lean=-1).mode == "SIDE-L"
    # the paper's selector (PAPER_RULES) and plus with the switch off ignore it
    for rules in (PAPER_RULES, PlusRules(meeting_side=False)):
        assert BehaviorSelector(P, rules).select(0.0, _img([1, 1, 1, 1, 1], [1, 0.9, 0.95, 0.2, 0.5]), None,
                                                 lean=-1).mode == "SIDE-L"
    assert not PAPER_RULES.meeting_side and PlusRules().meeting_side


def test_long_horizon_sees_a_crossing_the_paper_horizon_ends_before_by_hand():
    """The rule long_horizon (PlusRules, issue 23): big-cbf-plus imagines long_horizon_s = 2.5 s ahead (N = 25 steps
    of dt = 0.1 s); big-cbf the paper's N = 15. By hand: the robot at the origin heading for (6, 0) at v_max 0.8 m/s;
    a person (r 0.25 m) at (2.0, -1.8) walking +y at 0.9 m/s crosses the goal line at x = 2.0 at t = 2.0 s. GOAL's
    rollout is at x <= 1.2 m when the paper's horizon ends (1.5 s), the person then at y = -0.45 m: centre distance
    >= sqrt(0.8^2 + 0.45^2) = 0.92 m, beyond D_i (r_R + r + d0 + margin, under 0.8 m), so GOAL is accepted; over
    2.5 s the robot reaches x ~ 1.6-2.0 m while the person crosses y = 0 at x = 2.0 (t = 2 s): inside D_i, GOAL
    rejected (eq:behavior_acceptance (22))."""
    plus = BigCbfPlusPlanner(P)
    assert plus.params.N == 25 and plus.filter_params.N == P.N == 15
    assert BigCbfPlusPlanner(P, PlusRules(long_horizon=False)).params.N == P.N
    assert BigCbfPlanner(P).params.N == 15 and not PAPER_RULES.long_horizon
    st = RobotState(0.0, 0.0, 0.0)
    walker = Obstacles.from_lists([[2.0, -1.8]], v=[[0.0, 0.9]], r=0.25, ids=[4])
    short = imagine(st, walker, GOAL, P, rules=PlusRules())
    long_ = imagine(st, walker, GOAL, plus.params, rules=PlusRules())
    assert dict(zip(short.modes, short.accepted))["GOAL"]
    assert not dict(zip(long_.modes, long_.accepted))["GOAL"]
    assert long_.p.shape[1] == 26 and short.p.shape[1] == 16        # states k = 0..N


def test_long_horizon_judges_what_stands_still_over_the_stack_horizon_only_by_hand():
    """The rule long_horizon's barrier acceptance: a post (static, r 0.2 m) at x = 2.3 m on the goal line; GOAL's
    rollout runs x = 0.8 t, so x = 1.2 m at 1.5 s (1.1 m from the post's centre, beyond D_i = 0.56 m here) and
    x = 2.0 m at 2.5 s (0.3 m: inside): accepted with score_steps = 15 (the stack's N), rejected when every state
    of the 25 counts. A person (r 0.2 m) at x = 3.4 m walking at the robot at 0.5 m/s is 1.3 m from it at 1.5 s and
    0.15 m at 2.5 s: a moving obstacle, judged over all 25 states, score_steps or not."""
    plus = BigCbfPlusPlanner(P)
    assert plus.score_steps == 15 and BigCbfPlanner(P).score_steps is None
    assert BigCbfPlusPlanner(P, PlusRules(long_horizon=False)).score_steps is None
    st = RobotState(0.0, 0.0, 0.0)
    post = Obstacles.from_lists([[2.3, 0.0]], r=0.2, ids=[1], static=[True])
    goal_ok = lambda img: dict(zip(img.modes, img.accepted))["GOAL"]      # noqa: E731
    assert goal_ok(imagine(st, post, GOAL, P, rules=PlusRules()))                       # 1.5 s: x <= 1.2 m
    assert not goal_ok(imagine(st, post, GOAL, plus.params, rules=PlusRules()))         # 2.5 s, every state
    assert goal_ok(imagine(st, post, GOAL, plus.params, rules=PlusRules(), score_steps=15))
    walker = Obstacles.from_lists([[3.4, 0.0]], v=[[-0.5, 0.0]], r=0.2, ids=[1], static=[False])
    assert goal_ok(imagine(st, walker, GOAL, P, rules=PlusRules()))
    assert not goal_ok(imagine(st, walker, GOAL, plus.params, rules=PlusRules(), score_steps=15))
