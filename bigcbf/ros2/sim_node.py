"""The MuJoCo twin as a ROS 2 robot (``bigcbf sim --ros2 SCENARIO``): the scenario's world, robot and walking
people, with the sensors on ROS 2 topics and the wheels driven by /cmd_vel.

Published (simulation time, ``use_sim_time``; frames as in our MCAP logs, :mod:`bigcbf.logio.writer`)::

    at the start, latched  /tf_static (map -> odom, base_link -> laser, imu_link), /robot_description (URDF),
                           /goal_pose (the scenario's goal, in odom), /map (OccupancyGrid), /scene/markers
    every control tick     /clock, /tf (odom -> base_link, wheels), /odom (covariances from the robot profile),
    (T_C, 20 Hz)           /imu, /ground_truth/odom, /pedestrians/markers (the true people)
    every LiDAR scan       /scan (10 Hz, frame laser)

Subscribed: /cmd_vel as geometry_msgs/Twist and as geometry_msgs/TwistStamped (Nav2's ``enable_stamped_cmd_vel``),
reliable (as Nav2, teleop and the Rosmaster driver publish it). Two modes:

- real time (default): each control tick waits for the wall clock (``speed`` times real time) and applies the
  latest command; a command older than ``cmd_timeout_s`` (wall clock) is taken as zero, as a base driver's
  timeout does. Any ROS 2 stack can drive it.
- lock-step (``--lockstep``, with ``bigcbf filter --ros2 --lockstep``): at each control tick the twin publishes,
  then waits for the TwistStamped whose stamp is this tick's; the episode is then what the in-process episode of
  the same seed is, up to the messages' rounding. As fast as the two processes go.

The episode ends as ``bigcbf run``'s does (goal region on the odometry, contact, time limit); its metrics are the
twin's (success, collision, clearance, time); the filter's own (CBF activity, modes) are the filter node's.
"""
from __future__ import annotations

import time

import numpy as np

from ..control.cbf import FilterInfo
from ..control.planner import PlanInfo
from ..episode import PERSONAL_SPACE_M, Episode, _world_velocity, near_miss
from ..errors import UserError
from ..logio import convert, msgdefs
from ..logio.covariance import WorldCovariances
from ..logio.writer import MAP_FRAME, LogWriter
from ..types import Obstacles
from . import transport, wire

#: the method label of a twin episode driven over ROS 2
REMOTE = "ros2"
_NO_FILTER = FilterInfo(active=False, infeasible=False, fallback=None, solve_ms=0.0, n_constraints=0,
                        h_min=float("inf"), D=np.zeros(0))


class TopicWriter(LogWriter):
    """A :class:`LogWriter` whose messages go to DDS topics (same methods, topics, types and frames as a log).
    ``qos``: topic -> QosProfile (default :data:`transport.DEFAULT`; latched messages :data:`transport.LATCHED`)."""

    def __init__(self, node: transport.Node, qos: dict | None = None):
        self.node, self.qos = node, dict(qos or {})
        self.odom_frame, self.base_frame = "odom", "base_link"
        self.counts: dict[str, int] = {}
        self.pubs: dict[str, object] = {}
        self.path = f"dds domain {node.domain_id}"

    def publisher(self, topic: str, msgtype: str, latched: bool = False):
        pub = self.pubs.get(topic)
        if pub is None:
            qos = transport.LATCHED if latched else self.qos.get(topic, transport.DEFAULT)
            pub = self.pubs[topic] = self.node.publisher(topic, msgtype, qos)
        return pub

    def write(self, topic: str, msgtype: str, t: float, message: dict, *, latched: bool = False) -> None:
        self.publisher(topic, msgtype, latched)(message)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def close(self) -> None:
        """Nothing to finish (the node owns the participant)."""

    abort = close


