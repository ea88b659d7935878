"""Write robot logs as ROS 2 MCAP (mcap + mcap-ros2-support) with standard message types.

Foxglove, ``ros2 bag`` (with the MCAP storage plugin) and rosbags open the files. Chunks are small (64 KiB) so
that a log cut short (a crash, a full disk) still yields everything up to the last complete chunk.

Time base: simulation time. The log time of every message and every header stamp are the seconds passed to the
method that wrote it, which for a simulated run is the simulation time since the episode's start (as a robot
recorded with ``use_sim_time``); ``/clock`` (rosgraph_msgs/Clock) carries the same clock. Tools that show dates
show the epoch (1970-01-01) plus that time: choose "seconds" as the time format in Foxglove.

Topics and the method that writes each::

    /clock                       rosgraph_msgs/Clock              clock()
    /tf_static                   tf2_msgs/TFMessage               tf_static()      map -> odom, base_link -> laser,
                                                                                   imu_link (1)
    /robot_description           std_msgs/String                  robot_description()   the robot's URDF (1)
    /tf                          tf2_msgs/TFMessage               tf()             odom -> base_link, the wheels
    /map                         nav_msgs/OccupancyGrid           occupancy_grid() the scene's static geometry (1)
    /scene/markers               visualization_msgs/MarkerArray   scene_markers()  walls, boxes, cylinders (1)
    /pedestrians/markers         visualization_msgs/MarkerArray   pedestrians()    the true pedestrians
    /scan                        sensor_msgs/LaserScan            scan()           frame laser
    /odom                        nav_msgs/Odometry                odom()           wheel odometry, pose in odom (2)
    /imu                         sensor_msgs/Imu                  imu()            frame imu_link (2)
    /cmd_vel                     geometry_msgs/Twist              cmd_vel()        u_safe, what the robot is sent
    /cmd_vel_in                  geometry_msgs/Twist              cmd_vel_in()     u_in, before the CBF filter
    /ground_truth/odom           nav_msgs/Odometry                ground_truth()
    /goal_pose                   geometry_msgs/PoseStamped        goal_pose()      as Nav2's (1)
    /plan                        nav_msgs/Path                    plan()           the selected behavior's path
    /plan/candidates             visualization_msgs/MarkerArray   candidates()     BIG-CBF's imagined paths
    /behavior                    std_msgs/String                  behavior()       the selected behavior mode
    /tracked_obstacles           visualization_msgs/MarkerArray   obstacles()      see bigcbf.logio.convert
    /obstacles                   bigcbf_msgs/TrackedObstacleArray obstacle_states()  with covariances
    /cbf/inflated_radius         visualization_msgs/MarkerArray   inflated_radii() D_i rings and track ids

(1) written once at the start with the QoS of a latched topic (durability transient local, as rosbag2 records
it in the channel's ``offered_qos_profiles``), so a player gives them to late subscribers.
(2) covariances from the robot profile's sensor models when the caller gives them (the episode logger and the
calibration recorder do: :mod:`bigcbf.logio.covariance`), else zero.
The scene's topics are in frame ``map`` (:mod:`bigcbf.logio.scene_msgs`); the URDF: :mod:`bigcbf.logio.urdf`.

A log that is interrupted (Ctrl-C, SIGTERM: :mod:`bigcbf.logio.interrupts`) can be kept: ``finish_partial()``
completes it (summary and footer) as ``X.partial.mcap`` beside ``X.mcap``, never in the final file's place.
"""
from __future__ import annotations

import os
from pathlib import Path

from ..errors import UserError
from ..types import LaserScan, Obstacles, RobotState
from . import convert, msgdefs, scene_msgs
from .interrupts import critical

TOPIC_SCAN = "/scan"
TOPIC_ODOM = "/odom"
TOPIC_IMU = "/imu"
TOPIC_CMD = "/cmd_vel"
TOPIC_CMD_IN = "/cmd_vel_in"
TOPIC_TF = "/tf"
TOPIC_GROUND_TRUTH = "/ground_truth/odom"
TOPIC_BEHAVIOR = "/behavior"
TOPIC_OBSTACLES = "/tracked_obstacles"
TOPIC_OBSTACLE_STATES = "/obstacles"
TOPIC_CLOCK = "/clock"
TOPIC_TF_STATIC = "/tf_static"
TOPIC_ROBOT_DESCRIPTION = "/robot_description"
TOPIC_GOAL = "/goal_pose"
TOPIC_PLAN = "/plan"
TOPIC_CANDIDATES = "/plan/candidates"
TOPIC_INFLATED = "/cbf/inflated_radius"
TOPIC_MAP = "/map"
TOPIC_SCENE = "/scene/markers"
TOPIC_PEDESTRIANS = "/pedestrians/markers"

