"""The stack as a ROS 2 node (``bigcbf filter --ros2``): /scan and /odom in, /cmd_vel out, for a real robot or
the twin. Robot side: it imports no mujoco, dm_control or cv2 (tests/ros2/test_slim.py blocks them).

Topics (names can be remapped with the command line's options)::

    in   /scan          sensor_msgs/LaserScan     sensor-data QoS (best effort; reliable with --lockstep)
         /odom          nav_msgs/Odometry         sensor-data QoS; a control step per message, at most one per T_C
         /tf_static     tf2_msgs/TFMessage        latched; base_link (or base_footprint) -> the scan's frame: the
                                                  laser mount the perception uses
         /goal_pose     geometry_msgs/PoseStamped latched or not, in odom (Nav2's goal topic); or --goal X,Y
         /cmd_vel_in    geometry_msgs/Twist       method "filter" only: the command to filter (a Nav2 controller)
    out  /cmd_vel       geometry_msgs/Twist       u_safe (TwistStamped with --stamped or --lockstep, stamped
                                                  with the odometry's stamp it answers)
         /cmd_vel_in    geometry_msgs/Twist       the planner's u_in (methods with a planner)
         /behavior      std_msgs/String           the selected behavior mode
         /cbf/active    std_msgs/Bool             whether the CBF changed the command
         /cbf/h_min     std_msgs/Float64          min_i h_i of the step [m^2] (+inf: no obstacle)
         /cbf/margin_min std_msgs/Float64         the smallest kappa m_i of the CBF rows [m] (eq:shared_barrier (20))
         /filter/status std_msgs/String           "ok", or why the command is zero (the watchdog)
         /tracked_obstacles, /cbf/inflated_radius visualization_msgs/MarkerArray, with --markers

The watchdog sends a zero command (and says why on /filter/status) when the latest /odom or /scan is older than its
timeout on the wall clock (real time only: in lock-step the simulation may pause), when the scan's stamp is older
than the timeout at the odometry's stamp, or when a step took longer than its budget (its own overrun; the late
command is replaced by zero; in lock-step only with an explicit budget: the twin's time waits for the answer, and a
late answer zeroed there made a run on a loaded machine leave the in-process episode). Until the first scan and
the goal, the command is zero too; in lock-step a step that finds no scan yet waits for the first one (up to
FIRST_SCAN_WAIT_S on the wall clock, then zero): the twin publishes a scan at its first tick, and the two readers
matching the twin's writers at different instants on a loaded machine had put that tick's /odom ahead of its /scan.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from ..control.metrics import cbf_energy, percentile
from ..logio import convert, msgdefs
from . import transport
from .stack import FILTER_ONLY, SafetyStack

BOOL, FLOAT64 = "std_msgs/msg/Bool", "std_msgs/msg/Float64"
#: how long the first scans wait for the laser mount on /tf_static before the default mount is used [s]
MOUNT_WAIT_S = 1.0
#: lock-step: how long a step waits for the first scan before it answers zero ("no scan yet") [s, wall clock]
FIRST_SCAN_WAIT_S = 5.0


@dataclass
class FilterOptions:
    scan_topic: str = "/scan"
    odom_topic: str = "/odom"
    cmd_topic: str = "/cmd_vel"
    cmd_in_topic: str = "/cmd_vel_in"
    goal_topic: str = "/goal_pose"
    goal: tuple[float, float] | None = None
    stamped: bool = False
    lockstep: bool = False
    markers: bool = False
    scan_timeout_s: float = 0.5
    odom_timeout_s: float = 0.5
    overrun_ms: float | None = None         # default: the control period T_C; in lock-step, none
    idle_exit_s: float | None = None        # stop when no /odom came for this long after the first one


@dataclass
class FilterStats:
    """What the node did (its summary, ``bigcbf filter --json``)."""
    steps: int = 0
    scans: int = 0
    zero_commands: dict = field(default_factory=dict)     # reason -> count
    cbf_active: int = 0
    infeasible: int = 0
    e_cbf: float = 0.0
    mode_history: list = field(default_factory=list)
    scan_to_cmd_ms: list = field(default_factory=list)    # scan taken off the wire -> /cmd_vel written
    stack_ms: list = field(default_factory=list)          # the same scans: perception + control step alone
    #: the same span in the node thread's CPU time (what a loaded machine's preemption does not inflate)
    scan_to_cmd_cpu_ms: list = field(default_factory=list)

    def summary(self) -> dict:
        def p(xs, q):
            return round(percentile(xs, q), 4) if xs else None
        return {"steps": self.steps, "scans": self.scans, "zero_commands": dict(self.zero_commands),
                "cbf_active_ratio": self.cbf_active / self.steps if self.steps else 0.0,
                "qp_infeasible_ratio": self.infeasible / self.steps if self.steps else 0.0,
                "e_cbf": self.e_cbf, "mode_history": self.mode_history,
                "scan_to_cmd_p50_ms": p(self.scan_to_cmd_ms, 50), "scan_to_cmd_p95_ms": p(self.scan_to_cmd_ms, 95),
                "stack_p50_ms": p(self.stack_ms, 50), "stack_p95_ms": p(self.stack_ms, 95),
                "scan_to_cmd_cpu_p50_ms": p(self.scan_to_cmd_cpu_ms, 50),
                "scan_to_cmd_cpu_p95_ms": p(self.scan_to_cmd_cpu_ms, 95),
                "scan_to_cmd_cpu_ms": [round(x, 4) for x in self.scan_to_cmd_cpu_ms]}


class FilterNode:
    """``FilterNode(node, stack, options).spin(stop)``; every callback runs in the spinning thread."""

    def __init__(self, node: transport.Node, stack: SafetyStack, opts: FilterOptions):
        self.node, self.stack, self.opts = node, stack, opts
        self.T_C = stack.params.T_C_s
        #: the overrun budget [ms]; None: none (lock-step without an explicit one: simulated time waits)
        self.budget_ms = (float(opts.overrun_ms) if opts.overrun_ms is not None
                          else None if opts.lockstep else 1e3 * self.T_C)
        self.stats = FilterStats()
        self.R_u = stack.params.R_u_diag
        if opts.goal is not None:
            stack.set_goal(*opts.goal)
        sensor = transport.LOCKSTEP if opts.lockstep else transport.SENSOR_DATA
        stamped = opts.stamped or opts.lockstep
        self._cmd_type = msgdefs.TWIST_STAMPED if stamped else msgdefs.TWIST
        self.pub_cmd = node.publisher(opts.cmd_topic, self._cmd_type, transport.DEFAULT)
        self.pub_cmd_in = None if stack.planner is None else node.publisher(opts.cmd_in_topic, msgdefs.TWIST)
        self.pub_mode = node.publisher("/behavior", msgdefs.STRING)
        self.pub_active = node.publisher("/cbf/active", BOOL)
        self.pub_hmin = node.publisher("/cbf/h_min", FLOAT64)
        self.pub_margin = node.publisher("/cbf/margin_min", FLOAT64)
        self.pub_status = node.publisher("/filter/status", msgdefs.STRING)
        self.pub_markers = (node.publisher("/tracked_obstacles", msgdefs.MARKER_ARRAY),
                            node.publisher("/cbf/inflated_radius", msgdefs.MARKER_ARRAY)) if opts.markers else None
        self._mounts: dict[str, tuple[float, float, float]] = {}
        self._pending: list[tuple[object, float]] = []        # scans waiting for the odometry of their instant
        self._odom: list[tuple[float, object]] = []            # the last few (stamp, RobotState)
        self._odom_wall = self._scan_wall = None
        self._last_step_t: float | None = None
        self._scan_in: list[tuple[float, float]] = []          # (wall, CPU) wake times of the scans since the last
        #                                                        command
        self._stack_ms_pending = 0.0
        self._status = None
        self._mount_note = False
        self._deferred: tuple | None = None    # lock-step: a step waiting for the first scan (its _step args, wall)
        node.subscribe("/tf_static", msgdefs.TF_MESSAGE, self._on_tf_static, transport.LATCHED)
        node.subscribe(opts.goal_topic, msgdefs.POSE_STAMPED, self._on_goal, transport.LATCHED)
        node.subscribe(opts.scan_topic, msgdefs.LASER_SCAN, self._on_scan, sensor)   # before /odom: order kept
        node.subscribe(opts.odom_topic, msgdefs.ODOMETRY, self._on_odom, sensor)
        if stack.planner is None:
            node.subscribe(opts.cmd_in_topic, msgdefs.TWIST, self._on_cmd_in, transport.DEFAULT)

    # --- callbacks --------------------------------------------------------------------------------------------
    def _on_tf_static(self, msg, t_in) -> None:
        for tr in msg.transforms:
            if tr.header.frame_id in ("base_link", "base_footprint"):
                q = tr.transform.rotation
                self._mounts[tr.child_frame_id] = (tr.transform.translation.x, tr.transform.translation.y,
                                                   convert.quaternion_yaw(q.x, q.y, q.z, q.w))

    def _on_goal(self, msg, t_in) -> None:
        if self.opts.goal is None:
            self.stack.set_goal(msg.pose.position.x, msg.pose.position.y)

    def _on_scan(self, msg, t_in) -> None:
        self._scan_wall = t_in
        self._pending.append((convert.laser_scan(msg), (t_in, self.node.last_wake_cpu)))
        self._flush_scans()

    def _on_odom(self, msg, t_in) -> None:
        t = convert.stamp_s(msg.header.stamp)
        self._odom_wall = t_in
        self._odom = (self._odom + [(t, convert.odometry_state(msg))])[-8:]
        self._flush_scans()
        if self.stack.planner is not None and (self._last_step_t is None or t - self._last_step_t
                                               >= self.T_C - 1e-4):
            self._step(t, msg.header.stamp, None, t_in)

    def _on_cmd_in(self, msg, t_in) -> None:
        if self._odom:
            t = self._odom[-1][0]
            self._step(t, convert.time_msg(t), np.array(convert.twist_u(msg)), t_in)

    def _flush_scans(self) -> None:
        """Scans whose instant the odometry has reached, each with the pose of its instant (the latest odometry
        at or before its stamp: the episode's order)."""
        if self.stack.perception is None and self._pending:
            frame, first_in = self._pending[0][0].frame_id, self._pending[0][1][0]
            if frame in self._mounts:
                self.stack.set_mount(*self._mounts[frame])
            elif time.perf_counter() - first_in < MOUNT_WAIT_S:
                return                      # /tf_static (latched) may come just after the first scans
            elif not self._mount_note:
                self._mount_note = True
                print(f"note: no /tf_static transform base_link -> {frame} within {MOUNT_WAIT_S:g} s; the laser "
                      "mount is the perception parameters' (X3 default)", file=sys.stderr)
        while self._pending and self._odom and self._odom[-1][0] >= self._pending[0][0].stamp - 1e-9:
            scan, t_in = self._pending.pop(0)
            pose = next((s for t, s in reversed(self._odom) if t <= scan.stamp + 1e-9), self._odom[0][1])
            self._stack_ms_pending += self.stack.scan(scan, pose)
            self._scan_in.append(t_in)
            self.stats.scans += 1
        if self._deferred is not None and self.stack.scan_t is not None:
            self._answer_deferred()

    # --- a control step --------------------------------------------------------------------------------------
    def _why_zero(self, t: float) -> str | None:
        if self.stack.goal is None and self.stack.planner is not None:
            return "no goal yet"
        if self.stack.scan_t is None:
            return "no scan yet"
        if t - self.stack.scan_t > self.opts.scan_timeout_s:
            return f"stale /scan ({t - self.stack.scan_t:.2f} s at the odometry's stamp)"
        return None

    def _step(self, t: float, stamp, u_in, t_in: float, *, waited: bool = False) -> None:
        self._last_step_t = t
        why = self._why_zero(t)
        if why == "no scan yet" and self.opts.lockstep and not waited:
            self._deferred = ((t, stamp, u_in, t_in), time.perf_counter())     # answered by _flush_scans or spin
            return
        out = None
        if why is None:
            out = self.stack.control(t, self._odom[-1][1], u_in)
            if self.budget_ms is not None and 1e3 * (time.perf_counter() - t_in) > self.budget_ms:
                why = f"overrun ({1e3 * (time.perf_counter() - t_in):.1f} ms > {self.budget_ms:g} ms)"
        u = np.zeros(3) if why is not None else out.u_safe
        self._publish_cmd(u, stamp)
        now, cpu = time.perf_counter(), time.thread_time()
        if out is not None:
            self.stats.scan_to_cmd_ms += [1e3 * (now - s) for s, _ in self._scan_in]
            self.stats.scan_to_cmd_cpu_ms += [1e3 * (cpu - c) for _, c in self._scan_in]
            if self._scan_in:
                self.stats.stack_ms.append(self._stack_ms_pending + out.compute_ms)
        self._scan_in, self._stack_ms_pending = [], 0.0
        self._after_step(t, out, why)

    def _answer_deferred(self, waited: bool = False) -> None:
        """The lock-step step that waited for the first scan: with it, or (``waited``) zero after the wait."""
        args, self._deferred = self._deferred[0], None
        self._step(*args, waited=waited)

    def _publish_cmd(self, u, stamp) -> None:
        tw = convert.twist_msg(u)
        if self._cmd_type == msgdefs.TWIST_STAMPED:
            tw = {"header": {"stamp": {"sec": int(stamp["sec"] if isinstance(stamp, dict) else stamp.sec),
                                       "nanosec": int(stamp["nanosec"] if isinstance(stamp, dict) else stamp.nanosec)},
                             "frame_id": "base_link"}, "twist": tw}
        self.pub_cmd(tw)

    def _after_step(self, t: float, out, why: str | None) -> None:
        """The step's diagnostics: its topics and the summary's counts (after /cmd_vel: not in its latency)."""
        st = self.stats
        self._say(why or "ok")
        if why is not None:
            key = why.split(" (")[0]
            st.zero_commands[key] = st.zero_commands.get(key, 0) + 1
        if out is None:
            return
        st.steps += 1
        st.cbf_active += out.active
        st.infeasible += out.infeasible
        st.e_cbf += cbf_energy(out.u_safe, out.u_in, self.R_u)
        if not st.mode_history or st.mode_history[-1][1] != out.mode:
            st.mode_history.append((round(t, 3), out.mode))
        if self.pub_cmd_in is not None:
            self.pub_cmd_in(convert.twist_msg(out.u_in))
        self.pub_mode({"data": out.mode})
        self.pub_active({"data": out.active})
        self.pub_hmin({"data": out.h_min})
        self.pub_margin({"data": float(out.margins.min()) if out.margins.size else math.inf})
        if self.pub_markers is not None:
            self.pub_markers[0](convert.markers_msg(t, out.obstacles))
            self.pub_markers[1](convert.inflated_radius_markers(t, out.obstacles, out.D))

    def _say(self, status: str) -> None:
        if status != self._status:
            self._status = status
            self.pub_status({"data": status})

    # --- the loop ----------------------------------------------------------------------------------------------
    def watchdog(self) -> None:
        """Real time only: a zero command when /odom or /scan stopped coming (wall clock)."""
        if self.opts.lockstep or self._odom_wall is None:
            return
        now = time.perf_counter()
        why = None
        if now - self._odom_wall > self.opts.odom_timeout_s:
            why = f"stale /odom ({now - self._odom_wall:.2f} s)"
        elif self._scan_wall is not None and now - self._scan_wall > self.opts.scan_timeout_s:
            why = f"stale /scan ({now - self._scan_wall:.2f} s)"
        if why is not None:
            t = self._odom[-1][0] + (now - self._odom_wall)
            self._publish_cmd(np.zeros(3), convert.time_msg(t))
            self._after_step(t, None, why)

    def spin(self, should_stop=lambda: False, period_s: float = 0.02) -> None:
        while not should_stop():
            self.node.spin_once(period_s)
            self.watchdog()
            if self._deferred is not None and time.perf_counter() - self._deferred[1] > FIRST_SCAN_WAIT_S:
                self._answer_deferred(waited=True)
            if self.opts.idle_exit_s is not None and self._odom_wall is not None \
                    and time.perf_counter() - self._odom_wall > self.opts.idle_exit_s:
                return
