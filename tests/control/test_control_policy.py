"""One behavior policy (issue 22): the execution loop (eq:online_behavior_command (8)) and the imagination's rollout
(eq:behavior_rollout (12)) evaluate the same compiled pi_b (eq:behavior_subgoals (10), eq:behavior_feedback (11))
through ``behaviors.PolicyData``; what the rollout imagines at k = 0 is what the robot is commanded."""
import dataclasses

import numpy as np
import pytest

from bigcbf.control.behaviors import (BEHAVIORS, MODES, REVERSE, PolicyData, behavior_command, mode_indices,
                                      policy_velocity, release_velocity)
from bigcbf.control.governor import govern_command
from bigcbf.control.imagination import choose_release, imagine
from bigcbf.params import PHYSICAL, SIMULATION
from bigcbf.params.stack import PAPER_RULES, PlusRules
from bigcbf.types import Obstacles, RobotState

PLUS = PlusRules()                                  # big-cbf-plus's rules
GOVERNED = PlusRules(speed_governor=True)           # and the liveness option


def scene(seed):
    """A robot near the origin, a goal ahead, pedestrians, posts and a short wall of radius-0 points (a group)."""
    rng = np.random.default_rng(seed)
    n_ped, n_post, n_wall = 2, 3, 6
    p = np.concatenate([rng.uniform([0.5, -2.0], [3.5, 2.0], (n_ped + n_post, 2)),
                        np.stack([np.full(n_wall, rng.uniform(1.0, 3.0)),
                                  rng.uniform(-1.5, 0.5) + 0.2 * np.arange(n_wall)], 1)])
    M = len(p)
    v = np.concatenate([rng.normal(0.0, 0.6, (n_ped, 2)), np.zeros((M - n_ped, 2))])
    cov = np.tile(np.eye(2) * 0.004, (M, 1, 1))
    r = np.concatenate([np.full(n_ped, 0.25), rng.uniform(0.1, 0.3, n_post), np.zeros(n_wall)])
    static = np.arange(M) >= n_ped
    ids = np.where(np.arange(M) < n_ped + n_post, np.arange(M), -1)
    state = RobotState(float(rng.uniform(-0.2, 0.2)), float(rng.uniform(-0.2, 0.2)), float(rng.uniform(-3, 3)))
    return state, Obstacles(p, v, cov, r, static, ids), rng.uniform([4.0, -1.5], [6.0, 1.5])


@pytest.mark.parametrize("params, rules", [(SIMULATION, PAPER_RULES), (PHYSICAL, PAPER_RULES), (SIMULATION, PLUS),
                                           (PHYSICAL, PLUS), (SIMULATION, GOVERNED)])
@pytest.mark.parametrize("seed", range(6))
def test_the_rollout_starts_with_the_command_the_robot_gets(params, rules, seed):
    """At k = 0 the imagined robot and obstacles are the real ones, so the imagined command u_0 of every behavior
    is the command the execution loop would send in that mode (with the speed governor: governed, the same scale).
    Heading along the x axis the body and world frames coincide and the two are equal bit for bit; at another
    heading only the rotation into the body frame is written differently (e^{-i theta} against cos/sin): 1e-16."""
    state, obs, goal = scene(seed)
    for theta in (0.0, state.theta):
        at = RobotState(state.px, state.py, theta)
        img = imagine(at, obs, goal, params, rules=rules)
        for b, mode in enumerate(BEHAVIORS):
            u = behavior_command(mode, at, obs, goal, params, rules=rules)
            if rules.speed_governor and mode != "YIELD":
                u = govern_command(at, obs, u, params)[0]
            if theta == 0.0:
                np.testing.assert_array_equal(img.u[b, 0], u, err_msg=mode)
            else:
                np.testing.assert_allclose(img.u[b, 0], u, rtol=0, atol=1e-15, err_msg=mode)


@pytest.mark.parametrize("rules", [PAPER_RULES, PLUS])
@pytest.mark.parametrize("seed", range(3))
def test_the_release_rollout_starts_with_the_executed_release(seed, rules):
    """The fallback: the chosen release velocity's rollout starts with the command REVERSE then executes."""
    state, obs, goal = scene(seed)
    state = RobotState(state.px, state.py, 0.0)
    v, rel, best = choose_release(state, obs, goal, SIMULATION, rules=rules)
    u = behavior_command(REVERSE, state, obs, goal, SIMULATION, release_v=v, rules=rules)
    np.testing.assert_array_equal(rel.u[best, 0], u)


def test_policy_data_evaluates_every_row_at_its_own_position_and_obstacles():
    """PolicyData built once (groups from the first obstacle set) and evaluated at other positions and obstacle
    positions gives what policy_velocity gives there with those groups; REVERSE rows without a chosen velocity
    push from where they are (release_velocity), with one they keep it; every row is 0 in the goal region."""
    state, obs, goal = scene(1)
    idx = mode_indices(MODES)
    data = PolicyData.build(idx, goal, obs.p, obs.r, SIMULATION, obs_v=obs.v, rules=PLUS)
    rng = np.random.default_rng(5)
    p = rng.uniform([-0.5, -1.0], [1.0, 1.0], (len(idx), 2))
    moved = obs.p + 0.4 * obs.v
    v = data.velocity(p[:, 0] + 1j * p[:, 1], moved[:, 0] + 1j * moved[:, 1])
    want = policy_velocity(idx, p, goal, moved, obs.r, SIMULATION, groups=data.groups, obs_v=obs.v, rules=PLUS)
    assert np.stack([v.real, v.imag], -1).tobytes() == want.tobytes()
    np.testing.assert_array_equal(want[-1], release_velocity(p[-1:], goal, moved, obs.r, SIMULATION, obs.v)[0])
    chosen = PolicyData.build(idx, goal, obs.p, obs.r, SIMULATION, release=0.1 - 0.2j)
    assert chosen.velocity(p[:, 0] + 1j * p[:, 1], moved[:, 0] + 1j * moved[:, 1])[-1] == 0.1 - 0.2j
    at_goal = np.full(len(idx), complex(goal[0] - 0.1, goal[1]))             # 0.1 m < eps_g = 0.15 m
    assert not np.any(chosen.velocity(at_goal, moved[:, 0] + 1j * moved[:, 1]))


def test_policy_data_without_obstacles():
    """No obstacle: PASS has nothing to pass (0.85 m towards the goal), the push is straight back."""
    data = PolicyData.build(mode_indices(("PASS-L", "REVERSE")), np.array([5.0, 0.0]), np.zeros((0, 2)),
                            np.zeros(0), SIMULATION)
    v = data.velocity(np.zeros(2, complex), np.zeros(0, complex))
    assert v[0] == pytest.approx(0.8) and v[1] == pytest.approx(-SIMULATION.v_release_mps)
