"""Ground truth from the simulator: true clearances, physical contact, and obstacles for the truth mode.

Clearance and contact use ONE shape. The robot is its collision outline: the planar extent of its body's collision
geoms (bumper, chassis, LiDAR; the bumper, 0.30 x 0.20 m, contains the others' footprints), a rectangle at the
true pose (``outline_from_model`` reads it from the MJCF). Obstacles are what MuJoCo collides with: walls and boxes
are oriented rectangles, cylinders and pedestrians circles (a pedestrian is a capsule whose lower sphere is centred
on the floor, so that at every height the robot's body reaches it has its full radius; see ``sim/scene.py``), and
every obstacle is at least ``MIN_OBSTACLE_HEIGHT_M`` tall (the scenario loader checks it), so that it reaches the
bumper. The clearance is the signed distance between the outline and the nearest obstacle: the gap when apart, minus
the penetration depth when they overlap. MuJoCo creates a contact exactly when two collision geoms overlap (margin
0), so a negative clearance is a contact and a contact has a clearance <= 0, up to the physics' own tolerance
(``tests/test_truth.py`` measures that relation while the robot drives into every kind of obstacle at several
headings).

The paper's safety requirement (Eq. ``eq:true_safety_requirement``) is stated for a disc robot of radius r_R; the
controller keeps that disc (r_R = 0.15 m), which the outline's corners overhang by 0.03 m (the base clearance d0
covers them). The clearance metric measures the real body instead, so that it agrees with the collision flag.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from ..control.jit import kernel
from ..perception.ground_truth import ground_truth_obstacles, rectangle_segments
from ..types import Obstacles
from .scene import OBSTACLE_CONTACT, SceneSpec

#: obstacles must be at least this tall [m]: the robot's bumper spans 0.0075-0.078 m above the floor, so a taller
#: obstacle meets the body wherever the planar outlines overlap (a lower one could pass under it)
MIN_OBSTACLE_HEIGHT_M = 0.10


@dataclass(frozen=True)
class Outline:
    """The robot's collision outline in base_link: a rectangle of half sizes (half_x, half_y) [m] centred at
    (cx, cy) [m]."""
    half_x: float
    half_y: float
    cx: float = 0.0
    cy: float = 0.0

    @property
    def inner_radius(self) -> float:
        """Radius of the largest disc about base_link's origin inside the outline [m]."""
        return min(self.half_x - abs(self.cx), self.half_y - abs(self.cy))

    @property
    def outer_radius(self) -> float:
        """Radius of the smallest disc about base_link's origin containing the outline [m]."""
        return math.hypot(self.half_x + abs(self.cx), self.half_y + abs(self.cy))


def outline_from_model(model: mujoco.MjModel, body: str = "base_link") -> Outline:
    """The collision outline of ``body``'s subtree (the geoms that collide with obstacles, see sim/scene.py): the
    bounding rectangle of their planar footprints, which must itself be one of them (a box aligned with the body),
    so that the rectangle IS the outline and not an over-estimate of it."""
    base = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)
    geoms = [g for g in range(model.ngeom) if model.body_rootid[model.geom_bodyid[g]] == base
             and model.geom_contype[g] & OBSTACLE_CONTACT["conaffinity"]]
    boxes = []
    lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
    for g in geoms:
        if model.geom_bodyid[g] != base or not np.allclose(model.geom_quat[g], (1, 0, 0, 0)):
            raise ValueError(f"{body}: collision geom {g} is not an axis-aligned geom of the body itself")
        t, size, pos = int(model.geom_type[g]), model.geom_size[g], model.geom_pos[g][:2]
        if t == int(mujoco.mjtGeom.mjGEOM_BOX):
            half = size[:2]
            boxes.append((pos - half, pos + half))
        elif t in (int(mujoco.mjtGeom.mjGEOM_CYLINDER), int(mujoco.mjtGeom.mjGEOM_CAPSULE),
                   int(mujoco.mjtGeom.mjGEOM_SPHERE)):
            half = np.array([size[0], size[0]])
        else:
            raise ValueError(f"{body}: collision geom {g} of type {t} has no planar outline here")
        lo, hi = np.minimum(lo, pos - half), np.maximum(hi, pos + half)
    if not any(np.allclose(a, lo) and np.allclose(b, hi) for a, b in boxes):
        raise ValueError(f"{body}: no collision box contains the other collision geoms' footprints")
    c, h = (lo + hi) / 2, (hi - lo) / 2
    return Outline(float(h[0]), float(h[1]), float(c[0]), float(c[1]))


