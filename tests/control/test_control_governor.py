"""The speed governor of BIG-CBF's policies (bigcbf/control/governor.py): the filter model and the governed scale,
against values worked out by hand (``eq:cbf_condition`` (25) with D_i of eq:shared_barrier (20)
and eq:uncertainty_margin (21))."""
import dataclasses
import math

import numpy as np
import pytest

from bigcbf.control.governor import filter_model, govern_c, govern_command
from bigcbf.params import SIMULATION, ExecutionModel, UncertaintyParams
from bigcbf.types import Obstacles, RobotState

# no uncertainty terms and ideal execution: D = r_R + r_i + d0 = 0.15 + 0.25 + 0.10 = 0.5 for r_i = 0.25
BARE = dataclasses.replace(SIMULATION, uncertainty=UncertaintyParams(
    tau95_s=0.0, beta=0.0, e_zoh_m=0.0, execution=ExecutionModel(residual_bound_mps=(0.0, 0.0))))


def test_filter_model_projects_onto_one_row_or_the_corner_of_two():
    # one row w_x <= 0.25 (n = -1, l = -0.25): 0.8 -> 0.25
    w = filter_model(np.array([0.8 + 0j]), np.array([[-1 + 0j]]), np.array([[-0.25]]), 0.8)
    assert w[0] == pytest.approx(0.25 + 0j)
    # plus w_y >= 0.1 (n = i, l = 0.1): each single projection violates the other row; the corner (0.25, 0.1)
    w = filter_model(np.array([0.8 + 0j]), np.array([[-1 + 0j, 1j]]), np.array([[-0.25, 0.1]]), 0.8)
    assert w[0] == pytest.approx(0.25 + 0.1j)
    # an admissible velocity is left alone
    w = filter_model(np.array([0.1 + 0j]), np.array([[-1 + 0j, 1j]]), np.array([[-0.25, -0.1]]), 0.8)
    assert w[0] == pytest.approx(0.1 + 0j)
    # the speed disk: 0.7 + 0.7i is scaled to |w| = 0.8
    w = filter_model(np.array([0.7 + 0.7j]), np.array([[-1 + 0j]]), np.array([[-5.0]]), 0.8)
    assert w[0] == pytest.approx(0.8 * (0.7 + 0.7j) / abs(0.7 + 0.7j))


def test_obstacle_dead_ahead_slows_to_the_largest_admissible_scale():
    """Robot (0,0), u = (0.8, 0), static obstacle (0.7, 0), r = 0.25: q = (-0.7, 0), h = 0.49 - 0.25 = 0.24;
    eq:cbf_condition (25): -2 * 0.7 w_x + 1.5 * 0.24 >= 0  <=>  w_x <= 0.257143. Scale s gives w_x = 0.8 s:
    admissible up to s = 0.3214; the progress after the filter is min(0.8 s, 0.257143): 0.24 at s = 0.3, 0.257143 at s = 0.4 and at
    every larger s (projected onto the row). The smallest scale reaching the maximum: s* = 0.4, the governed command
    (0.32, 0), the model's velocity (0.257143, 0)."""
    s, w = govern_c(np.array([0j]), np.array([1 + 0j]), np.array([0.8 + 0j]), np.array([0.7 + 0j]),
                    np.array([0j]), np.array([0.0]), np.array([0.25]), BARE)
    assert s[0] == pytest.approx(0.4) and w[0] == pytest.approx(0.36 / 1.4 + 0j)
    obs = Obstacles.from_lists([[0.7, 0.0]], r=0.25)
    u, s1 = govern_command(RobotState(0, 0, 0), obs, np.array([0.8, 0.0, 0.0]), BARE)
    assert s1 == pytest.approx(0.4) and u == pytest.approx([0.32, 0.0, 0.0])
    # the planners: big-cbf (the paper's) commands the policy as it is; big-cbf-plus with the rule speed_governor
    # commands the governed policy; the rule is off in big-cbf-plus's defaults
    from bigcbf.control.behaviors import behavior_command
    from bigcbf.control.big_cbf import BigCbfPlanner, BigCbfPlusPlanner
    from bigcbf.params.stack import PlusRules
    goal, state = np.array([3.0, 0.0]), RobotState(0, 0, 0)
    far = Obstacles.from_lists([[1.2, 0.6]], r=0.25)
    for planner, governed in ((BigCbfPlanner(BARE), False), (BigCbfPlusPlanner(BARE), False),
                              (BigCbfPlusPlanner(BARE, PlusRules(speed_governor=True)), True)):
        u, info = planner.plan(0.0, state, far, goal)
        want = behavior_command(info.mode, state, far, goal, BARE, rules=planner.rules)
        if governed:
            want = govern_command(state, far, want, BARE)[0]
        assert u == pytest.approx(want)


