"""The route layer (issue 25): a global path on the robot's own map, whose look-ahead point is every method's goal.

Nav2 runs each local controller (DWB, MPPI, regulated pure pursuit) under a global planner (NavFn, Smac) that plans
on a costmap the robot builds from its own sensors; that is how a real robot leaves a concave trap deeper than its
local look-ahead. This layer does the same for EVERY method of the benchmark, so that no method wins by a layer its
rivals lack. It is a run option (``[route] enabled`` in the run configuration, ``--route on`` on the command line),
off by default (the paper's set-up). Robot side: it sees only what the stack sees (the LiDAR scans, the odometry
pose at each scan, the perception's obstacle estimates), never the simulator.

1. Map (:class:`OccupancyGrid`): an occupancy grid in the odom frame (REP 105), ``resolution_m`` cells over the box
   around the start and the goal widened by ``margin_m`` (at most ``max_cells`` cells: a larger box gets coarser
   cells). Each scan updates it in log-odds (Thrun, Burgard & Fox, Probabilistic Robotics, ch. 9): the cell of
   every return within ``mark_range_m`` gains ``l_hit``, every cell a beam crosses before its return (exact cell
   traversal, Amanatides & Woo 1987), up to ``clear_range_m``, loses ``l_free``; a cell gets at most one update per
   scan and a return wins over a crossing; values are clamped to [l_min, l_max]. These are Nav2's ObstacleLayer
   ``obstacle_max_range`` and ``raytrace_max_range``; like its default ``inf_is_valid: false`` a beam without a
   return clears nothing (it may be a dropout, not free space). A cell no beam has reached is UNKNOWN.
   Moving obstacles are not burned in: a return within r_i + ``dynamic_margin_m`` of a track the perception
   reports as dynamic (ids >= 0, not static) marks nothing, though its beam still clears the cells before it; a
   walker that stood still long enough to be reported static is marked, and cleared by the beams that pass
   through its cells once it has left.
2. Costs (Nav2's costmap_2d InflationLayer): d = distance from a cell to the nearest occupied cell. Occupied cells
   cannot be entered; within the inscribed radius r_R + d0 (the CBF's own clearance) a cell costs
   ``lethal_cost`` per metre more (not impassable, so that a robot that starts there, or a goal there, still has
   a path), beyond it ``inflation_cost`` exp(-``cost_scaling_per_m`` (d - r_R - d0)) up to
   ``inflation_radius_m`` (the InflationLayer's exponential decay), and unknown cells ``unknown_cost`` per metre
   more: traversable and optimistic, as NavFn's and Smac's ``allow_unknown: true``.
3. Path: A* over the 8-connected grid (NavFn with ``use_astar``, Smac Planner 2D), octile heuristic, no corner
   cutting past an occupied cell, replanned at ``replan_hz`` (Nav2's default behaviour tree replans at 1 Hz,
   ``RateController``) and at once when a scan marks a cell on the path ahead occupied.
4. Local goal: the farthest point of the path within ``lookahead_m`` of arc length from the path point nearest
   the robot whose straight line from the robot clears the occupied cells by r_R (the regulated pure pursuit's
   look-ahead point, ``lookahead_dist``, kept in sight so that it never lies behind a corner); the goal itself
   once it is within that reach. A point within the methods' arrival tolerance eps_g of the robot (where a
   method stops as arrived) gives way to the first path point beyond it: near the goal, a cell still marked where
   a person stood and left unseen (a beam without a return clears nothing) hides the goal from the visibility test
   and would hold every method 0.1-0.3 m short of it until the time limit. No path (the goal is walled off on the
   map): the goal itself, as without the route layer. Success is still judged on the real goal (bigcbf/episode.py).
5. Progress (off by default; ``progress_time_s`` > 0): Nav2's progress checker (``SimpleProgressChecker``: the robot
   must move ``required_movement_radius`` within ``movement_time_allowance``) with what its recovery does next (the
   path replanned), turned into memory on the map: when the robot has stayed within ``progress_radius_m`` of one
   point for ``progress_time_s``, the path ahead of it (``stall_ahead_m`` of arc length, widened by r_R) costs
   ``stall_cost`` per metre more from then on, and the path is replanned. A passage the map shows open but the
   method cannot take (wide enough for the footprint at rest, not for the filter's clearance at speed: every method
   stood still in such gaps of the dev worlds clutter_00006 and clutter_00015) is then left for another way round
   when there is one; where there is none (a door that is the only way) every path pays the same and the route
   stays. Each further stall there adds the cost again. With ``wait_range_m`` > 0 the robot is waiting, not
   stalled, while a track the perception reports as moving (ids >= 0, not static) is within that distance at the
   latest scan: the time allowance starts again from there.

Limitations (documented choices): the map is in odom, so odometry drift skews it slowly (Nav2's global costmap
lives in the map frame of a SLAM or localisation node, which this stack does not have); there is no path
smoothing (the look-ahead point's visibility test does that job); a pedestrian who stands still is part of the map
until beams pass through his cells again.
"""
from __future__ import annotations

