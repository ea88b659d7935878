"""Round trip: what LogWriter writes reads back with the same messages (rosbags, and mcap-ros2's own decoder)."""
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from bigcbf.logio import LogWriter, open_log, read_series
from bigcbf.logio import convert
from bigcbf.logio.episode_log import EpisodeLogger
from bigcbf.types import LaserScan, Obstacles, RobotState

OBS = Obstacles.from_lists(
    p=[[1.0, 2.0], [3.0, -1.5], [0.5, 0.25], [4.0, 4.0]],
    v=[[0.6, -0.2], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0]],
    r=[0.3, 0.2, 0.0, 0.0],
    cov=[[[0.04, 0.01], [0.01, 0.02]], [[0.01, 0.0], [0.0, 0.01]], [[0.0, 0.0], [0.0, 0.0]],
         [[0.002, 0.0], [0.0, 0.001]]],
    static=[False, True, True, True], ids=[7, 2, -1, -1])


def _scan(t):
    r = np.linspace(0.5, 7.5, 360).astype(np.float32)
    r[::7] = np.inf
    return LaserScan(t, -math.pi, 2 * math.pi / 360, 0.12, 8.0, r, frame_id="laser")


def _write(path: Path, n=30):
    with LogWriter(path, metadata={"purpose": "test"}) as w:
        for k in range(n):
            t = 0.05 * k
            s = RobotState(0.1 * k, -0.05 * k, 0.02 * k - 0.3, 0.4, -0.1, 0.2)
            w.cmd_vel(t, (0.5, -0.1, 0.3 + 0.01 * k))
            w.cmd_vel_in(t, (0.6, 0.0, 0.3))
            w.odom(t, s)
            w.ground_truth(t, RobotState(s.px + 0.01, s.py, s.theta, s.vx, s.vy, s.wz))
            w.tf(t, s)
            w.imu(t, {"orientation": (math.cos(0.1), 0.0, 0.0, math.sin(0.1)), "angular_velocity": (0.0, 0.0, 0.2),
                      "linear_acceleration": (0.1, 0.0, 9.81)})
            w.behavior(t, "SIDE-L" if k % 2 else "GOAL")
            if k % 2 == 0:
                w.scan(t, _scan(t))
                w.obstacles(t, OBS)


def test_time_and_yaw_conversions_by_hand():
    assert convert.time_msg(1.5) == {"sec": 1, "nanosec": 500_000_000}
    assert convert.time_msg(112.539) == {"sec": 112, "nanosec": 539_000_000}
    q = convert.yaw_quaternion(math.pi / 2)          # rotation of 90 deg about z: (0, 0, sin 45, cos 45)
    assert q["z"] == pytest.approx(math.sqrt(0.5)) and q["w"] == pytest.approx(math.sqrt(0.5))
    for yaw in (-3.0, -0.4, 0.0, 1.2, 3.1):
        q = convert.yaw_quaternion(yaw)
        assert convert.quaternion_yaw(q["x"], q["y"], q["z"], q["w"]) == pytest.approx(yaw)


def test_roundtrip_with_rosbags(tmp_path):
    path = tmp_path / "episode.mcap"
    _write(path)
    got: dict[str, list] = {}
    with AnyReader([path]) as r:
        types = {c.topic: c.msgtype for c in r.connections}
        for c, t, raw in r.messages():
            got.setdefault(c.topic, []).append((t, r.deserialize(raw, c.msgtype)))
    assert types == {"/cmd_vel": "geometry_msgs/msg/Twist", "/cmd_vel_in": "geometry_msgs/msg/Twist",
                     "/odom": "nav_msgs/msg/Odometry", "/ground_truth/odom": "nav_msgs/msg/Odometry",
                     "/tf": "tf2_msgs/msg/TFMessage", "/imu": "sensor_msgs/msg/Imu",
                     "/behavior": "std_msgs/msg/String", "/scan": "sensor_msgs/msg/LaserScan",
                     "/tracked_obstacles": "visualization_msgs/msg/MarkerArray"}
    assert len(got["/cmd_vel"]) == 30 and len(got["/scan"]) == 15 and len(got["/tracked_obstacles"]) == 15
    t, m = got["/cmd_vel"][4]
    assert t == 200_000_000 and (m.linear.x, m.linear.y, m.angular.z) == (0.5, -0.1, pytest.approx(0.34))
    t, m = got["/odom"][10]
    assert m.header.frame_id == "odom" and m.child_frame_id == "base_link"
    np.testing.assert_allclose(convert.odometry_state(m).as_array(), [1.0, -0.5, -0.1, 0.4, -0.1, 0.2], atol=1e-12)
    assert (m.header.stamp.sec, m.header.stamp.nanosec) == (0, 500_000_000)
    tf = got["/tf"][10][1].transforms[0]
    assert (tf.header.frame_id, tf.child_frame_id, tf.transform.translation.x) == ("odom", "base_link", 1.0)
    imu = got["/imu"][0][1]
    assert imu.orientation.w == pytest.approx(math.cos(0.1)) and imu.linear_acceleration.z == 9.81
    assert [m.data for _, m in got["/behavior"][:3]] == ["GOAL", "SIDE-L", "GOAL"]
    scan = convert.laser_scan(got["/scan"][1][1])
    ref = _scan(0.1)
    assert scan.stamp == pytest.approx(0.1) and scan.frame_id == "laser"
    np.testing.assert_array_equal(scan.ranges, ref.ranges)          # float32 exactly, inf preserved
    assert scan.angle_max == pytest.approx(ref.angle_max)
    markers = got["/tracked_obstacles"][0][1]
    assert markers.markers[0].action == convert.DELETEALL
    back = convert.obstacles_from_markers(markers)
    np.testing.assert_allclose(back.p, OBS.p)
    np.testing.assert_allclose(back.v, OBS.v)
    np.testing.assert_allclose(back.cov, OBS.cov, atol=1e-12)
    np.testing.assert_allclose(back.r, OBS.r)
    np.testing.assert_array_equal(back.static, OBS.static)
    np.testing.assert_array_equal(back.ids, OBS.ids)


