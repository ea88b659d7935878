"""Contacts classified by who moved into whom, and near misses (bigcbf/sim/contacts.py, issue 23): contacts of each
kind built by hand, the metrics accumulator's new fields, and real episodes with a contact of each kind."""
import math

import numpy as np
import pytest

from bigcbf.control.metrics import EpisodeMetrics
from bigcbf.episode import Episode
from bigcbf.scenario import parse_scenario
from bigcbf.sim.contacts import Body, classify, contact_geometry, near_miss
from bigcbf.sim.truth import Clearance, Outline

OUTLINE = Outline(0.15, 0.10)          # the Rosmaster X3's 0.30 x 0.20 m bumper
V_FREEZE = 0.05


def wall_at(x: float) -> Body:
    """A wall 0.1 m thick whose near face is at x, across the robot's way (along y)."""
    return Body("wall", "walls[0]", (x + 0.05, 0.0), (2.05, 0.05), math.pi / 2)


def test_static_wall_hit_while_driving_is_at_fault():
    # the robot's front face at 1.155 m, the wall's face at 1.15 m: 5 mm deep, driving at 0.5 m/s into it
    c = classify(OUTLINE, (1.005, 0.0, 0.0), (0.5, 0.0), 0.0, wall_at(1.15), V_FREEZE, t_s=3.2)
    assert c.kind == "wall" and c.name == "walls[0]" and c.t_s == 3.2
    assert c.normal == pytest.approx((-1.0, 0.0)) and c.penetration_m == pytest.approx(0.005)
    assert c.robot_radial_mps == pytest.approx(0.5) and c.other_radial_mps == 0.0 and c.at_fault
    # sliding along the same wall (velocity tangent to it) is not moving into it
    slide = classify(OUTLINE, (1.005, 0.0, 0.0), (0.0, 0.4), 0.0, wall_at(1.15), V_FREEZE)
    assert slide.robot_radial_mps == pytest.approx(0.0, abs=1e-9) and not slide.at_fault
    # creeping in below v_freeze: passive
    assert not classify(OUTLINE, (1.005, 0.0, 0.0), (0.04, 0.0), 0.0, wall_at(1.15), V_FREEZE).at_fault


def test_stationary_robot_hit_by_a_walker_is_passive():
    # a walker of radius 0.25 m coming from the robot's left at 1.6 m/s, 2 cm into the bumper's left side
    ped = Body("pedestrian", "p1", (0.0, 0.10 + 0.25 - 0.02), (0.25, 0.0), 0.0, (0.0, -1.6))
    c = classify(OUTLINE, (0.0, 0.0, 0.0), (0.0, 0.0), 0.0, ped, V_FREEZE)
    assert c.kind == "pedestrian" and c.name == "p1" and not c.at_fault
    assert c.normal == pytest.approx((0.0, -1.0)) and c.penetration_m == pytest.approx(0.02)
    assert c.robot_radial_mps == 0.0 and c.other_radial_mps == pytest.approx(1.6)
    assert c.point == pytest.approx((0.0, 0.10))


def test_robot_moving_away_hit_from_behind_is_passive():
    # driving on at 0.5 m/s; a walker at 1.2 m/s catches up from behind and touches the rear face
    ped = Body("pedestrian", "fast", (-0.15 - 0.2 + 0.01, 0.03), (0.2, 0.0), 0.0, (1.2, 0.0))
    c = classify(OUTLINE, (0.0, 0.0, 0.0), (0.5, 0.0), 0.0, ped, V_FREEZE)
    assert c.normal == pytest.approx((1.0, 0.0)) and c.penetration_m == pytest.approx(0.01)
    assert c.robot_radial_mps == 0.0 and c.other_radial_mps == pytest.approx(1.2) and not c.at_fault
    # the same walker met head-on while the robot drives at it: at fault, both closing
    head_on = classify(OUTLINE, (0.0, 0.0, math.pi), (-0.5, 0.0), 0.0, ped, V_FREEZE)
    assert head_on.at_fault and head_on.robot_radial_mps == pytest.approx(0.5)


def test_a_corner_swung_into_a_post_is_at_fault_and_the_geometry_agrees_with_truth():
    """A robot turning on the spot (no translation) that swings its front-left corner into a cylinder moves into it:
    the contact point's velocity w x r counts. The signed distance agrees with sim/truth.py's Clearance."""
    corner = np.array([0.15, 0.10])
    post = Body("cylinder", "cylinders[0]", tuple(corner + np.array([0.0, 0.2 - 0.004])), (0.2, 0.0))
    c = classify(OUTLINE, (0.0, 0.0, 0.0), (0.0, 0.0), 1.0, post, V_FREEZE)
    # w x r at the corner (0.15, 0.10) for w = 1 rad/s: (-0.10, 0.15); the normal is -y: radial speed 0.15
    assert c.robot_radial_mps == pytest.approx(0.15) and c.at_fault and c.penetration_m == pytest.approx(0.004)
    for pose in [(0.3, -0.2, 0.7), (1.1, 0.4, -2.0), (0.05, 0.0, 0.3)]:
        for body in (post, wall_at(0.2), Body("box", "boxes[0]", (0.4, 0.1), (0.2, 0.1), 0.5)):
            d, _, n = contact_geometry(OUTLINE, pose, body)
            assert np.linalg.norm(n) == pytest.approx(1.0)
            assert d == pytest.approx(_truth_distance(pose, body), abs=1e-9), (pose, body)


