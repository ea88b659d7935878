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
    ||u_safe - u_in||^2 (E_CBF of eq:sim_cbf_energy (27) with R = I) over the steps."""
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


# --- the observation space is the scenario's LiDAR; validation; registration in a fresh interpreter ----------------
import subprocess  # noqa: E402
import sys  # noqa: E402
import textwrap  # noqa: E402

import bigcbf  # noqa: E402
from bigcbf.errors import UserError  # noqa: E402

WALL_SCENE = """
name = "wall_ahead"
description = "A wall 10.25 m ahead of the robot (its near face), nothing else within 12 m: one return at 10 m."
time_limit_s = 10.0
[robot]
start = [0.0, 0.0, 0.0]
goal = [2.0, 0.0]
[[walls]]
start = [10.3, -2.0]
end = [10.3, 2.0]
[robot_profile.lidar]
n_beams = NBEAMS
range_max_m = 12.0
"""


def test_observation_space_is_the_scenarios_lidar_180_beams_12_m(tmp_path):
    """A profile with 180 beams and 12 m: the space says (180,) and 12 m, every observation is in it, and the wall's
    return at ~10.2 m reads as such (not as 12 m, the 'no return' value; nor clipped at the old 8 m)."""
    f = tmp_path / "wall_ahead.toml"
    f.write_text(WALL_SCENE.replace("NBEAMS", "180"))
    env = NavigationEnv(str(f), time_limit_s=2.0)
    scan_space = env.observation_space["scan"]
    assert scan_space.shape == (180,) and float(scan_space.high.max()) == 12.0
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert env.episode.world.lidar.config.n_beams == 180
    ahead = obs["scan"][90]                           # beam angle -pi + 90 * 2 pi / 180 = 0: straight ahead
    assert 9.8 < ahead < 10.5, ahead
    assert (obs["scan"] == 12.0).sum() > 90           # behind and beside: no return within 12 m
    for _ in range(5):
        obs, r, term, trunc, info = env.step(np.array([0.2, 0.0, 0.0], np.float32))
        assert env.observation_space.contains(obs)
        assert obs["scan"].shape == (180,) and 9.5 < obs["scan"][90] < 10.5
    env.close()


def test_a_lidar_drawn_per_seed_is_refused_at_the_reset_of_a_differing_seed(tmp_path):
    from bigcbf.scenario import load_scenario as load
    f = tmp_path / "wall_ahead.toml"
    f.write_text(WALL_SCENE.replace("NBEAMS", "{ choice = [180, 360] }"))
    env = NavigationEnv(str(f), time_limit_s=2.0)
    n0 = env.observation_space["scan"].shape[0]
    other = next(s for s in range(1, 64) if load(str(f), s).robot_profile.lidar.n_beams != n0)
    with pytest.raises(UserError, match=r"field 'robot_profile.lidar': seed \d+ draws a LiDAR of"):
        env.reset(seed=other)


@pytest.fixture(scope="module")
def env2():
    env = NavigationEnv("single_person_crossing", time_limit_s=2.0)
    yield env
    env.close()


@pytest.mark.parametrize("seed", [-1, 1.5, 2**40, True, "3"])
def test_reset_refuses_a_seed_outside_the_clis_range(env2, seed):
    with pytest.raises(UserError, match=r"^field 'seed': expected a (seed in \[0, 4294967295\]|whole number)"):
        env2.reset(seed=seed)


def test_reset_takes_the_clis_whole_seed_range(env2):
    obs, info = env2.reset(seed=np.int64(2**32 - 1))
    assert info["seed"] == 2**32 - 1 and env2.observation_space.contains(obs)


@pytest.mark.parametrize("action, what", [([np.nan, 0, 0], "finite"), ([0, 0, np.inf], "finite"),
                                          ([0.1, 0.0], r"shape \(2,\)"), (np.zeros((1, 3)), r"shape \(1, 3\)"),
                                          ("abc", "3 numbers")])
def test_step_refuses_a_non_finite_or_misshapen_action(env2, action, what):
    env2.reset(seed=0)
    with pytest.raises(UserError, match=rf"^field 'action': .*{what}"):
        env2.step(action)
    obs, r, term, trunc, info = env2.step(np.zeros(3))   # the refused action left the episode as it was
    assert np.isfinite(r) and info["control_steps"] == 1


def test_an_action_outside_the_box_is_clipped_to_it(env2):
    env2.reset(seed=0)
    obs, r, term, trunc, info = env2.step(np.array([5.0, -5.0, 0.5]))
    lo, hi = env2.config.stack.u_min, env2.config.stack.u_max
    assert info["u_in"].tolist() == [hi[0], lo[1], 0.5] and np.isfinite(r)


@pytest.mark.parametrize("limit, toml", [(float("nan"), "nan"), (float("inf"), "inf"), (-1.0, "-1.0"),
                                         (0.0, "0.0"), (600.5, "600.5"), ("3", "'3'"), (True, "true")])
def test_constructor_refuses_a_bad_time_limit_as_a_scenario_file_does(tmp_path, limit, toml):
    """The same check and the same words as a scenario file's time_limit_s (the file's error names the file too)."""
    with pytest.raises(UserError, match=r"^field 'time_limit_s': ") as got:
        NavigationEnv("single_person_crossing", time_limit_s=limit)
    f = tmp_path / "s.toml"
    f.write_text(WALL_SCENE.replace("NBEAMS", "180").replace("time_limit_s = 10.0", f"time_limit_s = {toml}"))
    with pytest.raises(UserError) as file_err:
        bigcbf.load_scenario(str(f))
    assert str(file_err.value) == f"{f}: {got.value}"


@pytest.mark.parametrize("scenario", ["no_such_scene", "missing/scene.toml"])
def test_constructor_refuses_a_bad_scenario_as_the_api_does(scenario):
    with pytest.raises(UserError) as api:
        bigcbf.run_episode(scenario, "cbf-only")
    with pytest.raises(UserError) as env:
        NavigationEnv(scenario)
    assert str(env.value) == str(api.value)


def test_constructor_refuses_bad_perception_render_mode_camera_size():
    for kw, field in [({"perception": "radar"}, "perception"), ({"render_mode": "human"}, "render_mode"),
                      ({"camera": "side"}, "camera"), ({"width": 0}, "width"), ({"height": 1.5}, "height")]:
        with pytest.raises(UserError, match=field):
            NavigationEnv("single_person_crossing", **kw)


def test_gym_make_finds_the_env_in_a_fresh_interpreter_without_importing_it_first():
    """Gymnasium 1.x has no plugin entry points: 'module:id' imports bigcbf.gym_env and registers the id."""
    code = textwrap.dedent("""
        import sys
        import gymnasium as gym
        assert "bigcbf.gym_env" not in sys.modules
        env = gym.make("bigcbf.gym_env:bigcbf/Navigation-v0", time_limit_s=2.0)
        obs, info = env.reset(seed=0)
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        assert env.observation_space.contains(obs)
        print(env.spec.id, obs["scan"].shape, info["control_steps"])
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[0] == ENV_ID and out.stdout.strip().endswith("(360,) 1")
