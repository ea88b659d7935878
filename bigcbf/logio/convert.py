"""Our types <-> ROS 2 messages (plain dicts for writing, attribute objects as rosbags decodes them for reading).

Frames follow REP 105 (``odom`` world frame, ``base_link`` body frame). Times are seconds (float) in our types and
``builtin_interfaces/Time`` (sec, nanosec) in messages.

Tracked obstacles as ``visualization_msgs/MarkerArray`` (lossless, so that logs can be read back into
:class:`bigcbf.types.Obstacles`): the array starts with one DELETEALL marker (viewers drop the previous
frame's markers), then per obstacle

- a CYLINDER in namespace ``obstacles`` (marker id = track id) or ``walls`` (wall points, id = running index,
  track id -1 on reading): position = estimated center, diameter = 2 r (a wall point, r = 0, is drawn 4 cm
  wide and carries its true radius in ``text``), ``text`` = "static r=<r>" or "dynamic r=<r>";
- an ARROW ``<ns>/velocity`` from the center to center + v * 1 s, when v is not zero;
- a flat SPHERE ``<ns>/covariance``, the 1-sigma ellipse of the 2x2 position covariance (axes 2 sigma_1 and
  2 sigma_2, yaw of the major axis), when the covariance is not zero.
"""
from __future__ import annotations

import math

import numpy as np

from ..types import LaserScan, Obstacles, RobotState

#: MarkerArray layout (see the module docstring)
MARKER_HEIGHT_M = 0.5
WALL_POINT_DRAW_DIAMETER_M = 0.04
NS_TRACKED, NS_WALLS = "obstacles", "walls"
ARROW, CYLINDER, SPHERE = 0, 3, 2
ADD, DELETEALL = 0, 3
_STATIC_RGBA = (0.55, 0.55, 0.55, 0.8)
_DYNAMIC_RGBA = (1.0, 0.45, 0.1, 0.8)
_WALL_RGBA = (0.3, 0.3, 0.3, 0.6)
_VEL_RGBA = (0.1, 0.4, 1.0, 0.9)
_COV_RGBA = (1.0, 0.85, 0.0, 0.35)


# --- time and rotation ---------------------------------------------------------------------------------------
def time_msg(t: float) -> dict:
    """Seconds -> builtin_interfaces/Time (sec, nanosec), rounded to the nanosecond."""
    ns = to_ns(t)
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def to_ns(t: float) -> int:
    return int(round(float(t) * 1e9))


def stamp_s(stamp) -> float:
    """builtin_interfaces/Time (ROS 1 or 2, as decoded by rosbags) -> seconds."""
    return stamp.sec + 1e-9 * stamp.nanosec