def _truth_distance(pose, body: Body) -> float:
    from bigcbf.sim.truth import rect_rect_distance
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    centre = np.array([x + c * OUTLINE.cx - s * OUTLINE.cy, y + s * OUTLINE.cx + c * OUTLINE.cy])
    if body.circle:
        q = np.array([[c, s], [-s, c]]) @ (np.asarray(body.centre) - centre)
        from bigcbf.sim.truth import point_box_distance
        return float(point_box_distance(q[0], q[1], OUTLINE.half_x, OUTLINE.half_y)) - body.half[0]
    return float(rect_rect_distance(centre, (OUTLINE.half_x, OUTLINE.half_y), yaw, np.array([body.centre]),
                                    np.array([body.half]), np.array([math.cos(body.yaw)]),
                                    np.array([math.sin(body.yaw)]))[0])


class _Peds:
    """A Clearance stand-in holding pedestrians only (near_miss needs its pedestrian_distances)."""

    def __init__(self, radii):
        self.ped_r = np.asarray(radii, float)
        self.outline = OUTLINE

    def pedestrian_distances(self, x, y, yaw, ped_p):
        return Clearance._circles(np.array([x, y]), np.array([OUTLINE.half_x, OUTLINE.half_y]), yaw,
                                  np.asarray(ped_p, float), self.ped_r)


def test_near_miss_by_hand():
    peds = _Peds([0.25, 0.25])
    # ahead at 2 m, closing at 1 m/s: clearance 2 - 0.15 - 0.25 = 1.6 m, 1.6 s; the other one walks away
    ttc, gap = near_miss(peds, (0.0, 0.0, 0.0), (0.0, 0.0), [(2.0, 0.0), (0.0, 1.0)], [(-1.0, 0.0), (0.0, 1.0)])
    assert ttc == pytest.approx(1.6) and gap == pytest.approx(1.0 - 0.10 - 0.25)
    # the robot driving at 0.6 m/s towards the first: closing at 1.6 m/s
    ttc, _ = near_miss(peds, (0.0, 0.0, 0.0), (0.6, 0.0), [(2.0, 0.0), (0.0, 1.0)], [(-1.0, 0.0), (0.0, 1.0)])
    assert ttc == pytest.approx(1.0)
    # nobody closing: inf; nobody at all: inf, inf
    assert near_miss(peds, (0.0, 0.0, 0.0), (0.0, 0.0), [(2.0, 0.0), (0.0, 1.0)], [(1.0, 0.0), (0.0, 0.0)])[0] \
        == math.inf
    assert near_miss(peds, (0.0, 0.0, 0.0), (0.0, 0.0), np.zeros((0, 2)), np.zeros((0, 2))) == (math.inf, math.inf)


def test_accumulator_near_misses_and_contact():
    m = EpisodeMetrics(R_u_diag=(1.0, 1.0, 1.0), v_freeze_mps=V_FREEZE, T_C_s=0.05)
    m.near_miss(3.0, 0.8, 0.5)
    m.physics(25, 0.002, 0.8)                    # 0.8 m away: outside the personal space
    m.near_miss(1.2, 0.4, 0.5)
    m.physics(20, 0.002, 0.4)                    # inside for 25 steps of 2 ms
    m.physics(5, 0.002, 0.4)
    m.near_miss(math.inf, 0.6, 0.5)
    m.physics(25, 0.002, 0.6)
    r = m.results(0.15)
    assert r["min_time_to_contact_s"] == 1.2 and r["personal_space_s"] == pytest.approx(0.05)
    assert r["contact"] is None and not r["at_fault_collision"] and not r["passive_collision"]
    c = classify(OUTLINE, (1.005, 0.0, 0.0), (0.5, 0.0), 0.0, wall_at(1.15), V_FREEZE)
    m.contacted(c.as_dict())
    m.contacted({**c.as_dict(), "at_fault": False})          # only the first contact counts
    r = m.results(0.2)
    assert r["at_fault_collision"] and not r["passive_collision"] and r["contact"]["kind"] == "wall"
    empty = EpisodeMetrics(R_u_diag=(1.0, 1.0, 1.0), v_freeze_mps=V_FREEZE, T_C_s=0.05).results(0.0)
    assert empty["min_time_to_contact_s"] == math.inf and empty["personal_space_s"] == 0.0


SCENE = """
name = "contact_test"
description = "contacts of each kind"
time_limit_s = 6.0
[robot]
start = [0.0, 0.0, 0.0]
goal = [0.0, -4.0]
"""


