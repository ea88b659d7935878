"""Procedural worlds: scenario families generated from a seed and written as ordinary scenario TOML.

``bigcbf scenarios generate FAMILY --seed N --out FILE`` writes one world; the ``generated`` bench suite
(bigcbf/bench/suites.py) writes a dev and a test split of every family into the bench's output directory. Each
file uses the schema of :mod:`bigcbf.scenario` with concrete numbers (no random ranges: the world *is* the draw),
so ``bigcbf run FILE`` replays it and a user can read and edit it. No module of the stack imports this one.

Families (each draws its parameters uniformly in the ranges listed by ``bigcbf scenarios generate --list``):

- ``posts``: staggered rows of round posts across a walled lane (gaps 0.8-1.2 m; the first row sometimes
  mirror-symmetric about the start-goal line, with a post or a gap on it);
- ``clutter``: random cylinders and boxes covering 5-20 % of a walled lane (BARN-like density);
- ``corridor``: corridors 1.6-3.0 m wide with walkers both ways at 0.3-1.3 m/s; in most of them a slow walker
  (0.2-0.35 m/s) ahead of the robot in its direction, slow enough that following it to the goal misses the time
  limit, so the robot has to overtake;
- ``doorway``: a cross wall with a door (thin) or a bottleneck (0.6-1.5 m deep), 0.8-1.2 m wide, on the way to
  the goal, with pedestrians coming through it against the robot (and sometimes one with it);
- ``crowd``: 3-10 pedestrians crossing, meeting and cutting diagonally across the robot's way, a drawn share of
  them non-reactive (they ignore the robot);
- ``room``: a closed room with furniture-like boxes and posts, random start, goal and start heading, an obstacle
  near the straight line between them, sometimes 1-2 walkers.

**Checked at generation (every world; a draw that fails is replaced by the next draw of the same generator).**
The robot's footprint is a disc of r_R = 0.15 m and it must keep a 0.10 m clearance, so its centre needs
``FOOTPRINT_M`` = 0.25 m from every static surface. On a grid of ``GRID_M`` = 5 cm cells over the family's
region, a cell is free if the exact distance from its centre to the nearest wall, box or cylinder is at least
0.25 m + ``GRID_ALLOWANCE_M`` (0.02 m, for what happens between cell centres); the start and the goal must be free
and connected (8-connected cells, no corner cutting). That is the requirement "solvable in principle". The
generator asks for more, so that the worlds test liveness rather than squeezing: some route's narrowest passage
is at least ``MIN_PASSAGE_M`` = 0.8 m wide (the narrowest door or post gap any family draws; to within the grid's
5 cm): start and goal are connected through cells at least 0.4 m - 0.035 m from every surface (the start and
the goal themselves at least 0.4 m). Walkers in corridors likewise leave a 0.8 m passage beside them. Also:

- the world stays solvable with every pedestrian standing where it waits (its first waypoint, when its start
  time is later than 0) and where it stops (its last waypoint, unless it loops), all at once, as static discs;
- each pedestrian's path keeps its radius + 0.05 m from static geometry (pedestrians are not stopped by walls in
  the simulation, so they must not be routed through them) and starts at least 0.6 m (surface to surface) from
  the robot's start;
- the corridor family's slow walker is slow enough that following it to the goal takes at least 4 s more than
  the time limit;
- worlds are not trivially empty: in the static families some obstacle (not a bounding wall) comes within
  0.25 m + ``NONTRIVIAL_M`` (0.2 m) of the straight start-goal segment, so driving straight is not enough; in the
  families with pedestrians at least one pedestrian's path comes within 1 m of the robot's route.

**Time limit.** T = L / 0.5 m/s + 8 s + 1.5 s per pedestrian, rounded up to a whole second, with L the length of
the shortest route through passages of at least 0.8 m (the 8-connected grid path, shortened by line-of-sight
shortcuts on the same cells: a few % longer than the true shortest such route, e.g. 2.4 % around one post, where
the grid path itself can be 8 % longer). 0.5 m/s is
5/8 of the robot's 0.8 m/s speed limit; the 8 s cover starting, braking at the goal and a few seconds of
waiting; each pedestrian adds 1.5 s of waiting for it.
"""
from __future__ import annotations

import json
import math
import re
import textwrap
import tomllib
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .errors import UserError

GENERATOR_VERSION = 1

ROBOT_RADIUS_M = 0.15
CLEARANCE_M = 0.10
FOOTPRINT_M = ROBOT_RADIUS_M + CLEARANCE_M      # the robot centre's distance to every static surface [m]
GRID_M = 0.05
GRID_ALLOWANCE_M = 0.02
MIN_PASSAGE_M = 0.80                            # the widest route's narrowest passage (door, gap) [m]
NONTRIVIAL_M = 0.20
PED_ROUTE_M = 1.0                               # a pedestrian path this close to the robot's route counts
PED_WALL_CLEARANCE_M = 0.05
PED_START_GAP_M = 0.60                          # pedestrian surface to robot surface at t = 0 [m]
PLAN_SPEED_MPS = 0.5
SLACK_S = 8.0
SLACK_PER_PEDESTRIAN_S = 1.5
MAX_ATTEMPTS = 400
PED_RADIUS_M = (0.2, 0.3)

XY = tuple[float, float]


def _r(x: float, nd: int = 3) -> float:
    return round(float(x), nd) + 0.0


def _xy(x: float, y: float) -> list[float]:
    return [_r(x), _r(y)]


# --- a world before it is written ----------------------------------------------------------------------------------

