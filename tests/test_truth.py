"""Clearance and contact use one shape (bigcbf/sim/truth.py): the signed distance between the robot's collision
outline and the obstacles, checked against hand-worked values and an independent computation, and against
MuJoCo's contacts while the robot drives into every kind of obstacle."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bigcbf.sim.scene import Box, Cylinder, PedestrianBody, SceneSpec, Wall
from bigcbf.sim.truth import (Clearance, GroundTruth, Outline, outline_from_model, rect_rect_distance,
                              rect_rect_distance_one, robot_outline)
from bigcbf.sim.world import SimWorld

#: the measured relation (below): contact <=> clearance <= 0 within this [m] (MuJoCo's soft contacts and the
#: robot's small pitch and roll on its rollers; the largest deviation measured was 0.5 mm)
CONTACT_TOL_M = 1e-3


def test_the_outline_is_the_bumper():
    """The MJCF's body collision geoms: bumper 0.30 x 0.20 m, chassis 0.30 x 0.124 m, LiDAR r 0.035 m at x 0.0435:
    the outline is the bumper."""
    o = robot_outline()
    assert (o.half_x, o.half_y, o.cx, o.cy) == pytest.approx((0.15, 0.10, 0.0, 0.0))
    assert o.inner_radius == pytest.approx(0.10) and o.outer_radius == pytest.approx(math.hypot(0.15, 0.10))


def _one(a_c, a_h, a_yaw, b_c, b_h, b_yaw):
    return float(rect_rect_distance(np.array(a_c, float), np.array(a_h, float), a_yaw, np.array([b_c], float),
                                    np.array([b_h], float), np.array([math.cos(b_yaw)]),
                                    np.array([math.sin(b_yaw)]))[0])


def test_rect_rect_by_hand():
    # side by side, 0.05 apart
    assert _one((0, 0), (0.15, 0.1), 0, (0.5, 0), (0.3, 0.3), 0) == pytest.approx(0.05)
    # overlapping by 0.03 in x
    assert _one((0, 0), (0.15, 0.1), 0, (0.42, 0), (0.3, 0.3), 0) == pytest.approx(-0.03)
    # corner to corner: gaps 0.3 and 0.4 -> 0.5
    assert _one((0, 0), (0.15, 0.1), 0, (0.15 + 0.3 + 1, 0.1 + 0.4 + 1), (1, 1), 0) == pytest.approx(0.5)
    # a square turned 45 deg whose corner points at the robot's front face: corner at x = 0.5 - 0.2 sqrt2
    d = 0.5 - 0.2 * math.sqrt(2) - 0.15
    assert _one((0, 0), (0.15, 0.1), 0, (0.5, 0), (0.2, 0.2), math.pi / 4) == pytest.approx(d)
    # the same square pushed in by 0.02: penetration 0.02 (along x, the robot's face normal)
    assert _one((0, 0), (0.15, 0.1), 0, (0.5 - d - 0.02, 0), (0.2, 0.2), math.pi / 4) == pytest.approx(-0.02)
    # the robot wholly inside a 1 x 1 m box, 0.2 m below its centre: moving it 0.4 m down separates them
    assert _one((0.1, -0.2), (0.15, 0.1), 0, (0, 0), (0.5, 0.5), 0) == pytest.approx(-0.4)


def _seg_dist(p, q, a, b):
    """Distance between segments pq and ab (independent reference: closest points by clamped projections)."""
    def pt_seg(x, s0, s1):
        t = np.clip(np.dot(x - s0, s1 - s0) / max(np.dot(s1 - s0, s1 - s0), 1e-300), 0, 1)
        return np.linalg.norm(x - (s0 + t * (s1 - s0)))
    def orient(u, v, w):
        return np.sign((v[0] - u[0]) * (w[1] - u[1]) - (v[1] - u[1]) * (w[0] - u[0]))
    if orient(p, q, a) * orient(p, q, b) < 0 and orient(a, b, p) * orient(a, b, q) < 0:
        return 0.0                                    # the segments cross
    return min(pt_seg(p, a, b), pt_seg(q, a, b), pt_seg(a, p, q), pt_seg(b, p, q))


def _corners(c, h, yaw):
    R = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
    return np.array(c) + np.array([[h[0], h[1]], [-h[0], h[1]], [-h[0], -h[1]], [h[0], -h[1]]]) @ R.T


def _inside(x, c, h, yaw):
    d = np.array(x) - c
    lx = math.cos(yaw) * d[0] + math.sin(yaw) * d[1]
    ly = -math.sin(yaw) * d[0] + math.cos(yaw) * d[1]
    return abs(lx) < h[0] and abs(ly) < h[1]


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-4, 4), st.floats(0.02, 0.6), st.floats(0.02, 0.6),
       st.floats(-4, 4), st.floats(-4, 4))
def test_rect_rect_against_segment_distances(bx, by, byaw, hx, hy, ayaw, _):
    """Apart: the distance equals the least distance between the edges; overlapping: negative, and some corner of
    one lies inside the other or edges cross."""
    a_c, a_h, b_c, b_h = (0.0, 0.0), (0.15, 0.1), (bx, by), (hx, hy)
    d = _one(a_c, a_h, ayaw, b_c, b_h, byaw)
    A, B = _corners(a_c, a_h, ayaw), _corners(b_c, b_h, byaw)
    edges = min(_seg_dist(A[i], A[(i + 1) % 4], B[j], B[(j + 1) % 4]) for i in range(4) for j in range(4))
    overlap = (any(_inside(x, b_c, b_h, byaw) for x in A) or any(_inside(x, a_c, a_h, ayaw) for x in B)
               or edges < 1e-12)
    if overlap:
        assert d <= 1e-12
        # the penetration is the shortest separating translation: over 1,440 directions none is shorter than -d
        # (the separating-axis theorem puts the minimum on an edge normal, which the implementation uses)
        th = np.r_[np.linspace(0, np.pi, 1440, endpoint=False), ayaw, ayaw + np.pi / 2, byaw, byaw + np.pi / 2]
        u = np.stack([np.cos(th), np.sin(th)], 1)
        reach = lambda C: (C @ u.T).max(0) - (C @ u.T).min(0)           # noqa: E731
        need = 0.5 * (reach(A) + reach(B)) - np.abs(u @ (np.array(b_c) - np.array(a_c)))
        assert need.min() == pytest.approx(-d, abs=1e-9)
    else:
        assert d == pytest.approx(edges, abs=1e-9)


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.floats(-1, 1), st.floats(-1, 1), st.floats(-4, 4), st.floats(0.02, 0.6), st.floats(0.02, 0.6),
       st.floats(-4, 4))
def test_the_scalar_pair_distance_equals_the_vectorized_one(bx, by, byaw, hx, hy, ayaw):
    d = _one((0.1, -0.2), (0.15, 0.1), ayaw, (bx, by), (hx, hy), byaw)
    one = rect_rect_distance_one(0.1, -0.2, math.cos(ayaw), math.sin(ayaw), 0.15, 0.1, bx, by, math.cos(byaw),
                                 math.sin(byaw), hx, hy)
    assert one == pytest.approx(d, abs=1e-12)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.floats(-3, 3), st.floats(-3, 3), st.floats(-4, 4))
def test_pruned_minimum_equals_the_full_one(x, y, yaw):
    scene = SceneSpec(walls=(Wall(-3, -1, 3, -1), Wall(-3, 1.2, 3, 1.2), Wall(2, -1, 2.5, 1.2)),
                      boxes=(Box(0.5, 0.3, 0.2, 0.4, 0.7), Box(-1.0, -0.2, 0.3, 0.1, -0.3)),
                      cylinders=(Cylinder(1.0, -0.5, 0.2),), pedestrians=(PedestrianBody("a", 0.25),))
    c = Clearance(scene)
    ped = np.array([[-0.5, 0.6]])
    full = min(c.static_distances(x, y, yaw).min(), c.pedestrian_distances(x, y, yaw, ped).min())
    assert c((x, y, yaw), ped) == pytest.approx(full, abs=1e-12)
    for running_min in (-0.5, 0.0, 0.2, 1.0):                      # as the episode calls it
        got = c((x, y, yaw), ped, running_min)
        assert got == pytest.approx(full, abs=1e-12) if full < running_min else got >= running_min - 1e-12


def test_outline_from_a_model_needs_a_box_that_holds_the_rest():
    import mujoco
    xml = """<mujoco><worldbody><body name="base_link"><freejoint/>
      <geom type="box" size="0.1 0.1 0.1" contype="8" conaffinity="4"/>
      <geom type="cylinder" size="0.2 0.05" contype="8" conaffinity="4"/></body></worldbody></mujoco>"""
    with pytest.raises(ValueError, match="no collision box"):
        outline_from_model(mujoco.MjModel.from_xml_string(xml))
    ok = xml.replace('size="0.2 0.05"', 'size="0.05 0.05" pos="0.04 0 0"')
    assert outline_from_model(mujoco.MjModel.from_xml_string(ok)) == Outline(0.1, 0.1, 0.0, 0.0)


CASES = {   # scene, start yaw, body twist (None: straight along world +x)
    "wall-front": (SceneSpec(walls=(Wall(0.6, -2, 0.6, 2),)), 0.0, (0.3, 0, 0)),
    "wall-yaw30": (SceneSpec(walls=(Wall(0.6, -2, 0.6, 2),)), math.radians(30), None),
    "wall-side": (SceneSpec(walls=(Wall(-2, 0.5, 2, 0.5),)), 0.0, (0, 0.3, 0)),
    "box-turned": (SceneSpec(boxes=(Box(0.7, 0.05, 0.2, 0.2, math.radians(45)),)), 0.0, (0.3, 0, 0)),
    "cylinder": (SceneSpec(cylinders=(Cylinder(0.7, 0.12, 0.2),)), 0.0, (0.3, 0, 0)),
    "cylinder-corner": (SceneSpec(cylinders=(Cylinder(0.55, 0.35, 0.1),)), 0.0, (0.3, 0.2, 0)),
    "pedestrian": (SceneSpec(pedestrians=(PedestrianBody("a", 0.25, 1.7, 0.8, 0.05),)), 0.0, (0.3, 0, 0)),
    "pedestrian-side": (SceneSpec(pedestrians=(PedestrianBody("a", 0.25, 1.7, 0.0, 0.6),)), 0.4, (0.0, 0.3, 0)),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_negative_clearance_is_contact_and_contact_is_non_positive_clearance(case):
    """Drive into the obstacle for 3 s, 10 ms blocks (as the episode samples): contact exactly while the
    clearance is <= 0, within CONTACT_TOL_M."""
    spec, yaw, u = CASES[case]
    spec = SceneSpec(**{**spec.__dict__, "robot_start": (0.0, 0.0, yaw)})
    world = SimWorld(spec)
    truth = GroundTruth(world.model, world.scene)
    ped = np.array([[p.x, p.y] for p in spec.pedestrians]).reshape(-1, 2)
    if u is None:
        u = (0.3 * math.cos(yaw), -0.3 * math.sin(yaw), 0.0)
    touched = False
    for _ in range(300):
        world.command(u)
        world.step(5)
        clearance, contact = truth.clearance(world.pose(), ped), truth.in_contact(world.data)
        touched |= contact
        assert (clearance <= CONTACT_TOL_M) if contact else (clearance >= -CONTACT_TOL_M), (clearance, contact)
    assert touched
