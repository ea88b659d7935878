"""The ``fast`` world family: walkers faster than the robot (1.0-2.0 x its 0.8 m/s top speed) closing on it from
the side, head-on and from behind, reactive and not, in corridors (with a crossing, for the walkers from the side)
and on open floor.

A distance barrier cannot hold its safe set against a person who closes faster than the robot can move away, so
some contacts here are passive (``bigcbf/sim/contacts.py`` classifies them). So that an avoidable contact is the
robot's, every walker is checked at generation to be in the LiDAR's view for at least the last
``VISIBLE_BEFORE_S`` (1 s) before it can reach the robot's path (:func:`visible_in_time`).

One file per family: importing the module registers the family in ``bigcbf.worlds.FAMILIES`` (the package
imports every module it holds), with the ranges ``bigcbf scenarios generate --list`` shows.
"""
from __future__ import annotations

import numpy as np

from ..params.robot import LidarModel
from ..params.stack import StackParams
from .generator import FAMILIES, Family
from .geometry import (MIN_PASSAGE_M, PED_RADIUS_M, PLAN_SPEED_MPS, ROBOT_RADIUS_M, Draft, _polyline_points,
                       _primitives, _r, _side, _u, distance)

#: the robot's top speed [m/s] (the stack's v_max_mps); walkers walk at 1.0-2.0 times it
V_MAX_MPS = StackParams().v_max_mps
SPEED_FACTOR = (1.0, 2.0)
#: every walker is in the LiDAR's view at least this long before it can reach the robot's path [s]
VISIBLE_BEFORE_S = 1.0
#: the LiDAR's range the check assumes: the default robot profile's [m]
LIDAR_RANGE_M = LidarModel().range_max_m
#: the robot's speeds along its straight path from which a walker must be seen (module docstring) [m/s]
VIEW_SPEEDS_MPS = tuple(float(v) for v in np.linspace(PLAN_SPEED_MPS, V_MAX_MPS, 4))
KINDS = ("side", "head-on", "behind")
_DT = 0.05


def _walker_at(p: dict, t: float) -> np.ndarray:
    """Where a walker is at time t walking its polyline at its speed from its start time (standing before and
    after), as drawn (the simulation's social forces may move a reactive one off it)."""
    w = np.asarray(p["waypoints"], float)
    s = max(0.0, t - p["start_time_s"]) * p["speed_mps"]
    for a, b in zip(w[:-1], w[1:]):
        seg = float(np.linalg.norm(b - a))
        if s <= seg:
            return a + (b - a) * (s / max(seg, 1e-12))
        s -= seg
    return w[-1]