def robot_outline(robot: str = "rosmaster_x3") -> Outline:
    """A registered robot's collision outline (the Rosmaster X3's: 0.30 x 0.20 m), from its MJCF (compiled once;
    ``bigcbf.robots.robot``)."""
    from ..robots import robot as registered
    return registered(robot).outline


def _rect_corners(c: np.ndarray, h: np.ndarray, cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    """Corners (N, 4, 2) of rectangles with centres c (N, 2), half sizes h (N, 2) and yaws given by cos, sin (N,)."""
    sx = np.array([1.0, -1.0, -1.0, 1.0])
    sy = np.array([1.0, 1.0, -1.0, -1.0])
    lx, ly = sx[None] * h[:, :1], sy[None] * h[:, 1:]
    return np.stack([c[:, :1] + cos[:, None] * lx - sin[:, None] * ly,
                     c[:, 1:] + sin[:, None] * lx + cos[:, None] * ly], axis=-1)


def point_box_distance(px, py, hx, hy) -> np.ndarray:
    """Signed distance of points (in the frame of a box of half sizes hx, hy) to the box: > 0 outside, < 0 inside
    (minus the depth)."""
    qx, qy = np.abs(px) - hx, np.abs(py) - hy
    return np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0)) + np.minimum(np.maximum(qx, qy), 0.0)


def rect_rect_distance(a_c, a_h, a_yaw: float, b_c: np.ndarray, b_h: np.ndarray, b_cos: np.ndarray,
                       b_sin: np.ndarray) -> np.ndarray:
    """Signed distance (N,) [m] between one rectangle A (centre a_c, half sizes a_h, yaw a_yaw) and N rectangles B
    (centres (N, 2), half sizes (N, 2), yaws as cos, sin (N,)): the gap when apart (the nearest points of two
    disjoint convex polygons include a corner of one of them), minus the penetration depth when they overlap (the
    shortest translation along one of the four edge normals that separates them: the separating-axis theorem)."""
    a_c, a_h = np.asarray(a_c, float), np.asarray(a_h, float)
    ca, sa = math.cos(a_yaw), math.sin(a_yaw)
    n = len(b_c)
    a_corners = _rect_corners(a_c[None], a_h[None], np.array([ca]), np.array([sa]))[0]         # (4, 2)
    b_corners = _rect_corners(b_c, b_h, b_cos, b_sin)                                         # (N, 4, 2)
    d = a_corners[None] - b_c[:, None]                                      # A's corners in each B's frame
    ax = b_cos[:, None] * d[..., 0] + b_sin[:, None] * d[..., 1]
    ay = -b_sin[:, None] * d[..., 0] + b_cos[:, None] * d[..., 1]
    gap_a = point_box_distance(ax, ay, b_h[:, :1], b_h[:, 1:]).min(axis=1)
    e = b_corners - a_c                                                     # B's corners in A's frame
    bx, by = ca * e[..., 0] + sa * e[..., 1], -sa * e[..., 0] + ca * e[..., 1]
    gap_b = point_box_distance(bx, by, a_h[0], a_h[1]).min(axis=1)
    gap = np.minimum(gap_a, gap_b)
    axes = np.stack([np.broadcast_to([ca, sa], (n, 2)), np.broadcast_to([-sa, ca], (n, 2)),
                     np.stack([b_cos, b_sin], 1), np.stack([-b_sin, b_cos], 1)], axis=1)          # (N, 4, 2)
    pa = np.einsum("nkj,ij->nki", axes, a_corners)                                             # (N, 4, 4)
    pb = np.einsum("nkj,nij->nki", axes, b_corners)
    # on each axis, how far one must move along it to separate the two (the half-lengths' sum minus the centres'
    # distance; when one interval holds the other this exceeds their intersection, as a translation must)
    reach = 0.5 * (pa.max(-1) - pa.min(-1) + pb.max(-1) - pb.min(-1))
    overlap = reach - np.abs(0.5 * (pa.max(-1) + pa.min(-1) - pb.max(-1) - pb.min(-1)))       # (N, 4)
    depth = overlap.min(axis=1)
    return np.where(depth > 0, -depth, np.maximum(gap, 0.0))


