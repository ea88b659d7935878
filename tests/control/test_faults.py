"""Perception faults (bigcbf/control/faults.py): non-finite or implausible obstacle estimates make the CBF filter
and every planner brake (u = 0), logged and never poisoning a planner's state; valid but extreme estimates still
give finite commands inside the actuator box. Property tests over random inputs (hypothesis)."""
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bigcbf.control.cbf import PERCEPTION_FAULT, CbfFilter
from bigcbf.control.faults import FAULT_MODE, MAX_COVARIANCE_M2, bad_obstacles, perception_fault
from bigcbf.control.imagination import imagine
from bigcbf.control.methods import METHODS
from bigcbf.params.stack import SIMULATION
from bigcbf.types import Obstacles, RobotState

P = SIMULATION
LO, HI = np.asarray(P.u_min), np.asarray(P.u_max)
GOAL = np.array([6.0, 0.0])
SETTINGS = settings(max_examples=40, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

BAD_FLOATS = [math.nan, math.inf, -math.inf]


@st.composite
def valid_obstacles(draw, min_m=1, max_m=6):
    """Valid estimates around the robot at the origin, including edge cases: an obstacle on the robot's centre,
    zero radius, wall points (ids < 0), large but plausible covariances and speeds."""
    m = draw(st.integers(min_m, max_m))
    coord = st.one_of(st.floats(-6, 6), st.just(0.0), st.floats(-1e3, 1e3))
    p = np.array([[draw(coord), draw(coord)] for _ in range(m)])
    v = np.array([[draw(st.floats(-3, 3)), draw(st.floats(-3, 3))] for _ in range(m)])
    cov = []
    for _ in range(m):
        a = draw(st.one_of(st.floats(0, 1), st.floats(0, 1e3)))
        c = draw(st.floats(0, 1))
        rho = draw(st.floats(-1, 1))
        b = rho * math.sqrt(a * c)
        cov.append([[a, b], [b, c]])
    r = np.array([draw(st.sampled_from([0.0, 0.05, 0.25, 0.6])) for _ in range(m)])
    ids = np.array([draw(st.sampled_from([-1, 0, 1, 2, 3, 4, 5, 6])) for _ in range(m)])
    static = np.array([draw(st.booleans()) for _ in range(m)])
    return Obstacles(p, v, np.array(cov, float), r, static, ids)


@st.composite
def faulty_obstacles(draw):
    """Valid estimates with one or more faulty fields: NaN/inf anywhere, a negative or absurd radius, a
    non-symmetric, non-PSD or absurd covariance, an absurd position or speed."""
    obs = draw(valid_obstacles())
    p, v, cov, r = obs.p.copy(), obs.v.copy(), obs.cov.copy(), obs.r.copy()
    for _ in range(draw(st.integers(1, 3))):
        i = draw(st.integers(0, len(r) - 1))
        kind = draw(st.sampled_from(["p", "v", "cov", "r", "r-neg", "r-huge", "cov-asym", "cov-nonpsd",
                                     "cov-huge", "p-huge", "v-huge"]))
        bad = draw(st.sampled_from(BAD_FLOATS))
        if kind == "p":
            p[i, draw(st.integers(0, 1))] = bad
        elif kind == "v":
            v[i, draw(st.integers(0, 1))] = bad
        elif kind == "cov":
            a, b = draw(st.integers(0, 1)), draw(st.integers(0, 1))
            cov[i, a, b] = bad
            if draw(st.booleans()):
                cov[i, b, a] = bad
        elif kind == "r":
            r[i] = bad
        elif kind == "r-neg":
            r[i] = -draw(st.floats(1e-6, 10))
        elif kind == "r-huge":
            r[i] = draw(st.floats(101, 1e300))
        elif kind == "cov-asym":
            cov[i, 0, 1] += draw(st.floats(1e-3, 10))
        elif kind == "cov-nonpsd":
            cov[i] = [[draw(st.floats(0, 1)), 2.0], [2.0, draw(st.floats(0, 1))]]
        elif kind == "cov-huge":
            cov[i] = np.eye(2) * draw(st.floats(1.01 * MAX_COVARIANCE_M2, 1e300))
        elif kind == "p-huge":
            p[i, draw(st.integers(0, 1))] = draw(st.sampled_from([-1, 1])) * draw(st.floats(1.01e4, 1e300))
        else:
            v[i, draw(st.integers(0, 1))] = draw(st.floats(60, 1e300))
    return Obstacles(p, v, cov, r, obs.static, obs.ids)


states = st.builds(RobotState, st.floats(-2, 2), st.floats(-2, 2), st.floats(-math.pi, math.pi),
                   st.floats(-0.8, 0.8), st.floats(-0.8, 0.8), st.floats(-1, 1))
commands = st.lists(st.floats(-2, 2), min_size=3, max_size=3).map(np.array)


def test_the_issue_s_24_variants_now_brake():
    """The measurement of issue 16: one obstacle with NaN or +-inf in one field (8 fields x 3 values) beside a
    valid one 0.5 m ahead; the filter passed 0.8 m/s in 16 of the 24 before."""
    f = CbfFilter(P)
    for field in ["p0", "p1", "v0", "v1", "c00", "c01", "c11", "r"]:
        for val in BAD_FLOATS:
            p, v, cov, r = np.array([[0.5, 0.0], [3.0, 1.0]]), np.zeros((2, 2)), np.zeros((2, 2, 2)), np.full(2, 0.2)
            if field[0] == "p":
                p[1, int(field[1])] = val
            elif field[0] == "v":
                v[1, int(field[1])] = val
            elif field[0] == "c":
                a, b = int(field[1]), int(field[2])
                cov[1, a, b] = cov[1, b, a] = val
            else:
                r[1] = val
            u, info = f.filter(RobotState(0, 0, 0), Obstacles(p, v, cov, r, np.ones(2, bool)), [0.8, 0, 0])
            assert np.array_equal(u, np.zeros(3)), (field, val)
            assert info.fallback == PERCEPTION_FAULT and info.active and "obstacle 1" in info.fault


@SETTINGS
@given(faulty_obstacles(), states, commands)
def test_filter_brakes_on_any_perception_fault(obs, state, u_in):
    assert bad_obstacles(obs)[0].any() and perception_fault(state, obs) is not None
    u, info = CbfFilter(P).filter(state, obs, u_in)
    assert np.array_equal(u, np.zeros(3))
    assert info.fallback == PERCEPTION_FAULT and info.fault and not info.infeasible
    assert info.active == bool(np.any(np.clip(u_in, LO, HI) != 0))
    assert len(info.D) == len(obs) and np.isfinite(info.D).all()


@SETTINGS
@given(valid_obstacles(), states, commands)
def test_filter_on_valid_extreme_estimates_is_finite_and_in_the_box(obs, state, u_in):
    assert perception_fault(state, obs) is None
    u, info = CbfFilter(P).filter(state, obs, u_in)
    assert np.isfinite(u).all() and np.all(u >= LO - 1e-12) and np.all(u <= HI + 1e-12)
    assert info.fallback != PERCEPTION_FAULT


@SETTINGS
@given(states, st.sampled_from([math.nan, math.inf, -math.inf, 1e5]), st.integers(0, 5), commands)
def test_a_faulty_robot_state_or_goal_brakes_too(state, bad, which, u_in):
    x = list(state.as_array())
    x[which] = bad if which != 2 or not math.isfinite(bad) else math.nan
    bad_state = RobotState(*x)
    u, info = CbfFilter(P).filter(bad_state, Obstacles.from_lists([[1.0, 0.0]], r=0.2), u_in)
    assert np.array_equal(u, np.zeros(3)) and info.fallback == PERCEPTION_FAULT
    assert perception_fault(state, Obstacles.empty(), [bad, 0.0]) is not None


@pytest.mark.parametrize("method", sorted(METHODS.names()))
def test_every_planner_brakes_on_faults_and_recovers(method):
    """For each method: a faulty step gives u_in = 0 and mode FAULT; valid (possibly extreme) steps before and
    after give finite commands inside the box, so the fault did not poison the planner's state."""
    planner = METHODS.get(method)(P)
    planner.reset(0)
    clock = [0.0]            # the planner's clock runs forward across examples, as in an episode

    @settings(max_examples=12 if method == "mppi" else 25, deadline=None, derandomize=True,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(valid_obstacles(max_m=4), faulty_obstacles(), states, st.integers(1, 20))
    def check(good, bad, state, ticks):
        t = clock[0] = clock[0] + 0.05 * ticks
        clock[0] += 0.6
        u, info = planner.plan(t, state, good, GOAL)
        assert np.isfinite(u).all() and np.all(u >= LO - 1e-9) and np.all(u <= HI + 1e-9), (method, u)
        u, info = planner.plan(t + 0.05, state, bad, GOAL)
        assert np.array_equal(u, np.zeros(3)) and info.mode == FAULT_MODE and not info.planned
        u, info = planner.plan(t + 0.5, state, good, GOAL)
        assert np.isfinite(u).all() and np.all(u >= LO - 1e-9) and np.all(u <= HI + 1e-9), (method, u)
        assert info.mode != FAULT_MODE

    check()


@SETTINGS
@given(valid_obstacles(), states)
def test_imagination_on_valid_extreme_estimates_is_finite(obs, state):
    img = imagine(state, obs, GOAL, P)
    assert np.isfinite(img.u).all() and np.isfinite(img.p).all() and not np.isnan(img.J).any()


@SETTINGS
@given(faulty_obstacles(), states)
def test_imagination_refuses_faulty_estimates(obs, state):
    with pytest.raises(ValueError, match="perception fault"):
        imagine(state, obs, GOAL, P)
