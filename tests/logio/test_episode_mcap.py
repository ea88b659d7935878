"""An episode's MCAP as a Nav2 user opens it in Foxglove or RViz: every channel reads back with rosbags, one TF tree
rooted at map connects every frame a message uses and every link of the URDF on /robot_description, latched topics
carry a transient-local QoS, the time base is the simulation clock, and the messages say what the episode did
(goal, plan, obstacles with covariances, D_i rings, where the pedestrians truly were)."""
import xml.etree.ElementTree as ET
from collections import defaultdict

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from bigcbf.control.behaviors import BEHAVIORS
from bigcbf.episode import Episode
from bigcbf.logio.episode_log import EpisodeLogger
from bigcbf.params.stack import SIMULATION
from bigcbf.scenario import load_scenario

TYPES = {
    "/clock": "rosgraph_msgs/msg/Clock", "/tf_static": "tf2_msgs/msg/TFMessage", "/tf": "tf2_msgs/msg/TFMessage",
    "/robot_description": "std_msgs/msg/String", "/goal_pose": "geometry_msgs/msg/PoseStamped",
    "/scan": "sensor_msgs/msg/LaserScan", "/odom": "nav_msgs/msg/Odometry", "/imu": "sensor_msgs/msg/Imu",
    "/cmd_vel": "geometry_msgs/msg/Twist", "/cmd_vel_in": "geometry_msgs/msg/Twist",
    "/ground_truth/odom": "nav_msgs/msg/Odometry", "/behavior": "std_msgs/msg/String", "/plan": "nav_msgs/msg/Path",
    "/plan/candidates": "visualization_msgs/msg/MarkerArray", "/tracked_obstacles": "visualization_msgs/msg/MarkerArray",
    "/obstacles": "bigcbf_msgs/msg/TrackedObstacleArray", "/cbf/inflated_radius": "visualization_msgs/msg/MarkerArray",
    "/map": "nav_msgs/msg/OccupancyGrid", "/scene/markers": "visualization_msgs/msg/MarkerArray",
    "/pedestrians/markers": "visualization_msgs/msg/MarkerArray",
}
LATCHED = ("/tf_static", "/robot_description", "/goal_pose", "/map", "/scene/markers")
WHEELS = ("fl_wheel", "fr_wheel", "rl_wheel", "rr_wheel")


@pytest.fixture(scope="module")
def episode_log(tmp_path_factory):
    """4 s of the single person crossing with BIG-CBF (the pedestrian is tracked from about 1 s on)."""
    path = tmp_path_factory.mktemp("mcap") / "episode.mcap"
    sc = load_scenario("single_person_crossing", 0)
    ep = Episode(sc, "big-cbf", 0, SIMULATION, time_limit_s=4.0)
    logger = EpisodeLogger(ep, path)
    truth = {}                                         # where the pedestrians were at each control step

    def record(rec):
        truth[round(rec.t, 6)] = np.array(ep.walkers.positions(), float)
    ep.observers.append(record)
    res = ep.run()
    logger.close()
    msgs = defaultdict(list)
    with AnyReader([path]) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        for con, t, raw in reader.messages():
            msgs[con.topic].append((t * 1e-9, reader.deserialize(raw, con.msgtype)))
    return path, sc, res, types, msgs, truth


def _header_frames(msg, out: set) -> None:
    """Every frame_id of every header inside a message (arrays of markers, poses, obstacles included)."""
    if hasattr(msg, "frame_id") and hasattr(msg, "stamp"):
        out.add(msg.frame_id)
    if hasattr(msg, "child_frame_id"):
        out.add(msg.child_frame_id)
    for name in getattr(msg, "__dataclass_fields__", ()):
        if name == "texture":                    # a Marker's unused texture image (no frame, no data)
            continue
        v = getattr(msg, name)
        for x in (v if isinstance(v, list) else [v]):
            if hasattr(x, "__dataclass_fields__"):
                _header_frames(x, out)