@dataclass
class Draft:
    """One drawn world: TOML-ready geometry, the region searched for a path, and what the checks require."""
    start: tuple[float, float, float]
    goal: XY
    bounds: tuple[float, float, float, float]                  # xmin, xmax, ymin, ymax of the path search [m]
    walls: list[dict] = field(default_factory=list)            # start, end, thickness_m
    boxes: list[dict] = field(default_factory=list)            # center, half_size, yaw_rad
    cylinders: list[dict] = field(default_factory=list)        # center, radius_m
    pedestrians: list[dict] = field(default_factory=list)      # name, waypoints, speed_mps, start_time_s, ...
    needs_detour: bool = False                                 # static families: the straight line must be blocked
    params: dict = field(default_factory=dict)                 # the drawn parameters, for the description
    #: a family's own requirement on the finished world (given its time limit): a reason to redraw, or None
    requirement: Callable[["Draft", float], str | None] | None = None

    def wall(self, a: XY, b: XY, thickness: float = 0.10) -> None:
        self.walls.append({"start": _xy(*a), "end": _xy(*b), "thickness_m": _r(thickness)})

    def box(self, c: XY, half: XY, yaw: float = 0.0) -> None:
        self.boxes.append({"center": _xy(*c), "half_size": _xy(*half), "yaw_rad": _r(yaw, 4)})

    def cylinder(self, c: XY, radius: float) -> None:
        self.cylinders.append({"center": _xy(*c), "radius_m": _r(radius)})

    def pedestrian(self, name: str, waypoints, speed: float, start_time: float, radius: float,
                   reactive: bool) -> None:
        self.pedestrians.append({"name": name, "waypoints": [_xy(*w) for w in waypoints], "speed_mps": _r(speed),
                                 "start_time_s": _r(max(start_time, 0.0), 2), "radius_m": _r(radius),
                                 "reactive": bool(reactive)})


# --- geometry: exact distances to the static scene ------------------------------------------------------------------

def _primitives(d: Draft) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (M, 5: cx, cy, hx, hy, yaw) - walls as the boxes the simulator builds - and circles (K, 3: cx, cy, r)."""
    boxes = []
    for w in d.walls:
        a, b = np.array(w["start"], float), np.array(w["end"], float)
        c, length = (a + b) / 2, float(np.linalg.norm(b - a))
        t = w["thickness_m"]
        boxes.append((c[0], c[1], length / 2 + t / 2, t / 2, math.atan2(b[1] - a[1], b[0] - a[0])))
    boxes += [(*b["center"], *b["half_size"], b["yaw_rad"]) for b in d.boxes]
    circles = [(*c["center"], c["radius_m"]) for c in d.cylinders]
    return np.array(boxes, float).reshape(-1, 5), np.array(circles, float).reshape(-1, 3)


def distance(points, boxes: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """Exact distance [m] from each point (N, 2) to the nearest surface of the boxes and circles (negative
    inside); +inf without geometry."""
    p = np.asarray(points, float).reshape(-1, 2)
    out = np.full(len(p), np.inf)
    for cx, cy, hx, hy, yaw in boxes:
        dx, dy = p[:, 0] - cx, p[:, 1] - cy
        c, s = math.cos(yaw), math.sin(yaw)
        qx, qy = np.abs(c * dx + s * dy) - hx, np.abs(-s * dx + c * dy) - hy
        dist = np.hypot(np.maximum(qx, 0), np.maximum(qy, 0)) + np.minimum(np.maximum(qx, qy), 0)
        np.minimum(out, dist, out=out)
    for cx, cy, r in circles:
        np.minimum(out, np.hypot(p[:, 0] - cx, p[:, 1] - cy) - r, out=out)
    return out


def _polyline_points(waypoints, step: float = 0.05) -> np.ndarray:
    w = np.asarray(waypoints, float)
    pts = [w[:1]]
    for a, b in zip(w[:-1], w[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / step)))
        pts.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
    return np.concatenate(pts)


@dataclass
class Grid:
    x0: float
    y0: float
    shape: tuple[int, int]                  # (nx, ny)
    free: np.ndarray                        # (nx, ny) bool: cells the robot's centre may use
    dist: np.ndarray | None = None          # (nx, ny) distance from each cell centre to the nearest surface [m]

    def with_clearance(self, c: float) -> "Grid":
        """The same grid with free = (distance >= c)."""
        return Grid(self.x0, self.y0, self.shape, self.dist >= c, self.dist)

    def cell(self, xy) -> tuple[int, int]:
        i = int(round((xy[0] - self.x0) / GRID_M))
        j = int(round((xy[1] - self.y0) / GRID_M))
        return i, j

    def inside(self, ij) -> bool:
        return 0 <= ij[0] < self.shape[0] and 0 <= ij[1] < self.shape[1]

    def center(self, ij) -> np.ndarray:
        return np.array([self.x0 + ij[0] * GRID_M, self.y0 + ij[1] * GRID_M])


def distance_grid(d: Draft, extra_circles: np.ndarray | None = None) -> Grid:
    """Distances from the cell centres of the draft's bounds to the nearest static surface (and ``extra_circles``
    (K, 3)); free = the footprint's cells (distance >= FOOTPRINT_M + GRID_ALLOWANCE_M)."""
    xmin, xmax, ymin, ymax = d.bounds
    xs = np.arange(xmin + GRID_M / 2, xmax, GRID_M)
    ys = np.arange(ymin + GRID_M / 2, ymax, GRID_M)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    boxes, circles = _primitives(d)
    if extra_circles is not None and len(extra_circles):
        circles = np.concatenate([circles, np.asarray(extra_circles, float).reshape(-1, 3)])
    dist = distance(np.stack([X.ravel(), Y.ravel()], 1), boxes, circles).reshape(X.shape)
    return Grid(float(xs[0]), float(ys[0]), X.shape, dist >= FOOTPRINT_M + GRID_ALLOWANCE_M, dist)


def connected(grid: Grid, a: XY, b: XY) -> bool:
    """Whether cells a and b are free and in one 8-connected component of the free cells."""
    from scipy import ndimage

    ia, ib = grid.cell(a), grid.cell(b)
    if not (grid.inside(ia) and grid.inside(ib) and grid.free[ia] and grid.free[ib]):
        return False
    labels, _ = ndimage.label(grid.free, structure=np.ones((3, 3), int))
    return bool(labels[ia] == labels[ib])


def widest_clearance(grid: Grid, a: XY, b: XY, hi: float = 3.0, tol: float = 0.005) -> float:
    """The largest c such that a and b are connected through cells at least c from every surface (the narrowest
    passage of the widest route is about 2c wide); 0 if they are not connected at all."""
    lo = 0.0
    if not connected(grid.with_clearance(lo), a, b):
        return 0.0
    hi = min(hi, float(grid.dist[grid.cell(a)]), float(grid.dist[grid.cell(b)]))
    if connected(grid.with_clearance(hi), a, b):
        return hi
    while hi - lo > tol:
        mid = (lo + hi) / 2
        if connected(grid.with_clearance(mid), a, b):
            lo = mid
        else:
            hi = mid
    return lo