def yaw_quaternion(yaw: float) -> dict:
    """A rotation about z by ``yaw`` [rad] as a geometry_msgs/Quaternion (x, y, z, w)."""
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def quaternion_yaw(x: float, y: float, z: float, w: float) -> float:
    """Yaw [rad] of a quaternion (ZYX convention, as tf2::getYaw)."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _vec3(v) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _header(t: float, frame_id: str) -> dict:
    return {"stamp": time_msg(t), "frame_id": frame_id}


# --- messages ------------------------------------------------------------------------------------------------
def twist_msg(u) -> dict:
    """Body twist (vx, vy, wz) -> geometry_msgs/Twist."""
    u = np.asarray(u, float)
    return {"linear": _vec3((u[0], u[1], 0.0)), "angular": _vec3((0.0, 0.0, u[2]))}


def odometry_msg(t: float, s: RobotState, frame_id: str = "odom", child_frame_id: str = "base_link",
                 pose_cov=None, twist_cov=None) -> dict:
    """RobotState -> nav_msgs/Odometry: pose in ``frame_id``, twist in ``child_frame_id`` (REP 105). Covariances:
    6x6 row-major (x, y, z, rot x, rot y, rot z), zero unless given (exact: the ground truth; the robot's
    odometry gets them from its noise models, ``bigcbf.logio.covariance``)."""
    return {
        "header": _header(t, frame_id), "child_frame_id": child_frame_id,
        "pose": {"pose": {"position": _vec3((s.px, s.py, 0.0)), "orientation": yaw_quaternion(s.theta)},
                 "covariance": _cov36(pose_cov)},
        "twist": {"twist": {"linear": _vec3((s.vx, s.vy, 0.0)), "angular": _vec3((0.0, 0.0, s.wz))},
                  "covariance": _cov36(twist_cov)},
    }


def _cov36(cov) -> list[float]:
    return [0.0] * 36 if cov is None else np.asarray(cov, float).reshape(36).tolist()


def laser_scan_msg(scan: LaserScan) -> dict:
    """LaserScan -> sensor_msgs/LaserScan (beams without a return stay +inf, REP 117)."""
    return {
        "header": _header(scan.stamp, scan.frame_id),
        "angle_min": float(scan.angle_min), "angle_max": float(scan.angle_max),
        "angle_increment": float(scan.angle_increment), "time_increment": float(scan.time_increment),
        "scan_time": float(scan.scan_time), "range_min": float(scan.range_min), "range_max": float(scan.range_max),
        "ranges": np.asarray(scan.ranges, np.float32).tolist(), "intensities": [],
    }


def imu_msg(t: float, imu: dict, frame_id: str = "imu_link", cov: dict | None = None) -> dict:
    """SimWorld.imu() dict (orientation (w, x, y, z), angular_velocity, linear_acceleration) -> sensor_msgs/Imu.

    ``cov``: the three 3x3 row-major covariances by name (``orientation``, ``angular_velocity``,
    ``linear_acceleration``; :meth:`bigcbf.logio.covariance.SensorNoise.imu_covariances`), zero unless given. An
    orientation covariance whose element 0 is -1 says there is no orientation estimate (REP 145): the message
    then carries the identity quaternion (ROS 2's default), not the dict's orientation."""
    cov = cov or {}
    oc = [float(v) for v in cov.get("orientation", [0.0] * 9)]
    w, x, y, z = (1.0, 0.0, 0.0, 0.0) if oc[0] == -1.0 else (float(v) for v in imu["orientation"])
    return {"header": _header(t, frame_id),
            "orientation": {"x": x, "y": y, "z": z, "w": w}, "orientation_covariance": oc,
            "angular_velocity": _vec3(imu["angular_velocity"]),
            "angular_velocity_covariance": [float(v) for v in cov.get("angular_velocity", [0.0] * 9)],
            "linear_acceleration": _vec3(imu["linear_acceleration"]),
            "linear_acceleration_covariance": [float(v) for v in cov.get("linear_acceleration", [0.0] * 9)]}


def tf_msg(t: float, s: RobotState, parent: str = "odom", child: str = "base_link", extra=()) -> dict:
    """The planar transform parent -> child at pose s, as tf2_msgs/TFMessage; ``extra``: more transforms of the
    same instant, [(parent, child, (x, y, z), quaternion (x, y, z, w)), ...] (the wheels' joints)."""
    return {"transforms": [{"header": _header(t, parent), "child_frame_id": child,
                            "transform": {"translation": _vec3((s.px, s.py, 0.0)),
                                          "rotation": yaw_quaternion(s.theta)}}]
            + [_transform(t, p, c, xyz, q) for p, c, xyz, q in extra]}


def _transform(t: float, parent: str, child: str, xyz, quat_xyzw) -> dict:
    return {"header": _header(t, parent), "child_frame_id": child,
            "transform": {"translation": _vec3(xyz), "rotation": dict(zip("xyzw", map(float, quat_xyzw)))}}


def string_msg(text: str) -> dict:
    return {"data": str(text)}


def clock_msg(t: float) -> dict:
    """rosgraph_msgs/Clock: the simulation time (what /clock carries when ``use_sim_time`` is on)."""
    return {"clock": time_msg(t)}


def static_tf_msg(t: float, transforms) -> dict:
    """tf2_msgs/TFMessage of fixed transforms: ``transforms`` = [(parent, child, (x, y, z), yaw), ...]."""
    return {"transforms": [{"header": _header(t, parent), "child_frame_id": child,
                            "transform": {"translation": _vec3(xyz), "rotation": yaw_quaternion(yaw)}}
                           for parent, child, xyz, yaw in transforms]}


def pose_stamped_msg(t: float, x: float, y: float, yaw: float = 0.0, frame_id: str = "odom") -> dict:
    """geometry_msgs/PoseStamped of a planar pose (e.g. the goal, as Nav2's /goal_pose)."""
    return {"header": _header(t, frame_id),
            "pose": {"position": _vec3((x, y, 0.0)), "orientation": yaw_quaternion(yaw)}}


def path_msg(t: float, points_xy, frame_id: str = "odom") -> dict:
    """nav_msgs/Path through 2-D points (K, 2), each pose facing the next point (the last one keeps the
    previous heading), as Nav2's /plan."""
    pts = np.asarray(points_xy, float).reshape(-1, 2)
    d = np.diff(pts, axis=0)
    yaw = np.arctan2(d[:, 1], d[:, 0]) if len(d) else np.zeros(0)
    yaw = np.concatenate([yaw, yaw[-1:] if len(yaw) else [0.0]])
    return {"header": _header(t, frame_id),
            "poses": [pose_stamped_msg(t, float(x), float(y), float(a), frame_id) for (x, y), a in zip(pts, yaw)]}


def _cov6(cov2) -> list[float]:
    """A 2x2 covariance of (x, y) placed in the 6x6 (x, y, z, rot x, rot y, rot z) row-major layout."""
    c = np.zeros((6, 6))
    c[:2, :2] = np.asarray(cov2, float)
    return c.ravel().tolist()


def tracked_obstacles_msg(t: float, obs: Obstacles, frame_id: str = "odom") -> dict:
    """Obstacles -> bigcbf_msgs/TrackedObstacleArray (msgdefs.CUSTOM_TYPES): ids, radius, static flag, centre with
    the tracker's position covariance, velocity."""
    items = []
    for k in range(len(obs)):
        p, v = obs.p[k], obs.v[k]
        items.append({"id": int(obs.ids[k]), "is_static": bool(obs.static[k]), "radius": float(obs.r[k]),
                      "pose": {"pose": {"position": _vec3((p[0], p[1], 0.0)), "orientation": yaw_quaternion(0.0)},
                               "covariance": _cov6(obs.cov[k])},
                      "twist": {"twist": {"linear": _vec3((v[0], v[1], 0.0)), "angular": _vec3((0.0, 0.0, 0.0))},
                                "covariance": [0.0] * 36}})
    return {"header": _header(t, frame_id), "obstacles": items}


LINE_STRIP, TEXT_VIEW_FACING = 4, 9
_RING_RGBA = (1.0, 0.75, 0.0, 0.9)
_PATH_RGBA = {True: (0.1, 0.95, 0.95, 1.0), False: (0.85, 0.85, 0.85, 0.6)}
_REJECTED_RGBA = (0.95, 0.35, 0.35, 0.6)


def _circle(xy, radius: float, z: float, n: int = 48) -> list[tuple[float, float, float]]:
    a = np.linspace(0.0, 2 * np.pi, n + 1)
    return [(float(xy[0] + radius * math.cos(x)), float(xy[1] + radius * math.sin(x)), z) for x in a]


def inflated_radius_markers(t: float, obs: Obstacles, D, frame_id: str = "odom") -> dict:
    """The CBF's inflated radii D_i of eq:shared_barrier (20) as visualization_msgs/MarkerArray: a DELETEALL, then per
    tracked obstacle a LINE_STRIP circle of radius D_i (namespace ``D``, id = track id) and its track id as text
    (namespace ``id``). Wall points (no track) are left out."""
    markers = [_marker(t, frame_id, "", 0, LINE_STRIP, action=DELETEALL)]
    D = np.asarray(D, float)
    if len(D) != len(obs):
        return {"markers": markers}
    for k in range(len(obs)):
        tid = int(obs.ids[k])
        if tid < 0:
            continue
        markers.append(_marker(t, frame_id, "D", tid, LINE_STRIP, scale=(0.02, 0.0, 0.0), rgba=_RING_RGBA,
                               points=_circle(obs.p[k], float(D[k]), 0.02), text=f"D={float(D[k]):.3f}"))
        markers.append(_marker(t, frame_id, "id", tid, TEXT_VIEW_FACING, obs.p[k], MARKER_HEIGHT_M + 0.25,
                               scale=(0.0, 0.0, 0.2), rgba=(1.0, 1.0, 1.0, 1.0), text=f"#{tid}"))
    return {"markers": markers}


def imagination_markers(t: float, modes, paths, accepted, selected: str | None, frame_id: str = "odom",
                        available=None) -> dict:
    """BIG-CBF's imagined paths of one selection (eq:behavior_rollout (12)) as visualization_msgs/MarkerArray: a
    DELETEALL, then one LINE_STRIP per available behavior (namespace = its name; selected cyan, accepted grey, rejected
    red)."""
    markers = [_marker(t, frame_id, "", 0, LINE_STRIP, action=DELETEALL)]
    for b, mode in enumerate(modes):
        if available is not None and not available[b]:
            continue
        sel = mode == selected
        rgba = _PATH_RGBA[True] if sel else (_PATH_RGBA[False] if accepted[b] else _REJECTED_RGBA)
        pts = [(float(x), float(y), 0.03) for x, y in np.asarray(paths[b], float).reshape(-1, 2)]
        markers.append(_marker(t, frame_id, mode, b, LINE_STRIP, scale=(0.04 if sel else 0.015, 0.0, 0.0),
                               rgba=rgba, points=pts, text=mode))
    return {"markers": markers}


def _marker(t, frame_id, ns, mid, mtype, pose_xy=(0.0, 0.0), z=0.0, yaw=0.0, scale=(0.0, 0.0, 0.0), rgba=(0, 0, 0, 0),
            points=(), text="", action=ADD) -> dict:
    return {"header": _header(t, frame_id), "ns": ns, "id": int(mid), "type": mtype, "action": action,
            "pose": {"position": _vec3((pose_xy[0], pose_xy[1], z)), "orientation": yaw_quaternion(yaw)},
            "scale": _vec3(scale), "color": dict(zip("rgba", map(float, rgba))),
            "lifetime": {"sec": 0, "nanosec": 0}, "frame_locked": False,
            "points": [_vec3((p[0], p[1], p[2])) for p in points], "colors": [], "text": text,
            "mesh_resource": "", "mesh_use_embedded_materials": False}


def _cov_ellipse(cov: np.ndarray) -> tuple[float, float, float]:
    """(sigma_major, sigma_minor, yaw of the major axis) of a symmetric 2x2 covariance."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    vals = np.maximum(vals, 0.0)
    major = vecs[:, 1]
    return math.sqrt(vals[1]), math.sqrt(vals[0]), math.atan2(major[1], major[0])


def markers_msg(t: float, obs: Obstacles, frame_id: str = "odom") -> dict:
    """Obstacles -> visualization_msgs/MarkerArray (layout in the module docstring)."""
    markers = [_marker(t, frame_id, "", 0, CYLINDER, action=DELETEALL)]
    wall_k = 0
    for k in range(len(obs)):
        tid = int(obs.ids[k])
        if tid >= 0:
            ns, mid = NS_TRACKED, tid
        else:
            ns, mid = NS_WALLS, wall_k
            wall_k += 1
        p, v, r = obs.p[k], obs.v[k], float(obs.r[k])
        static = bool(obs.static[k])
        diam = 2 * r if r > 0 else WALL_POINT_DRAW_DIAMETER_M
        rgba = _WALL_RGBA if tid < 0 else (_STATIC_RGBA if static else _DYNAMIC_RGBA)
        markers.append(_marker(t, frame_id, ns, mid, CYLINDER, p, MARKER_HEIGHT_M / 2, 0.0,
                               (diam, diam, MARKER_HEIGHT_M), rgba, text=f"{'static' if static else 'dynamic'} r={r!r}"))
        if np.any(v != 0):
            markers.append(_marker(t, frame_id, f"{ns}/velocity", mid, ARROW, scale=(0.03, 0.06, 0.08), rgba=_VEL_RGBA,
                                   points=[(p[0], p[1], MARKER_HEIGHT_M), (p[0] + v[0], p[1] + v[1], MARKER_HEIGHT_M)]))
        cov = np.asarray(obs.cov[k], float)
        if np.any(cov != 0):
            s1, s2, yaw = _cov_ellipse(cov)
            markers.append(_marker(t, frame_id, f"{ns}/covariance", mid, SPHERE, p, 0.01, yaw,
                                   (2 * s1, 2 * s2, 0.01), _COV_RGBA))
    return {"markers": markers}


# --- reading (objects decoded by rosbags) ----------------------------------------------------------------------
def twist_u(msg) -> tuple[float, float, float]:
    """geometry_msgs/Twist or TwistStamped -> (vx, vy, wz)."""
    tw = msg.twist if hasattr(msg, "twist") else msg
    return (tw.linear.x, tw.linear.y, tw.angular.z)


def odometry_state(msg) -> RobotState:
    """nav_msgs/Odometry -> RobotState (pose in the header frame, twist in the child frame)."""
    p, q, tw = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
    return RobotState(p.x, p.y, quaternion_yaw(q.x, q.y, q.z, q.w), tw.linear.x, tw.linear.y, tw.angular.z)


def laser_scan(msg) -> LaserScan:
    """sensor_msgs/LaserScan -> LaserScan (stamp from the header)."""
    return LaserScan(stamp=stamp_s(msg.header.stamp), angle_min=msg.angle_min, angle_increment=msg.angle_increment,
                     range_min=msg.range_min, range_max=msg.range_max, ranges=np.asarray(msg.ranges, np.float32),
                     frame_id=msg.header.frame_id, time_increment=msg.time_increment, scan_time=msg.scan_time)


def obstacles_from_markers(msg) -> Obstacles:
    """visualization_msgs/MarkerArray written by :func:`markers_msg` -> Obstacles (exact up to float rounding).

    Markers of other namespaces are ignored; a body marker's ``text`` must be as written ("static r=..." or
    "dynamic r=..."), else ValueError.
    """
    bodies: dict[tuple[str, int], dict] = {}
    extra: list = []
    for m in msg.markers:
        if m.action == DELETEALL:
            continue
        if m.ns in (NS_TRACKED, NS_WALLS):
            kind, _, rtxt = m.text.partition(" r=")
            if kind not in ("static", "dynamic") or not rtxt:
                raise ValueError(f"marker {m.ns}/{m.id}: text {m.text!r} is not 'static r=..' or 'dynamic r=..'")
            bodies[(m.ns, m.id)] = {"p": (m.pose.position.x, m.pose.position.y), "r": float(rtxt),
                                    "static": kind == "static", "id": m.id if m.ns == NS_TRACKED else -1,
                                    "v": (0.0, 0.0), "cov": np.zeros((2, 2))}
        else:
            extra.append(m)
    for m in extra:
        base, _, part = m.ns.rpartition("/")
        b = bodies.get((base, m.id))
        if b is None:
            continue
        if part == "velocity" and len(m.points) == 2:
            b["v"] = (m.points[1].x - m.points[0].x, m.points[1].y - m.points[0].y)
        elif part == "covariance":
            q = m.pose.orientation
            yaw = quaternion_yaw(q.x, q.y, q.z, q.w)
            s1, s2 = m.scale.x / 2, m.scale.y / 2
            R = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
            b["cov"] = R @ np.diag([s1 * s1, s2 * s2]) @ R.T
    if not bodies:
        return Obstacles.empty()
    bs = list(bodies.values())
    return Obstacles(np.array([b["p"] for b in bs], float), np.array([b["v"] for b in bs], float),
                     np.array([b["cov"] for b in bs], float), np.array([b["r"] for b in bs], float),
                     np.array([b["static"] for b in bs], bool), np.array([b["id"] for b in bs], int))
