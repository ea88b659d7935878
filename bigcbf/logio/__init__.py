"""Robot logs in and out: ROS 1 bags, ROS 2 bags and MCAP in (rosbags); ROS 2 MCAP out (mcap-ros2-support).

Log I/O lives in bigcbf (not in the twin) because the simulator records its own runs in the robot's format.
No MuJoCo here.
"""
from .reader import (LogData, OdomSeries, RobotLog, StampSeries, TopicInfo, TwistSeries, describe_topics, open_log,
                     read_series)
from .topics import CMD, IMU, ODOM, SCAN, Role, find_topic
from .writer import LogWriter

__all__ = ["LogWriter", "RobotLog", "open_log", "read_series", "LogData", "TwistSeries", "OdomSeries", "StampSeries",
           "TopicInfo", "describe_topics", "find_topic", "Role", "CMD", "ODOM", "SCAN", "IMU"]