import heapq
import math
import time
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt

from ..params.checks import check_field_ranges, ranged
from ..types import LaserScan, Obstacles, RobotState
from .jit import kernel

_SQRT2 = math.sqrt(2.0)


@dataclass(frozen=True)
class RouteParams:
    """The ``[route]`` table of a run configuration (bigcbf/config.py). Off by default (the paper's set-up)."""

    enabled: bool = False  # run every method under the route layer [-]
    resolution_m: float = ranged(0.1, 0.02, 1.0)  # grid cell side (coarser when the box needs more than max_cells) [m]
    margin_m: float = ranged(5.0, 0.5, 100.0)  # the grid covers the start-goal box widened by this on every side [m]
    max_cells: int = ranged(250_000, 1_000, 4_000_000)  # most cells of the grid [-]
    mark_range_m: float = ranged(6.0, 0.1, 100.0)  # returns farther than this mark nothing (obstacle_max_range) [m]
    clear_range_m: float = ranged(6.5, 0.1, 100.0)  # beams clear cells up to this range (raytrace_max_range) [m]
    l_hit: float = ranged(0.9, 0.0, 10.0, lo_open=True)  # log-odds gained by a cell holding a return [-]
    l_free: float = ranged(0.4, 0.0, 10.0, lo_open=True)  # log-odds lost by a cell a beam crosses [-]
    l_max: float = ranged(2.5, 0.0, 50.0, lo_open=True)  # clamp of the log-odds above [-]
    l_min: float = ranged(-2.0, -50.0, 0.0, hi_open=True)  # clamp of the log-odds below [-]
    occupied_logodds: float = ranged(0.6, 0.0, 50.0, lo_open=True)  # a cell at or above this is occupied [-]
    dynamic_margin_m: float = ranged(0.2, 0.0, 2.0)  # returns within r_i + this of a moving track mark nothing [m]
    inflation_radius_m: float = ranged(0.8, 0.0, 10.0)  # the cost gradient reaches this far from an obstacle [m]
    cost_scaling_per_m: float = ranged(3.0, 0.0, 100.0)  # decay rate of the gradient (cost_scaling_factor) [1/m]
    inflation_cost: float = ranged(4.0, 0.0, 1000.0)  # extra cost per metre at the inscribed radius [-]
    lethal_cost: float = ranged(50.0, 0.0, 1e6)  # extra cost per metre within the inscribed radius r_R + d0 [-]
    unknown_cost: float = ranged(0.5, 0.0, 1000.0)  # extra cost per metre through unknown cells (allow_unknown) [-]
    replan_hz: float = ranged(2.0, 0.1, 50.0)  # path replanning rate [Hz]
    lookahead_m: float = ranged(1.5, 0.2, 20.0)  # arc length of the look-ahead point along the path [m]
    progress_time_s: float = ranged(0.0, 0.0, 600.0)  # a stall: this long within progress_radius_m (0: off) [s]
    progress_radius_m: float = ranged(0.5, 0.01, 10.0)  # movement that counts as progress (Nav2's 0.5 m) [m]
    stall_ahead_m: float = ranged(1.0, 0.0, 20.0)  # arc length of the path ahead a stall makes costly [m]
    stall_cost: float = ranged(20.0, 0.0, 1e6)  # extra cost per metre of those cells, per stall [-]
    wait_range_m: float = ranged(0.0, 0.0, 100.0)  # no stall while a moving track is this near (0: none) [m]

    def __post_init__(self):
        check_field_ranges(self)
        from ..errors import FieldError
        if not self.l_min < 0.0 < self.occupied_logodds <= self.l_max:
            raise FieldError("occupied_logodds", f"must lie in (0, l_max = {self.l_max:g}], got "
                                                 f"{self.occupied_logodds:g}")
        if self.clear_range_m < self.mark_range_m:
            raise FieldError("clear_range_m", f"must be >= mark_range_m ({self.mark_range_m:g} m), got "
                                              f"{self.clear_range_m:g}")


