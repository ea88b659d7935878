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
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
PATH = "nav_msgs/msg/Path"
CLOCK = "rosgraph_msgs/msg/Clock"
OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
TRACKED_OBSTACLE = "bigcbf_msgs/msg/TrackedObstacle"
TRACKED_OBSTACLE_ARRAY = "bigcbf_msgs/msg/TrackedObstacleArray"

#: Our own message types, built from standard ones (ROS has no standard message for tracked obstacles with a
#: covariance). Their definitions travel inside every MCAP file (the schema), so Foxglove, ros2 bag and rosbags
#: decode them without a package.
CUSTOM_TYPES = {
    TRACKED_OBSTACLE: """# One obstacle estimate of the stack (bigcbf.types.Obstacles), in the header frame of its array.
int32 id                                    # track id; -1 for a wall point (not a tracked entity)
bool is_static                              # the static/dynamic classification of the tracker
float64 radius                              # physical radius r_i [m] (0 for a wall point)
geometry_msgs/PoseWithCovariance pose       # centre (z = 0); covariance rows/cols x, y: the tracker's 2x2 Sigma_i
geometry_msgs/TwistWithCovariance twist     # velocity (linear x, y); covariance not estimated (zero)
""",
    TRACKED_OBSTACLE_ARRAY: """std_msgs/Header header
bigcbf_msgs/TrackedObstacle[] obstacles
""",
}


@lru_cache(maxsize=1)
def typestore():
    """The ROS 2 Humble type store of rosbags (also the fallback for bags without embedded definitions)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    store = get_typestore(Stores.ROS2_HUMBLE)
    for name, text in CUSTOM_TYPES.items():
        store.register(get_types_from_msg(text, name))
    return store


@lru_cache(maxsize=None)
def schema_text(msgtype: str) -> str:
    """The ``ros2msg`` schema text of ``msgtype`` (e.g. "nav_msgs/msg/Odometry"), dependencies included."""
    text, _ = typestore().generate_msgdef(msgtype, ros_version=2)
    return text