class TwinEpisode(Episode):
    """An episode whose commands come from outside as the wheels' command itself (u_safe): no planner, no
    filter, no perception on the twin's side (the robot's stack runs elsewhere)."""

    def _estimate(self, scan, odom):
        return Obstacles.empty()

    def drive(self, u) -> None:
        """Apply ``u`` (vx, vy, wz) at the pending control tick; physics to the next one (``Episode.act`` with the
        command taken as it is)."""
        w, state = self.world, self.state
        u = np.asarray(u, float)
        w.command(u)
        ts = w.true_state()
        self.metrics.control_step(w.t, state, ts, self.goal, u, u,
                                  PlanInfo(mode=REMOTE, planned=False, planner_ms=0.0), _NO_FILTER)
        if self.peds.k:
            self.metrics.near_miss(*near_miss(self.truth.distance, (ts.px, ts.py, ts.theta), _world_velocity(ts),
                                              self.walkers.positions(), self.walkers.velocities), PERSONAL_SPACE_M)
        self._physics()
        self._observe()


class TwinNode:
    """The twin on DDS. ``run()`` plays the episode to its end and returns its EpisodeResult."""

    def __init__(self, episode: TwinEpisode, node: transport.Node, *, lockstep: bool = False, speed: float = 1.0,
                 cmd_timeout_s: float = 0.5, answer_timeout_s: float = 10.0, cmd_topic: str = "/cmd_vel"):
        self.ep, self.node, self.lockstep = episode, node, lockstep
        self.speed, self.cmd_timeout_s, self.answer_timeout_s = float(speed), cmd_timeout_s, answer_timeout_s
        # lock-step: the filter's readers of /scan and /odom are transient local (transport.LOCKSTEP)
        self.w = TopicWriter(node, {"/scan": transport.LOCKSTEP, "/odom": transport.LOCKSTEP} if lockstep else None)
        self._cmd: tuple[np.ndarray, float, int | None] | None = None    # (u, wall time, stamp ns or None)
        self.ignored = 0                                                   # lock-step: commands of no pending tick
        #: when a list: (t, odometry state, the scan published at this tick or None) per tick (bigcbf.ros2.perf)
        self.sent: list | None = None
        node.subscribe(cmd_topic, msgdefs.TWIST, self._on_twist, transport.DEFAULT)
        node.subscribe(cmd_topic, msgdefs.TWIST_STAMPED, self._on_twist_stamped, transport.DEFAULT)
        self._answers: dict[int, np.ndarray] = {}
        world = episode.world
        self._cov = WorldCovariances(world)
        self._urdf = None
        self._peds = [p for p in world.scene.pedestrians]

    def _on_twist(self, msg, t_in) -> None:
        self._cmd = (np.array(convert.twist_u(msg)), t_in, None)

    def _on_twist_stamped(self, msg, t_in) -> None:
        ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        u = np.array(convert.twist_u(msg))
        self._cmd = (u, t_in, ns)
        if self.lockstep:
            self._answers[ns] = u

    # --- publications --------------------------------------------------------------------------------------------
    def _start(self) -> None:
        from ..logio.urdf import robot_description

        w, world = self.w, self.ep.world
        sensors = world.sensor_frames()
        w.tf_static(0.0, [(MAP_FRAME, "odom", (0.0, 0.0, 0.0), 0.0)]
                    + [("base_link", child, (x, y, z), yaw) for child, (x, y, z, yaw) in sensors.items()])
        self._urdf = robot_description(world.model, sensors, base="base_link", name=world.robot.name)
        w.robot_description(0.0, self._urdf.text)
        w.goal_pose(0.0, self.ep.goal)
        w.occupancy_grid(0.0, world.scene)
        w.scene_markers(0.0, world.scene)
        for topic, msgtype in (("/clock", msgdefs.CLOCK), ("/tf", msgdefs.TF_MESSAGE), ("/imu", msgdefs.IMU),
                               ("/ground_truth/odom", msgdefs.ODOMETRY), ("/scan", msgdefs.LASER_SCAN),
                               ("/odom", msgdefs.ODOMETRY), ("/pedestrians/markers", msgdefs.MARKER_ARRAY)):
            w.publisher(topic, msgtype)

    def _publish_tick(self, last_scan_stamp):
        """The tick's messages; the odometry last (in lock-step it asks for the command). Returns the stamp of the
        newest scan published."""
        ep, w, world = self.ep, self.w, self.ep.world
        t, state = world.t, ep.state
        w.clock(t)
        w.tf(t, state, extra=self._urdf.wheel_transforms(world.data.qpos))
        w.imu(t, world.imu(), cov=self._cov.imu())
        w.ground_truth(t, world.true_state())
        if self._peds:
            w.pedestrians(t, [p.name for p in self._peds], np.asarray(ep.walkers.positions(), float),
                          [p.radius for p in self._peds], [p.height for p in self._peds])
        pose_cov, twist_cov = self._cov.odom(t, state)
        odom = wire.from_dict(msgdefs.ODOMETRY, convert.odometry_msg(t, state, "odom", "base_link", pose_cov,
                                                                     twist_cov))
        scan, new_scan = ep.last_scan, None
        if scan is not None and scan.stamp != last_scan_stamp:
            last_scan_stamp, new_scan = scan.stamp, scan
            w.scan(scan.stamp, scan)       # before the odometry: one participant, one socket, in order
        w.write("/odom", msgdefs.ODOMETRY, t, odom)      # right after the scan (built before it)
        if self.sent is not None:
            self.sent.append((t, state, new_scan))
        return last_scan_stamp

    # --- the loop -----------------------------------------------------------------------------------------------
    def wait_for_filter(self, timeout_s: float) -> None:
        """Lock-step: wait until the filter's readers of /scan, /odom and /tf_static and a publisher of /cmd_vel
        have matched, and the latched messages (mount, goal) have reached it.

        Every one of the three, not /odom alone: /tf_static's acknowledgement is empty while its reader is
        unmatched (the filter then waits for the mount). What a matched writer sends before the remote reader has
        matched it in turn reaches the reader on that match (transport.LOCKSTEP, transient local), and a step that
        comes before the first scan waits for it on the filter's side (filter_node.FIRST_SCAN_WAIT_S)."""
        deadline = time.monotonic() + timeout_s
        needed = [self.w.pubs[topic].writer for topic in ("/scan", "/odom", "/tf_static")]
        while any(len(w.get_matched_subscriptions()) == 0 for w in needed) or not any(
                len(r.get_matched_publications()) for r, _, _ in self.node._readers):
            if time.monotonic() > deadline:
                raise UserError(f"--lockstep: no filter node answered within {timeout_s:g} s on domain "
                                f"{self.node.domain_id} (start 'bigcbf filter --ros2 --lockstep' with the same "
                                "--domain-id)")
            self.node.spin_once(0.05)
        for topic in ("/tf_static", "/goal_pose"):
            self.w.pubs[topic].writer.wait_for_acks(int(timeout_s * 1e9))

    def _command(self, tick_ns: int, wall_deadline: float | None) -> np.ndarray:
        if self.lockstep:
            deadline = time.monotonic() + self.answer_timeout_s
            while tick_ns not in self._answers:
                if time.monotonic() > deadline:
                    raise UserError(f"--lockstep: no /cmd_vel for t = {tick_ns / 1e9:.3f} s within "
                                    f"{self.answer_timeout_s:g} s (is the filter node still running?)")
                self.node.spin_once(0.05)
            u = self._answers.pop(tick_ns)
            self.ignored += sum(1 for k in self._answers if k < tick_ns)
            self._answers = {k: v for k, v in self._answers.items() if k > tick_ns}
            return u
        while True:                      # real time: take commands until the tick's wall-clock time
            left = wall_deadline - time.perf_counter()
            if left <= 0:
                break
            self.node.spin_once(left)
        if self._cmd is None or time.perf_counter() - self._cmd[1] > self.cmd_timeout_s:
            return np.zeros(3)
        return self._cmd[0]

    def run(self, wait_s: float = 30.0):
        ep = self.ep
        self._start()
        ep.begin()
        if self.lockstep:
            self.wait_for_filter(wait_s)
        t0 = time.perf_counter()
        last_scan = None
        while not ep.done:
            last_scan = self._publish_tick(last_scan)
            t = ep.world.t
            u = self._command(convert.to_ns(t), t0 + (t + ep.params.T_C_s) / self.speed)
            ep.drive(u)
        res = ep.result()
        res.method = REMOTE
        return res
