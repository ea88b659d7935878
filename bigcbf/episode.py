"""One episode: the two-rate loop in MuJoCo physics, and the paper's per-episode metrics (Sec. IV).

    world (physics, 2 ms) -> LiDAR (10 Hz) -> perception -> planner (every T_C; BIG-CBF selects every T_B)
      -> common hard CBF filter (T_C = 50 ms) -> firmware and imperfection layer -> wheels

The stack sees only the LiDAR scans and the wheel odometry (pose in odom, body twist); faults of the robot profile
and the scenario (bigcbf/params/faults.py) reach it only through them: a scan that never arrives leaves the last
estimates in force, ageing (``obstacles_now``). Ground truth is used for
the metrics (collision, clearance) and for the pedestrians' motion, and, only in the flagged ``truth`` perception
mode, for the obstacle estimates. Success follows the paper: the robot's own state reaches the goal region
(eq:goal_region (5) on the controller's state x); the true distance to the goal at the end is reported too.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from .control.cbf import CbfFilter
from .control.encounters import NO_SIDES, EncounterSideRecorder
from .cost import check_episode_cost
from .control.kernels import goal_distance, in_goal_region
from .control.methods import METHODS, filter_params, make_planner
from .control.metrics import EpisodeMetrics
from .control.planner import PlanInfo
from .control.prediction import age_obstacles
from .control.route import RouteLayer, RouteParams
from .errors import UserError
from .params.perception import PerceptionParams
from .params.stack import StackParams
from .perception.pipeline import Perception
from .sanity import odometry_check, sensor_check
from .scenario import Scenario
from .sim.contacts import PERSONAL_SPACE_M, first_contact, near_miss
from .sim.lidar import LidarConfig
from .sim.pedestrians import SocialForceParams, WorldPedestrians
from .sim.truth import GroundTruth
from .sim.world import SimWorld
from .types import Obstacles, RobotState

PERCEPTION_MODES = ("lidar", "truth")
#: the method name of an episode whose u_in comes from outside (``Episode(..., method=None)``, e.g. a Gymnasium agent)
EXTERNAL = "external"
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
    e_cbf: float                  # eq:sim_cbf_energy (27)
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
    #: LiDAR scans that never arrived (the robot profile's scan dropout, bigcbf/params/faults.py)
    missed_scans: int = 0
    mode_history: list = field(default_factory=list)   # [(t, mode)] at each change
    perception: str = "lidar"
    warnings: dict = field(default_factory=dict)
    # chatter and stall (bigcbf/control/liveness.py defines them)
    mode_switches_per_min: float = 0.0
    side_reversals: int = 0         # left/right reversals of the mode history (PASS/SIDE -L vs -R)
    lateral_reversals: int = 0      # left/right reversals of the command's lateral component (every method)
    no_progress_s: float = 0.0      # time in 2 s windows that brought the robot < 0.1 m closer to the goal
    # side switches per encounter (bigcbf/control/encounters.py defines them); None for methods without sided modes
    encounters: int | None = None
    encounter_side_switches: int | None = None
    switches_per_encounter: float | None = None
    # the shared-uncertainty ablation's diagnostics (Sec. IV-C): E_CBF of the steps whose QP was infeasible, and the
    # margins kappa_l m_i (eq:shared_barrier (20)) each layer used, mean and 90th percentile over the episode [m]: the
    # imagination's over the selected rollout's steps and obstacles at each selection (BIG-CBF variants; NoShared: its
    # fixed margin; None for methods without imagination), the execution layer's over the CBF rows at each control step
    e_cbf_infeasible: float = 0.0
    m_img_mean_m: float | None = None
    m_img_p90_m: float | None = None
    m_exec_mean_m: float | None = None
    m_exec_p90_m: float | None = None
    # contacts classified by who moved into whom, and near misses with people (bigcbf/sim/contacts.py): the first
    # contact (kind and name of the body, normal, penetration, the robot's and the other's radial speeds), whether
    # the robot moved into it faster than v_freeze (at fault) or not (passive); the smallest constant-velocity time
    # to contact with a pedestrian (+inf, JSON null, when none closed); time with a pedestrian's body < 0.5 m away
    contact: dict | None = None
    at_fault_collision: bool = False
    passive_collision: bool = False
    min_time_to_contact_s: float = float("inf")
    personal_space_s: float = 0.0
    #: control steps whose distance rows held but not every velocity-aware row (StackParams.cbf_velocity_rows; the
    #: filter's lexicographic fallback, bigcbf/control/cbf.py), as a fraction; 0 with the switch off
    velocity_relaxed_ratio: float = 0.0

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


#: the largest |u_in| component a planner may return [m/s, rad/s]: 100 times any actuator box a Mecanum base has;
#: beyond it the filter's arithmetic itself breaks down (a fuzzer's planner returning 1e300 froze the robot silently)
MAX_COMMAND = 100.0


def checked_plan(method: str, out, t: float) -> tuple[np.ndarray, PlanInfo]:
    """A planner's ``plan()`` result ``out`` checked against the protocol (bigcbf/control/planner.py) before the CBF
    filter sees it: a tuple (u_in, info) with u_in 3 finite numbers (vx, vy, wz) and info a PlanInfo (a str mode,
    a finite planner_ms >= 0, a path None or (K, 2) finite). A user's planner that breaks it gets a UserError naming
    the method and what was wrong, not a traceback from deep in the filter. Returns (u_in as a float array, info)."""
    def bad(what: str) -> UserError:
        return UserError(f"method {method!r}: plan() {what} (at t = {t:.2f} s; the planner protocol: "
                         "bigcbf/control/planner.py, docs/extending.md)")

    if not isinstance(out, tuple) or len(out) != 2:
        got = f"a tuple of {len(out)}" if isinstance(out, tuple) else f"{type(out).__name__} {_short(out)}"
        raise bad(f"returned {got}, expected a tuple (u_in, PlanInfo)")
    u, info = out
    try:
        u = np.asarray(u, dtype=float)
    except (TypeError, ValueError):
        raise bad(f"returned a command that is not numbers ({type(u).__name__} {_short(u)}), expected 3 numbers "
                  "(vx, vy, wz)") from None
    if u.shape != (3,):
        raise bad(f"returned a command of shape {u.shape}, expected 3 numbers (vx, vy, wz)")
    if not np.isfinite(u).all():
        raise bad(f"returned a command that is not finite ({_short(u.tolist())}), expected 3 finite numbers "
                  "(vx, vy, wz)")
    if np.abs(u).max() > MAX_COMMAND:
        raise bad(f"returned a command of {_short(u.tolist())}: beyond +-{MAX_COMMAND:g} m/s (rad/s) it is no "
                  "velocity a robot can be asked for (the filter clips to the actuator box; a value this large is "
                  "a planner's bug)")
    if not isinstance(info, PlanInfo):
        raise bad(f"returned {type(info).__name__} {_short(info)} as its info, expected a "
                  "bigcbf.control.planner.PlanInfo")
    if not isinstance(info.mode, str):
        raise bad(f"returned PlanInfo.mode = {_short(info.mode)}, expected a string (its mode label)")
    ms = info.planner_ms
    if isinstance(ms, bool) or not isinstance(ms, (int, float, np.floating, np.integer)) or not (
            np.isfinite(ms) and ms >= 0):
        raise bad(f"returned PlanInfo.planner_ms = {_short(ms)}, expected a finite number of milliseconds >= 0")
    if info.path is not None:
        path = np.asarray(info.path)
        if path.ndim != 2 or path.shape[1:] != (2,) or not np.issubdtype(path.dtype, np.number) \
                or not np.isfinite(path).all():
            raise bad(f"returned PlanInfo.path of shape {path.shape} ({path.dtype}), expected None or finite "
                      "(K, 2) points in odom [m]")
    if info.margins_img is not None:
        m = np.asarray(info.margins_img)
        if m.ndim != 1 or not np.issubdtype(m.dtype, np.number) or not np.isfinite(m).all():
            raise bad(f"returned PlanInfo.margins_img of shape {m.shape} ({m.dtype}), expected None or a flat "
                      "array of finite margins [m]")
    return u, info


def _world_velocity(ts: RobotState) -> tuple[float, float]:
    """A true state's planar velocity in the world frame [m/s] (RobotState carries it in the body frame)."""
    c, s = np.cos(ts.theta), np.sin(ts.theta)
    return float(c * ts.vx - s * ts.vy), float(s * ts.vx + c * ts.vy)