def test_every_channel_reads_back_with_its_type(episode_log):
    _, _, res, types, msgs, _ = episode_log
    assert types == TYPES
    n_ctrl = res.control_steps
    for topic in ("/clock", "/tf", "/odom", "/cmd_vel", "/cmd_vel_in", "/ground_truth/odom", "/imu", "/behavior",
                  "/pedestrians/markers"):
        assert len(msgs[topic]) == n_ctrl, topic
    for topic in LATCHED:
        assert len(msgs[topic]) == 1 and msgs[topic][0][0] == 0.0, topic
    assert len(msgs["/scan"]) == len(msgs["/obstacles"]) == len(msgs["/cbf/inflated_radius"]) == 40   # 10 Hz
    assert 4 <= len(msgs["/plan"]) == len(msgs["/plan/candidates"]) <= 9          # one per selection (2 Hz)


def test_tf_tree_connects_every_frame_used(episode_log):
    _, _, _, _, msgs, _ = episode_log
    parent = {}
    for topic in ("/tf", "/tf_static"):
        for _, m in msgs[topic]:
            for tr in m.transforms:
                assert parent.setdefault(tr.child_frame_id, tr.header.frame_id) == tr.header.frame_id  # a tree
    used = set()
    for topic, items in msgs.items():
        for _, m in items:
            _header_frames(m, used)
    assert used == {"map", "odom", "base_link", "laser", "imu_link", *(f"{w}_link" for w in WHEELS)}
    for frame in used:                                # every frame reaches the root map through the tree
        f, hops = frame, 0
        while f != "map":
            f, hops = parent[f], hops + 1
            assert hops < 5
    static = {tr.child_frame_id: tr for tr in msgs["/tf_static"][0][1].transforms}
    m2o = static["odom"]                              # the simulator's world is where odom starts: identity
    assert m2o.header.frame_id == "map" and m2o.transform.rotation.w == 1.0
    assert (m2o.transform.translation.x, m2o.transform.translation.y, m2o.transform.translation.z) == (0, 0, 0)
    assert static["laser"].transform.translation.x == pytest.approx(0.0435)          # the model's LiDAR site
    assert static["laser"].transform.translation.z == pytest.approx(0.192, abs=1e-3)


def test_time_base_is_the_simulation_clock(episode_log):
    _, _, res, _, msgs, _ = episode_log
    clock = [(t, m.clock.sec + 1e-9 * m.clock.nanosec) for t, m in msgs["/clock"]]
    assert clock[0] == (0.0, 0.0)
    assert all(t == pytest.approx(c, abs=1e-9) for t, c in clock)
    assert np.all(np.diff([c for _, c in clock]) == pytest.approx(SIMULATION.T_C_s))
    assert clock[-1][1] <= res.sim_time_s
    for t, m in msgs["/odom"]:
        assert m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec == pytest.approx(t, abs=1e-9)


def test_latched_topics_are_transient_local_and_describe_the_robot(episode_log):
    path, _, _, _, msgs, _ = episode_log
    with open(path, "rb") as fh:
        channels = {c.topic: c for c in make_reader(fh).get_summary().channels.values()}
    for topic in LATCHED:
        qos = channels[topic].metadata["offered_qos_profiles"]
        assert "durability: 1" in qos and "reliability: 1" in qos, topic
    for topic in ("/tf", "/pedestrians/markers", "/scan"):
        assert "offered_qos_profiles" not in channels[topic].metadata, topic


