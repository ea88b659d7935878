"""ROS 2 message definitions for the MCAP schemas we write (from rosbags' ROS 2 Humble type store).

A ROS 2 MCAP schema (encoding ``ros2msg``) holds the full concatenated definition: the type's own fields, then
each dependency after a line of 80 '=' and ``MSG: pkg/Type``. Without the dependencies other readers (Foxglove,
ros2 bag, rosbags) cannot decode the messages, so we generate them from a complete type store rather than by hand.
"""
from __future__ import annotations

from functools import lru_cache

#: The message types our logs use (ROS 2 names).
LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
IMU = "sensor_msgs/msg/Imu"
TWIST = "geometry_msgs/msg/Twist"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
STRING = "std_msgs/msg/String"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"


@lru_cache(maxsize=1)
def typestore():
    """The ROS 2 Humble type store of rosbags (also the fallback for bags without embedded definitions)."""
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS2_HUMBLE)


@lru_cache(maxsize=None)
def schema_text(msgtype: str) -> str:
    """The ``ros2msg`` schema text of ``msgtype`` (e.g. "nav_msgs/msg/Odometry"), dependencies included."""
    text, _ = typestore().generate_msgdef(msgtype, ros_version=2)
    return text