#: every topic an episode log has, and its type (bigcbf.logio.episode_log writes them)
EPISODE_TOPICS = {
    TOPIC_TF_STATIC: msgdefs.TF_MESSAGE, TOPIC_ROBOT_DESCRIPTION: msgdefs.STRING, TOPIC_GOAL: msgdefs.POSE_STAMPED,
    TOPIC_CLOCK: msgdefs.CLOCK, TOPIC_TF: msgdefs.TF_MESSAGE, TOPIC_CMD: msgdefs.TWIST, TOPIC_CMD_IN: msgdefs.TWIST,
    TOPIC_ODOM: msgdefs.ODOMETRY, TOPIC_GROUND_TRUTH: msgdefs.ODOMETRY, TOPIC_IMU: msgdefs.IMU,
    TOPIC_BEHAVIOR: msgdefs.STRING, TOPIC_PLAN: msgdefs.PATH, TOPIC_CANDIDATES: msgdefs.MARKER_ARRAY,
    TOPIC_SCAN: msgdefs.LASER_SCAN, TOPIC_OBSTACLES: msgdefs.MARKER_ARRAY,
    TOPIC_OBSTACLE_STATES: msgdefs.TRACKED_OBSTACLE_ARRAY, TOPIC_INFLATED: msgdefs.MARKER_ARRAY,
    TOPIC_MAP: msgdefs.OCCUPANCY_GRID, TOPIC_SCENE: msgdefs.MARKER_ARRAY, TOPIC_PEDESTRIANS: msgdefs.MARKER_ARRAY,
}

#: the map frame of the scene's topics (the simulator's world; /tf_static: map -> odom, identity)
MAP_FRAME = "map"

#: suffix of an interrupted log kept by finish_partial (X.mcap -> X.partial.mcap)
PARTIAL_SUFFIX = ".partial"


def partial_path(path: str | Path) -> Path:
    """Where an interrupted log of ``path`` is kept: X.mcap -> X.partial.mcap (X.log -> X.log.partial.mcap)."""
    p = Path(path)
    stem = p.stem if p.suffix == ".mcap" else p.name
    return p.with_name(f"{stem}{PARTIAL_SUFFIX}.mcap")

#: rosbag2's record of a latched publisher's QoS (reliable, transient local, keep last 1)
LATCHED_QOS = """- history: 1
  depth: 1
  reliability: 1
  durability: 1
  deadline:
    sec: 2147483647
    nsec: 4294967295
  lifespan:
    sec: 2147483647
    nsec: 4294967295
  liveliness: 1
  liveliness_lease_duration:
    sec: 2147483647
    nsec: 4294967295
  avoid_ros_namespace_conventions: false
"""

CHUNK_BYTES = 64 * 1024


