"""What every world family shares: a world before it is written (:class:`Draft`), exact distances to its
static geometry, the grid path search, the generation-time checks (:func:`check`), the time limit rule
(:func:`time_limit`) and the draw helpers the families use.

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

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

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


# --- drawing: the families' helpers --------------------------------------------------------------------------------

def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def _side(rng) -> int:
    return 1 if rng.random() < 0.5 else -1

