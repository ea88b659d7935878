"""One episode: the two-rate loop in MuJoCo physics, and the paper's per-episode metrics (Sec. IV).

    world (physics, 2 ms) -> LiDAR (10 Hz) -> perception -> planner (every T_C; BIG-CBF selects every T_B)
      -> common hard CBF filter (T_C = 50 ms) -> firmware and imperfection layer -> wheels

The stack sees only the LiDAR scans and the wheel odometry (pose in odom, body twist). Ground truth is used for
the metrics (collision, clearance) and for the pedestrians' motion, and, only in the flagged ``truth`` perception
mode, for the obstacle estimates. Success follows the paper: the robot's own state reaches the goal region
(Eq. (5) on the controller's state x); the true distance to the goal at the end is reported too.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from .control.cbf import PERCEPTION_FAULT, CbfFilter
from .control.methods import METHODS
from .control.metrics import cbf_energy
from .params.perception import PerceptionParams
from .params.stack import SIMULATION, StackParams
from .perception.pipeline import Perception
from .scenario import Scenario
from .sim.lidar import LidarConfig
from .sim.pedestrians import Pedestrians
from .sim.truth import GroundTruth
from .sim.world import SimWorld
from .types import Obstacles, RobotState

PERCEPTION_MODES = ("lidar", "truth")
#: true clearance and physical contact are checked after every block of SimWorld.BLOCK_STEPS physics steps
#: (10 ms: at 2 m/s relative speed, 2 cm between samples; a contact lasts longer than that)


@dataclass
class EpisodeResult:
    scenario: str
    method: str
    seed: int
    success: bool
    collision: bool
    timeout: bool
    time_s: float                 # completion time (the episode's end time)
    #: min over the episode of the signed distance between the robot's collision outline and the nearest obstacle
    #: (sim/truth.py; < 0 is a penetration, which is a contact); +inf (JSON null) in a scene without obstacles
    min_clearance_m: float
    e_cbf: float                  # Eq. (20)
    cbf_active_ratio: float
    qp_infeasible_ratio: float
    planner_p95_ms: float
    cbf_p95_ms: float
    perception_p95_ms: float
    stopped_time_s: float         # simulated time whose last control tick saw a true planar speed below v_freeze
    final_goal_dist_m: float      # true distance to the goal at the end
    sim_time_s: float
    wall_time_s: float
    control_steps: int
    #: control steps at which the CBF filter found the obstacle estimates non-finite or implausible and braked
    #: (FilterInfo.fallback "perception-fault", see control/cbf.py)
    perception_faults: int = 0
    mode_history: list = field(default_factory=list)   # [(t, mode)] at each change
    perception: str = "lidar"
    warnings: dict = field(default_factory=dict)

    def metrics(self) -> dict:
        d = asdict(self)
        return d


@dataclass
class StepRecord:
    """What one control step did (handed to observers: video, logs)."""
    t: float
    state: RobotState
    true_state: RobotState
    obstacles: Obstacles
    u_in: np.ndarray
    u_safe: np.ndarray
    mode: str
    cbf_active: bool
    infeasible: bool
    D: np.ndarray
    path: np.ndarray | None
    scan: object | None


class Episode:
    """One scenario x method x seed. ``run()`` returns an EpisodeResult; observers see every control step."""

    def __init__(self, scenario: Scenario, method: str, seed: int, params: StackParams = SIMULATION,
                 perception: str = "lidar", perception_params: PerceptionParams = PerceptionParams(),
                 lidar: LidarConfig = LidarConfig(), time_limit_s: float | None = None):
        if perception not in PERCEPTION_MODES:
            raise ValueError(f"perception must be one of {PERCEPTION_MODES}")
        self.scenario, self.method, self.seed, self.params = scenario, method, int(seed), params
        self.perception_mode = perception
        self.time_limit_s = scenario.time_limit_s if time_limit_s is None else float(time_limit_s)
        self.world = SimWorld(scenario.scene(), profile=scenario.robot_profile, seed=seed, lidar=lidar)
        self.truth = GroundTruth(self.world.model, self.world.scene)
        peds = scenario.pedestrians
        self.peds = Pedestrians([p.waypoints for p in peds], [p.speed_mps for p in peds],
                                [p.start_time_s for p in peds], [p.radius_m for p in peds],
                                [p.loop for p in peds], [p.reactive for p in peds],
                                robot_radius=params.uncertainty.r_robot_m)
        m = self.world.model
        import mujoco
        self._mocap = [m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"ped_{p.name}")] for p in peds]
        self._ped_t, self._ped_next = 0.0, 0.0
        self._move_pedestrians(self.world)
        self.world.add_pre_step(self._move_pedestrians)
        self.planner = METHODS.get(method)(params)
        self.planner.reset(self.seed)
        self.cbf = CbfFilter(params)
        self.perception = Perception(perception_params)
        self.goal = scenario.goal
        self.observers: list[Callable[[StepRecord], None]] = []

    #: the social-force model runs at 50 Hz (its relaxation time is 0.5 s); between its updates the mocap bodies
    #: move on at the pedestrians' velocities, so their motion in the physics stays smooth
    PEDESTRIAN_PERIOD_S = 0.02

    def _move_pedestrians(self, world: SimWorld) -> None:
        """Before each physics block: the social-force step when due, and the mocap bodies moved to where the
        pedestrians are now (extrapolated at their velocities between social-force steps)."""
        if not self._mocap:
            return
        t = world.t
        if t >= self._ped_next - 1e-9:
            self.peds.step(t, self.PEDESTRIAN_PERIOD_S, robot_xy=tuple(world.data.qpos[0:2]))
            self._ped_t, self._ped_next = t, t + self.PEDESTRIAN_PERIOD_S
        world.data.mocap_pos[self._mocap, :2] = self.peds.p + (t - self._ped_t) * self.peds.v

    def _ped_positions(self) -> np.ndarray:
        return self.world.data.mocap_pos[self._mocap, :2] if self._mocap else np.zeros((0, 2))

    def _estimate(self, scan, odom: RobotState) -> Obstacles:
        if self.perception_mode == "truth":
            ts = self.world.true_state()
            return self.truth.obstacles((ts.px, ts.py), self._ped_positions(), self.peds.v)
        return self.perception.update(scan, (odom.px, odom.py, odom.theta))

    def run(self) -> EpisodeResult:
        p, w = self.params, self.world
        wall0 = time.perf_counter()
        steps_per_control = int(round(p.T_C_s / w.dt))
        steps_per_scan = int(round(1.0 / w.lidar.config.rate_hz / w.dt))
        e_cbf, active, infeasible, n_ctrl, stopped, faults = 0.0, 0, 0, 0, 0.0, 0
        is_stopped = False
        planner_ms, cbf_ms, percep_ms = [], [], []
        modes: list[tuple[float, str]] = []
        min_clear = np.inf
        collision = success = False
        obstacles, scan, scan_t = Obstacles.empty(), None, 0.0
        k = 0
        limit_steps = int(round(self.time_limit_s / w.dt))
        while k < limit_steps:
            if k % steps_per_scan == 0:
                scan = w.scan()
                t0 = time.perf_counter()
                obstacles = self._estimate(scan, w.odom())
                percep_ms.append(1e3 * (time.perf_counter() - t0))
                scan_t = w.t
            if k % steps_per_control == 0:
                state = w.odom() if self.perception_mode == "lidar" else w.true_state()
                if np.hypot(state.px - self.goal[0], state.py - self.goal[1]) <= p.eps_g_m:
                    success = True
                    break
                # estimates are up to one scan old: advance them to now with their velocity (Eq. (2))
                age = w.t - scan_t
                obs_now = obstacles if age <= 0 or len(obstacles) == 0 else Obstacles(
                    obstacles.p + age * obstacles.v, obstacles.v, obstacles.cov, obstacles.r, obstacles.static,
                    obstacles.ids)
                u_in, pinfo = self.planner.plan(w.t, state, obs_now, self.goal)
                u_safe, finfo = self.cbf.filter(state, obs_now, u_in)
                w.command(u_safe)
                if pinfo.planned:
                    planner_ms.append(pinfo.planner_ms)
                cbf_ms.append(finfo.solve_ms)
                e_cbf += cbf_energy(u_safe, u_in, p.R_u_diag)
                active += bool(finfo.active)
                infeasible += bool(finfo.infeasible)
                faults += finfo.fallback == PERCEPTION_FAULT
                n_ctrl += 1
                if not modes or modes[-1][1] != pinfo.mode:
                    modes.append((round(w.t, 3), pinfo.mode))
                ts = w.true_state()
                is_stopped = bool(np.hypot(ts.vx, ts.vy) < p.v_freeze_mps)   # until the next control tick
                if self.observers:
                    rec = StepRecord(w.t, state, ts, obs_now, np.asarray(u_in), np.asarray(u_safe), pinfo.mode,
                                     bool(finfo.active), bool(finfo.infeasible), np.asarray(finfo.D),
                                     pinfo.path, scan)
                    for obs in self.observers:
                        obs(rec)
            # physics up to the next scan or control tick, in blocks; clearance and contact after each block
            nxt = min(steps_per_scan - k % steps_per_scan, steps_per_control - k % steps_per_control,
                      limit_steps - k)
            while nxt > 0 and not collision:
                nb = min(nxt, w.BLOCK_STEPS)
                w.step(nb)
                k += nb
                nxt -= nb
                if is_stopped:
                    stopped += nb * w.dt
                min_clear = min(min_clear, self.truth.clearance(w.pose(), self._ped_positions(), min_clear))
                collision = self.truth.in_contact(w.data)
            if collision:
                break
        ts = w.true_state()
        return EpisodeResult(
            scenario=self.scenario.name, method=self.method, seed=self.seed, success=success,
            collision=collision, timeout=not (success or collision), time_s=round(w.t, 4),
            min_clearance_m=float(min_clear), e_cbf=e_cbf,
            cbf_active_ratio=active / max(n_ctrl, 1), qp_infeasible_ratio=infeasible / max(n_ctrl, 1),
            planner_p95_ms=_p95(planner_ms), cbf_p95_ms=_p95(cbf_ms), perception_p95_ms=_p95(percep_ms),
            stopped_time_s=round(stopped, 4),
            final_goal_dist_m=float(np.hypot(ts.px - self.goal[0], ts.py - self.goal[1])),
            sim_time_s=round(w.t, 4), wall_time_s=time.perf_counter() - wall0, control_steps=n_ctrl,
            perception_faults=faults, mode_history=modes, perception=self.perception_mode, warnings=w.warnings())


def _p95(xs) -> float:
    return float(np.percentile(xs, 95)) if len(xs) else 0.0


#: metrics that must be identical between two runs of the same episode (everything but wall-clock timings)
DETERMINISTIC_KEYS = ("success", "collision", "timeout", "time_s", "min_clearance_m", "e_cbf", "cbf_active_ratio",
                      "qp_infeasible_ratio", "stopped_time_s", "final_goal_dist_m", "sim_time_s", "control_steps",
                      "perception_faults", "mode_history")
