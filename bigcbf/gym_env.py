"""A Gymnasium environment of an episode: the MuJoCo scene with the common hard CBF filter in the loop.

    import gymnasium as gym
    env = gym.make("bigcbf.gym_env:bigcbf/Navigation-v0", scenario="crowd_crossing")   # imports and registers
    obs, info = env.reset(seed=0)                          # seed s: the world bigcbf run draws for --seed s
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

(``pip install 'bigcbf[gym]'``.) Gymnasium 1.x has no plugin system (1.0 removed the ``gymnasium.envs`` entry
points that 0.26-0.29 loaded on import), so a fresh interpreter finds ``bigcbf/Navigation-v0`` either through the
``module:id`` form above, which imports this module first, or after ``import bigcbf.gym_env`` (optionally
``gym.register_envs(bigcbf.gym_env)``), which registers it. Each step is one control period T_C of
:class:`bigcbf.episode.Episode`: the agent's action is the input command u_in, which goes through the same CBF-QP
filter (eq:hard_cbf_qp (26)) as every method's, then the robot's firmware and the physics run up to the next control
tick (scans and perception on the way, as in ``bigcbf run``). There is no second simulation loop: the environment
drives ``Episode.begin`` and ``Episode.act(u_in)``.

- action: u_in = (vx [m/s], vy [m/s], wz [rad/s]), a body twist; ``action_space`` is the actuator box
  [u_min, u_max] of the stack parameters. An action inside the box is sent as it is; one outside it is clipped to
  the box, axis by axis (as the robot's actuator limits would; Gymnasium's ``ClipAction`` convention), and
  ``info["u_in"]`` is the clipped command the filter received. An action that is not 3 numbers (shape (3,)) or
  has a NaN or infinite entry raises :class:`bigcbf.errors.UserError` naming ``action``.
- observation (a Dict): ``scan`` the latest LiDAR ranges of the scenario's robot profile (``[lidar]`` of
  ``bigcbf/profiles/x3_sim.toml`` or the scenario's ``[robot_profile.lidar]``: its ``n_beams`` beams, float32, m;
  beams without a return as its ``range_max_m``), ``odom`` the stack's state [px, py, theta, vx, vy, wz] (wheel
  odometry, pose in odom, twist in base_link; the true state with ``perception="truth"``), ``goal`` the goal
  [x, y] in odom. The spaces are built from the LiDAR the scenario's robot has (its world for seed 0); a
  scenario that draws ``n_beams`` or ``range_max_m`` per seed gets a UserError at the reset of a seed whose
  LiDAR differs (an observation space is fixed).
- reward (the paper has none; a choice documented here, weights in :class:`RewardWeights`): the progress towards
  the goal over the step (true distance, m) minus ``cbf_weight`` times the step's CBF intervention
  ||u_safe - u_in||^2_R (the term of E_CBF, eq:sim_cbf_energy (27)), plus ``success`` on reaching the goal region, minus
  ``collision`` on contact.
- terminated: goal reached or collision; truncated: the scenario's time limit.
- info: the episode's metrics so far (:class:`bigcbf.episode.EpisodeResult` without its wall-clock timings, which
  differ between identical runs), plus ``u_in`` (the command the filter received), ``u_safe`` (the filtered
  command sent) and ``cbf_active``.
- render_mode ``rgb_array``: the frame of ``bigcbf run --video`` (camera ``top`` or ``track``).

Bad arguments raise :class:`bigcbf.errors.UserError` (one line naming the field), checked as the CLI and
:mod:`bigcbf.api` check them: the scenario (a name or a TOML file, loaded and checked whole by the constructor),
``config``, ``perception``, ``time_limit_s`` (the rule of a scenario file's ``time_limit_s``: in (0, 600] s),
``render_mode``, ``camera``, ``width``/``height`` (whole numbers in [16, 4096] px), and ``reset(seed=...)``: a
whole number in [0, 4294967295], the range of ``bigcbf run --seed``.
"""
from __future__ import annotations

import numbers
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .config import RunConfig
from .episode import DETERMINISTIC_KEYS, PERCEPTION_MODES, Episode, StepRecord
from .errors import UserError
from .sim.lidar import LidarConfig

ENV_ID = "bigcbf/Navigation-v0"

#: bounds of the odometry and goal observations (finite, so that Gymnasium's checks pass; far beyond any scene)
POSITION_BOUND_M = 1000.0
SPEED_BOUND = 10.0
#: the cameras of ``bigcbf run --video`` and the frame sizes the renderer takes [px]
CAMERAS = ("top", "track")
FRAME_SIZE_PX = (16, 4096)


@dataclass(frozen=True)
class RewardWeights:
    progress_per_m: float = 1.0       # reward per metre of progress towards the goal
    cbf_weight: float = 1.0           # penalty per unit of ||u_safe - u_in||^2_R (eq:sim_cbf_energy (27)) in a step
    success: float = 10.0             # on reaching the goal region
    collision: float = 10.0           # penalty on contact


