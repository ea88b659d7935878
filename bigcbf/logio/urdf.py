"""The robot as URDF, derived from its compiled MJCF, for /robot_description (Foxglove's and RViz's robot model).

Viewers draw URDF, not MJCF, so the log carries a URDF made from the ``mujoco.MjModel`` the simulation runs:

- ``base_link`` is the log's base_link: the robot's frame on the floor (planar odometry puts it at z = 0). The
  MJCF body of that name rides at its rest height above the floor (its free joint's ``qpos0``), so its geoms are
  raised by that height here, as the sensor frames of /tf_static are (``SimWorld.sensor_frames``).
- each child body with one hinge joint (the four wheels) is a link ``<body>_link`` on a ``continuous`` joint named
  as the MJCF joint (axis and origin from the model); the rollers, capsules that URDF cannot draw, are summed up
  as the wheel's envelope cylinder: radius = the rollers' centre distance from the axle + their radius (the
  rolling radius, 0.0425 m), width = their extent along the axle;
- the sensor frames (``laser``, ``imu_link``) are links on fixed joints at the poses /tf_static gives them;
- geoms: boxes, cylinders and spheres map to URDF primitives (sizes: MuJoCo half sizes -> URDF full sizes, a
  cylinder's axis is z in both); the visual geoms (group 3) are ``<visual>`` with their colours, the geoms that
  collide (contype or conaffinity set) are ``<collision>``. Other geoms (the rollers, the battery's mass) are left
  out. No ``<inertial>``: the description is for viewers, the physics stays in the MJCF.

The TF frames of an episode log are exactly the URDF's links (plus ``map`` and ``odom``): /tf_static carries the
fixed joints, /tf the wheels' joint angles (as robot_state_publisher would) and odom -> base_link.
"""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

#: MuJoCo's mjtGeom / mjtJoint values used here (the model is duck-typed; no import of mujoco needed)
_SPHERE, _CAPSULE, _CYLINDER, _BOX = 2, 3, 5, 6
_FREE, _HINGE = 0, 3
VISUAL_GROUP = 3
WHEEL_RGBA = (0.15, 0.15, 0.15, 1.0)


@dataclass(frozen=True)
class Wheel:
    """A continuous joint of the URDF: ``joint`` (the MJCF joint's name), its child ``link``, the joint origin in
    ``base_link`` (``xyz``, quaternion ``quat`` (w, x, y, z)), its ``axis`` in the child frame, the ``qposadr`` of
    its angle in ``MjData.qpos``, and the wheel's envelope ``radius`` and ``width`` [m]."""
    joint: str
    link: str
    xyz: tuple[float, float, float]
    quat: tuple[float, float, float, float]
    axis: tuple[float, float, float]
    qposadr: int
    radius: float
    width: float


@dataclass(frozen=True)
class RobotDescription:
    """The URDF ``text`` and what the log's /tf needs to animate it (``wheels``)."""
    text: str
    base_link: str
    wheels: tuple[Wheel, ...]
    fixed: dict            # sensor frame -> (x, y, z, yaw) in base_link

    @property
    def links(self) -> list[str]:
        return [self.base_link, *(w.link for w in self.wheels), *self.fixed]

    def wheel_transforms(self, qpos) -> list[tuple[str, str, tuple, tuple]]:
        """(parent, child, xyz, quaternion (x, y, z, w)) of each wheel at the joint angles in ``qpos``."""
        out = []
        for w in self.wheels:
            a = float(qpos[w.qposadr])
            s = math.sin(a / 2)
            q = quat_mul(w.quat, (math.cos(a / 2), w.axis[0] * s, w.axis[1] * s, w.axis[2] * s))
            out.append((self.base_link, w.link, w.xyz, (q[1], q[2], q[3], q[0])))
        return out