def test_robot_description_is_a_urdf_whose_links_are_the_tf_frames(episode_log):
    """The URDF's links are the frames of /tf and /tf_static under base_link, its joints are the transforms (fixed:
    /tf_static at the joint's origin; continuous: /tf with the wheel turned about the joint's axis), and the wheels
    have the MJCF's rolling radius."""
    import mujoco

    from bigcbf.sim.kinematics import MecanumKinematics
    from bigcbf.sim.scene import ROBOT_XML
    _, _, _, _, msgs, _ = episode_log
    root = ET.fromstring(msgs["/robot_description"][0][1].data)
    assert root.tag == "robot" and root.get("name") == "rosmaster_x3"
    links = {el.get("name") for el in root.findall("link")}
    joints = {el.get("name"): el for el in root.findall("joint")}
    tf_frames = {tr.child_frame_id: tr.header.frame_id for topic in ("/tf", "/tf_static")
                 for _, m in msgs[topic] for tr in m.transforms}
    assert links == {f for f, p in tf_frames.items() if p != "map" and p != "odom"} | {"base_link"}
    assert links == {"base_link", "laser", "imu_link", *(f"{w}_link" for w in WHEELS)}
    static = {tr.child_frame_id: tr.transform for tr in msgs["/tf_static"][0][1].transforms}
    for name, j in joints.items():                       # every joint is one transform of the log, parent to child
        parent, child = j.find("parent").get("link"), j.find("child").get("link")
        assert tf_frames[child] == parent == "base_link", name
        xyz = [float(v) for v in j.find("origin").get("xyz").split()]
        if j.get("type") == "fixed":
            tr = static[child].translation
            assert (tr.x, tr.y, tr.z) == pytest.approx(xyz, abs=1e-6), name
        else:
            assert j.get("type") == "continuous" and name in WHEELS and j.find("axis").get("xyz") == "0 1 0"
            tr = [m for _, msg in msgs["/tf"][5:6] for m in msg.transforms if m.child_frame_id == child][0]
            assert (tr.transform.translation.x, tr.transform.translation.y, tr.transform.translation.z) == \
                pytest.approx(xyz, abs=1e-6)
            q = tr.transform.rotation                      # a turn about the axle (y) only
            assert q.x == pytest.approx(0, abs=1e-9) and q.z == pytest.approx(0, abs=1e-9)
            assert q.y ** 2 + q.w ** 2 == pytest.approx(1.0)
    # the wheels' turning shows in /tf: the front left wheel's angle changes while the robot drives
    angles = [2 * np.arctan2(m.y, m.w) for _, msg in msgs["/tf"] for tr in msg.transforms
              if tr.child_frame_id == "fl_wheel_link" for m in [tr.transform.rotation]]
    assert np.ptp(np.unwrap(angles)) > 1.0
    # wheel radius: the MJCF's rollers (centre distance from the axle + capsule radius), the kinematics' too
    m = mujoco.MjModel.from_xml_path(str(ROBOT_XML))
    wheel = m.body("fl_wheel").id
    rollers = [np.hypot(m.body_pos[b][0], m.body_pos[b][2]) + m.geom_size[g][0] for b in range(m.nbody)
               if m.body_parentid[b] == wheel for g in range(m.ngeom) if m.geom_bodyid[g] == b]
    assert len(rollers) == 12
    for w in WHEELS:
        link = root.find(f"link[@name='{w}_link']")
        radii = [float(c.get("radius")) for c in link.findall("collision/geometry/cylinder")]
        assert radii == [pytest.approx(np.mean(rollers), abs=1e-6)]
        assert radii == [pytest.approx(MecanumKinematics().rolling_radius_m, abs=1e-6)]
    # the body: the chassis' box and the LiDAR's cylinder at their MJCF sizes, raised to the floor-level base_link
    base = root.find("link[@name='base_link']")
    boxes = [c.get("size") for c in base.findall("collision/geometry/box")]
    assert "0.3 0.124 0.05" in boxes and "0.3 0.2 0.07" in boxes
    lidar = [v for v in base.findall("visual") if v.find("geometry/cylinder") is not None][0]
    z = float(lidar.find("origin").get("xyz").split()[2])
    assert z == pytest.approx(m.body("base_link").pos[2] + m.geom("lidar").pos[2], abs=1e-6)
    assert float(lidar.find("geometry/cylinder").get("radius")) == pytest.approx(m.geom("lidar").size[0])
    assert all(root.find(f"material[@name='{v.find('material').get('name')}']/color") is not None
               for v in root.iter("visual"))


def test_true_pedestrians_and_the_empty_scene(episode_log):
    """/pedestrians/markers: where the simulator had the pedestrian at each step, at its radius; /map: the scene
    (no walls here) known and free, with an unknown margin; /scene/markers: only its DELETEALL."""
    _, sc, _, _, msgs, truth = episode_log
    for t, arr in msgs["/pedestrians/markers"]:
        assert arr.markers[0].action == 3 and len(arr.markers) == 2
        m = arr.markers[1]
        assert m.header.frame_id == "map" and m.ns == "pedestrians" and m.text == "crosser"
        assert (m.pose.position.x, m.pose.position.y) == pytest.approx(tuple(truth[round(t, 6)][0]), abs=1e-9)
        assert m.scale.x == pytest.approx(2 * sc.pedestrians[0].radius_m)
    grid = msgs["/map"][0][1]
    data = np.array(grid.data).reshape(grid.info.height, grid.info.width)
    assert grid.header.frame_id == "map" and grid.info.resolution == pytest.approx(0.05)
    assert set(np.unique(data)) == {-1, 0}
    assert np.all(data[0] == -1) and np.all(data[:, -1] == -1)             # the unknown margin
    ox, oy = grid.info.origin.position.x, grid.info.origin.position.y
    for x, y in (sc.robot.start[:2], sc.robot.goal):                        # start and goal are known free
        assert data[int((y - oy) / 0.05), int((x - ox) / 0.05)] == 0
    assert [m.action for m in msgs["/scene/markers"][0][1].markers] == [3]