_STEPS = ((1, 0), (0, 1), (1, 1), (1, -1))


def _graph(grid: Grid):
    """The 8-connected graph of free cells (a diagonal step needs both cells beside it free)."""
    from scipy.sparse import coo_matrix

    f = grid.free
    nx, ny = f.shape
    idx = np.arange(nx * ny).reshape(nx, ny)

    def src(o, n):
        return slice(max(0, -o), n - max(0, o))

    def dst(o, n):
        return slice(max(0, o), n + min(0, o))

    rows, cols, w = [], [], []
    for di, dj in _STEPS:
        ok = f[src(di, nx), src(dj, ny)] & f[dst(di, nx), dst(dj, ny)]
        if di and dj:    # no corner cutting: both cells beside the diagonal step are free too
            ok &= f[dst(di, nx), src(dj, ny)] & f[src(di, nx), dst(dj, ny)]
        rows.append(idx[src(di, nx), src(dj, ny)][ok])
        cols.append(idx[dst(di, nx), dst(dj, ny)][ok])
        w.append(np.full(int(ok.sum()), GRID_M * math.hypot(di, dj)))
    rows, cols, w = map(np.concatenate, (rows, cols, w))
    return coo_matrix((w, (rows, cols)), shape=(nx * ny, nx * ny)).tocsr()