# --- the map -------------------------------------------------------------------------------------------------------

@kernel
def _integrate(L, seen, hit_stamp, free_stamp, sid, x0, y0, res, sx, sy, ca, sa, rng, hit, clear_len,
               l_hit, l_free, l_min, l_max):
    """One scan into the log-odds grid L (nx, ny): returns first (each cell once), then every beam's crossed cells
    up to clear_len (exact traversal), skipping the cells a return of this scan holds."""
    nx, ny = L.shape
    for b in range(rng.shape[0]):
        if hit[b]:
            ix = int(math.floor((sx + rng[b] * ca[b] - x0) / res))
            iy = int(math.floor((sy + rng[b] * sa[b] - y0) / res))
            if 0 <= ix < nx and 0 <= iy < ny and hit_stamp[ix, iy] != sid:
                hit_stamp[ix, iy] = sid
                L[ix, iy] = min(L[ix, iy] + l_hit, l_max)
                seen[ix, iy] = True
    for b in range(rng.shape[0]):
        length = clear_len[b]
        if not length > 0.0:
            continue
        dx = length * ca[b]
        dy = length * sa[b]
        fx = (sx - x0) / res
        fy = (sy - y0) / res
        ix = int(math.floor(fx))
        iy = int(math.floor(fy))
        if dx > 0.0:
            stx, tmx, tdx = 1, ((ix + 1) * res + x0 - sx) / dx, res / dx
        elif dx < 0.0:
            stx, tmx, tdx = -1, (ix * res + x0 - sx) / dx, -res / dx
        else:
            stx, tmx, tdx = 0, np.inf, np.inf
        if dy > 0.0:
            sty, tmy, tdy = 1, ((iy + 1) * res + y0 - sy) / dy, res / dy
        elif dy < 0.0:
            sty, tmy, tdy = -1, (iy * res + y0 - sy) / dy, -res / dy
        else:
            sty, tmy, tdy = 0, np.inf, np.inf
        for _ in range(int(2.0 * length / res) + 4):
            if 0 <= ix < nx and 0 <= iy < ny and hit_stamp[ix, iy] != sid and free_stamp[ix, iy] != sid:
                free_stamp[ix, iy] = sid
                L[ix, iy] = max(L[ix, iy] - l_free, l_min)
                seen[ix, iy] = True
            if tmx < tmy:
                t = tmx
                tmx += tdx
                ix += stx
            else:
                t = tmy
                tmy += tdy
                iy += sty
            if t >= 1.0:
                break


