"""The wire format (issue 28, item 1): DDS names, CDR byte for byte as rosbags serializes it, QoS, loopback DDS."""
import math
import time

import numpy as np
import pytest

from bigcbf.errors import UserError
from bigcbf.logio import convert, msgdefs
from bigcbf.ros2 import transport, wire
from bigcbf.types import LaserScan, RobotState

_NP = {"float32": np.float32, "float64": np.float64, "uint8": np.uint8, "int8": np.int8, "int16": np.int16,
       "uint16": np.uint16, "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
       "byte": np.uint8, "char": np.uint8, "bool": np.bool_}


def rosbags_msg(msgtype: str, d: dict):
    """The same message as a rosbags object (its classes, numpy arrays for sequences of numbers)."""
    store = msgdefs.typestore()
    kwargs = {}
    for name, (kind, det) in store.fielddefs[msgtype][1]:
        v = d[name]
        if int(kind) == 2:
            v = rosbags_msg(det, v)
        elif int(kind) in (3, 4):
            inner = det[0]
            v = [rosbags_msg(inner[1], x) for x in v] if int(inner[0]) == 2 else np.asarray(v, _NP[inner[1][0]])
        kwargs[name] = v
    return store.types[msgtype](**kwargs)


def _scan():
    r = np.linspace(0.1, 11.0, 360).astype(np.float32)
    r[5:9] = np.inf                                          # beams without a return (REP 117)
    return LaserScan(stamp=12.345678901, angle_min=-math.pi, angle_increment=2 * math.pi / 360, range_min=0.05,
                     range_max=12.0, ranges=r, frame_id="laser", time_increment=1e-5, scan_time=0.1)


STATE = RobotState(1.25, -0.5, 2.9, 0.31, -0.07, 0.42)
COV = np.arange(36, dtype=float).reshape(6, 6) * 1e-4
MESSAGES = {
    msgdefs.LASER_SCAN: lambda: convert.laser_scan_msg(_scan()),
    msgdefs.ODOMETRY: lambda: convert.odometry_msg(3.05, STATE, pose_cov=COV, twist_cov=COV.T),
    msgdefs.IMU: lambda: convert.imu_msg(3.05, {"orientation": (0.9, 0.0, 0.0, 0.43589), "angular_velocity": (0.01, -0.02, 0.4),
                                                "linear_acceleration": (0.3, 0.1, 9.81)},
                                         cov={"angular_velocity": [1e-6] * 9}),
    msgdefs.TF_MESSAGE: lambda: convert.tf_msg(3.05, STATE, extra=[("base_link", "wheel_fl", (0.1, 0.08, 0.03),
                                                                    (0.0, 0.3, 0.0, 0.95))]),
    msgdefs.CLOCK: lambda: convert.clock_msg(1234.5678),
    msgdefs.TWIST: lambda: convert.twist_msg((0.3, -0.1, 0.7)),
    msgdefs.TWIST_STAMPED: lambda: {"header": {"stamp": convert.time_msg(7.25), "frame_id": "base_link"},
                                    "twist": convert.twist_msg((0.3, -0.1, 0.7))},
}


@pytest.mark.parametrize("msgtype", list(MESSAGES))
def test_cdr_is_byte_identical_to_rosbags(msgtype):
    d = MESSAGES[msgtype]()
    ours = wire.encode(wire.from_dict(msgtype, d))
    theirs = bytes(msgdefs.typestore().serialize_cdr(rosbags_msg(msgtype, d), msgtype))
    assert ours[:4] == b"\x00\x01\x00\x00"                  # CDR (XCDR1) little-endian, as ROS 2 sends it
    assert ours == theirs
    back = wire.decode(msgtype, ours)                        # and it reads back as rosbags reads it
    ref = msgdefs.typestore().deserialize_cdr(theirs, msgtype)
    if msgtype == msgdefs.ODOMETRY:
        assert convert.odometry_state(back) == pytest.approx(convert.odometry_state(ref))
    if msgtype == msgdefs.LASER_SCAN:
        np.testing.assert_array_equal(convert.laser_scan(back).ranges, convert.laser_scan(ref).ranges)