def check_seed(seed) -> int:
    """A seed as ``bigcbf run --seed`` takes it (a whole number in [0, MAX_SEED]), else a UserError naming ``seed``
    (:func:`bigcbf.validate.check_seed`, the API's check)."""
    from .validate import check_seed as _check
    return _check(seed, "seed")


def check_time_limit(scenario, time_limit_s) -> float:
    """An episode's time limit checked as a scenario file's ``time_limit_s`` is (in (0, 600] s), else a UserError
    naming ``time_limit_s`` (:func:`bigcbf.validate.check_time_limit`, the API's check)."""
    from .validate import check_time_limit as _check
    return _check(time_limit_s, scenario)


class NavigationEnv(gym.Env):
    """One scenario (a name or a TOML path) with the stack's CBF filter between the agent and the robot."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, scenario: str = "single_person_crossing", config: RunConfig | str | None = None,
                 perception: str = "lidar", time_limit_s: float | None = None, render_mode: str | None = None,
                 camera: str = "top", width: int = 480, height: int = 360, reward: RewardWeights = RewardWeights()):
        from .api import load_config
        from .scenario import load_scenario

        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise UserError(f"must be one of {', '.join(self.metadata['render_modes'])} or None, got "
                            f"{render_mode!r}"[:160], field="render_mode")
        if perception not in PERCEPTION_MODES:
            raise UserError(f"perception must be one of {', '.join(PERCEPTION_MODES)}, got {perception!r}"[:160])
        if camera not in CAMERAS:
            raise UserError(f"must be one of {', '.join(CAMERAS)}, got {camera!r}"[:160], field="camera")
        for name, px in (("width", width), ("height", height)):
            if not (isinstance(px, (numbers.Integral, np.integer)) and not isinstance(px, bool)
                    and FRAME_SIZE_PX[0] <= px <= FRAME_SIZE_PX[1]):
                raise UserError(f"expected a whole number of pixels in [{FRAME_SIZE_PX[0]}, {FRAME_SIZE_PX[1]}], "
                                f"got {px!r}"[:160], field=name)
        # the whole file checked now (a UserError here rather than at the first reset); its robot (seed 0's world)
        # gives the observation space
        sc = load_scenario(scenario, 0)
        self.scenario, self.perception = str(scenario), perception
        self.time_limit_s = None if time_limit_s is None else check_time_limit(sc, time_limit_s)
        self.config = load_config(config)
        self.render_mode, self.camera, self.width, self.height = render_mode, camera, int(width), int(height)
        self.reward_weights = reward
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / self.config.stack.T_C_s))}
        # the LiDAR the episode's world builds (SimWorld without a lidar argument: the robot profile's model)
        stack, lidar = self.config.stack, LidarConfig.from_model(sc.robot_profile.lidar)
        self.lidar = lidar
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
        from .cli.argtypes import MAX_SEED
        from .scenario import load_scenario

        seed = None if seed is None else check_seed(seed)
        super().reset(seed=seed)
        ep_seed = seed if seed is not None else int(self.np_random.integers(0, MAX_SEED, endpoint=True))
        self._close_renderer()
        self.episode = None
        sc = load_scenario(self.scenario, ep_seed)
        self._check_lidar(sc, ep_seed)
        ep = Episode.from_config(sc, None, ep_seed, self.config, perception=self.perception,
                                 time_limit_s=self.time_limit_s)
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
        rec = ep.act(self._u_in(action))
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
    def _u_in(self, action) -> np.ndarray:
        """The agent's action as u_in: 3 finite numbers (else a UserError naming ``action``), clipped to the
        actuator box [u_min, u_max] (module docstring)."""
        try:
            u = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            raise UserError(f"expected 3 numbers (vx [m/s], vy [m/s], wz [rad/s]), got {action!r}"[:160],
                            field="action") from None
        if u.shape != (3,):
            raise UserError(f"expected 3 numbers (vx [m/s], vy [m/s], wz [rad/s]), shape (3,), got shape {u.shape}",
                            field="action")
        if not np.isfinite(u).all():
            raise UserError(f"expected finite numbers, got {u.tolist()}", field="action")
        stack = self.config.stack
        return np.clip(u, np.asarray(stack.u_min, np.float64), np.asarray(stack.u_max, np.float64))

    def _check_lidar(self, sc, seed: int) -> None:
        """The LiDAR of this seed's robot is the one the observation space was built from."""
        got = (sc.robot_profile.lidar.n_beams, float(sc.robot_profile.lidar.range_max_m))
        want = (self.lidar.n_beams, float(self.lidar.range_max_m))
        if got != want:
            raise UserError(f"seed {seed} draws a LiDAR of {got[0]} beams, {got[1]:g} m, where seed 0's (the "
                            f"observation space's) has {want[0]} beams, {want[1]:g} m: the environment needs one "
                            "n_beams and range_max_m for every seed", file=sc.file, field="robot_profile.lidar")

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
        info["u_in"] = np.zeros(3) if rec is None else np.asarray(rec.u_in, float).copy()
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
