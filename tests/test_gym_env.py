"""The Gymnasium environment: gymnasium's own checker, the same episode as the Episode loop, the reward's terms."""
import numpy as np
import pytest

gym = pytest.importorskip("gymnasium")

import bigcbf.gym_env  # noqa: E402  (registers bigcbf/Navigation-v0)
from bigcbf.control.methods import make_planner  # noqa: E402
from bigcbf.episode import DETERMINISTIC_KEYS, Episode  # noqa: E402
from bigcbf.gym_env import ENV_ID, NavigationEnv, RewardWeights  # noqa: E402
from bigcbf.scenario import load_scenario  # noqa: E402


def test_gymnasium_env_checker_passes_without_warnings(recwarn):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(ENV_ID, scenario="single_person_crossing", time_limit_s=3.0, render_mode="rgb_array")
    check_env(env.unwrapped)
    assert [str(w.message) for w in recwarn if "gymnasium" in str(w.filename)] == []
    obs, info = env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (360, 480, 3) and frame.std() > 10
    env.close()


def test_env_steps_are_the_episode_loop_with_the_agents_u_in():
    """An agent that sends exactly what CBF-only's planner would gives the episode `bigcbf run --method cbf-only`
    gives: the same deterministic metrics (the environment has no loop of its own)."""
    seed, limit = 1, 4.0
    env = NavigationEnv("single_person_crossing", time_limit_s=limit)
    obs, info = env.reset(seed=seed)
    params = env.episode.params                 # the environment's configuration (default: RunConfig())
    agent = make_planner("cbf-only", params)
    done = False
    while not done:
        ep = env.episode
        u, _ = agent.plan(ep.world.t, ep.state, ep.obstacles_now(), ep.goal)
        obs, reward, terminated, truncated, info = env.step(u)
        assert obs in env.observation_space
        done = terminated or truncated
    ref = Episode(load_scenario("single_person_crossing", seed), "cbf-only", seed, params,
                  time_limit_s=limit).run().metrics()
    for k in DETERMINISTIC_KEYS:
        if k == "mode_history":
            assert [m for _, m in info[k]] == ["external"] and [m for _, m in ref[k]] == ["GOAL"]
        else:
            assert info[k] == ref[k], k          # bit for bit
    assert truncated and not terminated and info["control_steps"] == 80


def test_reward_is_progress_minus_cbf_intervention():
    """With only the progress term, the rewards add up to the distance gained; the CBF term is the sum of
    ||u_safe - u_in||^2 (E_CBF of Eq. (20) with R = I) over the steps."""
    env = NavigationEnv("required_sidestepping", time_limit_s=6.0,
                        reward=RewardWeights(progress_per_m=1.0, cbf_weight=0.0, success=0.0, collision=0.0))
    env.reset(seed=0)
    d0 = env._goal_dist()
    total, du2 = 0.0, 0.0
    for _ in range(120):                      # straight at the wall in front of the goal: the filter brakes
        obs, r, term, trunc, info = env.step(np.array([0.8, 0.0, 0.0], np.float32))
        total += r
        du2 += float(np.sum((info["u_safe"] - np.array([0.8, 0.0, 0.0])) ** 2))
        if term or trunc:
            break
    assert total == pytest.approx(d0 - env._goal_dist(), abs=1e-9)
    assert info["e_cbf"] == pytest.approx(du2, rel=1e-6) and info["e_cbf"] > 1.0
    assert info["cbf_active_ratio"] > 0.3 and not info["collision"]