def shortest_path(grid: Grid, start: XY, goal: XY) -> np.ndarray | None:
    """Cell centres (K, 2) of the shortest 8-connected path from start to goal, or None if there is none."""
    from scipy.sparse.csgraph import dijkstra

    s, g = grid.cell(start), grid.cell(goal)
    if not (grid.inside(s) and grid.inside(g) and grid.free[s] and grid.free[g]):
        return None
    ny = grid.shape[1]
    si, gi = s[0] * ny + s[1], g[0] * ny + g[1]
    dist, pred = dijkstra(_graph(grid), directed=False, indices=si, return_predecessors=True)
    if not np.isfinite(dist[gi]):
        return None
    path = [gi]
    while path[-1] != si:
        path.append(int(pred[path[-1]]))
    ij = np.array(path[::-1])
    return np.stack([grid.x0 + (ij // ny) * GRID_M, grid.y0 + (ij % ny) * GRID_M], 1)


def _visible(grid: Grid, a, b) -> bool:
    n = max(2, int(math.ceil(np.linalg.norm(np.subtract(b, a)) / (GRID_M / 2))) + 1)
    pts = np.asarray(a, float) + (np.subtract(b, a)) * np.linspace(0, 1, n)[:, None]
    i = np.rint((pts[:, 0] - grid.x0) / GRID_M).astype(int)
    j = np.rint((pts[:, 1] - grid.y0) / GRID_M).astype(int)
    if i.min() < 0 or j.min() < 0 or i.max() >= grid.shape[0] or j.max() >= grid.shape[1]:
        return False
    return bool(grid.free[i, j].all())


def smooth(grid: Grid, path: np.ndarray) -> np.ndarray:
    """Line-of-sight shortcut of a grid path: from each kept point, jump to the farthest point of the path still
    visible through free cells. Around a round post it comes out about 2 % longer than the taut string (the
    8-connected grid path itself is up to 8 % longer); never shorter than the free cells allow."""
    keep = [0]
    k = 0
    while k < len(path) - 1:
        j = k + 1
        while j + 1 < len(path) and _visible(grid, path[k], path[j + 1]):
            j += 1
        keep.append(j)
        k = j
    return path[keep]


def _length(poly: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(poly, axis=0), axis=1)))


def _segment_distance(points: np.ndarray, a, b) -> np.ndarray:
    a, b = np.asarray(a, float), np.asarray(b, float)
    ab = b - a
    t = np.clip(((points - a) @ ab) / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


@dataclass(frozen=True)
class CheckResult:
    ok: bool
    reason: str = ""
    path_length_m: float = float("nan")        # smoothed shortest path of the footprint [m]
    route: np.ndarray | None = None            # its corner points (K, 2)
    passage_m: float = float("nan")            # the widest route's narrowest passage, about (2 x clearance) [m]


def check(d: Draft) -> CheckResult:
    """The generation-time checks of the module docstring."""
    boxes, circles = _primitives(d)
    start, goal = np.array(d.start[:2]), np.array(d.goal)
    need = MIN_PASSAGE_M / 2
    for what, p in (("start", start), ("goal", goal)):
        if distance(p, boxes, circles)[0] < need:
            return CheckResult(False, f"the {what} is closer than {need:.2f} m to an obstacle")
    grid = distance_grid(d)
    if not connected(grid, start, goal):
        return CheckResult(False, "no free path for the footprint from start to goal")
    wide = grid.with_clearance(need - GRID_M / 2 - GRID_ALLOWANCE_M / 2)
    path = shortest_path(wide, start, goal)
    if path is None:
        return CheckResult(False, f"every route has a passage narrower than {MIN_PASSAGE_M} m")
    path[0], path[-1] = start, goal
    route = smooth(wide, path)
    length = _length(route)
    passage = 2 * widest_clearance(grid, start, goal)
    # pedestrians: their paths clear of static geometry, their t = 0 positions clear of the robot
    standing = []
    for p in d.pedestrians:
        pts = _polyline_points(p["waypoints"])
        r = p["radius_m"]
        if distance(pts, boxes, circles).min() < r + PED_WALL_CLEARANCE_M:
            return CheckResult(False, f"pedestrian {p['name']}'s path runs through static geometry")
        if np.linalg.norm(np.subtract(p["waypoints"][0], start)) < r + ROBOT_RADIUS_M + PED_START_GAP_M:
            return CheckResult(False, f"pedestrian {p['name']} starts too close to the robot")
        if p["start_time_s"] > 0:
            standing.append((*p["waypoints"][0], r))
        if not p.get("loop", False):
            standing.append((*p["waypoints"][-1], r))
    if standing:
        circ = np.array(standing, float)
        if np.any(np.linalg.norm(circ[:, :2] - goal, axis=1) < circ[:, 2] + FOOTPRINT_M + GRID_ALLOWANCE_M):
            return CheckResult(False, "a pedestrian waits or stops on the goal")
        if not connected(distance_grid(d, circ), start, goal):
            return CheckResult(False, "pedestrians waiting or stopped block every path")
    # not trivially empty
    if d.needs_detour:
        interior = _primitives(Draft(start=d.start, goal=d.goal, bounds=d.bounds, boxes=d.boxes,
                                     cylinders=d.cylinders))
        seg = _polyline_points([start, goal], 0.025)
        if distance(seg, *interior).min() > FOOTPRINT_M + NONTRIVIAL_M:
            return CheckResult(False, "trivial: the straight line from start to goal passes every obstacle")
    if d.pedestrians:
        dense = _polyline_points(route, 0.1)
        near = min(float(np.min(_segment_distance(dense, a, b)))
                   for p in d.pedestrians for a, b in zip(p["waypoints"][:-1], p["waypoints"][1:]))
        if near > PED_ROUTE_M:
            return CheckResult(False, "trivial: no pedestrian comes near the robot's route")
    return CheckResult(True, "", length, route, passage)


def time_limit(path_length_m: float, n_pedestrians: int) -> float:
    """T = L / 0.5 m/s + 8 s + 1.5 s per pedestrian, rounded up to a whole second (module docstring)."""
    return float(math.ceil(path_length_m / PLAN_SPEED_MPS + SLACK_S + SLACK_PER_PEDESTRIAN_S * n_pedestrians
                           - 1e-9))


# --- the families ----------------------------------------------------------------------------------------------------

def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def _side(rng) -> int:
    return 1 if rng.random() < 0.5 else -1


def _posts(rng: np.random.Generator) -> Draft:
    n_rows = int(rng.integers(2, 5))
    half_w = _u(rng, 2.5, 3.5)
    r = _u(rng, 0.08, 0.20)
    spacing = _u(rng, 1.2, 2.0)
    x1 = _u(rng, 2.5, 3.5)
    symmetric = rng.random() < 0.5
    on_line = "post" if rng.random() < 0.5 else "gap"
    y_s = 0.0 if symmetric else _u(rng, -0.4, 0.4)
    gaps, offset, rows = [], 0.0, []
    for k in range(n_rows):
        gap = _u(rng, 0.8, 1.2)
        pitch = gap + 2 * r
        if k == 0:
            offset = (0.0 if on_line == "post" else pitch / 2) if symmetric else _u(rng, 0.0, pitch)
        else:
            offset = offset + pitch / 2 + _u(rng, -0.1, 0.1) * pitch
        gaps.append(gap)
        rows.append((x1 + k * spacing, offset, pitch))
    x_last = rows[-1][0]
    x_g = x_last + _u(rng, 1.5, 2.5)
    y_g = 0.0 if symmetric else _u(rng, -0.4, 0.4)
    d = Draft(start=(0.0, _r(y_s), 0.0), goal=(_r(x_g), _r(y_g)), bounds=(-1.0, x_g + 1.5, -half_w, half_w),
              needs_detour=True)
    d.wall((-1.0, -half_w), (x_g + 1.5, -half_w))
    d.wall((-1.0, half_w), (x_g + 1.5, half_w))
    lim = half_w - 0.05 - r - 0.05              # post surface at least 0.05 m from the wall's face
    n_posts = 0
    for x, offset, pitch in rows:
        base = offset - pitch * math.floor((offset + lim) / pitch)
        y = base
        while y <= lim + 1e-9:
            d.cylinder((x, y), r)
            n_posts += 1
            y += pitch
    d.params = {"rows": n_rows, "post radius": f"{r:.2f} m", "gaps": ", ".join(f"{g:.2f}" for g in gaps) + " m",
                "row spacing": f"{spacing:.2f} m", "first row": (f"symmetric about the start-goal line, a {on_line} "
                                                                 "on it" if symmetric else "at a random offset"),
                "lane width": f"{2 * half_w:.2f} m", "posts": n_posts}
    return d


def _clutter(rng: np.random.Generator) -> Draft:
    half_w = _u(rng, 2.5, 3.5)
    x_g = _u(rng, 8.0, 11.0)
    density = _u(rng, 0.05, 0.20)
    start = (0.0, _r(_u(rng, -0.5, 0.5)), 0.0)
    goal = (_r(x_g), _r(_u(rng, -1.0, 1.0)))
    d = Draft(start=start, goal=goal, bounds=(-1.0, x_g + 1.5, -half_w, half_w), needs_detour=True)
    d.wall((-1.0, -half_w), (x_g + 1.5, -half_w))
    d.wall((-1.0, half_w), (x_g + 1.5, half_w))
    zone = (1.5, x_g - 1.2, -half_w + 0.1, half_w - 0.1)
    area = (zone[1] - zone[0]) * (zone[3] - zone[2])
    covered, n_cyl, n_box = 0.0, 0, 0
    keep_clear = np.array([start[:2], goal])
    for _ in range(1000):
        if covered >= density * area:
            break
        c = (_u(rng, zone[0], zone[1]), _u(rng, zone[2], zone[3]))
        if rng.random() < 0.6:
            rad = _u(rng, 0.10, 0.35)
            if np.min(np.linalg.norm(keep_clear - c, axis=1)) - rad < FOOTPRINT_M + 0.5:
                continue
            d.cylinder(c, rad)
            covered += math.pi * rad ** 2
            n_cyl += 1
        else:
            half = (_u(rng, 0.1, 0.5), _u(rng, 0.1, 0.5))
            if np.min(np.linalg.norm(keep_clear - c, axis=1)) - math.hypot(*half) < FOOTPRINT_M + 0.5:
                continue
            d.box(c, half, _u(rng, 0.0, math.pi))
            covered += 4 * half[0] * half[1]
            n_box += 1
    d.params = {"target coverage": f"{100 * density:.1f} %", "cylinders": n_cyl, "boxes": n_box,
                "lane": f"{x_g + 2.5:.1f} m x {2 * half_w:.2f} m"}
    return d


def _lane(rng, width: float, r: float, side: int) -> float:
    """A walker's lateral offset in a corridor of ``width``, on ``side`` (+1 left, -1 right) of the centre line or
    on it: inside with 0.1 m to spare, and leaving a passage of at least MIN_PASSAGE_M free on its other side."""
    lo = max(0.0, MIN_PASSAGE_M + r - width / 2)
    hi = width / 2 - r - 0.1
    return side * _u(rng, lo, max(lo, hi))


def _corridor(rng: np.random.Generator) -> Draft:
    width = _u(rng, 1.6, 3.0)
    length = _u(rng, 10.0, 14.0)
    x_g = length - 1.0
    d = Draft(start=(0.0, 0.0, 0.0), goal=(_r(x_g), 0.0), bounds=(-1.5, length + 1.0, -width / 2, width / 2))
    d.wall((-1.5, -width / 2), (length + 1.0, -width / 2))
    d.wall((-1.5, width / 2), (length + 1.0, width / 2))
    slow = rng.random() < 0.7
    n_other = int(rng.integers(1, 4)) if slow else int(rng.integers(2, 5))
    # walkers keep to one side per direction (the robot's way: ``keep``, the other way: -``keep``), so that walkers
    # meeting each other do not push one another into the middle, where a non-reactive one would close the corridor
    keep = _side(rng)
    kinds = []
    if slow:
        r = _u(rng, *PED_RADIUS_M)
        x0, y = _u(rng, 1.3, 2.2), _lane(rng, width, r, keep)
        d.pedestrian("slow_ahead", [(x0, y), (length + 4.0, y)], 0.3, 0.0, r, rng.random() < 0.5)
        kinds.append("a slow walker ahead")
    n_counter = n_same = 0
    for k in range(n_other):
        r = _u(rng, *PED_RADIUS_M)
        v = _u(rng, 0.3, 1.3)
        reactive = rng.random() < 0.5
        counter = rng.random() < 0.75
        y = _lane(rng, width, r, -keep if counter else keep)
        if counter:
            n_counter += 1
            x_meet = _u(rng, 2.0, x_g - 1.0)                      # where it would meet a robot at 0.5 m/s
            t0 = x_meet / PLAN_SPEED_MPS - (length + 3.0 - x_meet) / v + _u(rng, -2.0, 2.0)
            d.pedestrian(f"counter{n_counter}", [(length + 3.0, y), (-3.5, y)], v, t0, r, reactive)
        else:
            n_same += 1
            v = _u(rng, 0.6, 1.3)
            d.pedestrian(f"ahead{n_same}", [(_u(rng, 2.5, 6.0), y), (length + 4.0, y)], v, 0.0, r, reactive)
    kinds += [f"{n_counter} coming the other way"] if n_counter else []
    kinds += [f"{n_same} faster walking the robot's way" if n_same else ""]
    d.params = {"width": f"{width:.2f} m", "length": f"{length + 2.5:.1f} m",
                "walkers": ", ".join(k for k in kinds if k)}

    if slow:
        def need_overtake(dr: Draft, limit: float) -> str | None:
            """Set the slow walker's speed (0.2-0.35 m/s) so that following it to the goal (0.9 m behind it)
            takes at least 4 s longer than the time limit."""
            p = dr.pedestrians[0]
            behind = dr.goal[0] + 0.9 - p["waypoints"][0][0]
            v_max = min(0.35, behind / (limit + 4.0))
            if v_max < 0.2:
                return "the slow walker would have to be slower than 0.2 m/s to force overtaking"
            p["speed_mps"] = _r(_u(rng, 0.2, v_max))
            dr.params["slow walker"] = (f"{p['speed_mps']:.2f} m/s, "
                                        f"{'reactive' if p['reactive'] else 'non-reactive'}; following it to "
                                        f"the goal would take {behind / p['speed_mps']:.0f} s")
            return None
        d.requirement = need_overtake
    return d


def _doorway(rng: np.random.Generator) -> Draft:
    half_w = _u(rng, 2.5, 3.5)
    x_w = _u(rng, 3.5, 5.0)
    door = rng.random() < 0.5
    depth = _u(rng, 0.1, 0.25) if door else _u(rng, 0.6, 1.5)
    w = _u(rng, 0.8, 1.2)
    x_in, x_out = x_w - depth / 2, x_w + depth / 2          # the opening's faces toward the start / the goal
    x_g = x_out + _u(rng, 2.5, 4.0)
    edge = half_w - 0.45
    y_s, y_g = _u(rng, -1.0, 1.0), _u(rng, -(half_w - 0.8), half_w - 0.8)
    # the opening where the straight start-goal line crosses the wall, give or take 0.25 m: this family is about
    # negotiating the opening, not about finding it (a local planner cannot find a door far off its way)
    y_line = y_s + (y_g - y_s) * x_w / x_g
    lim = half_w - w / 2 - 0.6
    y_d = float(np.clip(y_line + _u(rng, -0.25, 0.25), -lim, lim))
    d = Draft(start=(0.0, _r(y_s), 0.0), goal=(_r(x_g), _r(y_g)), bounds=(-1.0, x_g + 1.5, -half_w, half_w))
    d.wall((-1.0, -half_w), (x_g + 1.5, -half_w))
    d.wall((-1.0, half_w), (x_g + 1.5, half_w))
    lo, hi = y_d - w / 2, y_d + w / 2
    d.box((x_w, (-half_w + lo) / 2), (depth / 2, (lo + half_w) / 2))
    d.box((x_w, (hi + half_w) / 2), (depth / 2, (half_w - hi) / 2))
    n = int(rng.integers(1, 4))
    t_arrive = x_w / PLAN_SPEED_MPS + _u(rng, -3.0, 1.0)     # around when a robot at 0.5 m/s gets there
    for k in range(n):
        r = _u(rng, *PED_RADIUS_M)
        v = _u(rng, 0.5, 1.3)
        # walking from t = 0; the last 2-3 m straight toward the opening along its axis (visible through it);
        # before that, from wherever it had to start to get there at t_arrive
        a0 = (x_out + _u(rng, 2.0, 3.0), y_d)
        lead = max(0.5, v * t_arrive - (a0[0] - x_out))
        phi = _u(rng, -1.0, 1.0)
        p0 = (a0[0] + lead * math.cos(phi), float(np.clip(y_d + lead * math.sin(phi), -edge, edge)))
        end = (_u(rng, 0.3, max(0.4, x_in - 1.5)), _side(rng) * edge)
        d.pedestrian(f"counter{k + 1}", [p0, a0, (x_out + 0.3, y_d), (x_in - 0.5, y_d), end], v, 0.0, r,
                     rng.random() < 0.5)
        t_arrive += _u(rng, 1.0, 3.5)
    with_flow = rng.random() < 0.3
    if with_flow:    # ahead of the robot from the start (people coming from behind would run into it)
        r = _u(rng, *PED_RADIUS_M)
        path = [(_u(rng, 1.5, max(1.6, x_in - 1.0)), _u(rng, -edge, edge)), (x_in - 0.5, y_d), (x_out + 0.5, y_d),
                (x_g + _u(rng, -1.0, 1.0), _side(rng) * edge)]
        d.pedestrian("with_flow", path, _u(rng, 0.5, 1.0), 0.0, r, rng.random() < 0.5)
    d.params = {"opening": f"{'door' if door else 'bottleneck'} {w:.2f} m wide, {depth:.2f} m deep, "
                           f"{y_d - y_line:+.2f} m beside the start-goal line", "counter-flow pedestrians": n,
                "pedestrian going the robot's way": "one" if with_flow else "none"}
    return d


def _arrival(rng, path, v: float, x_route: float, robot_speed: float = 0.55) -> float:
    """A start time that brings a walker (path, speed v) to the point of its path nearest x = x_route, i.e. to the
    robot's way, when a robot at ``robot_speed`` would get there, 2 s earlier to 1.5 s later."""
    w = np.asarray(path, float)
    pts = _polyline_points(w, 0.05)
    k = int(np.argmin(np.abs(pts[:, 0] - x_route) + 0.2 * np.abs(pts[:, 1])))
    along = float(np.sum(np.linalg.norm(np.diff(pts[:k + 1], axis=0), axis=1)))
    return x_route / robot_speed - along / v + _u(rng, -2.0, 1.5)


def _crowd(rng: np.random.Generator) -> Draft:
    half_w = _u(rng, 2.5, 3.5)
    x_g = _u(rng, 8.0, 11.0)
    d = Draft(start=(0.0, _r(_u(rng, -0.5, 0.5)), 0.0), goal=(_r(x_g), _r(_u(rng, -1.0, 1.0))),
              bounds=(-1.0, x_g + 1.0, -half_w, half_w))
    d.wall((-1.0, -half_w), (x_g + 1.5, -half_w))
    d.wall((-1.0, half_w), (x_g + 1.5, half_w))
    n = int(rng.integers(3, 11))
    p_non = _u(rng, 0.0, 0.6)
    edge = half_w - 0.45
    counts = {"crossing": 0, "head-on": 0, "diagonal": 0}
    n_non = 0
    for k in range(n):
        r = _u(rng, *PED_RADIUS_M)
        v = _u(rng, 0.5, 1.3)
        u = rng.random()
        s = _side(rng)
        if u < 0.6:
            kind = "crossing"
            x_c = _u(rng, 2.0, x_g - 1.5)
            path = [(x_c + _u(rng, -1.0, 1.0), s * edge), (x_c + _u(rng, -1.0, 1.0), -s * edge)]
            x_route = x_c
        elif u < 0.85:
            kind = "head-on"
            path = [(x_g + _u(rng, 1.5, 3.0), _u(rng, -1.5, 1.5)), (-2.5, _u(rng, -1.5, 1.5))]
            x_route = _u(rng, 2.0, x_g - 1.0)
        else:
            kind = "diagonal"
            path = [(_u(rng, 0.5 * x_g, x_g + 1.0), s * edge), (_u(rng, 0.0, 0.5 * x_g), -s * edge)]
            x_route = 0.5 * (path[0][0] + path[1][0])
        counts[kind] += 1
        reactive = rng.random() >= p_non
        n_non += not reactive
        d.pedestrian(f"p{k + 1}", path, v, _arrival(rng, path, v, x_route), r, reactive)
    d.params = {"pedestrians": n, "non-reactive": n_non,
                "kinds": ", ".join(f"{c} {k}" for k, c in counts.items() if c),
                "floor": f"{x_g + 2.5:.1f} m x {2 * half_w:.2f} m"}
    return d


def _room(rng: np.random.Generator) -> Draft:
    lx, ly = _u(rng, 6.0, 10.0), _u(rng, 5.0, 8.0)
    hx, hy = lx / 2, ly / 2
    for _ in range(100):
        s = np.array([_u(rng, -hx + 0.8, hx - 0.8), _u(rng, -hy + 0.8, hy - 0.8)])
        g = np.array([_u(rng, -hx + 0.8, hx - 0.8), _u(rng, -hy + 0.8, hy - 0.8)])
        if np.linalg.norm(g - s) >= max(4.0, 0.5 * math.hypot(lx, ly)):
            break
    d = Draft(start=(_r(s[0]), _r(s[1]), _r(_u(rng, -math.pi, math.pi), 4)), goal=(_r(g[0]), _r(g[1])),
              bounds=(-hx, hx, -hy, hy), needs_detour=True)
    for a, b in (((-hx, -hy), (hx, -hy)), ((hx, -hy), (hx, hy)), ((hx, hy), (-hx, hy)), ((-hx, hy), (-hx, -hy))):
        d.wall(a, b)
    n = int(rng.integers(2, 8))
    dg = (g - s) / np.linalg.norm(g - s)
    ng = np.array([-dg[1], dg[0]])
    placed = 0
    for k in range(200):
        if placed >= n:
            break
        if placed == 0:    # one obstacle near the straight line, so that it is no straight drive
            c = s + _u(rng, 0.35, 0.65) * (g - s) + _u(rng, -0.3, 0.3) * ng
        else:
            c = np.array([_u(rng, -hx + 0.3, hx - 0.3), _u(rng, -hy + 0.3, hy - 0.3)])
        if rng.random() < 0.6:
            half = (_u(rng, 0.2, 0.7), _u(rng, 0.2, 0.5))
            size = math.hypot(*half)
            yaw = _u(rng, -0.3, 0.3) + (math.pi / 2 if rng.random() < 0.5 else 0.0)
            if min(np.linalg.norm(c - s), np.linalg.norm(c - g)) - size < FOOTPRINT_M + 0.35:
                continue
            d.box(tuple(c), half, yaw)
        else:
            rad = _u(rng, 0.15, 0.35)
            if min(np.linalg.norm(c - s), np.linalg.norm(c - g)) - rad < FOOTPRINT_M + 0.35:
                continue
            d.cylinder(tuple(c), rad)
        placed += 1
    n_peds = int(rng.choice([0, 0, 1, 2]))
    for k in range(n_peds):
        r = _u(rng, *PED_RADIUS_M)
        v = _u(rng, 0.5, 1.2)
        mid = s + _u(rng, 0.3, 0.7) * (g - s)
        direction = ng * _side(rng) + _u(rng, -0.5, 0.5) * dg
        direction /= np.linalg.norm(direction)
        # from wall to wall through ``mid``: walk back and forth along ``direction`` to 0.45 m from the walls
        def to_wall(sign):
            t = np.inf
            for axis, h in ((0, hx), (1, hy)):
                comp = sign * direction[axis]
                if abs(comp) > 1e-9:
                    t = min(t, ((h - 0.45) * np.sign(comp) - mid[axis]) / comp)
            return mid + sign * t * direction
        path = [tuple(to_wall(-1.0)), tuple(to_wall(1.0))]
        along = float(np.linalg.norm(mid - path[0]))
        t0 = float(np.linalg.norm(mid - s)) / 0.55 - along / v + _u(rng, -3.0, 2.0)
        d.pedestrian(f"walker{k + 1}", path, v, t0, r, rng.random() < 0.5)
    d.params = {"room": f"{lx:.1f} m x {ly:.1f} m", "obstacles": placed, "walkers": n_peds,
                "start to goal": f"{np.linalg.norm(g - s):.1f} m"}
    return d


@dataclass(frozen=True)
class Family:
    name: str
    summary: str                     # one line
    design: str                      # the family's design, the start of each world's description
    ranges: tuple[str, ...]          # the drawn parameters and their ranges (for --list)
    build: Callable[[np.random.Generator], Draft]


FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family("posts", "staggered rows of round posts across a walled lane",
           "Rows of round posts stand across a walled lane, each row staggered by half a pitch against the one "
           "before, so that no straight line threads all rows: the robot has to pick a gap in every row and "
           "shift sideways between rows. When the first row is symmetric about the start-goal line (a post or "
           "a gap on it), neither side is better, and a planner that keeps changing its mind stalls in front of it.",
           ("rows: 2-4", "gap between posts of a row: 0.8-1.2 m (surface to surface)", "post radius: 0.08-0.20 m",
            "row spacing: 1.2-2.0 m", "first row: 50 % symmetric about the start-goal line (a post or a gap on it)",
            "lane width: 5-7 m, walls on both sides; start and goal up to 0.4 m off the axis"),
           _posts),
    Family("clutter", "random cylinders and boxes in a walled lane (BARN-like density)",
           "Cylinders and boxes of random size and orientation are scattered over a walled lane, overlapping "
           "freely (which makes clusters and dead ends), up to a drawn share of its area, as in BARN's "
           "generated worlds. The start and the goal are kept clear.",
           ("covered share of the cluttered area: 5-20 %", "cylinders (60 %): radius 0.10-0.35 m",
            "boxes (40 %): half sizes 0.1-0.5 m, any yaw", "lane: 10.5-13.5 m long, 5-7 m wide",
            "goal 8-11 m ahead, up to 1 m off the axis"),
           _clutter),
    Family("corridor", "corridors 1.6-3.0 m wide with walkers both ways, often a slow one ahead",
           "A straight corridor with walkers in both directions, each direction keeping to one side, each walker "
           "in a lane that leaves a passage of at least 0.8 m on its other side. In most worlds a slow walker (0.2-0.35 m/s) goes ahead of the robot, its way, "
           "slow enough that following it to the goal misses the time limit: the robot has to commit to one "
           "side and overtake, between the walkers coming the other way.",
           ("width: 1.6-3.0 m", "length: 12.5-16.5 m (goal 9-13 m ahead)",
            "slow walker ahead: 70 % of worlds, 0.2-0.35 m/s (at most the speed that forces overtaking)",
            "other walkers: 1-4, 75 % coming the other way (0.3-1.3 m/s, timed to meet the robot), 25 % ahead of "
            "it walking its way faster (0.6-1.3 m/s)", "each walker reactive or not, 50/50; radius 0.2-0.3 m",
            "walkers going the robot's way keep to one side (drawn), the others to the other side"),
           _corridor),
    Family("doorway", "a door or bottleneck 0.8-1.2 m wide with counter-flow pedestrians",
           "A cross wall blocks a walled lane except for one opening, a door in a thin wall or a bottleneck up to "
           "1.5 m deep, on the way from the start to the goal, barely wide enough for the robot or for one "
           "pedestrian. Pedestrians on the far side come through it toward the robot around the time it arrives (sometimes one also goes through with the "
           "robot): the robot has to wait for the opening to clear, or take it first, without meeting anyone "
           "inside.",
           ("opening: 0.8-1.2 m wide, door (0.10-0.25 m deep) or bottleneck (0.6-1.5 m deep), 50/50",
            "the start-goal line crosses the cross wall (3.5-5 m ahead) within 0.25 m of the opening's centre",
            "counter-flow pedestrians: 1-3, 0.5-1.3 m/s, walking from the start, the last 2-3 m straight at the "
            "opening, reaching it 1-3.5 s apart around when the robot would; reactive 50/50", "a pedestrian going the robot's way: 30 % of worlds, ahead of the robot from the start (0.5-1.0 m/s)",
            "lane width 5-7 m; goal 2.5-4 m past the opening"),
           _doorway),
    Family("crowd", "3-10 pedestrians crossing, meeting and cutting across, reactive and not",
           "Open floor between two walls; pedestrians cross the robot's way from both sides, come head-on from "
           "beyond the goal, or cut diagonally, timed to reach the robot's way around when it gets there. A "
           "drawn share of them ignore the robot (non-reactive); the others step aside (social force).",
           ("pedestrians: 3-10 (60 % crossing, 25 % head-on, 15 % diagonal), 0.5-1.3 m/s, radius 0.2-0.3 m",
            "non-reactive share: drawn in 0-60 %", "timing: each reaches the robot's way 2 s before to 1.5 s after a "
            "robot at 0.55 m/s would", "floor: 10.5-13.5 m long, 5-7 m wide; goal 8-11 m ahead"),
           _crowd),
    Family("room", "a closed room with furniture, random start, goal and heading",
           "A closed rectangular room with furniture-like boxes and round posts, one of them near the straight "
           "line from the start to the goal. Start and goal are anywhere in the room at least 4 m apart, and the "
           "robot starts facing any direction (it drives holonomically). Sometimes one or two people walk across "
           "the room.",
           ("room: 6-10 m x 5-8 m", "obstacles: 2-7 (boxes of half size 0.2-0.7 m x 0.2-0.5 m, posts of radius "
            "0.15-0.35 m)", "start-goal distance: at least 4 m and half the room's diagonal",
            "walkers: 0 (50 %), 1 or 2 (25 % each), crossing the start-goal line, reactive 50/50"),
           _room),
)}