class OccupancyGrid:
    """A log-odds occupancy grid in odom over [lo, hi] (cell (i, j) covers x0 + [i, i+1) res, y0 + [j, j+1) res)."""

    def __init__(self, lo, hi, resolution_m: float, max_cells: int):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        size = np.maximum(hi - lo, resolution_m)
        res = float(resolution_m)
        if np.prod(np.ceil(size / res)) > max_cells:        # coarser cells, so that the box fits in max_cells
            res = float(np.sqrt(size[0] * size[1] / max_cells)) * 1.01
            while np.prod(np.ceil(size / res)) > max_cells:
                res *= 1.01
        self.res = res
        self.nx, self.ny = (int(v) for v in np.ceil(size / res))
        self.x0, self.y0 = float(lo[0]), float(lo[1])
        self.logodds = np.zeros((self.nx, self.ny))
        self.seen = np.zeros((self.nx, self.ny), bool)
        self._hit_stamp = np.zeros((self.nx, self.ny), np.int64)
        self._free_stamp = np.zeros((self.nx, self.ny), np.int64)
        self._sid = 0

    @property
    def shape(self) -> tuple[int, int]:
        return self.nx, self.ny

    def cell(self, xy) -> tuple[int, int]:
        """The cell holding point ``xy``, clipped onto the grid."""
        return (min(max(int(math.floor((xy[0] - self.x0) / self.res)), 0), self.nx - 1),
                min(max(int(math.floor((xy[1] - self.y0) / self.res)), 0), self.ny - 1))

    def centers(self, cells) -> np.ndarray:
        """Cell centres (K, 2) in odom of integer cells (K, 2)."""
        cells = np.asarray(cells, float).reshape(-1, 2)
        return np.c_[self.x0 + (cells[:, 0] + 0.5) * self.res, self.y0 + (cells[:, 1] + 0.5) * self.res]

    def integrate(self, sensor_xy, angles, ranges, hit, clear_len, params: RouteParams) -> None:
        """One scan: beams from ``sensor_xy`` at odom ``angles``; ``hit`` marks the returns that mark their cell,
        ``clear_len`` how far each beam clears (0: nothing)."""
        self._sid += 1
        _integrate(self.logodds, self.seen, self._hit_stamp, self._free_stamp, self._sid, self.x0, self.y0, self.res,
                   float(sensor_xy[0]), float(sensor_xy[1]), np.cos(angles), np.sin(angles),
                   np.ascontiguousarray(ranges, float), np.ascontiguousarray(hit, np.bool_),
                   np.ascontiguousarray(clear_len, float), params.l_hit, params.l_free, params.l_min, params.l_max)

    def occupied(self, params: RouteParams) -> np.ndarray:
        return self.logodds >= params.occupied_logodds

    def unknown(self) -> np.ndarray:
        return ~self.seen


# --- the path ------------------------------------------------------------------------------------------------------

