"""Contacts classified by who moved into whom, and near misses with people (issue 23).

A distance barrier cannot keep a holonomic robot clear of a person who closes on it faster than the robot can
move away (at the barrier's boundary the CBF condition needs v_max >= the obstacle's closing speed), so a contact
with a fast walker may not be the robot's doing. Following the standard notion for moving obstacles (passive
safety: the robot is stopped at contact) and HuNavSim's evaluator (robot-on-person and person-on-robot collisions
counted apart), every contact is classified at the first physics block in contact:

- the geometry: the robot's true collision outline (``sim/truth.py``'s :class:`~bigcbf.sim.truth.Outline`, a
  rectangle at the true pose) against the body it touches (walls and boxes: rectangles; cylinders and pedestrians:
  circles). The contact normal ``n`` is the unit vector from the other body to the robot along the nearest points
  (when they overlap: along the shortest translation that separates them), the penetration is minus their signed
  distance.
- the velocities just before contact (at the start of that physics block, so that the contact's own impulse has not
  yet changed them): the robot's true planar velocity at its contact point, ``v_R + w_R x r`` (for a robot that only
  translates, ``v_R``; a robot swinging a corner into a body moves into it), and the other body's true velocity
  ``v_O`` (0 for static geometry; a pedestrian's from the simulation).
- the robot's radial speed ``max(0, -v_R . n)`` (towards the body) and the other body's ``max(0, v_O . n)``
  (towards the robot).
- at fault: the robot's radial speed exceeds ``v_freeze`` (the stack's ``v_freeze_mps``, 0.05 m/s); passive
  otherwise (the robot was stopped, or moving away or along, when it was hit).

Near misses, at every control step, against the pedestrians (:func:`near_miss`): the constant-velocity time to
contact (the true clearance to a pedestrian's body divided by the rate at which the centres close, inf when they do
not close) and the smallest clearance to a pedestrian's body, whose time below ``PERSONAL_SPACE_M`` (0.5 m) is the
episode's personal-space intrusion.

No MuJoCo import here: the episode (bigcbf/episode.py) passes its model and data, poses and velocities.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .truth import Outline

#: a pedestrian's body closer than this to the robot's outline intrudes on its personal space [m] (the "personal"
#: zone of proxemics, 0.45-1.2 m between people, at its near end)
PERSONAL_SPACE_M = 0.5
#: kinds of body a contact can be with
KINDS = ("wall", "box", "cylinder", "pedestrian")


@dataclass(frozen=True)
class Body:
    """The body the robot touches: ``kind`` (one of :data:`KINDS`), its ``name`` (``walls[2]``, ``boxes[0]``,
    ``cylinders[1]``, or the pedestrian's name), its shape (a rectangle: centre, half sizes, yaw; a circle: centre,
    radius in ``half[0]``) and its planar velocity [m/s]."""
    kind: str
    name: str
    centre: tuple[float, float]
    half: tuple[float, float]
    yaw: float = 0.0
    velocity: tuple[float, float] = (0.0, 0.0)

    @property
    def circle(self) -> bool:
        return self.kind in ("cylinder", "pedestrian")


@dataclass(frozen=True)
class Contact:
    """A classified contact (module docstring); :meth:`as_dict` is the episode's ``contact`` field."""
    kind: str
    name: str
    t_s: float
    normal: tuple[float, float]          # unit, from the other body to the robot
    point: tuple[float, float]           # the robot's contact point (world) [m]
    penetration_m: float
    robot_speed_mps: float               # the robot's planar speed at its contact point
    robot_radial_mps: float              # towards the body (>= 0)
    other_radial_mps: float              # the other body's towards the robot (>= 0)
    at_fault: bool

    def as_dict(self) -> dict:
        d = asdict(self)
        d["normal"], d["point"] = list(self.normal), list(self.point)
        return d


def _robot_frame(outline: Outline, pose) -> tuple[np.ndarray, float, float]:
    """The outline's centre (world) and the pose's cos, sin."""
    x, y, yaw = (float(v) for v in pose)
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([x + c * outline.cx - s * outline.cy, y + s * outline.cx + c * outline.cy]), c, s


