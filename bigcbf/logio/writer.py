"""Write robot logs as ROS 2 MCAP (mcap + mcap-ros2-support) with standard message types.

Foxglove, ``ros2 bag`` (with the MCAP storage plugin) and rosbags open the files. Log time = the time passed to
each method (simulation time in seconds; header stamps are the same clock). Chunks are small (64 KiB) so that a
log cut short (a crash, a full disk) still yields everything up to the last complete chunk.

Topics of an episode (issue 8) and the method that writes each::

    /scan                sensor_msgs/LaserScan            scan()
    /odom                nav_msgs/Odometry                odom()           wheel odometry, pose in odom
    /imu                 sensor_msgs/Imu                  imu()
    /cmd_vel             geometry_msgs/Twist              cmd_vel()        u_safe, what the robot is sent
    /cmd_vel_in          geometry_msgs/Twist              cmd_vel_in()     u_in, before the CBF filter
    /tf                  tf2_msgs/TFMessage               tf()             odom -> base_link
    /ground_truth/odom   nav_msgs/Odometry                ground_truth()
    /behavior            std_msgs/String                  behavior()       the selected behavior mode
    /tracked_obstacles   visualization_msgs/MarkerArray   obstacles()      see bigcbf.logio.convert
"""
from __future__ import annotations

from pathlib import Path

from ..errors import UserError
from ..types import LaserScan, Obstacles, RobotState
from . import convert, msgdefs

TOPIC_SCAN = "/scan"
TOPIC_ODOM = "/odom"
TOPIC_IMU = "/imu"
TOPIC_CMD = "/cmd_vel"
TOPIC_CMD_IN = "/cmd_vel_in"
TOPIC_TF = "/tf"
TOPIC_GROUND_TRUTH = "/ground_truth/odom"
TOPIC_BEHAVIOR = "/behavior"
TOPIC_OBSTACLES = "/tracked_obstacles"

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
    def write(self, topic: str, msgtype: str, t: float, message: dict) -> None:
        """Write one message (a dict shaped like ``msgtype``) on ``topic`` at log time ``t`` [s]."""
        schema = self._schemas.get(msgtype)
        if schema is None:
            schema = self._schemas[msgtype] = self._w.register_msgdef(msgtype, msgdefs.schema_text(msgtype))
        ns = convert.to_ns(t)
        try:
            self._w.write_message(topic, schema, message, log_time=ns, publish_time=ns,
                                  sequence=self.counts.get(topic, 0))
        except OSError as exc:       # a full disk, say: drop the unfinished log, say so in one line
            self.abort()
            raise UserError(f"cannot write: {exc.strerror}", file=str(self.path)) from None
        self.counts[topic] = self.counts.get(topic, 0) + 1

    # --- the topics of an episode ----------------------------------------------------------------------------
    def scan(self, t: float, scan: LaserScan, topic: str = TOPIC_SCAN) -> None:
        self.write(topic, msgdefs.LASER_SCAN, t, convert.laser_scan_msg(scan))

    def odom(self, t: float, state: RobotState, topic: str = TOPIC_ODOM) -> None:
        self.write(topic, msgdefs.ODOMETRY, t, convert.odometry_msg(t, state, self.odom_frame, self.base_frame))

    def ground_truth(self, t: float, state: RobotState, topic: str = TOPIC_GROUND_TRUTH) -> None:
        self.write(topic, msgdefs.ODOMETRY, t, convert.odometry_msg(t, state, self.odom_frame, self.base_frame))

    def imu(self, t: float, imu: dict, topic: str = TOPIC_IMU, frame_id: str = "imu_link") -> None:
        self.write(topic, msgdefs.IMU, t, convert.imu_msg(t, imu, frame_id))

    def cmd_vel(self, t: float, u, topic: str = TOPIC_CMD) -> None:
        """The command sent to the robot (u_safe), body twist (vx [m/s], vy [m/s], wz [rad/s])."""
        self.write(topic, msgdefs.TWIST, t, convert.twist_msg(u))

    def cmd_vel_in(self, t: float, u, topic: str = TOPIC_CMD_IN) -> None:
        """The planner's input command u_in, before the CBF filter."""
        self.write(topic, msgdefs.TWIST, t, convert.twist_msg(u))

    def tf(self, t: float, state: RobotState, topic: str = TOPIC_TF) -> None:
        self.write(topic, msgdefs.TF_MESSAGE, t, convert.tf_msg(t, state, self.odom_frame, self.base_frame))

    def behavior(self, t: float, mode: str, topic: str = TOPIC_BEHAVIOR) -> None:
        self.write(topic, msgdefs.STRING, t, convert.string_msg(mode))

    def obstacles(self, t: float, obs: Obstacles, topic: str = TOPIC_OBSTACLES) -> None:
        self.write(topic, msgdefs.MARKER_ARRAY, t, convert.markers_msg(t, obs, self.odom_frame))

    # --- life cycle ------------------------------------------------------------------------------------------
    def close(self) -> None:
        """Finish the log; it appears at its path only now."""
        if self._fh is not None:
            try:
                try:
                    self._w.finish()
                finally:
                    self._fh.close()
                    self._fh = None
            except OSError as exc:
                self._file.discard()
                raise UserError(f"cannot write: {exc.strerror}", file=str(self.path)) from None
            self._file.commit()

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
