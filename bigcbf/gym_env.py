"""A Gymnasium environment of an episode: the MuJoCo scene with the common hard CBF filter in the loop.

    import gymnasium as gym
    import bigcbf.gym_env                                  # registers bigcbf/Navigation-v0
    env = gym.make("bigcbf/Navigation-v0", scenario="crowd_crossing")
    obs, info = env.reset(seed=0)                          # seed s: the world bigcbf run draws for --seed s
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

(``pip install 'bigcbf[gym]'``.) Each step is one control period T_C of :class:`bigcbf.episode.Episode`: the agent's
action is the input command u_in, which goes through the same CBF-QP filter (Eq. (19)) as every method's, then the
robot's firmware and the physics run up to the next control tick (scans and perception on the way, as in
``bigcbf run``). There is no second simulation loop: the environment drives ``Episode.begin`` and
``Episode.act(u_in)``.

- action: u_in = (vx [m/s], vy [m/s], wz [rad/s]), a body twist in the actuator box [u_min, u_max] of the stack
  parameters (clipped to it).
- observation (a Dict): ``scan`` the latest LiDAR ranges (n_beams, float32, m; beams without a return as
  ``range_max``), ``odom`` the stack's state [px, py, theta, vx, vy, wz] (wheel odometry, pose in odom, twist in
  base_link; the true state with ``perception="truth"``), ``goal`` the goal [x, y] in odom.
- reward (the paper has none; a choice documented here, weights in :class:`RewardWeights`): the progress towards
  the goal over the step (true distance, m) minus ``cbf_weight`` times the step's CBF intervention
  ||u_safe - u_in||^2_R (the term of E_CBF, Eq. (20)), plus ``success`` on reaching the goal region, minus
  ``collision`` on contact.
- terminated: goal reached or collision; truncated: the scenario's time limit.
- info: the episode's metrics so far (:class:`bigcbf.episode.EpisodeResult` without its wall-clock timings, which
  differ between identical runs), plus ``u_safe`` (the filtered command sent) and ``cbf_active``.
- render_mode ``rgb_array``: the frame of ``bigcbf run --video`` (camera ``top`` or ``track``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .config import RunConfig
from .episode import DETERMINISTIC_KEYS, Episode, StepRecord
from .sim.lidar import LidarConfig

ENV_ID = "bigcbf/Navigation-v0"

#: bounds of the odometry and goal observations (finite, so that Gymnasium's checks pass; far beyond any scene)
POSITION_BOUND_M = 1000.0
SPEED_BOUND = 10.0


@dataclass(frozen=True)
class RewardWeights:
    progress_per_m: float = 1.0       # reward per metre of progress towards the goal
    cbf_weight: float = 1.0           # penalty per unit of ||u_safe - u_in||^2_R (Eq. (20)) in a step
    success: float = 10.0             # on reaching the goal region
    collision: float = 10.0           # penalty on contact


class NavigationEnv(gym.Env):
    """One scenario (a name or a TOML path) with the stack's CBF filter between the agent and the robot."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, scenario: str = "single_person_crossing", config: RunConfig | str | None = None,
                 perception: str = "lidar", time_limit_s: float | None = None, render_mode: str | None = None,
                 camera: str = "top", width: int = 480, height: int = 360, reward: RewardWeights = RewardWeights()):
        from .api import load_config
        from .scenario import resolve_path

        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None")
        resolve_path(scenario)                      # a UserError now rather than at the first reset
        self.scenario, self.perception, self.time_limit_s = str(scenario), perception, time_limit_s
        self.config = load_config(config)
        self.render_mode, self.camera, self.width, self.height = render_mode, camera, width, height
        self.reward_weights = reward
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / self.config.stack.T_C_s))}
        stack, lidar = self.config.stack, LidarConfig()
        self.action_space = spaces.Box(np.asarray(stack.u_min, np.float32), np.asarray(stack.u_max, np.float32),
                                       dtype=np.float32)
        b = POSITION_BOUND_M
        odom_hi = np.array([b, b, np.pi, SPEED_BOUND, SPEED_BOUND, SPEED_BOUND])
        self.observation_space = spaces.Dict({
            "scan": spaces.Box(0.0, lidar.range_max_m, (lidar.n_beams,), np.float32),
            "odom": spaces.Box(-odom_hi, odom_hi, dtype=np.float64),
            "goal": spaces.Box(-b, b, (2,), np.float64),
        })
        self._range_max = float(lidar.range_max_m)
        self._odom_hi = odom_hi
        self.episode: Episode | None = None
        self._renderer = self._overlay = None
        self._rec: StepRecord | None = None

    # --- Gymnasium API ------------------------------------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        from .scenario import load_scenario

        super().reset(seed=seed)
        ep_seed = int(seed) if seed is not None else int(self.np_random.integers(0, 2**31 - 1))
        self._close_renderer()
        ep = Episode.from_config(load_scenario(self.scenario, ep_seed), None, ep_seed, self.config,
                                 perception=self.perception, time_limit_s=self.time_limit_s)
        ep.begin()
        self.episode, self._rec = ep, None
        if self.render_mode == "rgb_array":            # the overlay follows every step (the robot's trail)
            from .sim.render import Renderer
            from .video import Overlay
            self._renderer = Renderer(ep.world.model, self.width, self.height)
            self._overlay = Overlay(ep, self._renderer, self.camera, title="agent", legend="box")   # (H, W) frames
        self._dist = self._goal_dist()
        return self._obs(), self._info()

    def step(self, action):
        ep = self.episode
        if ep is None:
            raise RuntimeError("call reset() before step()")
        if ep.done:
            raise RuntimeError("the episode is over: call reset()")
        u_in = np.clip(np.asarray(action, np.float64).reshape(3), self.action_space.low, self.action_space.high)
        rec = ep.act(u_in)
        self._rec = rec
        if self._overlay is not None:
            self._overlay.observe(rec)
        res = ep.result()
        dist = self._goal_dist()
        w, R = self.reward_weights, np.asarray(self.config.stack.R_u_diag, float)
        du = rec.u_safe - rec.u_in
        reward = w.progress_per_m * (self._dist - dist) - w.cbf_weight * float(du @ (R * du))
        self._dist = dist
        terminated = bool(res.success or res.collision)
        reward += w.success * res.success - w.collision * res.collision
        truncated = bool(ep.done and not terminated)
        return self._obs(), float(reward), terminated, truncated, self._info(rec)

    def render(self):
        if self.render_mode != "rgb_array" or self._overlay is None:
            return None
        rec = self._rec or self._record_now()
        return self._overlay.frame(rec)

    def close(self):
        self._close_renderer()
        self.episode = None

    # --- helpers ----------------------------------------------------------------------------------------------
    def _state(self):
        w = self.episode.world
        return w.odom() if self.perception == "lidar" else w.true_state()

    def _goal_dist(self) -> float:
        ts = self.episode.world.true_state()
        return float(np.hypot(ts.px - self.episode.goal[0], ts.py - self.episode.goal[1]))

    def _obs(self) -> dict:
        ep = self.episode
        scan = ep.last_scan
        r = np.full(self.observation_space["scan"].shape, self._range_max, np.float32)
        if scan is not None:
            r = np.where(np.isfinite(scan.ranges), np.minimum(scan.ranges, self._range_max), self._range_max)
        odom = np.clip(self._state().as_array(), -self._odom_hi, self._odom_hi)
        return {"scan": r.astype(np.float32), "odom": odom, "goal": np.asarray(ep.goal, np.float64).copy()}

    def _info(self, rec: StepRecord | None = None) -> dict:
        m = self.episode.result().metrics()
        info = {k: m[k] for k in ("scenario", "method", "seed", "perception", *DETERMINISTIC_KEYS)}
        info["u_safe"] = np.zeros(3) if rec is None else np.asarray(rec.u_safe, float).copy()
        info["cbf_active"] = False if rec is None else bool(rec.cbf_active)
        return info

    def _record_now(self) -> StepRecord:
        """A record of the current state without a command (a frame before the first step)."""
        ep, z = self.episode, np.zeros(3)
        st = self._state()
        return StepRecord(ep.world.t, st, ep.world.true_state(), ep.obstacles_now(), z, z, "-", False, False,
                          np.zeros(0), None, ep.last_scan)

    def _close_renderer(self):
        if self._renderer is not None:
            self._renderer.close()
        self._renderer = self._overlay = None


if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point=f"{__name__}:NavigationEnv")
