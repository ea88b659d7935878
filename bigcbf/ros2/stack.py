"""The navigation stack of one robot, fed from messages: what :class:`bigcbf.episode.Episode` does between the
LiDAR and the wheels, without the simulator (robot side: no mujoco, dm_control or cv2).

    scan (with the odometry pose at its time) -> perception -> estimates
    odometry at a control tick -> estimates aged to now -> planner (or an outside u_in) -> common CBF filter -> u_safe

It follows the episode's order step for step (``Episode._observe`` and ``Episode.act``): a scan updates the
estimates with the odometry pose of the scan's instant; at a control tick the estimates are aged by the time since
that scan (``age_obstacles``, eq:obs_prop (2)), the planner plans toward the goal, and the common filter filters
its command. So a lock-step run of the twin and the filter node does what the in-process episode does, up to the
rounding of the messages (tests/ros2/test_loopback.py states by how much).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from ..control.cbf import CbfFilter
from ..control.methods import filter_params, make_planner
from ..control.planner import PlanInfo
from ..control.prediction import age_obstacles
from ..errors import UserError
from ..params.perception import X3_LASER_MOUNT, PerceptionParams
from ..params.stack import StackParams
from ..perception.pipeline import Perception
from ..types import LaserScan, Obstacles, RobotState

#: the method name of the filter alone: u_in comes from /cmd_vel_in (a Nav2 controller upstream)
FILTER_ONLY = "filter"
#: the methods the filter node runs (docs/ros2.md); any registered method works, these are the documented ones
NODE_METHODS = ("big-cbf", "big-cbf-plus", FILTER_ONLY)


@dataclass
class StepOut:
    """What one control step did (the node publishes it)."""
    t: float
    u_in: np.ndarray
    u_safe: np.ndarray
    mode: str
    active: bool
    infeasible: bool
    h_min: float
    margins: np.ndarray
    D: np.ndarray
    obstacles: Obstacles
    compute_ms: float


class SafetyStack:
    """Perception, a planner (``method``; :data:`FILTER_ONLY` for none) and the common CBF filter of ``params``."""

    def __init__(self, method: str, params: StackParams, perception_params: PerceptionParams = PerceptionParams(),
                 seed: int = 0, method_params=None):
        self.method, self.params, self.method_params = method, params, method_params
        self.planner = None if method == FILTER_ONLY else make_planner(method, params, method_params)
        if self.planner is not None:
            self.planner.reset(int(seed))
        self.cbf = CbfFilter(filter_params(self.planner, params))
        self.perception_params = perception_params
        self.perception: Perception | None = None      # built at the first scan, with the laser mount then known
        self.obstacles = Obstacles.empty()
        self.scan_t: float | None = None
        self.scan_period_s = 0.1
        self.goal: np.ndarray | None = None

    @classmethod
    def from_config(cls, method: str, config, seed: int = 0) -> "SafetyStack":
        """The stack of ``method`` (or :data:`FILTER_ONLY`) as a run configuration (``bigcbf.config.RunConfig``)
        gives it to every front door: the method's stack keys and own parameters, the perception's (what
        ``Episode.from_config`` takes)."""
        m = None if method == FILTER_ONLY else method
        return cls(method, config.stack_for(m), config.perception, seed=seed,
                   method_params=None if m is None else config.method_params(m))

    def set_mount(self, x: float, y: float, yaw: float) -> None:
        """The laser's mount on the base (base_link -> the scan's frame, from /tf_static), used where the
        perception parameters keep the default mount (as ``bigcbf.robots`` does for the simulated robot)."""
        p = self.perception_params
        if (p.laser_x_m, p.laser_y_m, p.laser_yaw_rad) == X3_LASER_MOUNT:
            self.perception_params = replace(p, laser_x_m=float(x), laser_y_m=float(y), laser_yaw_rad=float(yaw))

    def set_goal(self, x: float, y: float) -> None:
        if not (math.isfinite(x) and math.isfinite(y)):
            raise UserError(f"goal: expected finite coordinates, got ({x}, {y})")
        self.goal = np.array([x, y], float)

    def scan(self, scan: LaserScan, pose: RobotState) -> float:
        """A new scan with the odometry pose of its instant; returns the perception's time [ms]."""
        if self.perception is None:
            self.perception = Perception(self.perception_params)
        t0 = time.perf_counter()
        self.obstacles = self.perception.update(scan, (pose.px, pose.py, pose.theta))
        self.scan_t = scan.stamp
        if scan.scan_time > 0:
            self.scan_period_s = float(scan.scan_time)
        return 1e3 * (time.perf_counter() - t0)

    def obstacles_now(self, t: float) -> Obstacles:
        if self.scan_t is None:
            return Obstacles.empty()
        return age_obstacles(self.obstacles, t - self.scan_t, self.scan_period_s, self.params.uncertainty)

    def control(self, t: float, state: RobotState, u_in=None) -> StepOut:
        """One control step at time ``t`` (the odometry's stamp): the planner's u_in (or the given one, filter
        alone), the common filter."""
        t0 = time.perf_counter()
        obs = self.obstacles_now(t)
        if u_in is None:
            if self.planner is None or self.goal is None:
                raise RuntimeError("control() without u_in needs a planner and a goal")
            u_in, info = self.planner.plan(t, state, obs, self.goal)
            u_in = np.asarray(u_in, float)
        else:
            u_in, info = np.asarray(u_in, float), PlanInfo(mode=FILTER_ONLY, planned=False, planner_ms=0.0)
        u_safe, finfo = self.cbf.filter(state, obs, u_in)
        return StepOut(t, u_in, np.asarray(u_safe, float), info.mode, bool(finfo.active), bool(finfo.infeasible),
                       float(finfo.h_min), np.asarray(finfo.margins, float), np.asarray(finfo.D, float), obs,
                       1e3 * (time.perf_counter() - t0))

    def warm_up(self) -> float:
        """Run perception, planner and filter of a throwaway copy of this stack on a made-up scene, so that the
        compiled kernels are compiled (or loaded from numba's cache) now and not at the first real scan or the first
        time the filter engages. Returns the seconds it took.

        The scene (synthetic scans, ``perception.synthetic.ray_scan``): the robot drives 3 s at 0.3 m/s toward a
        goal 3 m ahead (10 Hz scans, 20 Hz control; the path scripted, not the method's) past a wall 0.6 m to its
        left and a box, while a walker crosses its path at 1 m/s: tracks confirmed, static and dynamic, imagined
        candidates near obstacles. Then the filter alone on made-up estimates: a command into an obstacle 0.5 m
        ahead (the filter's QP with active rows) and a robot boxed in by wall points within its safety distance
        (the infeasible case). The warm-up before this one (a still and a moving blob, nothing near) left the
        filter's QP (solve_hard, gi_solve, _kkt, _solve_dense, _box_rows, _clip_violation) and two more array
        layouts of the imagination's barrier kernel to the first real encounters: seconds of compiling inside a
        control step on a fresh install, a late command or the overrun valve's zero command there
        (tests/ros2/test_ros2_warmup.py)."""
        from ..perception.synthetic import box_segments, ray_scan

        t0 = time.perf_counter()
        twin = SafetyStack(self.method, self.params, self.perception_params, method_params=self.method_params)
        twin.set_goal(3.0, 0.0)
        walls = [(-0.5, 0.6, 3.5, 0.6)] + box_segments(1.6, -0.9, 0.15, 0.15)
        for k in range(60):              # 3 s at the control rate, a scan every other tick; the robot's path is
            t = 0.05 * k                 # scripted (0.3 m/s ahead), so every method's stack sees the same scans
            pose = RobotState(0.3 * t, 0.0, 0.0, 0.3, 0.0, 0.0)
            if k % 2 == 0:
                walker = (1.2, -1.6 + 1.0 * t, 0.25)
                twin.scan(ray_scan((pose.px, pose.py, pose.theta), [walker], walls, stamp=t, noise=0.01,
                                   rng=np.random.default_rng(k)), pose)
            twin.control(t, pose, None if twin.planner is not None else np.array([0.4, 0.0, 0.0]))
        here = RobotState(0.0, 0.0, 0.0, 0.3, 0.0, 0.0)
        ahead = Obstacles(np.array([[0.5, 0.05]]), np.zeros((1, 2)), np.tile(1e-4 * np.eye(2), (1, 1, 1)),
                          np.array([0.1]), np.ones(1, bool), np.array([0]))
        twin.cbf.filter(here, ahead, np.array([0.6, 0.0, 0.0]))
        ring = 0.2 * np.stack([np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4)], axis=1)
        boxed = Obstacles(ring, np.zeros((8, 2)), np.tile(1e-4 * np.eye(2), (8, 1, 1)), np.zeros(8),
                          np.ones(8, bool), np.full(8, -1))
        twin.cbf.filter(here, boxed, np.array([0.6, 0.2, 0.0]))
        return time.perf_counter() - t0
