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
        compiled kernels are compiled now and not at the first real scan. Returns the seconds it took."""
        t0 = time.perf_counter()
        n = 360
        ranges = np.full(n, np.inf, np.float32)
        ranges[170:190] = 1.5
        scan = LaserScan(stamp=0.0, angle_min=-math.pi, angle_increment=2 * math.pi / n, range_min=0.05,
                         range_max=12.0, ranges=ranges, frame_id="laser", time_increment=0.0, scan_time=0.1)
        twin = SafetyStack(self.method, self.params, self.perception_params, method_params=self.method_params)
        twin.set_goal(3.0, 0.0)
        pose = RobotState(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        for k in range(12):      # 3 scans of a still blob, then one moving across the scan (a walker's paths)
            if k >= 3:
                ranges = np.full(n, np.inf, np.float32)
                ranges[150 + 2 * k:160 + 2 * k] = 2.0
            twin.scan(replace(scan, stamp=0.1 * k, ranges=ranges), pose)
            twin.control(0.1 * k, pose, None if twin.planner is not None else np.array([0.2, 0.0, 0.0]))
        return time.perf_counter() - t0