# --- generating and writing -------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class World:
    family: str
    seed: int
    name: str
    draft: Draft
    path_length_m: float
    time_limit_s: float
    attempts: int
    toml: str


def family(name: str) -> Family:
    if name not in FAMILIES:
        raise UserError(f"unknown world family {name!r}; known: {', '.join(FAMILIES)}")
    return FAMILIES[name]


def world_name(family_name: str, seed: int) -> str:
    return f"{family_name}_{int(seed):05d}"


def generate(family_name: str, seed: int) -> World:
    """The world of ``family_name`` for ``seed``: the first draw of the family's generator (seeded by the family
    name and ``seed`` only) that passes :func:`check` and its family's own requirement."""
    fam = family(family_name)
    if int(seed) < 0:
        raise UserError(f"--seed must be >= 0, got {seed}")
    rng = np.random.default_rng([int(seed), zlib.crc32(fam.name.encode()), GENERATOR_VERSION])
    reasons: dict[str, int] = {}
    for attempt in range(1, MAX_ATTEMPTS + 1):
        d = fam.build(rng)
        res = check(d)
        if res.ok:
            limit = time_limit(res.path_length_m, len(d.pedestrians))
            why = d.requirement(d, limit) if d.requirement else None
            if why is None:
                name = world_name(fam.name, seed)
                text = _toml(fam, int(seed), name, d, res, limit, attempt)
                return World(fam.name, int(seed), name, d, res.path_length_m, limit, attempt, text)
            res = CheckResult(False, why)
        reasons[res.reason] = reasons.get(res.reason, 0) + 1
    raise RuntimeError(f"{fam.name} seed {seed}: no valid world in {MAX_ATTEMPTS} draws ({reasons})")