class LogWriter:
    """A ROS 2 MCAP log. Use as a context manager, or call close(); the file is complete only after close()."""

    def __init__(self, path: str | Path, *, odom_frame: str = "odom", base_frame: str = "base_link",
                 metadata: dict[str, str] | None = None):
        from mcap_ros2.writer import Writer

        from ..outputs import AtomicFile
        self.path = Path(path)
        if self.path.is_dir():
            raise UserError("is a directory, expected an .mcap file path", file=str(self.path))
        self._file = AtomicFile(self.path, "log")     # written beside the path, renamed to it by close()
        try:
            self._fh = open(self._file.tmp, "wb")
        except OSError as exc:
            self._file.discard()
            raise UserError(f"cannot write: {exc.strerror}", file=str(self.path)) from None
        self._w = Writer(self._fh, chunk_size=CHUNK_BYTES)
        self._schemas: dict[str, object] = {}
        self.odom_frame, self.base_frame = odom_frame, base_frame
        self.counts: dict[str, int] = {}
        if metadata:
            self._w.add_metadata("bigcbf", {str(k): str(v) for k, v in metadata.items()})

    # --- generic ---------------------------------------------------------------------------------------------
    def write(self, topic: str, msgtype: str, t: float, message: dict, *, latched: bool = False) -> None:
        """Write one message (a dict shaped like ``msgtype``) on ``topic`` at log time ``t`` [s]. ``latched``: the
        topic's channel records a transient-local QoS (set by its first message)."""
        schema = self._schemas.get(msgtype)
        if schema is None:
            schema = self._schemas[msgtype] = self._w.register_msgdef(msgtype, msgdefs.schema_text(msgtype))
        if latched and topic not in self._w._channel_ids:
            # mcap-ros2-support registers channels without metadata; register this one ourselves, as its writer
            # would, plus the QoS (its attributes are private: the version is pinned in constraints.txt)
            self._w._channel_ids[topic] = self._w._writer.register_channel(
                topic=topic, message_encoding="cdr", schema_id=schema.id,
                metadata={"offered_qos_profiles": LATCHED_QOS})
        ns = convert.to_ns(t)
        try:
            with critical:              # an interrupt waits for the message to be written whole
                self._w.write_message(topic, schema, message, log_time=ns, publish_time=ns,
                                      sequence=self.counts.get(topic, 0))
        except OSError as exc:       # a full disk, say: drop the unfinished log, say so in one line
            self.abort()
            raise UserError(f"cannot write: {exc.strerror}", file=str(self.path)) from None
        self.counts[topic] = self.counts.get(topic, 0) + 1

    # --- the topics of an episode ----------------------------------------------------------------------------
    def scan(self, t: float, scan: LaserScan, topic: str = TOPIC_SCAN) -> None:
        self.write(topic, msgdefs.LASER_SCAN, t, convert.laser_scan_msg(scan))

    def odom(self, t: float, state: RobotState, topic: str = TOPIC_ODOM, *, pose_cov=None, twist_cov=None) -> None:
        """The robot's odometry; ``pose_cov``, ``twist_cov``: 6x6 covariances (zero unless given; see
        :mod:`bigcbf.logio.covariance`)."""
        self.write(topic, msgdefs.ODOMETRY, t, convert.odometry_msg(t, state, self.odom_frame, self.base_frame,
                                                                    pose_cov, twist_cov))

    def ground_truth(self, t: float, state: RobotState, topic: str = TOPIC_GROUND_TRUTH) -> None:
        self.write(topic, msgdefs.ODOMETRY, t, convert.odometry_msg(t, state, self.odom_frame, self.base_frame))

    def imu(self, t: float, imu: dict, topic: str = TOPIC_IMU, frame_id: str = "imu_link", *,
            cov: dict | None = None) -> None:
        """A SimWorld.imu() reading; ``cov``: its covariances by name (see :func:`bigcbf.logio.convert.imu_msg`)."""
        self.write(topic, msgdefs.IMU, t, convert.imu_msg(t, imu, frame_id, cov))

    def cmd_vel(self, t: float, u, topic: str = TOPIC_CMD) -> None:
        """The command sent to the robot (u_safe), body twist (vx [m/s], vy [m/s], wz [rad/s])."""
        self.write(topic, msgdefs.TWIST, t, convert.twist_msg(u))

    def cmd_vel_in(self, t: float, u, topic: str = TOPIC_CMD_IN) -> None:
        """The planner's input command u_in, before the CBF filter."""
        self.write(topic, msgdefs.TWIST, t, convert.twist_msg(u))

    def tf(self, t: float, state: RobotState, topic: str = TOPIC_TF, *, extra=()) -> None:
        """odom -> base_link at ``state``, and ``extra`` transforms [(parent, child, xyz, quaternion (x, y, z, w))]
        of the same instant (the wheels' joints, :meth:`bigcbf.logio.urdf.RobotDescription.wheel_transforms`)."""
        self.write(topic, msgdefs.TF_MESSAGE, t, convert.tf_msg(t, state, self.odom_frame, self.base_frame, extra))

    def behavior(self, t: float, mode: str, topic: str = TOPIC_BEHAVIOR) -> None:
        self.write(topic, msgdefs.STRING, t, convert.string_msg(mode))

    def obstacles(self, t: float, obs: Obstacles, topic: str = TOPIC_OBSTACLES) -> None:
        self.write(topic, msgdefs.MARKER_ARRAY, t, convert.markers_msg(t, obs, self.odom_frame))

    def obstacle_states(self, t: float, obs: Obstacles, topic: str = TOPIC_OBSTACLE_STATES) -> None:
        """The estimates with their covariances (bigcbf_msgs/TrackedObstacleArray)."""
        self.write(topic, msgdefs.TRACKED_OBSTACLE_ARRAY, t, convert.tracked_obstacles_msg(t, obs, self.odom_frame))

    def inflated_radii(self, t: float, obs: Obstacles, D, topic: str = TOPIC_INFLATED) -> None:
        """The CBF's D_i (eq:shared_barrier (20)) as rings around the tracked obstacles, with their track ids."""
        self.write(topic, msgdefs.MARKER_ARRAY, t, convert.inflated_radius_markers(t, obs, D, self.odom_frame))

    def clock(self, t: float, topic: str = TOPIC_CLOCK) -> None:
        self.write(topic, msgdefs.CLOCK, t, convert.clock_msg(t))

    def tf_static(self, t: float, transforms, topic: str = TOPIC_TF_STATIC) -> None:
        """Fixed transforms [(parent, child, (x, y, z), yaw), ...], latched."""
        self.write(topic, msgdefs.TF_MESSAGE, t, convert.static_tf_msg(t, transforms), latched=True)

    def robot_description(self, t: float, text: str, topic: str = TOPIC_ROBOT_DESCRIPTION) -> None:
        """The robot model's URDF (std_msgs/String), latched, as robot_state_publisher publishes it."""
        self.write(topic, msgdefs.STRING, t, convert.string_msg(text), latched=True)

    def goal_pose(self, t: float, goal_xy, topic: str = TOPIC_GOAL) -> None:
        """The goal, latched (a viewer that connects late still shows it)."""
        self.write(topic, msgdefs.POSE_STAMPED, t,
                   convert.pose_stamped_msg(t, float(goal_xy[0]), float(goal_xy[1]), 0.0, self.odom_frame),
                   latched=True)

    def occupancy_grid(self, t: float, scene, topic: str = TOPIC_MAP, resolution: float | None = None) -> None:
        """The scene's static geometry as nav_msgs/OccupancyGrid in ``map``, latched (bigcbf.logio.scene_msgs)."""
        self.write(topic, msgdefs.OCCUPANCY_GRID, t, scene_msgs.occupancy_grid_msg(t, scene, MAP_FRAME, resolution),
                   latched=True)

    def scene_markers(self, t: float, scene, topic: str = TOPIC_SCENE) -> None:
        """Walls, boxes and cylinders as markers in ``map``, latched."""
        self.write(topic, msgdefs.MARKER_ARRAY, t, scene_msgs.scene_markers_msg(t, scene, MAP_FRAME), latched=True)

    def pedestrians(self, t: float, names, positions, radii, heights, topic: str = TOPIC_PEDESTRIANS) -> None:
        """The true pedestrians as markers in ``map``."""
        self.write(topic, msgdefs.MARKER_ARRAY, t,
                   scene_msgs.pedestrian_markers_msg(t, names, positions, radii, heights, MAP_FRAME))

    def plan(self, t: float, points_xy, topic: str = TOPIC_PLAN) -> None:
        self.write(topic, msgdefs.PATH, t, convert.path_msg(t, points_xy, self.odom_frame))

    def candidates(self, t: float, modes, paths, accepted, selected: str | None, available=None,
                   topic: str = TOPIC_CANDIDATES) -> None:
        self.write(topic, msgdefs.MARKER_ARRAY, t,
                   convert.imagination_markers(t, modes, paths, accepted, selected, self.odom_frame, available))

    # --- life cycle ------------------------------------------------------------------------------------------
    def _finish_file(self) -> None:
        """Write the MCAP's last chunk, summary and footer, and close the temporary file."""
        try:
            self._w.finish()
        finally:
            self._fh.close()
            self._fh = None

    def close(self) -> None:
        """Finish the log; it appears at its path only now."""
        if self._fh is not None:
            try:
                self._finish_file()
            except OSError as exc:
                self._file.discard()
                raise UserError(f"cannot write: {exc.strerror}", file=str(self.path)) from None
            self._file.commit()

    def finish_partial(self) -> Path | None:
        """Complete an interrupted log (its last chunk, summary and footer: a valid MCAP) and keep it as
        ``X.partial.mcap`` beside ``X.mcap`` (:func:`partial_path`; an older one there is replaced); the final path
        is left as it was and no temporary file remains. Returns the partial log's path (None if the log was
        already closed or dropped). A signal during this waits until it is done (:mod:`bigcbf.logio.interrupts`)."""
        if self._fh is None:
            return None
        with critical:
            target = partial_path(self._file.target)
            try:
                self._finish_file()
                os.replace(self._file.tmp, target)
            except OSError as exc:
                self._file.discard()
                raise UserError(f"cannot write the partial log: {exc.strerror}", file=str(target)) from None
        return target

    def abort(self) -> None:
        """Drop the unfinished log (its path is left as it was)."""
        if self._fh is not None:
            try:
                self._fh.close()
            finally:
                self._fh = None
                self._file.discard()

    def __enter__(self) -> "LogWriter":
        return self

    def __exit__(self, exc_type, *exc) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
