"""The simulated world as ROS 2 messages: the static scene as markers and as an occupancy grid, the true
pedestrians as markers. The scene is duck-typed (``bigcbf.sim.scene.SceneSpec``: ``walls`` with x0, y0, x1, y1,
thickness, height; ``boxes`` with x, y, half_x, half_y, yaw, height; ``cylinders`` with x, y, radius, height;
``extent``, ``robot_start``, ``goal``, ``pedestrians`` with x, y, radius, height), so this module needs no MuJoCo.

Frame ``map``: the simulator's world, which is also where the robot's ``odom`` starts (/tf_static carries the
identity map -> odom). These messages are the truth; the stack's own estimates (/tracked_obstacles, /obstacles)
stay in ``odom``.

Occupancy grid (nav_msgs/OccupancyGrid, as Nav2's map_server publishes it): the scenario's area -- the bounding
box of its declared area (``extent`` about the midpoint of start and goal, as the video's top view), its walls,
boxes and cylinders, the robot's start and goal and the pedestrians' start -- is known: 100 where a cell's
inscribed disc (radius = resolution / 2) overlaps a wall, box or cylinder, else 0 (a cell that only shares an edge
with an obstacle is free; pedestrians move: they are not in the map). A margin of ``UNKNOWN_MARGIN_M`` around it is
unknown (-1). The resolution is 0.05 m, coarser for scenes too large for ``MAX_CELLS`` cells at that resolution
(0.1, 0.2, 0.25, 0.5, 1, 2, 5 m).
"""
from __future__ import annotations

import math

import numpy as np

from .convert import CYLINDER, DELETEALL, _header, _marker, _vec3, yaw_quaternion

CUBE = 1
NS_WALLS, NS_BOXES, NS_CYLINDERS, NS_PEDESTRIANS = "walls", "boxes", "cylinders", "pedestrians"
#: the colours of the simulator's scene (bigcbf.sim.scene)
WALL_RGBA = (0.72, 0.70, 0.66, 1.0)
OBSTACLE_RGBA = (0.80, 0.45, 0.20, 1.0)
PEDESTRIAN_RGBA = (0.25, 0.40, 0.85, 0.9)

RESOLUTION_M = 0.05
COARSER_M = (0.1, 0.2, 0.25, 0.5, 1.0, 2.0, 5.0)
MAX_CELLS = 1_000_000
UNKNOWN_MARGIN_M = 1.0
FREE, OCCUPIED, UNKNOWN = 0, 100, -1


def wall_rect(w) -> tuple[float, float, float, float, float]:
    """A wall segment as the box the simulator builds (bigcbf.sim.scene.compose): (cx, cy, half_x, half_y, yaw),
    its length extended by half the thickness at each end."""
    dx, dy = w.x1 - w.x0, w.y1 - w.y0
    return ((w.x0 + w.x1) / 2, (w.y0 + w.y1) / 2, math.hypot(dx, dy) / 2 + w.thickness / 2, w.thickness / 2,
            math.atan2(dy, dx))


def scene_markers_msg(t: float, scene, frame_id: str = "map") -> dict:
    """The static scene as visualization_msgs/MarkerArray: a DELETEALL, then a CUBE per wall (namespace
    ``walls``, id = its index in the scenario) and per box (``boxes``), a CYLINDER per cylinder (``cylinders``),
    each standing on the floor at its true size and height."""
    markers = [_marker(t, frame_id, "", 0, CUBE, action=DELETEALL)]
    for k, w in enumerate(scene.walls):
        cx, cy, hx, hy, yaw = wall_rect(w)
        markers.append(_marker(t, frame_id, NS_WALLS, k, CUBE, (cx, cy), w.height / 2, yaw,
                               (2 * hx, 2 * hy, w.height), WALL_RGBA, text=f"walls[{k}]"))
    for k, b in enumerate(scene.boxes):
        markers.append(_marker(t, frame_id, NS_BOXES, k, CUBE, (b.x, b.y), b.height / 2, b.yaw,
                               (2 * b.half_x, 2 * b.half_y, b.height), OBSTACLE_RGBA, text=f"boxes[{k}]"))
    for k, c in enumerate(scene.cylinders):
        markers.append(_marker(t, frame_id, NS_CYLINDERS, k, CYLINDER, (c.x, c.y), c.height / 2, 0.0,
                               (2 * c.radius, 2 * c.radius, c.height), OBSTACLE_RGBA, text=f"cylinders[{k}]"))
    return {"markers": markers}


def pedestrian_markers_msg(t: float, names, positions, radii, heights, frame_id: str = "map") -> dict:
    """The true pedestrians as visualization_msgs/MarkerArray: a DELETEALL, then a CYLINDER per pedestrian
    (namespace ``pedestrians``, id = its index, ``text`` = its name) of its radius and height at its position."""
    markers = [_marker(t, frame_id, "", 0, CYLINDER, action=DELETEALL)]
    pos = np.asarray(positions, float).reshape(-1, 2)
    for k, (name, p, r, h) in enumerate(zip(names, pos, radii, heights)):
        markers.append(_marker(t, frame_id, NS_PEDESTRIANS, k, CYLINDER, p, h / 2, 0.0, (2 * r, 2 * r, h),
                               PEDESTRIAN_RGBA, text=str(name)))
    return {"markers": markers}


