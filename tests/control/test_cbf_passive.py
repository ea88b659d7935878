"""The "passive" last resort of the common filter (StackParams.cbf_last_resort, bigcbf/control/cbf.py): on an
infeasible step the robot's velocity does not approach any body whose barrier is already violated."""
import dataclasses

import numpy as np
import pytest

from bigcbf.control.cbf import CbfFilter, cbf_rows
from bigcbf.params.stack import StackParams
from bigcbf.types import Obstacles, RobotState


def squeezed():
    """A robot between two wall points 0.2 m away on either side (inside both D_i) with a walker closing at 1.2 m/s
    from ahead: no command satisfies every row."""
    p = np.array([[0.0, 0.2], [0.0, -0.2], [0.55, 0.05]])
    v = np.array([[0.0, 0.0], [0.0, 0.0], [-1.2, 0.0]])
    cov = np.tile(np.eye(2) * 1e-4, (3, 1, 1))
    return Obstacles(p, v, cov, np.array([0.0, 0.0, 0.25]), np.array([True, True, False]), np.array([-1, -1, 7]))


@pytest.mark.parametrize("theta", [0.0, 0.7, -2.0])
def test_passive_does_not_approach_bodies_it_is_inside(theta):
    params = dataclasses.replace(StackParams(), cbf_last_resort="passive")
    state = RobotState(0.0, 0.0, theta)
    obs = squeezed()
    u_in = np.array([0.6 * np.cos(-theta), 0.6 * np.sin(-theta), 0.0])    # full ahead (+x in odom) into the walker
    u, info = CbfFilter(params).filter(state, obs, u_in)
    assert info.infeasible and info.fallback == "passive"
    rows = cbf_rows(state, obs, u_in, params)
    inside = np.flatnonzero(rows.h < 0)
    assert len(inside) >= 2
    ex = params.uncertainty.execution
    A, d = np.asarray(ex.A, float), np.asarray(ex.d, float)
    c, s = np.cos(theta), np.sin(theta)
    body = (A @ u + d)[:2]
    v_world = np.array([c * body[0] - s * body[1], s * body[0] + c * body[1]])
    for i in inside:     # q_i = p - p_i: the robot's velocity along q_i is >= 0 (it moves away or keeps its distance)
        assert rows.q[i] @ v_world >= -1e-9, (i, rows.q[i] @ v_world)
    # the slack command (the default) approaches at least one of them in this case: the option changes something
    u_s, info_s = CbfFilter(StackParams()).filter(state, obs, u_in)
    assert info_s.fallback == "least-violation"
    body_s = (A @ u_s + d)[:2]
    vs = np.array([c * body_s[0] - s * body_s[1], s * body_s[0] + c * body_s[1]])
    assert min(rows.q[i] @ vs for i in inside) < -1e-6