@kernel
def rect_rect_distance_one(ax: float, ay: float, ac: float, as_: float, ahx: float, ahy: float, bx: float,
                           by: float, bc: float, bs: float, bhx: float, bhy: float) -> float:
    """``rect_rect_distance`` for one pair, in plain floats (the episode measures a few rectangles every 10 ms,
    where numpy's per-call overhead dominated): rectangle A with centre (ax, ay), yaw given by (ac, as_) = (cos,
    sin) and half sizes (ahx, ahy), rectangle B likewise. Centred rectangles project onto a unit axis u as
    intervals of half-length hx |u.e1| + hy |u.e2| about their centres, so their overlap on u is
    r_A + r_B - |u.(c_B - c_A)|. Compiled (``_bounded_kernel`` calls it; float arguments)."""
    dx, dy = bx - ax, by - ay
    depth = math.inf
    for ux, uy in ((ac, as_), (-as_, ac), (bc, bs), (-bs, bc)):
        ra = ahx * abs(ux * ac + uy * as_) + ahy * abs(uy * ac - ux * as_)
        rb = bhx * abs(ux * bc + uy * bs) + bhy * abs(uy * bc - ux * bs)
        overlap = ra + rb - abs(ux * dx + uy * dy)
        if overlap <= 0.0:
            break
        depth = min(depth, overlap)
    else:
        return -depth
    gap = math.inf
    for (cx, cy, c, sn, hx, hy), (ox, oy, oc, osn, ohx, ohy) in (
            ((ax, ay, ac, as_, ahx, ahy), (bx, by, bc, bs, bhx, bhy)),
            ((bx, by, bc, bs, bhx, bhy), (ax, ay, ac, as_, ahx, ahy))):
        for sx, sy in ((1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)):    # corners of one, in the other's frame
            px = cx + c * sx * hx - sn * sy * hy - ox
            py = cy + sn * sx * hx + c * sy * hy - oy
            qx = abs(oc * px + osn * py) - ohx
            qy = abs(oc * py - osn * px) - ohy
            gap = min(gap, math.hypot(max(qx, 0.0), max(qy, 0.0)) + min(max(qx, qy), 0.0))
    return max(gap, 0.0)


_NO_XY, _NO_R = np.zeros((0, 2)), np.zeros(0)