def test_names():
    assert wire.dds_topic("/scan") == "rt/scan" and wire.dds_topic("/ns/odom") == "rt/ns/odom"
    assert wire.dds_type(msgdefs.LASER_SCAN) == "sensor_msgs::msg::dds_::LaserScan_"
    assert wire.idl_class(msgdefs.TWIST_STAMPED).__idl_typename__ == "geometry_msgs::msg::dds_::TwistStamped_"
    with pytest.raises(UserError, match="not a ROS 2 topic name"):
        wire.dds_topic("scan")
    with pytest.raises(UserError, match="unknown ROS 2 message type"):
        wire.idl_class("nope_msgs/msg/Nope")


def test_qos_profiles_are_ros2s():
    assert (transport.SENSOR_DATA.reliable, transport.SENSOR_DATA.depth) == (False, 5)     # rmw_qos_profile_sensor_data
    assert (transport.DEFAULT.reliable, transport.DEFAULT.transient_local, transport.DEFAULT.depth) == (True, False, 10)
    assert (transport.LATCHED.reliable, transport.LATCHED.transient_local, transport.LATCHED.depth) == (True, True, 1)
    with pytest.raises(UserError, match="ROS_DOMAIN_ID"):
        transport.check_domain_id(233)


def test_loopback_pub_sub_with_ros2_qos(domain_id):
    """Two participants on loopback: a reliable writer reaches a best-effort (sensor-data) reader, both /cmd_vel
    types share one topic name, a latched message reaches a late reader."""
    a = transport.Node("a", domain_id, loopback=True)
    b = transport.Node("b", domain_id, loopback=True)
    assert "<AllowMulticast>false</AllowMulticast>" in transport.LOOPBACK_CONFIG
    got = []
    b.subscribe("/odom", msgdefs.ODOMETRY, lambda m, t: got.append(("odom", convert.odometry_state(m))),
                transport.SENSOR_DATA)
    b.subscribe("/cmd_vel", msgdefs.TWIST, lambda m, t: got.append(("twist", convert.twist_u(m))), transport.DEFAULT)
    b.subscribe("/cmd_vel", msgdefs.TWIST_STAMPED, lambda m, t: got.append(("stamped", convert.twist_u(m))),
                transport.DEFAULT)
    odom = a.publisher("/odom", msgdefs.ODOMETRY, transport.DEFAULT)
    tw = a.publisher("/cmd_vel", msgdefs.TWIST)
    tws = a.publisher("/cmd_vel", msgdefs.TWIST_STAMPED)
    latched = a.publisher("/goal_pose", msgdefs.POSE_STAMPED, transport.LATCHED)
    latched(convert.pose_stamped_msg(0.0, 4.0, 1.0))
    deadline = time.monotonic() + 5
    while min(a.matched(odom), a.matched(tw), a.matched(tws)) == 0 and time.monotonic() < deadline:
        time.sleep(0.01)
    odom(convert.odometry_msg(1.0, STATE))
    tw(convert.twist_msg((0.1, 0.0, 0.2)))
    tws(MESSAGES[msgdefs.TWIST_STAMPED]())
    while len(got) < 3 and time.monotonic() < deadline:
        b.spin_once(0.1)
    kinds = dict(got)
    assert kinds["odom"] == pytest.approx(STATE)
    assert kinds["twist"] == pytest.approx((0.1, 0.0, 0.2)) and kinds["stamped"] == pytest.approx((0.3, -0.1, 0.7))
    goals = []
    b.subscribe("/goal_pose", msgdefs.POSE_STAMPED, lambda m, t: goals.append(m.pose.position.x), transport.LATCHED)
    while not goals and time.monotonic() < deadline:
        b.spin_once(0.1)
    assert goals == [4.0]
    a.close()
    b.close()