def _point_box(q: np.ndarray, h: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """A point q in a box's frame (half sizes h): (signed distance, the box's nearest surface point, the outward unit
    normal of the box there)."""
    inside = np.all(np.abs(q) <= h)
    if not inside:
        p = np.clip(q, -h, h)
        d = q - p
        return float(np.linalg.norm(d)), p, d / np.linalg.norm(d)
    depth = h - np.abs(q)                               # to each pair of faces
    k = int(np.argmin(depth))
    n = np.zeros(2)
    n[k] = 1.0 if q[k] >= 0 else -1.0
    p = q.copy()
    p[k] = n[k] * h[k]
    return -float(depth[k]), p, n


def _corners(c: np.ndarray, h, cs: float, sn: float) -> np.ndarray:
    sx, sy = np.array([1.0, -1.0, -1.0, 1.0]) * h[0], np.array([1.0, 1.0, -1.0, -1.0]) * h[1]
    return np.stack([c[0] + cs * sx - sn * sy, c[1] + sn * sx + cs * sy], 1)


def contact_geometry(outline: Outline, pose, body: Body) -> tuple[float, np.ndarray, np.ndarray]:
    """(signed distance [m], unit normal from the body to the robot, the robot's contact point) between the
    robot's outline at ``pose`` (x, y, yaw) and ``body`` (module docstring)."""
    rc, cs, sn = _robot_frame(outline, pose)
    rh = np.array([outline.half_x, outline.half_y])
    R = np.array([[cs, -sn], [sn, cs]])
    bc = np.asarray(body.centre, float)
    if body.circle:
        q = R.T @ (bc - rc)                             # the circle's centre in the outline's frame
        d, p, n_out = _point_box(q, rh)                 # n_out: out of the robot, towards the circle
        return d - float(body.half[0]), R @ p + rc, -(R @ n_out)
    bh = np.asarray(body.half, float)
    bcs, bsn = math.cos(body.yaw), math.sin(body.yaw)
    B = np.array([[bcs, -bsn], [bsn, bcs]])
    ra, rb = _corners(rc, rh, cs, sn), _corners(bc, bh, bcs, bsn)
    # separating axes: the overlap along each edge normal; all positive -> they overlap by the smallest
    axes = [R[:, 0], R[:, 1], B[:, 0], B[:, 1]]
    overlaps = []
    for u in axes:
        pa, pb = ra @ u, rb @ u
        overlaps.append(0.5 * (pa.max() - pa.min() + pb.max() - pb.min()) - abs(0.5 * (pa.max() + pa.min())
                                                                                 - 0.5 * (pb.max() + pb.min())))
    if min(overlaps) > 0:
        k = int(np.argmin(overlaps))
        u = axes[k] if float(axes[k] @ (rc - bc)) >= 0 else -axes[k]
        # the robot's deepest point along -u: its corner(s) farthest into the body
        proj = ra @ u
        point = ra[np.isclose(proj, proj.min(), atol=1e-9)].mean(axis=0)
        return -float(overlaps[k]), point, u
    # apart: the nearest points of two disjoint convex polygons include a corner of one of them
    best = (math.inf, None, None)
    for corner in ra:                                   # the robot's corners against the body
        d, p, n_out = _point_box(B.T @ (corner - bc), bh)
        if d < best[0]:
            best = (d, corner, B @ n_out)               # out of the body, towards the robot
    for corner in rb:                                   # the body's corners against the robot
        d, p, n_out = _point_box(R.T @ (corner - rc), rh)
        if d < best[0]:
            best = (d, R @ p + rc, -(R @ n_out))
    return best[0], best[1], best[2]


def classify(outline: Outline, pose, robot_velocity, robot_yaw_rate: float, body: Body, v_freeze_mps: float,
             t_s: float = 0.0) -> Contact:
    """The contact of the robot's outline at ``pose`` (x, y, yaw) with ``body`` (module docstring).
    ``robot_velocity``: the robot's planar velocity (world frame) [m/s] and ``robot_yaw_rate`` [rad/s] just
    before contact; the body's velocity is its own (``Body.velocity``)."""
    d, point, n = contact_geometry(outline, pose, body)
    r = point - np.asarray(pose[:2], float)
    v = np.asarray(robot_velocity, float) + robot_yaw_rate * np.array([-r[1], r[0]])   # v + w x r
    robot_radial = max(0.0, -float(v @ n))
    other_radial = max(0.0, float(np.asarray(body.velocity, float) @ n))
    return Contact(kind=body.kind, name=body.name, t_s=round(float(t_s), 4),
                   normal=(round(float(n[0]), 6), round(float(n[1]), 6)),
                   point=(round(float(point[0]), 4), round(float(point[1]), 4)),
                   penetration_m=round(max(0.0, -d), 6), robot_speed_mps=round(float(np.hypot(*v)), 6),
                   robot_radial_mps=round(robot_radial, 6), other_radial_mps=round(other_radial, 6),
                   at_fault=bool(robot_radial > v_freeze_mps))


def scene_body(clearance, geom_name: str, ped_names, ped_p, ped_v) -> Body | None:
    """The :class:`Body` a MuJoCo obstacle geom of the scene stands for (``sim/scene.py`` names them ``wall<k>``,
    ``box<k>``, ``cylinder<k>``, ``ped_<name>``), from a :class:`bigcbf.sim.truth.Clearance` (walls then boxes as
    its rectangles, cylinders as its circles) and the pedestrians' names, positions and velocities now; None for
    another geom."""
    c = clearance
    n_walls = sum(1 for x in c.names if x.startswith("walls["))
    for prefix, kind in (("wall", "wall"), ("box", "box"), ("cylinder", "cylinder")):
        rest = geom_name[len(prefix):]
        if geom_name.startswith(prefix) and rest.isdigit():
            k = int(rest)
            if kind == "cylinder":
                if k >= len(c.circ_r):
                    return None
                return Body(kind, f"cylinders[{k}]", tuple(map(float, c.circ_c[k])), (float(c.circ_r[k]), 0.0))
            i = k if kind == "wall" else n_walls + k
            if i >= len(c.rect_c):
                return None
            return Body(kind, f"{kind}s[{k}]" if kind == "wall" else f"boxes[{k}]", tuple(map(float, c.rect_c[i])),
                        tuple(map(float, c.rect_h[i])), float(c.rect_yaw[i]))
    if geom_name.startswith("ped_"):
        names = list(ped_names)
        if geom_name[4:] in names:
            i = names.index(geom_name[4:])
            return Body("pedestrian", names[i], tuple(map(float, ped_p[i])), (float(c.ped_r[i]), 0.0), 0.0,
                        tuple(map(float, ped_v[i])))
    return None


def near_miss(clearance, pose, robot_velocity, ped_p, ped_v) -> tuple[float, float]:
    """(time to contact [s], clearance [m]) against the nearest pedestrians now: the smallest over pedestrians of
    the constant-velocity time to contact (the true clearance from the robot's outline to the pedestrian's body,
    over the rate at which robot and pedestrian centres close; inf when none closes; 0 in contact) and the smallest
    clearance to a pedestrian's body (inf without pedestrians). ``clearance``: the episode's
    :class:`bigcbf.sim.truth.Clearance`; ``robot_velocity`` and ``ped_v`` in the world frame [m/s]."""
    ped_p = np.asarray(ped_p, float).reshape(-1, 2)
    if not len(ped_p):
        return math.inf, math.inf
    x, y, yaw = (float(v) for v in pose)
    gaps = clearance.pedestrian_distances(x, y, yaw, ped_p)
    rel = ped_p - (x, y)
    dist = np.maximum(np.hypot(rel[:, 0], rel[:, 1]), 1e-9)
    dv = np.asarray(ped_v, float).reshape(-1, 2) - np.asarray(robot_velocity, float)
    closing = -np.einsum("ij,ij->i", rel, dv) / dist             # > 0: the centres approach
    ttc = np.where(gaps <= 0, 0.0, np.where(closing > 1e-9, np.maximum(gaps, 0.0) / np.maximum(closing, 1e-9),
                                             math.inf))
    return float(ttc.min()), float(gaps.min())


def touched_geoms(model, data, robot_geom: np.ndarray, obstacle_geom: np.ndarray) -> list[str]:
    """The names of the obstacle geoms in contact with the robot now (MuJoCo's contacts; ``robot_geom`` and
    ``obstacle_geom`` the masks of :class:`bigcbf.sim.truth.GroundTruth`), in MuJoCo's order, each once."""
    n = data.ncon
    out: list[str] = []
    for a, b in data.contact.geom[:n]:
        for mine, other in ((a, b), (b, a)):
            if robot_geom[mine] and obstacle_geom[other]:
                name = model.geom(int(other)).name
                if name not in out:
                    out.append(name)
    return out


def first_contact(truth, model, data, pose, robot_velocity, robot_yaw_rate: float, ped_names, ped_p, ped_v,
                  v_freeze_mps: float, t_s: float) -> Contact | None:
    """The episode's first contact classified (:func:`classify`): of the bodies MuJoCo reports touching the robot,
    the one it penetrates deepest. ``truth``: the episode's :class:`bigcbf.sim.truth.GroundTruth`; the robot's and
    the pedestrians' velocities (world frame) from just before the physics block that made the contact."""
    best = None
    for name in touched_geoms(model, data, truth.robot_geom, truth.obstacle_geom):
        body = scene_body(truth.distance, name, ped_names, ped_p, ped_v)
        if body is None:
            continue
        c = classify(truth.outline, pose, robot_velocity, robot_yaw_rate, body, v_freeze_mps, t_s)
        if best is None or c.penetration_m > best.penetration_m:
            best = c
    return best