def _extent(d: Draft) -> float:
    """Half-size of the top view (4:3 frame, orthographic height 2.1 extent) that shows the whole region."""
    xmin, xmax, ymin, ymax = d.bounds
    cx, cy = (d.start[0] + d.goal[0]) / 2, (d.start[1] + d.goal[1]) / 2
    ax = max(cx - xmin, xmax - cx) + 0.3
    ay = max(cy - ymin, ymax - cy) + 0.3
    return _r(max(ax / 1.4, ay / 1.05), 2)


def toml_key(k: str) -> str:
    """A TOML key: bare when it can be, else quoted."""
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def toml_value(v) -> str:
    """One inline TOML value of the scenario files' schema: bool, number, string, (nested) array, inline table (the
    generated worlds here; the faulted scenes of ``bigcbf.bench.faults``)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)          # a JSON string is a valid TOML basic string
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{toml_key(k)} = {toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to a scenario file")


_value = toml_value


def _toml(fam: Family, seed: int, name: str, d: Draft, res: CheckResult, limit: float, attempts: int) -> str:
    params = "; ".join(f"{k}: {v}" for k, v in d.params.items())
    n_p = len(d.pedestrians)
    paragraphs = [
        f"Procedural world of the {fam.name} family ({fam.summary}), seed {seed}. {fam.design}",
        f"This world: {params}.",
        f"Generated by `bigcbf scenarios generate {fam.name} --seed {seed}` (generator version {GENERATOR_VERSION}, "
        f"draw {attempts}). Checked at generation: a path of {res.path_length_m:.2f} m keeps a {ROBOT_RADIUS_M:.2f} m "
        f"robot {CLEARANCE_M:.2f} m clear of all static geometry, also with every pedestrian standing where it "
        f"waits and where it stops; the narrowest passage on the widest route is {res.passage_m:.2f} m wide. Time limit: {res.path_length_m:.2f} m / {PLAN_SPEED_MPS} m/s + {SLACK_S:.0f} s + "
        f"{SLACK_PER_PEDESTRIAN_S} s x {n_p} pedestrian{'s' if n_p != 1 else ''}, rounded up: {limit:.0f} s."]
    description = "\n\n".join("\n".join(textwrap.wrap(p, 116)) for p in paragraphs)
    lines = [f"# {name}: generated by `bigcbf scenarios generate {fam.name} --seed {seed}` "
             f"(bigcbf world generator version {GENERATOR_VERSION}); run it with `bigcbf run FILE`.",
             f"name = {_value(name)}", 'description = """', description, '"""',
             f"time_limit_s = {_value(limit)}", f"extent_m = {_value(_extent(d))}", "", "[robot]",
             f"start = {_value([_r(v, 4) for v in d.start])}", f"goal = {_value(list(d.goal))}"]
    for key in ("walls", "boxes", "cylinders", "pedestrians"):
        for item in getattr(d, key):
            lines += ["", f"[[{key}]]"] + [f"{k} = {_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


def parse(text: str, file: str = "<generated>"):
    """The Scenario a generated TOML text describes (as load_scenario reads it, seed 0)."""
    from .scenario import parse_scenario
    return parse_scenario(text, file, 0)


def write(world: World, path: Path) -> bool:
    """Write the world's TOML to ``path`` unless it already holds exactly that text; True if written."""
    path = Path(path)
    try:
        if path.read_text() == world.toml:
            return False
    except (OSError, UnicodeDecodeError):
        pass
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(world.toml)
    return True


#: The generated suite's splits: world seeds per family (disjoint). Tune on dev; report test.
SPLITS: dict[str, range] = {"dev": range(0, 30), "test": range(1000, 1030)}


def suite_worlds(out: Path, splits=None) -> list[tuple[Path, str, str]]:
    """Write the generated suite's worlds into ``out/worlds/<split>/`` (only files whose text changed) and
    return (path, split, family) in an interleaved order (seed by seed, every family), so that a bench that is
    stopped part-way has covered all families evenly."""
    out = Path(out)
    entries = []
    for split in (splits or SPLITS):
        for seed in SPLITS[split]:
            for fam in FAMILIES:
                w = generate(fam, seed)
                p = out / "worlds" / split / f"{w.name}.toml"
                write(w, p)
                entries.append((p, split, fam))
    return entries