def _seg_dist(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    t = min(1.0, max(0.0, float((q - a) @ ab) / max(float(ab @ ab), 1e-12)))
    return float(np.linalg.norm(q - (a + t * ab)))


def visible_in_time(d: Draft, horizon_s: float) -> str | None:
    """The visibility check (None when every walker passes it, else the reason). For each walker, walking its
    path at its speed from its start time: the first time t_reach at which its body can touch the robot's straight
    path from start to goal (its centre within its radius + r_R = 0.15 m of the segment); over
    [t_reach - 1 s, t_reach] it must be within the LiDAR's range (``LIDAR_RANGE_M``) of the robot and its centre
    seen along a line that no wall, box or cylinder crosses, from where the robot would be by then on that path at
    any speed between the 0.5 m/s the time limit assumes and its top speed (``VIEW_SPEEDS_MPS``). A walker that
    can reach the path within the first second fails."""
    start, goal = np.array(d.start[:2], float), np.array(d.goal, float)
    length = float(np.linalg.norm(goal - start))
    boxes, circles = _primitives(d)
    for p in d.pedestrians:
        t_reach = None
        for t in np.arange(0.0, horizon_s + _DT / 2, _DT):
            if _seg_dist(_walker_at(p, t), start, goal) <= p["radius_m"] + ROBOT_RADIUS_M:
                t_reach = float(t)
                break
        if t_reach is None:
            continue                           # never reaches the path within the time limit
        if t_reach < VISIBLE_BEFORE_S:
            return f"walker {p['name']} can reach the robot's path within {VISIBLE_BEFORE_S:g} s of the start"
        for t in np.arange(t_reach - VISIBLE_BEFORE_S, t_reach + _DT / 2, _DT):
            q = _walker_at(p, t)
            for v in VIEW_SPEEDS_MPS:
                robot = start + (goal - start) * min(1.0, v * t / max(length, 1e-9))
                if float(np.linalg.norm(q - robot)) > LIDAR_RANGE_M:
                    return (f"walker {p['name']} is beyond the LiDAR's range {t_reach - t:.2f} s before it can reach "
                            "the path")
                sight = _polyline_points([robot, q], 0.05)
                if len(boxes) + len(circles) and distance(sight, boxes, circles).min() <= 0.0:
                    return f"walker {p['name']} is hidden {t_reach - t:.2f} s before it can reach the path"
    return None


def _lane(rng, width: float, r: float) -> float:
    """A head-on or overtaking walker's lateral offset in a corridor of ``width`` (either side of the centre line):
    inside with 0.1 m to spare, leaving a passage of at least MIN_PASSAGE_M on its other side."""
    lo = max(0.0, MIN_PASSAGE_M + r - width / 2)
    hi = width / 2 - r - 0.1
    return _side(rng) * _u(rng, lo, max(lo, hi))


def _fast(rng: np.random.Generator) -> Draft:
    corridor = rng.random() < 0.5
    x_g = _u(rng, 8.0, 11.0)
    width = _u(rng, 2.0, 3.0) if corridor else _u(rng, 5.0, 7.0)
    half = width / 2
    back = 5.0                                                  # the floor reaches this far behind the start
    d = Draft(start=(0.0, 0.0, 0.0), goal=(_r(x_g), _r(_u(rng, -0.3, 0.3) if not corridor else 0.0)),
              bounds=(-1.0, x_g + 1.0, -half, half))
    n = int(rng.integers(1, 4))
    kinds = [KINDS[int(rng.integers(0, 3))] for _ in range(n)]
    # a corridor's walkers from the side come through a crossing: both walls open 1.6-2.4 m wide around x_c
    x_c = _u(rng, 3.0, x_g - 2.0)
    gap = _u(rng, 1.6, 2.4)
    for y in (-half, half):
        if corridor and "side" in kinds:
            d.wall((-back, y), (x_c - gap / 2, y))
            d.wall((x_c + gap / 2, y), (x_g + 5.0, y))
        else:
            d.wall((-back, y), (x_g + 5.0, y))
    described = []
    n_non = 0
    for k, kind in enumerate(kinds):
        r = _u(rng, *PED_RADIUS_M)
        factor = _u(rng, *SPEED_FACTOR)
        v = factor * V_MAX_MPS
        reactive = rng.random() < 0.5
        n_non += not reactive
        s = _side(rng)
        if kind == "side":
            if corridor:
                x0 = x_c + _u(rng, -0.3, 0.3) * (gap / 2 - r)
                path = [(x0, s * (half + 2.5)), (x0 + _u(rng, -0.2, 0.2), -s * (half + 2.5))]
            else:
                x0 = _u(rng, 2.5, x_g - 1.5)
                path = [(x0 + _u(rng, -1.0, 1.0), s * (half - 0.45)), (x0 + _u(rng, -1.0, 1.0), -s * (half - 0.45))]
            x_meet = 0.5 * (path[0][0] + path[1][0])
            t0 = x_meet / PLAN_SPEED_MPS - abs(path[0][1]) / v + _u(rng, -1.5, 1.5)
        elif kind == "head-on":
            y = _lane(rng, width, r) if corridor else _u(rng, -1.0, 1.0)
            path = [(x_g + 4.0, y), (-back + 0.5, y + (0.0 if corridor else _u(rng, -1.0, 1.0)))]
            x_meet = _u(rng, 2.5, x_g - 1.0)
            t0 = x_meet / PLAN_SPEED_MPS - (x_g + 4.0 - x_meet) / v + _u(rng, -1.5, 1.5)
        else:
            y = _lane(rng, width, r) if corridor else _u(rng, -0.8, 0.8)
            path = [(-_u(rng, 2.5, 4.5), y), (x_g + 4.0, y + (0.0 if corridor else _u(rng, -1.0, 1.0)))]
            t0 = _u(rng, 0.0, 4.0)
        d.pedestrian(f"{kind.replace('-', '')}{k + 1}", path, v, t0, r, reactive)
        described.append(f"{kind} at {v:.2f} m/s ({factor:.2f} x v_max){'' if reactive else ', non-reactive'}")
    d.params = {"layout": (f"corridor {width:.2f} m wide" + (f", a crossing {gap:.2f} m wide {x_c:.1f} m ahead"
                                                              if "side" in kinds else "")) if corridor
                else f"open floor {width:.2f} m wide", "walkers": "; ".join(described)}
    d.requirement = lambda dr, limit: visible_in_time(dr, limit)
    return d


FAMILIES.add(Family(
    name="fast",
    summary="walkers 1-2x faster than the robot, from the side, head-on and from behind",
    design="Walkers faster than the robot (1.0-2.0 times its 0.8 m/s top speed) close on it from the side, "
           "head-on or from behind, reactive and not, in a corridor (the walkers from the side through a crossing) "
           "or on open floor. A distance barrier cannot hold its set against a person who closes faster than the "
           "robot can move away: contacts are classified at fault or passive. Every walker is in the LiDAR's view "
           "(within range, not hidden by walls) for at least the last second before it can reach the robot's "
           "straight path, so an avoidable contact is the robot's.",
    ranges=("layout: corridor 2.0-3.0 m wide (with a crossing 1.6-2.4 m wide when a walker comes from the side) "
            "or open floor 5-7 m wide, 50/50; goal 8-11 m ahead",
            "walkers: 1-3, each from the side, head-on or from behind (1/3 each), 0.8-1.6 m/s (1.0-2.0 x v_max), "
            "radius 0.2-0.3 m, reactive 50/50",
            "timing: side and head-on walkers reach the robot's way 1.5 s before to 1.5 s after a robot at "
            "0.5 m/s would; walkers from behind start 2.5-4.5 m behind it, 0-4 s in",
            f"checked: each walker within {LidarModel().range_max_m:g} m and unoccluded for the last "
            f"{VISIBLE_BEFORE_S:g} s before it can reach the robot's straight path, seen from the robot on it at "
            f"{PLAN_SPEED_MPS:g}-{V_MAX_MPS:g} m/s"),
    build=_fast,
    order=8,
))