class Clearance:
    """Signed distances between the robot's outline at a pose and a scene's obstacles (module docstring)."""

    def __init__(self, scene: SceneSpec, outline: Outline | None = None):
        self.outline = robot_outline(scene.robot) if outline is None else outline
        rects, names = [], []
        for k, w in enumerate(scene.walls):
            a, b = np.array([w.x0, w.y0]), np.array([w.x1, w.y1])
            L = np.linalg.norm(b - a)
            rects.append(((a + b) / 2, (L / 2 + w.thickness / 2, w.thickness / 2), np.arctan2(*(b - a)[::-1])))
            names.append(f"walls[{k}]")
        for k, o in enumerate(scene.boxes):
            rects.append(((o.x, o.y), (o.half_x, o.half_y), o.yaw))
            names.append(f"boxes[{k}]")
        self.rect_c = np.array([r[0] for r in rects], float).reshape(-1, 2)
        self.rect_h = np.array([r[1] for r in rects], float).reshape(-1, 2)
        self.rect_yaw = np.array([r[2] for r in rects], float)
        self.rect_cos, self.rect_sin = np.cos(self.rect_yaw), np.sin(self.rect_yaw)
        self.circ_c = np.array([(c.x, c.y) for c in scene.cylinders], float).reshape(-1, 2)
        self.circ_r = np.array([c.radius for c in scene.cylinders], float)
        #: the static obstacles' names in the order of ``static_distances`` (e.g. "walls[2]", "cylinders[0]")
        self.names = names + [f"cylinders[{k}]" for k in range(len(scene.cylinders))]
        self.ped_r = np.array([p.radius for p in scene.pedestrians], float)

    def rect_distances(self, p: np.ndarray) -> np.ndarray:
        """Distance from the point p (2,) to each wall and box (0 inside) [m]."""
        d = p - self.rect_c
        lx = self.rect_cos * d[:, 0] + self.rect_sin * d[:, 1]
        ly = -self.rect_sin * d[:, 0] + self.rect_cos * d[:, 1]
        qx = np.maximum(np.abs(lx) - self.rect_h[:, 0], 0)
        qy = np.maximum(np.abs(ly) - self.rect_h[:, 1], 0)
        return np.hypot(qx, qy)

    def _outline_pose(self, x: float, y: float, yaw: float) -> tuple[np.ndarray, np.ndarray]:
        o = self.outline
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([x + c * o.cx - s * o.cy, y + s * o.cx + c * o.cy]), np.array([o.half_x, o.half_y])

    @staticmethod
    def _circles(centre: np.ndarray, half: np.ndarray, yaw: float, c: np.ndarray, r: np.ndarray) -> np.ndarray:
        cs, sn = math.cos(yaw), math.sin(yaw)
        d = c - centre
        lx, ly = cs * d[:, 0] + sn * d[:, 1], -sn * d[:, 0] + cs * d[:, 1]
        return point_box_distance(lx, ly, half[0], half[1]) - r

    def static_distances(self, x: float, y: float, yaw: float) -> np.ndarray:
        """Signed distance [m] from the outline at (x, y, yaw) to each wall, box and cylinder (``names``' order)."""
        centre, half = self._outline_pose(x, y, yaw)
        rect = (rect_rect_distance(centre, half, yaw, self.rect_c, self.rect_h, self.rect_cos, self.rect_sin)
                if len(self.rect_c) else np.zeros(0))
        return np.concatenate([rect, self._circles(centre, half, yaw, self.circ_c, self.circ_r)])

    def pedestrian_distances(self, x: float, y: float, yaw: float, ped_p: np.ndarray) -> np.ndarray:
        """Signed distance [m] from the outline at (x, y, yaw) to each pedestrian at ped_p (P, 2)."""
        centre, half = self._outline_pose(x, y, yaw)
        return self._circles(centre, half, yaw, np.asarray(ped_p, float).reshape(-1, 2), self.ped_r)

    def __call__(self, pose, ped_p: np.ndarray, below: float = math.inf) -> float:
        """min over obstacles of the signed distance from the outline at pose (x, y, yaw) [m] (+inf without
        obstacles). The outline lies between the discs of radius ``inner_radius`` and ``outer_radius`` about the
        robot's centre, so an obstacle at centre-to-surface distance d is between d - outer and d - inner away:
        obstacles are measured exactly nearest first, and only while their lower bound can still beat the best.
        ``below``: a caller that needs the value only when it is below this (a running minimum) gets, otherwise,
        some value >= below; the exact minimum whenever it is below."""
        return self.bounded(pose, ped_p, below)[0]

    def bounded(self, pose, ped_p: np.ndarray, below: float = math.inf, static: bool = True,
                pedestrians: bool = True) -> tuple[float, float]:
        """(``self(pose, ped_p, below)``, a lower bound on the exact minimum): the value itself when it is exact,
        else what the pruning proved (every obstacle not measured is at least that far). The bound holds where
        it is >= 0 (the centre-distance bounds assume the bodies apart; a deep overlap can be deeper).
        ``static``, ``pedestrians``: False leaves those obstacles out (the minimum over the others).

        Compiled (``_bounded_kernel``, issue 26: the episode calls it after every physics block where the motion
        bound does not settle the value): :meth:`bounded_reference`'s operations in its order, the same bits but
        where a circle's distance goes through the C library's hypot instead of CPython's ``math.hypot``
        (tests/sim/test_sim_fastpaths.py)."""
        o = self.outline
        ped_p = np.asarray(ped_p, float).reshape(-1, 2)
        return _bounded_kernel(float(pose[0]), float(pose[1]), float(pose[2]), o.cx, o.cy, o.half_x, o.half_y,
                               o.outer_radius, o.inner_radius, self.rect_c, self.rect_h, self.rect_cos,
                               self.rect_sin, self.circ_c, self.circ_r, ped_p, self.ped_r, float(below),
                               bool(static), bool(pedestrians))

    def bounded_reference(self, pose, ped_p: np.ndarray, below: float = math.inf, static: bool = True,
                          pedestrians: bool = True) -> tuple[float, float]:
        """(``self(pose, ped_p, below)``, a lower bound on the exact minimum): the value itself when it is exact,
        else what the pruning proved (every obstacle not measured is at least that far). The bound holds where
        it is >= 0 (the centre-distance bounds assume the bodies apart; a deep overlap can be deeper).
        ``static``, ``pedestrians``: False leaves those obstacles out (the minimum over the others)."""
        x, y, yaw = float(pose[0]), float(pose[1]), float(pose[2])
        o = self.outline
        outer, inner = o.outer_radius, o.inner_radius
        ped_p = np.asarray(ped_p, float).reshape(-1, 2)
        groups = []                                  # (centres or None for walls and boxes, distances, radii)
        if static and len(self.rect_c):
            groups.append((None, self.rect_distances(np.array([x, y])), None))
        for c, r in ((self.circ_c, self.circ_r) if static else (_NO_XY, _NO_R),
                     (ped_p, self.ped_r) if pedestrians else (_NO_XY, _NO_R)):
            if len(c):
                groups.append((c, np.hypot(c[:, 0] - x, c[:, 1] - y) - r, r))
        if not groups:
            return math.inf, math.inf
        lowest = min(float(d.min()) for _, d, _ in groups)
        if lowest - outer >= below:                  # everything surely at least `below` away
            return lowest - outer, lowest - outer
        limit = min(below, lowest - inner) + outer   # no obstacle farther than this (centre distance) matters
        candidates = sorted((float(d[i]), g, i) for g, (_, d, _) in enumerate(groups)
                            for i in np.flatnonzero(d <= limit).tolist())
        cs, sn = math.cos(yaw), math.sin(yaw)
        cx, cy = x + cs * o.cx - sn * o.cy, y + sn * o.cx + cs * o.cy
        best = math.inf
        for d, g, i in candidates:
            if d - outer >= best:
                break
            c, _, r = groups[g]
            if c is None:
                rc, rh = self.rect_c[i], self.rect_h[i]
                v = rect_rect_distance_one(cx, cy, cs, sn, o.half_x, o.half_y, float(rc[0]), float(rc[1]),
                                           float(self.rect_cos[i]), float(self.rect_sin[i]), float(rh[0]),
                                           float(rh[1]))
            else:
                px, py = float(c[i, 0]) - cx, float(c[i, 1]) - cy
                qx, qy = abs(cs * px + sn * py) - o.half_x, abs(cs * py - sn * px) - o.half_y
                v = math.hypot(max(qx, 0.0), max(qy, 0.0)) + min(max(qx, qy), 0.0) - float(r[i])
            best = min(best, v)
        return best, min(best, limit - outer)       # those not measured: beyond `limit` or behind the break