def test_obstacle_ahead_right_keeps_full_speed_and_slides_along_the_row():
    """Obstacle at distance 0.7 along -(-0.6, 0.8): o = (0.42, -0.56), n = q/|q| = (-0.6, 0.8), h = 0.24, the row
    -0.6 w_x + 0.8 w_y >= -0.257143. w0 = (0.8 s, 0) is admissible up to s = 0.5357 (s = 0.5: progress 0.4).
    Above, the projection w = w0 + (0.48 s - 0.257143)(-0.6, 0.8) gains 0.512 s + 0.154286 along x, largest at
    s = 1 (0.666286 > 0.4). s* = 1 and the model's velocity (0.8 - 0.6 * 0.222857, 0.8 * 0.222857) =
    (0.666286, 0.178286)."""
    o = 0.7 * (0.6 - 0.8j)
    s, w = govern_c(np.array([0j]), np.array([1 + 0j]), np.array([0.8 + 0j]), np.array([o]),
                    np.array([0j]), np.array([0.0]), np.array([0.25]), BARE)
    assert s[0] == pytest.approx(1.0)
    assert w[0].real == pytest.approx(0.8 - 0.6 * (0.48 - 0.36 / 1.4)) and w[0].imag == pytest.approx(
        0.8 * (0.48 - 0.36 / 1.4))


def test_uncertainty_radius_grows_with_the_scale_eq_15():
    """With tau95 = 0.2 s (kappa_exec = 1) the radius depends on the scale: D(s) = 0.5 + 0.2 * 0.8 s
    (eq:uncertainty_margin (21), static obstacle). Obstacle dead ahead at 0.9: h(s) = 0.81 - D(s)^2, and
    eq:cbf_condition (25) bounds w_x <= 1.5 h(s) / 1.8.
    s = 0.4: D = 0.564, h = 0.491904, bound 0.40992 >= 0.32: admissible, progress 0.32.
    s = 0.5: D = 0.58, h = 0.4736, bound 0.394667 < 0.4: w = 0.394667, progress 0.394667.
    s = 0.6: D = 0.596, h = 0.454784, bound 0.378987: progress 0.378987 (the bound shrinks further above).
    s* = 0.5, w = 0.394667."""
    unc = dataclasses.replace(BARE.uncertainty, tau95_s=0.2)
    params = dataclasses.replace(BARE, uncertainty=unc)
    s, w = govern_c(np.array([0j]), np.array([1 + 0j]), np.array([0.8 + 0j]), np.array([0.9 + 0j]),
                    np.array([0j]), np.array([0.0]), np.array([0.25]), params)
    assert s[0] == pytest.approx(0.5)
    assert w[0] == pytest.approx(1.5 * (0.81 - 0.58 ** 2) / 1.8 + 0j)


def test_empty_scene_and_zero_command_are_left_alone():
    s, w = govern_c(np.array([0j]), np.array([1 + 0j]), np.array([0.8 + 0j]), np.zeros(0, complex),
                    np.zeros(0, complex), np.zeros(0), np.zeros(0), BARE)
    assert s[0] == 1.0 and w[0] == pytest.approx(0.8 + 0j)
    s, w = govern_c(np.array([0j]), np.array([1 + 0j]), np.array([0j]), np.array([0.7 + 0j]),
                    np.array([0j]), np.array([0.0]), np.array([0.25]), BARE)
    assert s[0] == 1.0 and w[0] == 0j
    assert math.isfinite(abs(w[0]))
