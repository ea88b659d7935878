"""The common filter's slowdown (StackParams.cbf_slowdown, bigcbf/control/cbf.py, "The slowdown"): a step with no
feasible command at u_in's margins is filtered again from s u_in, s in SLOWDOWN_SCALES, fastest first."""
import dataclasses

import numpy as np
import pytest

from bigcbf.control.cbf import SLOWDOWN_SCALES, CbfFilter, cbf_rows
from bigcbf.control.methods import filter_params, make_planner
from bigcbf.errors import FieldError
from bigcbf.params.stack import PlusRules, StackParams
from bigcbf.types import Obstacles, RobotState

U_IN = np.array([0.8, 0.0, 0.0])          # full ahead, along the gap


def gap(half_width: float) -> Obstacles:
    """Two wall points (radius 0, static, well measured) at +-half_width across the robot's path."""
    p = np.array([[0.0, half_width], [0.0, -half_width]])
    return Obstacles(p, np.zeros((2, 2)), np.tile(np.eye(2) * 1e-4, (2, 1, 1)), np.zeros(2), np.ones(2, bool),
                     np.array([-1, -1]))


def margin_at(scale: float, params: StackParams) -> float:
    """D_i^exec of a wall point when the filter starts from scale * U_IN (it does not depend on where the point is)."""
    return float(cbf_rows(RobotState(0.0, 0.0, 0.0), gap(1.0), scale * U_IN, params).D[0])


def test_a_gap_wide_only_at_a_slower_speed_is_passed_at_the_first_feasible_scale():
    off = StackParams()
    on = dataclasses.replace(off, cbf_slowdown=True)
    assert SLOWDOWN_SCALES == (0.5, 0.25, 0.0)
    d_full, d_half, d_quarter = margin_at(1.0, off), margin_at(0.5, off), margin_at(0.25, off)
    assert d_full > d_half > d_quarter            # D_i^exec grows with the command (eq:uncertainty_margin)
    half_width = 0.5 * (d_half + d_quarter)       # inside D_i at 0.5 u_in on both sides, outside at 0.25 u_in
    state, obs = RobotState(0.0, 0.0, 0.0), gap(half_width)

    u_off, info_off = CbfFilter(off).filter(state, obs, U_IN)
    assert info_off.infeasible and info_off.fallback == "least-violation" and info_off.slowdown is None

    u, info = CbfFilter(on).filter(state, obs, U_IN)
    assert not info.infeasible and info.active
    assert info.fallback == "slowdown" and info.slowdown == 0.25
    # independently: at 0.5 u_in's margins the filter alone finds no command; at 0.25 u_in's it does
    assert CbfFilter(off).filter(state, obs, 0.5 * U_IN)[1].infeasible
    rows = cbf_rows(state, obs, 0.25 * U_IN, off)
    assert np.all(rows.h > 0) and np.allclose(rows.D, d_quarter)
    assert np.all(rows.C @ u >= rows.l - 1e-9)
    # the minimum intervention from 0.25 u_in: the slowed command satisfies both rows, so it is the answer
    assert np.allclose(u, 0.25 * U_IN, atol=1e-9)
    assert np.allclose(info.D, d_quarter)


def test_without_a_feasible_slower_command_the_step_is_the_same_as_without_the_switch():
    off = StackParams()
    obs = gap(0.5 * margin_at(0.0, off))          # inside D_i on both sides even at rest
    state = RobotState(0.0, 0.0, 0.0)
    for last_resort in ("slack", "passive"):
        p_off = dataclasses.replace(off, cbf_last_resort=last_resort)
        u_off, i_off = CbfFilter(p_off).filter(state, obs, U_IN)
        u_on, i_on = CbfFilter(dataclasses.replace(p_off, cbf_slowdown=True)).filter(state, obs, U_IN)
        assert i_on.infeasible and i_on.fallback == i_off.fallback and i_on.slowdown is None
        assert np.array_equal(u_on, u_off)


@pytest.mark.parametrize("half_width", [0.6, 1.5])
def test_a_feasible_step_is_untouched_by_the_switch(half_width):
    off = StackParams()
    state, obs = RobotState(0.0, 0.0, 0.3), gap(half_width)
    u_off, i_off = CbfFilter(off).filter(state, obs, U_IN)
    u_on, i_on = CbfFilter(dataclasses.replace(off, cbf_slowdown=True)).filter(state, obs, U_IN)
    assert not i_off.infeasible and np.array_equal(u_on, u_off) and i_on.fallback == i_off.fallback


def test_the_slowdown_is_off_by_default_and_a_switch_of_every_method():
    p = StackParams()
    assert not p.cbf_slowdown
    assert not filter_params(make_planner("big-cbf-plus", p), p).cbf_slowdown
    assert filter_params(make_planner("big-cbf-plus", p, PlusRules(slowdown=True)), p).cbf_slowdown
    for name in ("big-cbf", "cbf-only", "backup-cbf"):
        assert not filter_params(make_planner(name, p), p).cbf_slowdown
    assert filter_params(make_planner("cbf-only", dataclasses.replace(p, cbf_slowdown=True)),
                         dataclasses.replace(p, cbf_slowdown=True)).cbf_slowdown


def test_the_switch_must_be_a_boolean():
    with pytest.raises(FieldError, match="must be true or false") as e:
        StackParams(cbf_slowdown="yes")
    assert e.value.field == "cbf_slowdown"