@kernel
def _bounded_kernel(x, y, yaw, ocx, ocy, half_x, half_y, outer, inner, rect_c, rect_h, rect_cos, rect_sin, circ_c,
                    circ_r, ped_c, ped_r, below, static, pedestrians):
    """:meth:`Clearance.bounded_reference` compiled: (value, lower bound). The candidates (centre-to-surface
    distance d <= limit) are measured in the order of sorted (d, group, index) tuples: a stable sort by d of the
    candidates listed group by group, index by index."""
    nr = rect_c.shape[0] if static else 0
    nc = circ_c.shape[0] if static else 0
    npd = ped_c.shape[0] if pedestrians else 0
    n = nr + nc + npd
    if n == 0:
        return math.inf, math.inf
    d = np.empty(n)
    for i in range(nr):                    # rect_distances: the point's distance to each wall and box
        ex, ey = x - rect_c[i, 0], y - rect_c[i, 1]
        lx = rect_cos[i] * ex + rect_sin[i] * ey
        ly = -rect_sin[i] * ex + rect_cos[i] * ey
        qx = max(abs(lx) - rect_h[i, 0], 0.0)
        qy = max(abs(ly) - rect_h[i, 1], 0.0)
        d[i] = np.hypot(qx, qy)
    for i in range(nc):
        d[nr + i] = np.hypot(circ_c[i, 0] - x, circ_c[i, 1] - y) - circ_r[i]
    for i in range(npd):
        d[nr + nc + i] = np.hypot(ped_c[i, 0] - x, ped_c[i, 1] - y) - ped_r[i]
    lowest = d.min()
    if lowest - outer >= below:            # everything surely at least `below` away
        return lowest - outer, lowest - outer
    limit = min(below, lowest - inner) + outer
    cand = np.flatnonzero(d <= limit)
    order = cand[np.argsort(d[cand], kind="mergesort")]
    cs, sn = math.cos(yaw), math.sin(yaw)
    cx, cy = x + cs * ocx - sn * ocy, y + sn * ocx + cs * ocy
    best = math.inf
    for k in order:
        if d[k] - outer >= best:
            break
        if k < nr:
            v = rect_rect_distance_one(cx, cy, cs, sn, half_x, half_y, rect_c[k, 0], rect_c[k, 1], rect_cos[k],
                                       rect_sin[k], rect_h[k, 0], rect_h[k, 1])
        else:
            if k < nr + nc:
                px, py, r = circ_c[k - nr, 0] - cx, circ_c[k - nr, 1] - cy, circ_r[k - nr]
            else:
                px, py, r = ped_c[k - nr - nc, 0] - cx, ped_c[k - nr - nc, 1] - cy, ped_r[k - nr - nc]
            qx, qy = abs(cs * px + sn * py) - half_x, abs(cs * py - sn * px) - half_y
            v = math.hypot(max(qx, 0.0), max(qy, 0.0)) + min(max(qx, qy), 0.0) - r
        best = min(best, v)
    return best, min(best, limit - outer)