def _episode(extra: str, u_in, time_limit_s: float = 4.0, yaw: float = 0.0):
    sc = parse_scenario(SCENE.replace("[0.0, 0.0, 0.0]", f"[0.0, 0.0, {yaw}]") + extra, "contact_test.toml", 0)
    ep = Episode(sc, None, 0, time_limit_s=time_limit_s)
    ep.begin()
    while not ep.done:
        ep.act(u_in)
    return ep.result()


def test_an_episode_driving_into_a_box_the_lidar_cannot_see_is_at_fault():
    """A 0.10 m box, below the LiDAR's beam: nothing stops the robot's 0.4 m/s, and the contact is the robot's."""
    res = _episode("[[boxes]]\ncenter = [1.2, 0.0]\nhalf_size = [0.1, 0.5]\nheight_m = 0.1\n", (0.4, 0.0, 0.0))
    assert res.collision and res.at_fault_collision and not res.passive_collision
    c = res.contact
    assert c["kind"] == "box" and c["name"] == "boxes[0]" and c["robot_radial_mps"] > 0.3
    assert c["normal"] == pytest.approx([-1.0, 0.0], abs=0.05) and 0.0 <= c["penetration_m"] < 0.02
    assert res.min_time_to_contact_s == math.inf and res.personal_space_s == 0.0     # no people


def test_an_episode_with_a_fast_walker_catching_the_robot_in_a_corridor_is_passive():
    """A non-reactive walker at 1.6 m/s (twice the robot's top speed) comes down a 0.7 m corridor at the robot (facing
    down it), which is told to stand still: the CBF filter moves it away down the corridor (never towards the walker), the walker
    catches it from behind. The contact is passive: the walker closing, the robot not."""
    walls = "".join(f"[[walls]]\nstart = [{x}, -6.0]\nend = [{x}, 3.0]\nthickness_m = 0.1\n" for x in (-0.4, 0.4))
    walker = ('[[pedestrians]]\nname = "runner"\nwaypoints = [[0.0, 2.0], [0.0, -5.5]]\nspeed_mps = 1.6\n'
              "radius_m = 0.2\nreactive = false\n")
    res = _episode(walls + walker, (0.0, 0.0, 0.0), time_limit_s=5.0, yaw=-math.pi / 2)
    assert res.collision and res.passive_collision and not res.at_fault_collision
    c = res.contact
    assert c["kind"] == "pedestrian" and c["name"] == "runner" and c["other_radial_mps"] > 1.0
    assert c["robot_radial_mps"] <= V_FREEZE and c["normal"][1] < -0.7          # hit from behind (+y)
    assert res.min_time_to_contact_s < 0.5 and res.personal_space_s > 0.1


def test_bench_summary_counts_contacts_by_fault_with_wilson_intervals(tmp_path):
    """summarize and summary.md by hand: of 4 episodes, 1 at-fault and 1 passive contact, 1 near miss (TTC 0.6 s
    without contact), one that never met a person; a row from before the classification counts in no rate."""
    import sys
    sys.path.insert(0, str(__import__("pathlib").Path(__file__).parent / "bench"))
    from test_bench_report import row

    from bigcbf.bench import report
    from bigcbf.bench.stats import wilson_pct

    def ep(seed, collision=False, fault=False, ttc=math.inf, space=0.0):
        return row("a", "dwa", seed, success=not collision, timeout=False, collision=collision,
                   at_fault_collision=collision and fault, passive_collision=collision and not fault,
                   min_time_to_contact_s=ttc, personal_space_s=space)
    rows = [ep(0, True, True, 0.1, 1.0), ep(1, True, False, 0.2, 2.0), ep(2, ttc=0.6, space=0.5), ep(3)]
    s = report.summarize(rows)
    assert (s["collisions"], s["at_fault_collisions"], s["passive_collisions"]) == (2, 1, 1)
    assert s["at_fault_collision_pct"] == 25.0 and s["at_fault_collision_ci95_pct"] == wilson_pct(1, 4)
    assert s["near_miss_pct"] == 25.0 and s["near_miss_ci95_pct"] == wilson_pct(1, 4)
    assert s["min_time_to_contact_s"] == pytest.approx(0.3) and s["personal_space_s"] == pytest.approx(0.875)
    old = row("a", "dwa", 9, collision=True)                        # recorded before: no classification
    assert report.summarize([old])["at_fault_collisions"] is None
    assert report.summarize(rows + [old])["at_fault_collision_pct"] == 25.0
    summary = report.build_summary(rows, ["dwa"], ["a"], [0, 1, 2, 3])
    md = report.summary_markdown(summary)
    assert "Contacts: at fault or passive, and near misses" in md
    assert f"| DWA + CBF | 4 | 2 | 1: 25.0 [{wilson_pct(1, 4)[0]:.1f}, {wilson_pct(1, 4)[1]:.1f}] | 1: 25.0 [" in md
    assert report._heatmap_contacts(s) == "hit 1F 1P" and report._heatmap_contacts(report.summarize([old])) == "hit 1"
