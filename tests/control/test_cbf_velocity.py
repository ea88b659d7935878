"""Issue 23, items 2 and 3: the velocity-aware barrier (a collision-cone row per moving obstacle, a switch of the one
common filter), the ``dpcbf`` method, and the filter's last resort when no command satisfies every row."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from bigcbf.control.cbf import CbfFilter, cbf_rows
from bigcbf.control.methods import METHODS, filter_params, make_planner
from bigcbf.episode import Episode
from bigcbf.errors import FieldError, UserError
from bigcbf.params import SIMULATION
from bigcbf.params.stack import load_stack_params
from bigcbf.scenario import load_scenario
from bigcbf.types import Obstacles, RobotState

P = SIMULATION
ON = dataclasses.replace(P, cbf_velocity_rows=True)


def obstacles(p, v, r=0.25, ids=None):
    p, v = np.atleast_2d(np.asarray(p, float)), np.atleast_2d(np.asarray(v, float))
    m = len(p)
    return Obstacles(p, v, np.zeros((m, 2, 2)), np.full(m, r), np.zeros(m, bool),
                     np.arange(m) if ids is None else np.asarray(ids))


def world_velocity(state, u, params=P):
    ex = params.uncertainty.execution
    b = np.asarray(ex.A)[:2] @ u + np.asarray(ex.d)[:2]
    c, s = math.cos(state.theta), math.sin(state.theta)
    return np.array([c * b[0] - s * b[1], s * b[0] + c * b[1]])


def in_truncated_cone(q, w, D, tau, n=2000):
    """Brute force: does the relative motion q + t w enter the disk of radius D within t in (0, tau]?"""
    t = np.linspace(tau / n, tau, n)
    return bool(np.any(np.hypot(q[0] + t * w[0], q[1] + t * w[1]) < D - 1e-9))


def test_the_switch_is_off_by_default_and_dpcbf_is_cbf_only_with_it_on():
    assert P.cbf_velocity_rows is False and P.cbf_last_resort == "slack"
    planner = make_planner("dpcbf", P)
    assert "dpcbf" in METHODS and filter_params(planner, P).cbf_velocity_rows is True
    assert filter_params(make_planner("cbf-only", P), P) is P


def test_no_moving_obstacle_no_difference():
    """Static obstacles, slow ones and wall points get no cone row: the filter with the switch on is the paper's."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        st = RobotState(*rng.uniform(-1, 1, 2), rng.uniform(-3, 3))
        obs = obstacles(rng.uniform(-2, 2, (3, 2)), rng.uniform(-0.1, 0.1, (3, 2)), ids=[0, 1, -1])
        obs.v[2] = (1.0, 0.0)                                  # a wall point, however fast, gets none either
        u_in = rng.uniform(-1, 1, 3)
        u_off, i_off = CbfFilter(P).filter(st, obs, u_in)
        u_on, i_on = CbfFilter(ON).filter(st, obs, u_in)
        assert np.array_equal(u_off, u_on) and i_on.n_velocity_rows == 0
        assert (i_off.infeasible, i_off.fallback) == (i_on.infeasible, i_on.fallback)


def test_the_cone_row_is_sound_and_minimally_intervening():
    """Whenever the QP is feasible, the executed relative velocity keeps out of every moving obstacle's truncated
    collision cone (brute force over t); when u_in already did and the paper's filter leaves it alone, so does the
    switch."""
    rng = np.random.default_rng(7)
    tau = ON.cbf_velocity_horizon_s
    n_acted = n_free = 0
    for _ in range(400):
        st = RobotState(0.0, 0.0, rng.uniform(-math.pi, math.pi))
        m = int(rng.integers(1, 4))
        ang = rng.uniform(-math.pi, math.pi, m)
        dist = rng.uniform(1.0, 4.0, m)
        p = np.c_[dist * np.cos(ang), dist * np.sin(ang)]
        v = rng.uniform(-1.3, 1.3, (m, 2))
        obs = obstacles(p, v)
        u_in = np.r_[rng.uniform(-0.8, 0.8, 2), 0.0]
        u, info = CbfFilter(ON).filter(st, obs, u_in)
        q = -p
        if not info.infeasible and not info.velocity_relaxed:
            w = world_velocity(st, u)[None, :] - v
            for i in range(m):
                if np.hypot(*v[i]) >= ON.cbf_velocity_min_speed_mps and np.hypot(*q[i]) > info.D[i]:
                    assert not in_truncated_cone(q[i], w[i], info.D[i] - 1e-6, tau)
            n_acted += info.n_velocity_rows > 0 and info.active
        w_in = world_velocity(st, u_in)[None, :] - v
        u_off, i_off = CbfFilter(P).filter(st, obs, u_in)
        if not i_off.active and not any(in_truncated_cone(q[i], w_in[i], info.D[i] * 1.001, tau) for i in range(m)):
            assert np.array_equal(u, u_off) and not info.active
            n_free += 1
    assert n_acted > 20 and n_free > 20          # both branches were exercised