class GroundTruth:
    """The simulator's truth for one episode: clearance (``Clearance``), contact (MuJoCo's), truth-mode obstacles."""

    def __init__(self, model: mujoco.MjModel, scene: SceneSpec):
        self.outline = outline_from_model(model)
        self.distance = Clearance(scene, self.outline)
        c = self.distance
        self.segments = np.array([rectangle_segments(*cc, *h, y) for cc, h, y in
                                  zip(c.rect_c, c.rect_h, c.rect_yaw)]).reshape(-1, 4)
        self.circ_c, self.circ_r, self.ped_r = c.circ_c, c.circ_r, c.ped_r
        # physical contact: robot geoms against obstacle geoms (not the floor)
        body_root = model.body_rootid[model.geom_bodyid]
        base = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "base_link")
        self.robot_geom = body_root == base
        self.obstacle_geom = (~self.robot_geom) & (model.geom_group >= 1) & (model.geom_group <= 2)
        # (geom a, geom b) -> robot against obstacle, either way round: one look-up per contact in in_contact
        pair = self.robot_geom[:, None] & self.obstacle_geom[None, :]
        self._contact_pair = pair | pair.T
        self._outer = self.outline.outer_radius
        self._anchor_static: tuple[float, float, float, float] | None = None        # (clearance)
        self._anchor: tuple[float, float, float, np.ndarray, float] | None = None

    def obstacles(self, p, ped_p: np.ndarray, ped_v: np.ndarray) -> Obstacles:
        """Truth-mode obstacle estimates (debugging and ablations only, flagged as such): pedestrians and
        cylinders as exact circles, walls and boxes as wall points, laid out as the LiDAR pipeline does."""
        centers = np.concatenate([ped_p.reshape(-1, 2), self.circ_c])
        vels = np.concatenate([ped_v.reshape(-1, 2), np.zeros_like(self.circ_c)])
        radii = np.concatenate([self.ped_r, self.circ_r])
        static = np.concatenate([np.zeros(len(self.ped_r), bool), np.ones(len(self.circ_r), bool)])
        return ground_truth_obstacles(np.asarray(p, float), centers, vels, radii, segments=self.segments,
                                      static=static)

    #: slack [m] on the motion bound of ``clearance`` for the rounding of the distances (about 1e-15 m)
    BOUND_SLACK_M = 1e-9

    def clearance(self, pose, ped_p: np.ndarray, below: float = math.inf) -> float:
        """The signed distance [m] between the robot's outline at its true pose (x, y, yaw) and the nearest
        obstacle (``Clearance``; ``below`` as there); < 0 is a penetration, i.e. a contact.

        Between measurements nothing is measured while a bound proves the value is not below ``below``: the
        signed distance between two bodies changes by at most how far their points move, so from the last
        measurement's lower bound L (at pose and pedestrians p0, q0) it is now at least L - (|p - p0| +
        outer_radius |yaw - yaw0| + max_j |q_j - q0_j|) (every point of the outline moves at most |p - p0| +
        outer_radius |yaw - yaw0|); when that is >= ``below`` and >= 0 (bodies apart all along) this returns it
        (a value >= ``below``, as ``Clearance`` may), otherwise it measures. The static obstacles (walls, boxes,
        cylinders: their bound wears off with the robot's motion alone) and the pedestrians are bounded and
        measured apart; the minimum of the two is ``Clearance``'s. The episode's running minimum is the same
        number either way, and most physics blocks, away from the closest approach, need no measurement."""
        x, y, yaw = float(pose[0]), float(pose[1]), float(pose[2])
        ped_p = np.asarray(ped_p, float).reshape(-1, 2)
        skip = below < math.inf
        a = self._anchor_static
        value = None
        if skip and a is not None:
            bound = a[3] - math.hypot(x - a[0], y - a[1]) - self._outer * abs(yaw - a[2]) - self.BOUND_SLACK_M
            if bound >= below and bound >= 0.0:
                value = bound
        if value is None:
            value, lower = self.distance.bounded((x, y, yaw), ped_p, below, pedestrians=False)
            self._anchor_static = (x, y, yaw, lower)
        if not len(ped_p):
            return value
        a = self._anchor
        if skip and a is not None and a[3].shape == ped_p.shape:      # |q - q0| <= sqrt(2) max(|dx|, |dy|)
            bound = (a[4] - math.hypot(x - a[0], y - a[1]) - self._outer * abs(yaw - a[2])
                     - 1.4142135623730951 * float(np.abs(ped_p - a[3]).max()) - self.BOUND_SLACK_M)
            if bound >= below and bound >= 0.0:
                return min(value, bound)
        v, lower = self.distance.bounded((x, y, yaw), ped_p, below, static=False)
        self._anchor = (x, y, yaw, ped_p.copy(), lower)
        return min(value, v)

    def in_contact(self, data: mujoco.MjData) -> bool:
        """Physical contact between the robot and any obstacle, wall or pedestrian (MuJoCo's contacts)."""
        if data.ncon == 0:
            return False
        c = data.contact                    # (ncon contacts)
        return bool(self._contact_pair[c.geom1, c.geom2].any())