def test_other_readers_decode_our_schemas(tmp_path):
    """mcap-ros2's own decoder (what Foxglove-like tools do) needs the complete schemas to decode."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    path = tmp_path / "episode.mcap"
    _write(path, n=4)
    seen = {}
    with open(path, "rb") as fh:
        for _, channel, _, msg in make_reader(fh, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            seen.setdefault(channel.topic, msg)
    assert set(seen) >= {"/scan", "/tracked_obstacles", "/odom", "/imu", "/tf", "/behavior", "/cmd_vel"}
    assert seen["/tracked_obstacles"].markers[1].ns == "obstacles"
    assert seen["/odom"].pose.pose.position.x == 0.0


def test_read_series_and_our_reader(tmp_path):
    path = tmp_path / "episode.mcap"
    _write(path)
    with open_log(path) as log:
        assert log.format == "mcap" and not log.recovered
        d = read_series(log, cmd="/cmd_vel", odom="/odom", scan="/scan")
    np.testing.assert_allclose(d.cmd.t, 0.05 * np.arange(30))
    np.testing.assert_allclose(d.cmd.u[:, 2], 0.3 + 0.01 * np.arange(30))
    np.testing.assert_allclose(d.odom.pose[:, 0], 0.1 * np.arange(30))
    np.testing.assert_allclose(d.odom.stamp, d.odom.t)
    assert len(d.scan.t) == 15


def test_ros2_sqlite_bag_folder_even_named_dot_bag(tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from bigcbf.logio.msgdefs import typestore
    ts = typestore()
    Twist = ts.types["geometry_msgs/msg/Twist"]
    Vector3 = ts.types["geometry_msgs/msg/Vector3"]
    for name in ("plain", "looks_like_ros1.bag"):
        folder = tmp_path / name
        with Writer(folder, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
            conn = w.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=ts)
            for k in range(5):
                msg = Twist(linear=Vector3(x=0.1 * k, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.0))
                w.write(conn, 1_000_000_000 + k * 50_000_000, ts.serialize_cdr(msg, "geometry_msgs/msg/Twist"))
        with open_log(folder) as log:
            assert log.format == "ros2"
            d = read_series(log, cmd="/cmd_vel")
        np.testing.assert_allclose(d.cmd.t, 1.0 + 0.05 * np.arange(5))
        np.testing.assert_allclose(d.cmd.u[:, 0], 0.1 * np.arange(5))


class _FakeWorld:
    def imu(self):
        return {"orientation": (1.0, 0.0, 0.0, 0.0), "angular_velocity": (0.0, 0.0, 0.0),
                "linear_acceleration": (0.0, 0.0, 9.81)}


def test_episode_logger_records_every_topic(tmp_path):
    ep = SimpleNamespace(observers=[], world=_FakeWorld(), method="big-cbf", seed=3,
                         scenario=SimpleNamespace(name="corridor"))
    path = tmp_path / "run.mcap"
    logger = EpisodeLogger(ep, path)
    assert ep.observers == [logger]
    scans = [_scan(0.0), _scan(0.1)]
    for k in range(4):                                   # 4 control steps, a new scan every second step
        t = 0.05 * k
        s = RobotState(0.05 * k, 0.0, 0.0, 1.0, 0.0, 0.0)
        rec = SimpleNamespace(t=t, state=s, true_state=s, obstacles=OBS, u_in=np.array([1.0, 0, 0]),
                              u_safe=np.array([0.8, 0, 0]), mode="GOAL", scan=scans[k // 2])
        for obs in ep.observers:
            obs(rec)
    logger.close()
    with open_log(path) as log:
        counts = {k: v.count for k, v in log.topics.items()}
        assert counts == {"/clock": 4, "/cmd_vel": 4, "/cmd_vel_in": 4, "/odom": 4, "/tf": 4, "/ground_truth/odom": 4,
                          "/imu": 4, "/behavior": 4, "/scan": 2, "/tracked_obstacles": 2, "/obstacles": 2,
                          "/tf_static": 1}                 # map -> odom, with no sensor frames
        cmds = [m for _, _, m in log.messages(["/cmd_vel", "/cmd_vel_in"])]
    assert [c.linear.x for c in cmds[:2]] == [0.8, 1.0]