@kernel
def _astar(cost, sx, sy, gx, gy):
    """A* over the 8-connected grid of per-cell costs (inf: cannot be entered), from cell (sx, sy) to (gx, gy);
    moving to a neighbour costs its cost times the step length in cells; no diagonal step past an occupied cell.
    The goal cell can always be entered. Returns the cells (K, 2) from start to goal, or (0, 2) without a path.

    Length: a numba kernel holding textbook A* in one piece (the search loop, then the walk back along its parent
    array), to read against the description above."""
    nx, ny = cost.shape
    n = nx * ny
    g = np.full(n, np.inf)
    parent = np.full(n, -1, np.int64)
    closed = np.zeros(n, np.bool_)
    start = sx * ny + sy
    goal = gx * ny + gy
    g[start] = 0.0
    heap = [(0.0, start)]
    dxs = (1, -1, 0, 0, 1, 1, -1, -1)
    dys = (0, 0, 1, -1, 1, -1, 1, -1)
    found = start == goal
    while len(heap) > 0 and not found:
        _, c = heapq.heappop(heap)
        if closed[c]:
            continue
        closed[c] = True
        if c == goal:
            found = True
            break
        cx = c // ny
        cy = c - cx * ny
        for k in range(8):
            x = cx + dxs[k]
            y = cy + dys[k]
            if x < 0 or x >= nx or y < 0 or y >= ny:
                continue
            m = x * ny + y
            if closed[m]:
                continue
            step = 1.0
            if k >= 4:
                if not (np.isfinite(cost[x, cy]) and np.isfinite(cost[cx, y])):
                    continue
                step = 1.4142135623730951
            cm = 1.0 if m == goal else cost[x, y]
            if not np.isfinite(cm):
                continue
            new = g[c] + step * cm
            if new < g[m]:
                g[m] = new
                parent[m] = c
                ax = abs(x - gx)
                ay = abs(y - gy)
                h = max(ax, ay) + (1.4142135623730951 - 1.0) * min(ax, ay)    # octile; every cell costs >= 1
                heapq.heappush(heap, (new + h, m))
    if not found:
        return np.zeros((0, 2), np.int64)
    k = 1
    c = goal
    while c != start:
        c = parent[c]
        k += 1
    out = np.zeros((k, 2), np.int64)
    c = goal
    for i in range(k - 1, -1, -1):
        out[i, 0] = c // ny
        out[i, 1] = c - (c // ny) * ny
        c = parent[c]
    return out


def cell_costs(occupied: np.ndarray, unknown: np.ndarray, res: float, inscribed_m: float,
               params: RouteParams, stalled: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per-cell costs (>= 1 per cell length; inf: occupied) and the distance [m] of each cell to the nearest occupied
    one (inf without any), as Nav2's inflation layer grades them (module docstring, step 2); ``stalled``: the
    extra cost per metre of the cells where the robot stalled (step 5), added."""
    if occupied.any():
        d = distance_transform_edt(~occupied) * res
    else:
        d = np.full(occupied.shape, np.inf)
    grad = params.inflation_cost * np.exp(-params.cost_scaling_per_m * np.maximum(d - inscribed_m, 0.0))
    extra = np.where(d < inscribed_m, params.lethal_cost, np.where(d <= params.inflation_radius_m, grad, 0.0))
    cost = 1.0 + extra + params.unknown_cost * unknown
    if stalled is not None:
        cost = cost + stalled
    cost[occupied] = np.inf
    return cost, d


def shortest_path(cost: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> np.ndarray:
    """The cheapest 8-connected cell path (K, 2) from ``start`` to ``goal`` on ``cost`` ((0, 2): none)."""
    return _astar(np.ascontiguousarray(cost, float), int(start[0]), int(start[1]), int(goal[0]), int(goal[1]))


def _movers(obstacles: Obstacles | None) -> tuple[np.ndarray, np.ndarray]:
    """The centres (K, 2) and radii (K,) of the tracks the perception reports as moving (ids >= 0, not static)."""
    if obstacles is None or not len(obstacles):
        return np.zeros((0, 2)), np.zeros(0)
    moving = (np.asarray(obstacles.ids) >= 0) & ~np.asarray(obstacles.static, bool)
    return np.asarray(obstacles.p, float)[moving], np.asarray(obstacles.r, float)[moving]


# --- the layer -----------------------------------------------------------------------------------------------------

class RouteLayer:
    """The map, the path and the local goal of one episode (module docstring). ``reset(start, goal)``, then
    ``scan(...)`` for every LiDAR scan and ``local_goal(...)`` at every control tick.

    ``r_robot_m``, ``d0_m``: the footprint radius r_R and the base clearance d0 (the inscribed radius of the
    costmap is their sum); ``laser_mount``: the laser frame's pose (x, y, yaw) in base_link; ``arrive_m``: the
    methods' arrival tolerance (the goal region's eps_g, eq:goal_region): a look-ahead point within it would read
    as arrived and stop the method short of the goal (step 4). Timings (ms) of each call are kept in ``scan_ms``,
    ``plan_ms`` and ``goal_ms``."""

    def __init__(self, params: RouteParams, r_robot_m: float, d0_m: float,
                 laser_mount: tuple[float, float, float] = (0.0, 0.0, 0.0), arrive_m: float = 0.0):
        self.params = params
        self.r_robot_m, self.d0_m = float(r_robot_m), float(d0_m)
        self.arrive_m = float(arrive_m)
        if not (math.isfinite(self.arrive_m) and self.arrive_m >= 0):
            raise ValueError(f"arrive_m must be a finite distance >= 0, got {arrive_m!r}")
        self.laser_mount = tuple(float(v) for v in laser_mount)
        self.grid: OccupancyGrid | None = None
        self.path: np.ndarray | None = None

    def reset(self, start_xy, goal_xy) -> None:
        """A new, unknown map over the box around ``start_xy`` and ``goal_xy`` (widened by margin_m); no path."""
        p = self.params
        start, goal = np.asarray(start_xy, float)[:2], np.asarray(goal_xy, float)[:2]
        lo, hi = np.minimum(start, goal) - p.margin_m, np.maximum(start, goal) + p.margin_m
        self.grid = OccupancyGrid(lo, hi, p.resolution_m, p.max_cells)
        self.goal = goal.copy()
        self.path = None                         # (K, 2) odom, ends at the goal
        self._path_cells: np.ndarray | None = None
        self._dist: np.ndarray | None = None     # distance to the nearest occupied cell at the last plan [m]
        self._next_plan_t = -math.inf
        self._dirty = True
        self.scan_ms: list[float] = []
        self.plan_ms: list[float] = []
        self.goal_ms: list[float] = []
        self.plans = self.failed_plans = 0
        self._stalled: np.ndarray | None = None  # step 5's extra cost per metre per cell (None: no stall yet)
        self._anchor: tuple[np.ndarray, float] | None = None     # (position, time) progress is measured from
        self.stalls: list[tuple[float, float, float]] = []       # (t, x, y) of each stall
        self._waiting = False                    # a moving track within wait_range_m at the latest scan (step 5)

    def scan(self, scan: LaserScan, pose, obstacles: Obstacles | None = None) -> None:
        """Integrate one scan taken with the robot at ``pose`` = (x, y, theta) in odom; returns near a moving track
        of ``obstacles`` (the perception's estimates from this scan) mark nothing."""
        if self.grid is None:
            raise RuntimeError("RouteLayer.scan before reset()")
        t0 = time.perf_counter()
        p, g = self.params, self.grid
        x, y, th = (float(v) for v in pose)
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(th)):
            return                               # a faulty pose maps nothing (the filter brakes on it)
        lx, ly, lyaw = self.laser_mount
        c, s = math.cos(th), math.sin(th)
        sensor = np.array([x + c * lx - s * ly, y + s * lx + c * ly])
        r = np.asarray(scan.ranges, float)
        ang = th + lyaw + scan.angle_min + scan.angle_increment * np.arange(len(r))
        valid = np.isfinite(r) & (r >= scan.range_min) & (r <= scan.range_max)
        hit = valid & (r <= p.mark_range_m)
        mp, mr = _movers(obstacles)
        if len(mr) and hit.any():
            b = np.flatnonzero(hit)
            pts = sensor + r[b, None] * np.c_[np.cos(ang[b]), np.sin(ang[b])]
            d = np.linalg.norm(pts[:, None, :] - mp[None], axis=2)
            near = (d <= mr[None] + p.dynamic_margin_m).any(axis=1)
            hit[b[near]] = False
        if p.wait_range_m > 0:                   # step 5: waiting for a mover whose edge is this near
            self._waiting = bool((np.hypot(mp[:, 0] - x, mp[:, 1] - y) - mr <= p.wait_range_m).any())
        clear_len = np.where(valid, np.minimum(r - 0.5 * g.res, p.clear_range_m), 0.0)
        g.integrate(sensor, ang, np.where(valid, r, 0.0), hit, clear_len, p)
        if self._path_cells is not None and len(self._path_cells):   # a return on the path ahead: replan now
            occ = g.logodds[self._path_cells[:, 0], self._path_cells[:, 1]] >= p.occupied_logodds
            if occ.any():
                self._dirty = True
        self.scan_ms.append(1e3 * (time.perf_counter() - t0))

    def plan(self, start_xy) -> np.ndarray | None:
        """Replan from ``start_xy`` to the goal on the current map; returns the path (K, 2) in odom (None: no
        path)."""
        t0 = time.perf_counter()
        p, g = self.params, self.grid
        cost, self._dist = cell_costs(g.occupied(p), g.unknown(), g.res, self.r_robot_m + self.d0_m, p,
                                      self._stalled)
        cells = shortest_path(cost, g.cell(start_xy), g.cell(self.goal))
        self.plans += 1
        if len(cells) == 0:
            self.failed_plans += 1
            self.path = self._path_cells = None
        else:
            path = g.centers(cells)
            path[-1] = self.goal                      # ends at the goal itself, not its cell's centre
            self.path, self._path_cells = path, cells
        self._dirty = False
        self.plan_ms.append(1e3 * (time.perf_counter() - t0))
        return self.path

    def local_goal(self, t: float, state: RobotState, goal) -> np.ndarray:
        """The goal handed to the method at time ``t`` [s]: the path's look-ahead point (module docstring, step 4),
        replanning first when due. A goal other than the one of ``reset`` starts its own path. A non-finite state
        gets the goal itself (the planner's ``fail_safe`` answers it)."""
        if self.grid is None:
            raise RuntimeError("RouteLayer.local_goal before reset()")
        t0 = time.perf_counter()
        goal = np.asarray(goal, float)
        if not np.array_equal(goal, self.goal):
            self.goal, self._dirty = goal.copy(), True
        pos = np.array([state.px, state.py])
        if not np.isfinite(pos).all():           # a faulty state: the goal as it is (the planner's fail_safe acts)
            return goal
        if self.params.progress_time_s > 0:
            self._progress(t, pos)
        if self._dirty or t >= self._next_plan_t:
            self.plan(pos)
            self._next_plan_t = t + 1.0 / self.params.replan_hz
        out = goal if self.path is None else self._carrot(pos)
        self.goal_ms.append(1e3 * (time.perf_counter() - t0))
        return out

    def _progress(self, t: float, pos: np.ndarray) -> None:
        """Step 5: a stall (no ``progress_radius_m`` of movement in ``progress_time_s``) makes the path ahead
        costly and asks for a new path; progress is measured afresh from there."""
        p = self.params
        if (self._anchor is None or self._waiting
                or np.linalg.norm(pos - self._anchor[0]) > p.progress_radius_m):
            self._anchor = (pos.copy(), t)
            return
        if t - self._anchor[1] < p.progress_time_s:
            return
        self._anchor = (pos.copy(), t)
        if self.path is None or p.stall_cost <= 0:
            return
        self.stalls.append((float(t), float(pos[0]), float(pos[1])))
        if self._stalled is None:
            self._stalled = np.zeros(self.grid.shape)
        self._stalled += p.stall_cost * self._stall_cells(pos)
        self._dirty = True

    def _stall_cells(self, pos: np.ndarray) -> np.ndarray:
        """(nx, ny) bool: the cells whose centre lies within r_R of the path's points from the one nearest ``pos``
        to ``stall_ahead_m`` of arc length ahead of it."""
        g = self.grid
        _, ahead, s = self._ahead(pos)
        pts = ahead[s <= self.params.stall_ahead_m]
        reach = max(self.r_robot_m, 0.5 * g.res)
        out = np.zeros(g.shape, bool)
        lo = g.cell(pts.min(axis=0) - reach)           # the cells that can lie within reach, clipped onto the grid
        hi = np.add(g.cell(pts.max(axis=0) + reach), 1)
        cx = g.x0 + (np.arange(lo[0], hi[0]) + 0.5) * g.res
        cy = g.y0 + (np.arange(lo[1], hi[1]) + 0.5) * g.res
        d2 = ((cx[:, None, None] - pts[None, None, :, 0]) ** 2
              + (cy[None, :, None] - pts[None, None, :, 1]) ** 2).min(axis=2)
        out[lo[0]:hi[0], lo[1]:hi[1]] = d2 <= reach * reach
        return out

    def _ahead(self, pos: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
        """The index of the path point nearest ``pos``, the path from it on, and the arc length along it from that
        point to each of its points."""
        path = self.path
        i0 = int(np.argmin(np.sum((path - pos) ** 2, axis=1)))
        ahead = path[i0:]
        return i0, ahead, np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(ahead, axis=0), axis=1))]

    def _carrot(self, pos: np.ndarray) -> np.ndarray:
        path = self.path
        i0, ahead, s = self._ahead(pos)
        s = np.linalg.norm(ahead[0] - pos) + s
        within = np.flatnonzero(s <= self.params.lookahead_m)
        pick = min(1, len(ahead) - 1)
        for j in within[::-1]:
            if self._visible(pos, ahead[j]):
                pick = int(j)
                break
        if pick < len(ahead) - 1 and np.linalg.norm(ahead[pick] - pos) <= self.arrive_m:
            # within the arrival tolerance the method would stop there: the first path point beyond it instead
            # (e.g. the goal, when a cell marked near it hides it: a person who stood there and left unseen)
            far = np.flatnonzero(np.linalg.norm(ahead[pick:] - pos, axis=1) > self.arrive_m)
            pick = pick + int(far[0]) if len(far) else len(ahead) - 1
        return self.goal.copy() if i0 + pick == len(path) - 1 else ahead[pick].copy()

    def _visible(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Whether the segment a -> b keeps r_R from every occupied cell (at the last plan), its part within
        r_R + d0 of a not counted (the robot may stand that close to a wall)."""
        g, d = self.grid, self._dist
        length = float(np.linalg.norm(b - a))
        skip = self.r_robot_m + self.d0_m
        if length <= skip:
            return True
        n = int(math.ceil(length / (0.5 * g.res)))
        u = np.linspace(skip / length, 1.0, max(n, 2))
        pts = a + u[:, None] * (b - a)
        ix = np.clip(np.floor((pts[:, 0] - g.x0) / g.res).astype(int), 0, g.nx - 1)
        iy = np.clip(np.floor((pts[:, 1] - g.y0) / g.res).astype(int), 0, g.ny - 1)
        return bool(np.all(d[ix, iy] >= self.r_robot_m))