def test_distance_rows_come_first():
    """Crowded random scenes (2-4 walkers 0.7-2 m away, up to 1.5 m/s): the switch never makes a step infeasible that
    the paper's filter solves, and the other way round (the lexicographic fallback); where the cone rows were
    relaxed, every distance row (eq:cbf_condition (25)) holds at the command and the fallback says so."""
    rng = np.random.default_rng(11)
    n_relaxed = n_infeasible = 0
    for _ in range(300):
        st = RobotState(0.0, 0.0, rng.uniform(-math.pi, math.pi))
        m = int(rng.integers(2, 5))
        ang, dist = rng.uniform(-math.pi, math.pi, m), rng.uniform(0.7, 2.0, m)
        obs = obstacles(np.c_[dist * np.cos(ang), dist * np.sin(ang)], rng.uniform(-1.5, 1.5, (m, 2)))
        u_in = np.r_[rng.uniform(-0.8, 0.8, 2), 0.0]
        u, info = CbfFilter(ON).filter(st, obs, u_in)
        _, off = CbfFilter(P).filter(st, obs, u_in)
        assert info.infeasible == off.infeasible
        n_infeasible += info.infeasible
        if info.velocity_relaxed:
            n_relaxed += 1
            assert info.fallback == "velocity-relaxed" and not info.infeasible and info.max_violation > 0
            rows = cbf_rows(st, obs, u_in, ON)
            dist_rows = info.rows[:len(info.rows) - info.n_velocity_rows]
            assert np.all(rows.C[dist_rows] @ u >= rows.l[dist_rows] - 1e-6)
    assert n_relaxed >= 5 and n_infeasible >= 5            # both branches occur


def _chase(params, steps=120, dt=0.05):
    """A walker at 1.2 m/s behind the robot, walking at it; the robot asks for 0.8 m/s straight on (eq:execution
    (1) with the nominal model, integrated kinematically). Returns (the smallest centre distance, infeasible steps)."""
    filt = CbfFilter(params)
    p, pi, vi = np.zeros(2), np.array([-2.0, 0.0]), np.array([1.2, 0.0])
    dmin, n_inf = math.inf, 0
    for _ in range(steps):
        st = RobotState(p[0], p[1], 0.0)
        u, info = filt.filter(st, obstacles(pi, vi), np.array([0.8, 0.0, 0.0]))
        n_inf += info.infeasible
        p = p + dt * world_velocity(st, u, params)
        pi = pi + dt * vi
        dmin = min(dmin, float(np.hypot(*(p - pi))))
    return dmin, n_inf


def test_a_faster_walker_from_behind():
    """The issue's case: the distance barrier pushes the robot down the walker's path and loses (the QP becomes
    infeasible, the walker runs into it); the cone row steps aside in time, every QP feasible."""
    contact = P.uncertainty.r_robot_m + 0.25
    d_off, inf_off = _chase(P)
    d_on, inf_on = _chase(ON)
    assert d_off < contact and inf_off > 0
    assert d_on > contact + P.uncertainty.d0_m and inf_on == 0


def _infeasible_case():
    """A walker just outside the barrier, closing from behind at 1.5 m/s: no command in the box holds the row."""
    st = RobotState(0.0, 0.0, 0.0)
    return st, obstacles([-0.62, -0.05], [1.5, 0.0])


@pytest.mark.parametrize("resort", ["slack", "brake", "evade"])
def test_last_resorts(resort):
    st, obs = _infeasible_case()
    u, info = CbfFilter(dataclasses.replace(P, cbf_last_resort=resort)).filter(st, obs, np.array([0.3, 0.0, 0.0]))
    assert info.infeasible and np.all(np.isfinite(u))
    if resort == "slack":
        assert info.fallback == "least-violation" and u[0] == pytest.approx(0.8)      # away along q, at the limit
    elif resort == "brake":
        assert info.fallback == "brake" and np.array_equal(u, np.zeros(3))
    else:                                   # across the walker's path, on the side the robot is (q_y > 0: left)
        assert info.fallback == "evade" and u[1] == pytest.approx(P.v_max_mps) and abs(u[0]) < 1e-9


def test_evade_falls_back_to_slack_for_a_static_obstacle():
    st = RobotState(0.0, 0.0, 0.0)
    obs = obstacles([[0.5, 0.0], [-0.5, 0.0]], [[0.0, 0.0], [0.0, 0.0]], r=0.2)    # squeezed between two posts
    u_s, i_s = CbfFilter(P).filter(st, obs, np.array([0.3, 0.0, 0.0]))
    u_e, i_e = CbfFilter(dataclasses.replace(P, cbf_last_resort="evade")).filter(st, obs, np.array([0.3, 0.0, 0.0]))
    assert i_e.infeasible and i_e.fallback == "least-violation" and np.array_equal(u_s, u_e)


def test_bad_values_are_one_line_errors(tmp_path):
    with pytest.raises(FieldError, match="must be one of slack, brake, evade") as err:
        dataclasses.replace(P, cbf_last_resort="fly")
    assert err.value.field == "cbf_last_resort"
    for text, field in [('cbf_last_resort = "fly"\n', "cbf_last_resort"),
                        ("cbf_velocity_horizon_s = 0.0\n", "cbf_velocity_horizon_s"),
                        ("cbf_velocity_min_speed_mps = -1.0\n", "cbf_velocity_min_speed_mps"),
                        ('cbf_velocity_rows = "yes"\n', "cbf_velocity_rows")]:
        f = tmp_path / "s.toml"
        f.write_text(text)
        with pytest.raises(UserError) as err:
            load_stack_params(f)
        assert err.value.file == str(f) and err.value.field == field


def test_dpcbf_episode_is_cbf_only_through_the_switched_filter():
    """A real episode: dpcbf equals cbf-only with the switch set in the stack parameters, and its filter has it."""
    sc = load_scenario("single_person_crossing")
    a = Episode(sc, "dpcbf", params=P, seed=1, time_limit_s=3.0)
    assert a.cbf.params.cbf_velocity_rows is True
    ra = a.run()
    rb = Episode(sc, "cbf-only", params=ON, seed=1, time_limit_s=3.0).run()
    for k in ("e_cbf", "qp_infeasible_ratio", "cbf_active_ratio", "min_clearance_m", "final_goal_dist_m"):
        assert getattr(ra, k) == getattr(rb, k)