def scene_area(scene) -> tuple[float, float, float, float]:
    """(xmin, ymin, xmax, ymax) [m] of the scenario's known area (module docstring)."""
    start = np.asarray(scene.robot_start[:2], float)
    goal = start if scene.goal is None else np.asarray(scene.goal, float)
    c, e = (start + goal) / 2, float(scene.extent)
    pts = [c - e, c + e, start, goal]
    for w in scene.walls:
        cx, cy, hx, hy, yaw = wall_rect(w)
        pts.extend(_rect_corners(cx, cy, hx, hy, yaw))
    for b in scene.boxes:
        pts.extend(_rect_corners(b.x, b.y, b.half_x, b.half_y, b.yaw))
    for cy in scene.cylinders:
        pts.extend([(cy.x - cy.radius, cy.y - cy.radius), (cy.x + cy.radius, cy.y + cy.radius)])
    for p in getattr(scene, "pedestrians", ()):
        pts.extend([(p.x - p.radius, p.y - p.radius), (p.x + p.radius, p.y + p.radius)])
    a = np.array(pts, float).reshape(-1, 2)
    lo, hi = a.min(axis=0), a.max(axis=0)
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def _rect_corners(cx, cy, hx, hy, yaw) -> list[tuple[float, float]]:
    c, s = math.cos(yaw), math.sin(yaw)
    return [(cx + c * dx - s * dy, cy + s * dx + c * dy) for dx in (-hx, hx) for dy in (-hy, hy)]


def grid_resolution(width_m: float, height_m: float) -> float:
    """RESOLUTION_M, or the first of COARSER_M at which the grid has at most MAX_CELLS cells."""
    for res in (RESOLUTION_M, *COARSER_M):
        if math.ceil(width_m / res) * math.ceil(height_m / res) <= MAX_CELLS:
            return res
    return COARSER_M[-1]


def rasterize(scene, resolution: float | None = None) -> tuple[np.ndarray, tuple[float, float], float]:
    """(grid (rows = y, columns = x) of int8 FREE / OCCUPIED / UNKNOWN, origin (x, y) of cell (0, 0)'s corner,
    resolution) of the scene's static geometry (rules in the module docstring)."""
    x0, y0, x1, y1 = scene_area(scene)
    ox, oy = x0 - UNKNOWN_MARGIN_M, y0 - UNKNOWN_MARGIN_M
    w_m, h_m = x1 - x0 + 2 * UNKNOWN_MARGIN_M, y1 - y0 + 2 * UNKNOWN_MARGIN_M
    res = grid_resolution(w_m, h_m) if resolution is None else float(resolution)
    nx, ny = max(1, math.ceil(w_m / res)), max(1, math.ceil(h_m / res))
    xs = ox + (np.arange(nx) + 0.5) * res
    ys = oy + (np.arange(ny) + 0.5) * res
    X, Y = np.meshgrid(xs, ys)                         # (ny, nx): row = y, as nav_msgs/OccupancyGrid's data
    grid = np.full((ny, nx), UNKNOWN, np.int8)
    known = (X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1)
    grid[known] = FREE
    occ = np.zeros((ny, nx), bool)
    reach = res / 2 - 1e-9                             # the cell's inscribed disc overlaps the obstacle
    rects = [wall_rect(w) for w in scene.walls] + [(b.x, b.y, b.half_x, b.half_y, b.yaw) for b in scene.boxes]
    for cx, cy, hx, hy, yaw in rects:
        c, s = math.cos(yaw), math.sin(yaw)
        dx, dy = X - cx, Y - cy
        qx = np.maximum(np.abs(c * dx + s * dy) - hx, 0.0)
        qy = np.maximum(np.abs(-s * dx + c * dy) - hy, 0.0)
        occ |= qx * qx + qy * qy < reach * reach
    for cyl in scene.cylinders:
        occ |= np.hypot(X - cyl.x, Y - cyl.y) < cyl.radius + reach
    grid[occ] = OCCUPIED
    return grid, (ox, oy), res


def occupancy_grid_msg(t: float, scene, frame_id: str = "map", resolution: float | None = None) -> dict:
    """nav_msgs/OccupancyGrid of the scene's static geometry (:func:`rasterize`)."""
    grid, (ox, oy), res = rasterize(scene, resolution)
    return {"header": _header(t, frame_id),
            "info": {"map_load_time": _header(t, frame_id)["stamp"], "resolution": float(res),
                     "width": int(grid.shape[1]), "height": int(grid.shape[0]),
                     "origin": {"position": _vec3((ox, oy, 0.0)), "orientation": yaw_quaternion(0.0)}},
            "data": grid.ravel().tolist()}