def _short(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


class Episode:
    """One scenario x method x seed. ``run()`` returns an EpisodeResult; observers see every control step.

    ``method``: a method name (``bigcbf.control.methods``: registered, entry point or ``package.module:Class``),
    or None for an episode whose u_in comes from outside (``act(u_in)``). ``method_params``: the method's own
    parameters (its ``params_type``; default its defaults). :meth:`from_config` takes them all from a RunConfig.

    ``params``: the stack parameters; default (None) those of ``RunConfig()`` for the method (Table I overlaid with
    the twin-calibrated stack profile of the simulated X3, ``default_stack_params()``, with the method's keys of a
    shipped tuned configuration), and then ``method_params`` None is ``RunConfig()``'s too: every front door
    (``bigcbf run``/``bench``/``demo``, :func:`bigcbf.run_episode`, the Gymnasium environment) builds from it, so
    ``Episode(sc, m, seed)`` is ``Episode.from_config(sc, m, seed, RunConfig())``. Pass ``SIMULATION`` for Table I
    alone (the golden tests and ``bigcbf perf`` do; given ``params``, ``method_params`` None is the dataclass's).
    """

    @classmethod
    def from_config(cls, scenario: Scenario, method: str | None, seed: int, config, **kwargs) -> "Episode":
        """An episode with the stack, perception, pedestrian and method parameters of a
        :class:`bigcbf.config.RunConfig`; ``kwargs`` as for the constructor (perception, time_limit_s, ...)."""
        return cls(scenario, method, seed, config.stack_for(method), perception_params=config.perception,
                   pedestrian_params=config.pedestrians,
                   method_params=None if method is None else config.method_params(method),
                   route=config.route, **kwargs)

    def __init__(self, scenario: Scenario, method: str | None, seed: int, params: StackParams | None = None,
                 perception: str = "lidar", perception_params: PerceptionParams = PerceptionParams(),
                 lidar: LidarConfig | None = None, time_limit_s: float | None = None,
                 pedestrian_params: SocialForceParams = SocialForceParams(), method_params=None,
                 route: RouteParams | None = None):
        if perception not in PERCEPTION_MODES:
            raise ValueError(f"perception must be one of {PERCEPTION_MODES}")
        if params is None:          # RunConfig()'s stack for the method (and its parameters): the shipped defaults
            from .config import RunConfig
            default = RunConfig()
            params = default.stack_for(method)
            if method_params is None and method is not None:
                method_params = default.method_params(method)
        self.scenario, self.method, self.seed, self.params = scenario, method, int(seed), params
        self.perception_mode = perception
        self.time_limit_s = scenario.time_limit_s if time_limit_s is None else float(time_limit_s)
        # refused before anything is built when its estimated work is above the bound (bigcbf/cost.py)
        check_episode_cost(scenario, method, params, method_params=method_params,
                           perception_params=perception_params, lidar=lidar, time_limit_s=self.time_limit_s,
                           perception=perception)
        self.world = SimWorld(scenario.scene(), profile=scenario.robot_profile, seed=seed, lidar=lidar)
        self.truth = GroundTruth(self.world.model, self.world.scene)
        # the pedestrians walk in the world (their social-force model and mocap bodies: sim/pedestrians.py)
        self.walkers = WorldPedestrians(self.world, scenario.pedestrians, pedestrian_params,
                                        robot_radius=params.uncertainty.r_robot_m, seed=self.seed)
        self.peds = self.walkers.pedestrians
        # method None: no planner, every act() gets its u_in from outside (EXTERNAL)
        self.planner = None if method is None else make_planner(method, params, method_params)
        if self.planner is not None:
            self.planner.reset(self.seed)
        self.cbf = CbfFilter(filter_params(self.planner, params))    # a method may set filter switches (dpcbf)
        self.perception = Perception(self.world.robot.perception_params(perception_params))   # its laser mount
        self.goal = scenario.goal
        # the route layer (control/route.py): its look-ahead point is the method's goal; success stays the real goal
        mount = self.perception.params
        self.route = None if route is None or not route.enabled else RouteLayer(
            route, params.uncertainty.r_robot_m, params.uncertainty.d0_m,
            (mount.laser_x_m, mount.laser_y_m, mount.laser_yaw_rad), arrive_m=params.eps_g_m)
        self.observers: list[Callable[[StepRecord], None]] = []
        # results that would be false without a word (bigcbf/sanity.py): warnings beside MuJoCo's, and their lines
        self.sanity_warnings, self.notes = sensor_check(self.world.scene, self.world.lidar.config, params,
                                                        scenario.robot_profile)

    def _stack_pose(self) -> RobotState:
        """The pose the stack works with: the odometry (the truth in the ``truth`` perception mode)."""
        return self.world.odom() if self.perception_mode == "lidar" else self.world.true_state()

    def _estimate(self, scan, odom: RobotState) -> Obstacles:
        if self.perception_mode == "truth":
            ts = self.world.true_state()
            return self.truth.obstacles((ts.px, ts.py), self.walkers.positions(), self.walkers.velocities)
        return self.perception.update(scan, (odom.px, odom.py, odom.theta))

    # --- the loop, one control period at a time ------------------------------------------------------------
    #
    #   begin()                      -> physics up to the first control tick (scans on the way), then observe it
    #   act(u_in=None)               -> plan (or take u_in), filter, command; physics to the next control tick
    #   done / result()              -> whether the episode ended (goal, collision, time limit); its metrics
    #
    # run() is begin() then act() until done. Stepping through act() gives exactly run()'s episode (same order of
    # scans, estimates, commands and physics); the Gymnasium environment (bigcbf.gym_env) steps it with its
    # agent's u_in instead of the planner's.

    def begin(self) -> None:
        """Start the episode: physics up to the first control tick, where :meth:`act` takes over."""
        w = self.world
        self._wall0 = time.perf_counter()
        self._spc = int(round(self.params.T_C_s / w.dt))                      # physics steps per control tick
        self._sps = w.lidar.config.steps_per_scan(w.dt)                       # physics steps per scan
        self._limit = int(round(self.time_limit_s / w.dt))
        self._k = 0
        self.metrics = EpisodeMetrics.for_params(self.params)     # every metric of the episode goes through it
        self._sides = (EncounterSideRecorder(self.params) if getattr(self.planner, "sided_modes", False)
                       else None)                                 # switches per encounter (control/encounters.py)
        self._collision = self._success = False
        self._obstacles, self._scan, self._scan_t, self._scanned = Obstacles.empty(), None, 0.0, -1
        self.state: RobotState | None = None       # the stack's state at the pending control tick
        self.done = False
        if self.route is not None:
            self.route.reset(self._stack_pose().p, self.goal)
        self._observe()

    def _observe(self) -> None:
        """From the current physics step: scans when due, then at a control tick the stack's state and the goal
        check; physics in between. Stops at a control tick (pending for act) or when the episode ends."""
        w = self.world
        while not self.done:
            k = self._k
            if k >= self._limit:
                self.done = True
                return
            if k % self._sps == 0 and self._scanned != k:
                self._scanned = k
                scan = w.scan()
                if scan is not None:         # None: the scan never arrived (a fault); the estimates age
                    self._scan = scan
                    t0 = time.perf_counter()
                    self._obstacles = self._estimate(scan, w.odom())
                    self.metrics.scan(1e3 * (time.perf_counter() - t0))
                    if self.route is not None:   # the map from the stack's own pose; moving tracks not burned in
                        pose = self._stack_pose()
                        self.route.scan(scan, (pose.px, pose.py, pose.theta), self._obstacles)
                    self._scan_t = w.t
                else:
                    self.metrics.scan(None)
            if k % self._spc == 0:
                state = w.odom() if self.perception_mode == "lidar" else w.true_state()
                dist = goal_distance(state.p, self.goal)
                if in_goal_region(dist, self.params.eps_g_m):   # eq:goal_region
                    self._success = self.done = True
                    if k == 0:               # success before any command: said, never silent (bigcbf/sanity.py)
                        self.sanity_warnings["started_in_goal_region"] = 1
                        self.notes.append(f"the robot started inside the goal region: {float(dist):.2f} m from the "
                                          f"goal, eps_g_m {self.params.eps_g_m:g} m; success at t = 0 without moving")
                    return
                self.state = state
                return
            self._physics()

    @property
    def last_scan(self):
        """The latest LiDAR scan (None before the first)."""
        return self._scan

    def obstacles_now(self) -> Obstacles:
        """The estimates at the pending control tick, aged to now (``prediction.age_obstacles``: moved with their
        velocity, ``eq:obs_prop`` (2); when scans went missing, the covariance grown beyond one scan period,
        ``eq:cov_prop`` (3))."""
        return age_obstacles(self._obstacles, self.world.t - self._scan_t, 1.0 / self.world.lidar.config.rate_hz,
                             self.params.uncertainty)

    def _plan(self, t, state, obstacles, goal):
        """The planner's plan(). A user's planner (not a registered method) that raises gets one line naming the
        method and its error (the traceback stays on the exception's __cause__ for a debugger); a built-in
        method's exception is a bug of ours and propagates as it is."""
        try:
            return self.planner.plan(t, state, obstacles, goal)
        except UserError:
            raise
        except Exception as exc:
            if self.method in METHODS:
                raise
            raise UserError(f"method {self.method!r}: plan() raised {type(exc).__name__}: {str(exc)[:200]} (at t = "
                            f"{t:.2f} s)") from exc

    def act(self, u_in=None) -> StepRecord | None:
        """One control period at the pending control tick: the planner's u_in (or the given one), the common CBF
        filter, the command; then physics up to the next control tick. Returns what the step did."""
        if self.done:
            raise RuntimeError("the episode is over")
        w, state = self.world, self.state
        obs_now = self.obstacles_now()
        if u_in is None:
            goal = self.goal if self.route is None else self.route.local_goal(w.t, state, self.goal)
            u_in, pinfo = checked_plan(self.method, self._plan(w.t, state, obs_now, goal), w.t)
        else:
            u_in, pinfo = np.asarray(u_in, float), PlanInfo(mode=EXTERNAL, planned=False, planner_ms=0.0)
        u_safe, finfo = self.cbf.filter(state, obs_now, u_in)
        w.command(u_safe)
        ts = w.true_state()
        self.metrics.control_step(w.t, state, ts, self.goal, u_in, u_safe, pinfo, finfo)
        if self._sides is not None and pinfo.mode != EXTERNAL:
            self._sides.add(w.t, state, obs_now, goal, pinfo.mode, pinfo.planned)
        if self.peds.k:                                   # near misses with people (sim/contacts.py)
            self.metrics.near_miss(*near_miss(self.truth.distance, (ts.px, ts.py, ts.theta), _world_velocity(ts),
                                              self.walkers.positions(), self.walkers.velocities), PERSONAL_SPACE_M)
        rec = StepRecord(w.t, state, ts, obs_now, np.asarray(u_in), np.asarray(u_safe), pinfo.mode,
                         bool(finfo.active), bool(finfo.infeasible), np.asarray(finfo.D), pinfo.path, self._scan)
        for observer in self.observers:
            observer(rec)
        self._physics()
        self._observe()
        return rec

    def _physics(self) -> None:
        """Physics up to the next scan or control tick, in blocks; true clearance and contact after each block."""
        w = self.world
        k = self._k
        nxt = min(self._sps - k % self._sps, self._spc - k % self._spc, self._limit - k)
        before = None
        while nxt > 0 and not self._collision:
            nb = min(nxt, w.BLOCK_STEPS)
            before = w.snapshot(), self.walkers.velocities.copy()       # the velocities a contact is judged by
            w.step(nb)
            self._k += nb
            nxt -= nb
            self.metrics.physics(nb, w.dt, self.truth.clearance(w.pose(), self.walkers.positions(),
                                                                self.metrics.min_clearance_m))
            self._collision = self.truth.in_contact(w.data)
        if self._collision:
            self.done = True
            if before is not None:
                self._classify_contact(w.true_state(before[0]), before[1])

    def _classify_contact(self, ts: RobotState, ped_v: np.ndarray) -> None:
        """The contact just made, classified by who moved into whom (sim/contacts.py) with the robot's and the
        pedestrians' velocities from before the physics block that made it."""
        w = self.world
        c = first_contact(self.truth, w.model, w.data, w.pose(), _world_velocity(ts), ts.wz,
                          [p.name for p in self.scenario.pedestrians], self.walkers.positions(), ped_v,
                          self.params.v_freeze_mps, w.t)
        if c is not None:
            self.metrics.contacted(c.as_dict())

    def result(self) -> EpisodeResult:
        """The episode's metrics so far (final once ``done``)."""
        w = self.world
        ts = w.true_state()
        warnings = {**w.warnings(), **self.sanity_warnings}
        if self.done:                # success is judged on the odometry (the paper's rule): say when it lied
            odom = w.odom() if self.perception_mode == "lidar" else ts
            diverged, lines = odometry_check((ts.px, ts.py), (odom.px, odom.py), self.params.eps_g_m)
            warnings.update(diverged)
            self.notes += [x for x in lines if x not in self.notes]
        return EpisodeResult(
            scenario=self.scenario.name, method=self.method or EXTERNAL, seed=self.seed, success=self._success,
            collision=self._collision, timeout=self.done and not (self._success or self._collision),
            time_s=round(w.t, 4), final_goal_dist_m=float(np.hypot(ts.px - self.goal[0], ts.py - self.goal[1])),
            sim_time_s=round(w.t, 4), wall_time_s=time.perf_counter() - self._wall0,
            perception=self.perception_mode, warnings=warnings, **self.metrics.results(w.t),
            **(NO_SIDES if self._sides is None else self._sides.metrics()))

    def run(self) -> EpisodeResult:
        """The whole episode: :meth:`begin`, then :meth:`act` until done."""
        self.begin()
        while not self.done:
            self.act()
        return self.result()


#: metrics that must be identical between two runs of the same episode (everything but wall-clock timings)
DETERMINISTIC_KEYS = ("success", "collision", "timeout", "time_s", "min_clearance_m", "e_cbf", "cbf_active_ratio",
                      "qp_infeasible_ratio", "stopped_time_s", "final_goal_dist_m", "sim_time_s", "control_steps",
                      "perception_faults", "mode_history", "mode_switches_per_min", "side_reversals",
                      "lateral_reversals", "no_progress_s", "encounters", "encounter_side_switches",
                      "switches_per_encounter", "e_cbf_infeasible", "m_img_mean_m", "m_img_p90_m",
                      "m_exec_mean_m", "m_exec_p90_m", "missed_scans", "contact", "at_fault_collision",
                      "passive_collision", "min_time_to_contact_s", "personal_space_s", "velocity_relaxed_ratio")
