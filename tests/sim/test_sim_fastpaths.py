"""The per-physics-block fast paths of the simulation loop give exactly the numbers of the forms they replace:
the clearance's motion bound (sim/truth.py), the float odometry (sim/firmware.py), the pedestrians' preferred
velocities (sim/pedestrians.py), the contact look-up and the state snapshots (sim/world.py)."""
from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from bigcbf.sim.firmware import WheelOdometry
from bigcbf.sim.kinematics import MecanumKinematics
from bigcbf.sim.pedestrians import Pedestrians
from bigcbf.sim.scene import Box, Cylinder, PedestrianBody, SceneSpec, Wall
from bigcbf.sim.truth import Clearance, GroundTruth
from bigcbf.sim.world import SimWorld


def _scene():
    return SceneSpec(walls=(Wall(-3, -1.5, 3, -1.5), Wall(-3, 1.5, 3, 1.5), Wall(3, -1.5, 3, 1.5)),
                     boxes=(Box(1.5, 0.8, 0.3, 0.2, 0.4),), cylinders=(Cylinder(0.5, -0.9, 0.2),),
                     pedestrians=(PedestrianBody("a", 0.25), PedestrianBody("b", 0.3)))


@pytest.mark.parametrize("seed", range(4))
def test_bounded_clearance_gives_the_same_running_minimum(seed):
    """A random walk of the robot (with turns) and two pedestrians past walls, a box and a cylinder: the running
    minimum through GroundTruth.clearance (which skips what its bound proves) equals, bit for bit, the one through
    the exact Clearance at every block; every skipped value is >= the running minimum and <= the exact value."""
    world = SimWorld(_scene())
    truth = GroundTruth(world.model, world.scene)
    exact = Clearance(world.scene, truth.outline)
    rng = np.random.default_rng(seed)
    pose = np.array([-2.0, 0.0, 0.0])
    peds = np.array([[2.0, 1.0], [1.0, -1.2]])
    lo_fast = lo_exact = math.inf
    skipped = 0
    for _ in range(1500):
        pose += rng.normal(0, [0.01, 0.01, 0.05])
        pose[0] = np.clip(pose[0], -2.8, 2.8)
        pose[1] = np.clip(pose[1], -1.3, 1.3)
        pose[2] = math.atan2(math.sin(pose[2]), math.cos(pose[2]))
        peds += rng.normal(0, 0.013, peds.shape)
        v = exact(tuple(pose), peds)
        f = truth.clearance(tuple(pose), peds, lo_fast)
        assert f >= lo_fast or f == v
        if f != v:
            skipped += 1
            assert lo_fast <= f <= v
        lo_fast, lo_exact = min(lo_fast, f), min(lo_exact, v)
        assert lo_fast == lo_exact
    assert skipped > 100                       # the bound does skip (and the comparison above is not idle)


def test_bounded_is_a_lower_bound():
    """Clearance.bounded's second value, where it is >= 0 (where GroundTruth.clearance uses it), never exceeds the
    exact minimum, whatever ``below`` pruned; the random poses include overlaps (where it may)."""
    c = Clearance(_scene())
    rng = np.random.default_rng(0)
    for _ in range(500):
        pose = (rng.uniform(-2.5, 2.5), rng.uniform(-1.2, 1.2), rng.uniform(-math.pi, math.pi))
        peds = rng.uniform(-2, 2, (2, 2))
        full = c(pose, peds)
        for below in (math.inf, full + 0.5, full + 0.01, full - 0.01, 0.0):
            value, lower = c.bounded(pose, peds, below)
            assert lower < 0 or lower <= full
            if full >= 0:                  # (Clearance's own contract; an overlap's pruning is looser)
                assert value == full if full < below else value >= below


def test_float_odometry_is_the_numpy_kinematics():
    kin = MecanumKinematics()
    odo = WheelOdometry(kin)
    for w in np.random.default_rng(1).normal(0, 10, (2000, 4)):
        assert np.array_equal(odo._forward(w), kin.forward(w))