def quat_mul(a, b) -> tuple[float, float, float, float]:
    """Hamilton product of quaternions (w, x, y, z)."""
    aw, ax, ay, az = (float(v) for v in a)
    bw, bx, by, bz = (float(v) for v in b)
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def quat_rpy(q) -> tuple[float, float, float]:
    """Quaternion (w, x, y, z) -> URDF's fixed-axis roll, pitch, yaw [rad]."""
    w, x, y, z = (float(v) for v in q)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def _fmt(values) -> str:
    return " ".join(f"{float(v):.6g}" if abs(float(v)) > 1e-12 else "0" for v in values)


def _origin(parent: ET.Element, xyz, quat=(1.0, 0.0, 0.0, 0.0)) -> None:
    ET.SubElement(parent, "origin", xyz=_fmt(xyz), rpy=_fmt(quat_rpy(quat)))


def _geometry(parent: ET.Element, gtype: int, size) -> bool:
    g = ET.Element("geometry")
    if gtype == _BOX:
        ET.SubElement(g, "box", size=_fmt(2 * np.asarray(size[:3], float)))
    elif gtype == _CYLINDER:
        ET.SubElement(g, "cylinder", radius=_fmt([size[0]]), length=_fmt([2 * size[1]]))
    elif gtype == _SPHERE:
        ET.SubElement(g, "sphere", radius=_fmt([size[0]]))
    else:
        return False
    parent.append(g)
    return True


class _Materials:
    """URDF materials by colour, declared once at the robot level."""

    def __init__(self, robot: ET.Element):
        self.robot, self.names = robot, {}

    def name(self, rgba) -> str:
        key = tuple(round(float(v), 4) for v in rgba)
        if key not in self.names:
            self.names[key] = f"color{len(self.names)}"
            m = ET.SubElement(self.robot, "material", name=self.names[key])
            ET.SubElement(m, "color", rgba=_fmt(key))
        return self.names[key]


def _add_geoms(model, body: int, link: ET.Element, materials: _Materials, lift: float) -> None:
    for g in range(model.ngeom):
        if model.geom_bodyid[g] != body:
            continue
        gtype = int(model.geom_type[g])
        xyz = np.array(model.geom_pos[g], float) + (0.0, 0.0, lift)
        if int(model.geom_group[g]) == VISUAL_GROUP:
            el = ET.Element("visual")
            _origin(el, xyz, model.geom_quat[g])
            if _geometry(el, gtype, model.geom_size[g]):
                ET.SubElement(el, "material", name=materials.name(model.geom_rgba[g]))
                link.append(el)
        if model.geom_contype[g] or model.geom_conaffinity[g]:
            el = ET.Element("collision")
            _origin(el, xyz, model.geom_quat[g])
            if _geometry(el, gtype, model.geom_size[g]):
                link.append(el)


def _envelope(model, wheel_body: int, axis: np.ndarray) -> tuple[float, float]:
    """(radius, width) of the wheel's rollers: the capsules of its child bodies, in the wheel's frame."""
    radii, extents = [], []
    for b in range(model.nbody):
        if model.body_parentid[b] != wheel_body:
            continue
        c = np.array(model.body_pos[b], float)
        for g in range(model.ngeom):
            if model.geom_bodyid[g] != b or int(model.geom_type[g]) != _CAPSULE:
                continue
            r = float(model.geom_size[g][0])
            radii.append(float(np.linalg.norm(c - axis * (c @ axis))) + r)      # centre's distance from the axle
            # the capsule's segment (its local z, half length size[1]) projected on the axle
            w, x, y, z = (float(v) for v in model.geom_quat[g])
            seg_z = np.array([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)])
            mid = c + _rotate(model.body_quat[b], np.array(model.geom_pos[g], float))
            half = float(model.geom_size[g][1]) * abs(float(_rotate(model.body_quat[b], seg_z) @ axis))
            extents.append(abs(float(mid @ axis)) + half + r)
    if not radii:
        raise ValueError(f"wheel body {model.body(wheel_body).name!r} has no roller capsules")
    return float(np.mean(radii)), 2 * max(extents)


def _rotate(q, v: np.ndarray) -> np.ndarray:
    w, x, y, z = (float(a) for a in q)
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    return R @ v