def test_goal_plan_obstacles_and_rings_say_what_the_episode_did(episode_log):
    _, sc, _, _, msgs, _ = episode_log
    g = msgs["/goal_pose"][0][1].pose.position
    assert (g.x, g.y) == pytest.approx(tuple(sc.robot.goal))
    odom = {round(t, 6): m.pose.pose.position for t, m in msgs["/odom"]}
    for t, path in msgs["/plan"]:                      # each plan starts where the robot was (the imagination's p_0)
        p0, o = path.poses[0].pose.position, odom[round(t, 6)]
        assert path.header.frame_id == "odom" and len(path.poses) == SIMULATION.N + 1
        assert np.hypot(p0.x - o.x, p0.y - o.y) < 1e-6
    for _, cand in msgs["/plan/candidates"]:
        names = [m.ns for m in cand.markers[1:]]
        assert set(names) <= set(BEHAVIORS) and len(names) >= 5
    tracked = [(t, o) for t, arr in msgs["/obstacles"] for o in arr.obstacles if o.id >= 0]
    assert tracked, "the pedestrian is tracked"
    for _, o in tracked:
        cov = np.array(o.pose.covariance).reshape(6, 6)
        assert cov[0, 0] > 0 and cov[1, 1] > 0 and cov[0, 1] == cov[1, 0] and np.all(cov[2:] == 0)
    walls = [o for _, arr in msgs["/obstacles"] for o in arr.obstacles if o.id < 0]
    assert all(o.radius == 0.0 for o in walls)
    rings = [m for _, arr in msgs["/cbf/inflated_radius"] for m in arr.markers if m.ns == "D"]
    assert len(rings) == len(tracked)
    for m in rings:                                    # a circle of radius D_i > r_R + r_i around the track
        pts = np.array([(p.x, p.y) for p in m.points])
        radius = np.hypot(*(pts - pts[:-1].mean(axis=0)[None]).T)        # (the last point closes the ring)
        D = float(m.text.split("=")[1])
        assert np.allclose(radius, D, atol=2e-3) and D > SIMULATION.uncertainty.r_robot_m + 0.1


def test_odometry_and_imu_carry_the_robot_profiles_covariances(episode_log):
    """The scenario's robot (x3_sim): /odom's twist covariance is its encoders' and gyro's at the 10 ms readings the
    stack gets (bigcbf.logio.covariance), the pose covariance grows from zero (dead reckoning), /imu has no
    orientation (REP 145) and the gyro's yaw-rate variance; /ground_truth/odom is exact."""
    from bigcbf.logio.covariance import SensorNoise
    from bigcbf.sim.kinematics import MecanumKinematics
    _, sc, _, _, msgs, _ = episode_log
    noise = SensorNoise.from_profile(sc.robot_profile, MecanumKinematics())
    assert noise.encoder_counts_per_rev == 1320 and noise.gyro_bias_max == 8.7e-4
    expect = noise.twist_covariance(0.01, 0.01)
    yaw_var = [m.pose.covariance[35] for _, m in msgs["/odom"]]
    assert yaw_var[0] == 0.0 and np.all(np.diff(yaw_var) >= 0) and yaw_var[-1] > 0
    for t, m in msgs["/odom"][1:]:
        assert np.array(m.twist.covariance).reshape(6, 6) == pytest.approx(expect, rel=1e-9, abs=1e-18), t
    for _, m in msgs["/imu"][1:]:
        assert m.orientation_covariance[0] == -1.0 and m.orientation.w == 1.0
        assert m.angular_velocity_covariance[8] == pytest.approx(expect[5, 5], rel=1e-9)
    for _, m in msgs["/ground_truth/odom"]:
        assert not np.any(m.pose.covariance) and not np.any(m.twist.covariance)