def _desired_numpy(p: Pedestrians, t: float) -> np.ndarray:
    """Pedestrians._desired as it was written in numpy (the reference)."""
    e = np.zeros((p.k, 2))
    for i in range(p.k):
        if t < p.t0[i] or p.done[i]:
            continue
        path = p.paths[i]
        d = path[p.target[i]] - p.p[i]
        if np.linalg.norm(d) < p.params.waypoint_tol_m:
            if p.target[i] + 1 < len(path):
                p.target[i] += 1
            elif p.loop[i]:
                p.target[i] = 0
            else:
                p.done[i] = True
                continue
            d = path[p.target[i]] - p.p[i]
        e[i] = d / max(np.linalg.norm(d), 1e-9)
    return e * p.v0[:, None]


def test_desired_velocities_match_the_numpy_form():
    """Walkers stepped to the end of their paths (one looping, one stopping): every call, the numpy form on a twin
    stepped alike, to 8 ulps (3 seen): numpy's 2-norm is BLAS's dot, whose kernel OpenBLAS picks per CPU (with fused
    multiply-adds on some, 1 ulp off sqrt(dx dx + dy dy); seen on a 2026-11-27 CI machine), while the fast form's
    plain floats are the same bits on every machine; the waypoints reached are the same exactly."""
    rng = np.random.default_rng(3)
    args = ([rng.uniform(-3, 3, (4, 2)) for _ in range(3)], [1.1, 0.9, 1.3], [0.0, 0.5, 1.0], [0.25, 0.3, 0.2],
            [True, False, False], [True, False, True])
    a, b = Pedestrians(*args), Pedestrians(*args)
    for k in range(1500):
        t = 0.02 * k
        np.testing.assert_array_max_ulp(a._desired(t), _desired_numpy(b, t), maxulp=8)
        assert np.array_equal(a.target, b.target) and np.array_equal(a.done, b.done)
        a.step(t, 0.02, robot_xy=(0.0, 0.0))
        b.step(t, 0.02, robot_xy=(0.0, 0.0))
    assert a.done.any() and a.target[0] >= 0


def test_contact_lookup_and_snapshot():
    """in_contact's pair table agrees with the masks it is built from, for every geom pair; a snapshot gives the
    true state of its moment after the physics moved on."""
    world = SimWorld(_scene())
    truth = GroundTruth(world.model, world.scene)
    n = world.model.ngeom
    for a in range(n):
        for b in range(n):
            want = (truth.robot_geom[a] and truth.obstacle_geom[b]) or (truth.robot_geom[b] and truth.obstacle_geom[a])
            assert truth._contact_pair[a, b] == want
    world.command((0.4, 0.1, 0.3))
    world.advance(0.5)
    snap, then = world.snapshot(), world.true_state()
    world.advance(0.2)
    assert world.true_state() != then and world.true_state(snap) == then
    assert isinstance(world.data, mujoco.MjData)


def test_compiled_clearance_matches_its_reference():
    """Clearance.bounded (compiled, issue 26) against bounded_reference (the Python form) at random poses, with
    and without ``below``, over every obstacle subset: the same value and bound, to the last bit but where a
    circle's distance goes through ``math.hypot``, whose CPython form (correctly rounded) and the C library's (the
    kernel's) differ in the last bit in about 1 case in 200; and the kernel is not a stand-in: poses near the
    obstacles take every branch (a rectangle apart and overlapping, a circle, a pedestrian, the early return)."""
    c = Clearance(_scene())
    rng = np.random.default_rng(3)
    same = 0
    for k in range(3000):
        pose = (rng.uniform(-3.2, 3.2), rng.uniform(-1.7, 1.7), rng.uniform(-4, 4))
        peds = rng.uniform(-2, 2, (2, 2))
        below = (math.inf, rng.uniform(-0.3, 1.0))[k % 2]
        static, peds_on = ((True, True), (True, False), (False, True))[k % 3]
        a = c.bounded(pose, peds, below, static, peds_on)
        b = c.bounded_reference(pose, peds, below, static, peds_on)
        same += a == b
        for x, y in zip(a, b):
            assert x == y or abs(x - y) <= 4 * np.spacing(max(abs(y), 1.0))
    assert same >= 2900
    assert c.bounded((0.0, 0.0, 0.0), np.zeros((0, 2)), math.inf, False, True) == (math.inf, math.inf)