def robot_description(model, sensor_frames: dict, *, base: str = "base_link",
                      name: str = "rosmaster_x3") -> RobotDescription:
    """The URDF of the robot whose root body is ``base`` in the compiled ``model`` (layout in the module
    docstring). ``sensor_frames``: frame -> (x, y, z, yaw) in the floor-level base_link (``SimWorld.sensor_frames``,
    what /tf_static publishes).

    Length: one URDF tree built in document order (the base link, each wheel's link and joint, the sensor frames, then
    the materials moved to the front)."""
    base_id = next((i for i in range(model.nbody) if model.body(i).name == base), None)
    if base_id is None:
        raise ValueError(f"the model has no body {base!r}")
    lift = float(model.body_pos[base_id][2])
    for j in range(model.body_jntadr[base_id], model.body_jntadr[base_id] + model.body_jntnum[base_id]):
        if int(model.jnt_type[j]) == _FREE:
            lift = float(model.qpos0[model.jnt_qposadr[j] + 2])        # the rest height, as sensor_frames uses
    robot = ET.Element("robot", name=name)
    materials = _Materials(robot)
    base_el = ET.SubElement(robot, "link", name=base)
    _add_geoms(model, base_id, base_el, materials, lift)
    wheels = []
    for b in range(model.nbody):
        if model.body_parentid[b] != base_id or model.body_jntnum[b] != 1:
            continue
        j = int(model.body_jntadr[b])
        if int(model.jnt_type[j]) != _HINGE:
            continue
        axis = np.array(model.jnt_axis[j], float)
        radius, width = _envelope(model, b, axis)
        link_name = f"{model.body(b).name}_link"
        xyz = tuple(float(v) for v in np.array(model.body_pos[b], float) + (0.0, 0.0, lift))
        quat = tuple(float(v) for v in model.body_quat[b])
        link = ET.SubElement(robot, "link", name=link_name)
        _add_geoms(model, b, link, materials, 0.0)
        # the rollers' envelope: a cylinder about the axle (URDF cylinders lie along z: turn z onto the axis)
        zx = np.cross((0.0, 0.0, 1.0), axis)
        turn = ((1.0, 0.0, 0.0, 0.0) if np.linalg.norm(zx) < 1e-9 else
                (math.cos(math.acos(axis[2]) / 2), *(zx / np.linalg.norm(zx) * math.sin(math.acos(axis[2]) / 2))))
        for tag in ("visual", "collision"):
            el = ET.SubElement(link, tag)
            _origin(el, (0.0, 0.0, 0.0), turn)
            _geometry(el, _CYLINDER, (radius, width / 2))
            if tag == "visual":
                ET.SubElement(el, "material", name=materials.name(WHEEL_RGBA))
        joint = ET.SubElement(robot, "joint", name=model.joint(j).name, type="continuous")
        _origin(joint, xyz, quat)
        ET.SubElement(joint, "parent", link=base)
        ET.SubElement(joint, "child", link=link_name)
        ET.SubElement(joint, "axis", xyz=_fmt(axis))
        wheels.append(Wheel(model.joint(j).name, link_name, xyz, quat, tuple(float(v) for v in axis),
                            int(model.jnt_qposadr[j]), radius, width))
    fixed = {}
    for frame, (x, y, z, yaw) in sensor_frames.items():
        ET.SubElement(robot, "link", name=frame)
        joint = ET.SubElement(robot, "joint", name=f"{frame}_joint", type="fixed")
        ET.SubElement(joint, "origin", xyz=_fmt((x, y, z)), rpy=_fmt((0.0, 0.0, yaw)))
        ET.SubElement(joint, "parent", link=base)
        ET.SubElement(joint, "child", link=frame)
        fixed[frame] = (float(x), float(y), float(z), float(yaw))
    mats = [el for el in robot if el.tag == "material"]         # declared before the links that use them
    for el in mats:
        robot.remove(el)
    robot[0:0] = mats
    ET.indent(robot)
    text = ('<?xml version="1.0"?>\n<!-- generated by bigcbf.logio.urdf from the MJCF the simulation runs -->\n'
            + ET.tostring(robot, encoding="unicode") + "\n")
    return RobotDescription(text, base, tuple(wheels), fixed)
