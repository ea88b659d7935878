"""The ``fast`` world family: walkers faster than the robot (1.0-2.0 x its 0.8 m/s top speed) closing on it from
the side (alone, or two converging from both sides at about the same place and time), head-on and from behind,
reactive and not, in corridors and on open floor; many of them emerge from behind an occluder (a box, a pillar, a
wall corner, the edge of an opening in a corridor's wall), so the robot sees them late.

Timing: each walker is timed for a robot driving its straight path at a speed drawn per walker from 0.5-0.8 m/s
(``TIMED_FOR_MPS``: the time limit's planning speed up to the top speed; no method's speed): a walker from the side
crosses the robot's line where that robot would be, within +-0.5 s; a head-on one meets it; one from behind
catches up with it (or follows it when not faster). Head-on and overtaking walkers walk with their body on the
robot's line (in a corridor leaving a passage of 0.8 m beside them). A corridor's walkers from the side come from a
room behind either wall through an opening in it; the rooms are closed, so a robot that dodges into one can leave
it only the way it came, and reach back (away from the goal) only 0.3 m past the opening, so that they are no
pocket toward the goal for a local planner to be trapped in (that is the traps family's test).

A distance barrier cannot hold its safe set against a person who closes faster than the robot can move away, so
some contacts here are passive (``bigcbf/sim/contacts.py`` classifies them). So that an avoidable contact is the
robot's, every walker is checked at generation to be in the LiDAR's view for at least the last
``VISIBLE_BEFORE_S`` (1 s) before it can reach the robot's path (:func:`visible_in_time`): the occluders are every
wall, box and cylinder and every other walker's body where it is by then; a draw that fails is replaced. An
occluder is placed so that a walker standing behind it is hidden from where the robot is (at its assumed speed)
when the walker sets off, and the walker turns at the path from a stand-off of r + r_R + (1.1-1.8 s) x its speed,
so it comes into view about then; where the floor leaves no room to hide it (a fast walker timed for a fast robot
sets off late, with the robot already close), it is seen standing. Each world's description gives, per walker,
how long it is in view before it can reach the path, seen from a robot at its assumed speed (:func:`seen_for`).

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


def _hidden(q: np.ndarray, robot: np.ndarray, boxes: np.ndarray, circles: np.ndarray) -> bool:
    """Whether the line of sight from ``robot`` to ``q`` crosses a wall, box or cylinder or a body of
    ``circles`` (sampled every 5 cm: every wall is 0.1 m thick, every body and post wider)."""
    if not (len(boxes) + len(circles)):
        return False
    sight = _polyline_points([robot, q], 0.05)
    return bool(distance(sight, boxes, circles).min() <= 0.0)


def _reach_time(p: dict, start: np.ndarray, goal: np.ndarray, horizon_s: float) -> float | None:
    """The first time at which the walker's body can touch the robot's straight path (its centre within its
    radius + r_R of the segment), walking as drawn; None if not within ``horizon_s``."""
    for t in np.arange(0.0, horizon_s + _DT / 2, _DT):
        if _seg_dist(_walker_at(p, t), start, goal) <= p["radius_m"] + ROBOT_RADIUS_M:
            return float(t)
    return None


def _others(d: Draft, p: dict, t: float) -> np.ndarray:
    """The other walkers' bodies at time t, as drawn: circles (K, 3)."""
    return np.array([(*_walker_at(o, t), o["radius_m"]) for o in d.pedestrians if o is not p], float).reshape(-1, 3)


def visible_in_time(d: Draft, horizon_s: float) -> str | None:
    """The visibility check (None when every walker passes it, else the reason). For each walker, walking its
    path at its speed from its start time: the first time t_reach at which its body can touch the robot's straight
    path from start to goal (its centre within its radius + r_R = 0.15 m of the segment); over
    [t_reach - 1 s, t_reach] it must be within the LiDAR's range (``LIDAR_RANGE_M``) of the robot and its centre
    seen along a line that no wall, box, cylinder or other walker's body (where that walker is by then, as drawn)
    crosses, from where the robot would be by then on that path at any speed between the 0.5 m/s the time limit
    assumes and its top speed (``VIEW_SPEEDS_MPS``). A walker that can reach the path within the first second
    fails."""
    start, goal = np.array(d.start[:2], float), np.array(d.goal, float)
    length = float(np.linalg.norm(goal - start))
    boxes, circles = _primitives(d)
    for p in d.pedestrians:
        t_reach = _reach_time(p, start, goal, horizon_s)
        if t_reach is None:
            continue                           # never reaches the path within the time limit
        if t_reach < VISIBLE_BEFORE_S:
            return f"walker {p['name']} can reach the robot's path within {VISIBLE_BEFORE_S:g} s of the start"
        for t in np.arange(t_reach - VISIBLE_BEFORE_S, t_reach + _DT / 2, _DT):
            q = _walker_at(p, t)
            occluders = np.concatenate([circles, _others(d, p, t)])
            for v in VIEW_SPEEDS_MPS:
                robot = start + (goal - start) * min(1.0, v * t / max(length, 1e-9))
                if float(np.linalg.norm(q - robot)) > LIDAR_RANGE_M:
                    return (f"walker {p['name']} is beyond the LiDAR's range {t_reach - t:.2f} s before it can reach "
                            "the path")
                if _hidden(q, robot, boxes, occluders):
                    return f"walker {p['name']} is hidden {t_reach - t:.2f} s before it can reach the path"
    return None


def seen_for(d: Draft, p: dict, speed_mps: float, horizon_s: float = 60.0) -> float | None:
    """How long [s] walker ``p`` is continuously in view (within the LiDAR's range, its centre unoccluded as in
    :func:`visible_in_time`) before it can reach the robot's straight path, seen from the robot on that path at
    ``speed_mps``; None if it never reaches the path within ``horizon_s``. For the worlds' descriptions."""
    start, goal = np.array(d.start[:2], float), np.array(d.goal, float)
    length = float(np.linalg.norm(goal - start))
    boxes, circles = _primitives(d)
    t_reach = _reach_time(p, start, goal, horizon_s)
    if t_reach is None:
        return None
    t = t_reach
    while t > 0.0:
        q = _walker_at(p, t - _DT)
        robot = start + (goal - start) * min(1.0, speed_mps * (t - _DT) / max(length, 1e-9))
        if (float(np.linalg.norm(q - robot)) > LIDAR_RANGE_M
                or _hidden(q, robot, boxes, np.concatenate([circles, _others(d, p, t - _DT)]))):
            break
        t -= _DT
    return t_reach - max(t, 0.0)


#: the robot speeds a walker's timing assumes, one drawn per walker [m/s]
TIMED_FOR_MPS = (0.5, 0.8)
#: how far off that robot's arrival a walker reaches the robot's path [s]
TIMING_JITTER_S = 0.5
#: where an occluder's inner edge stands off the robot's path: r + r_R + (this many seconds) x the walker's speed
HIDE_LEAD_S = (1.1, 1.8)
OCCLUDERS = ("box", "pillar", "wall corner")
#: kinds of walker events and their shares: a pair is two walkers from the side, from opposite sides
EVENTS = (("side", 0.3), ("pair", 0.25), ("head-on", 0.25), ("behind", 0.2))


def _lane(rng, width: float, r: float) -> float:
    """A head-on or overtaking walker's lateral offset in a corridor of ``width`` (either side of the centre line,
    the robot's line): its body on the robot's line (offset at most r + 0.1 m, so it overlaps the robot's body
    there by at least 0.15 m), leaving a passage of at least MIN_PASSAGE_M on its other side."""
    lo = max(0.0, MIN_PASSAGE_M + r - width / 2)
    hi = min(width / 2 - r - 0.1, r + 0.1)
    return _side(rng) * _u(rng, lo, max(lo, hi))


def _on_line(rng, goal: tuple, r: float, x_m: float, x_a: float, x_b: float) -> tuple:
    """An open floor's head-on or overtaking walker's straight path from x = x_a to x = x_b: through the robot's
    line at x_m, offset at most r + 0.1 m from it (its body on it), at a slope of up to 0.05."""
    y_m = goal[1] * x_m / goal[0] + _u(rng, -(r + 0.1), r + 0.1)
    slope = _u(rng, -0.05, 0.05)
    return (x_a, y_m + slope * (x_a - x_m)), (x_b, y_m + slope * (x_b - x_m))


def _stand_off(x_w: float, x_face: float, y_in: float, r: float, half: float, robot_x: float) -> float:
    """How far from the robot's path [m] a walker at x_w stands so that an occluder's edge at (x_face, y_in) hides
    its centre from (robot_x, 0) with 0.2 m to spare (at most half - r - 0.15, inside the floor)."""
    near = x_face - robot_x
    y0 = y_in * (x_w - robot_x) / near + 0.2 if near > 0.3 else np.inf
    return float(min(half - r - 0.15, max(y_in + 0.3, y0)))


def _occluder(rng, d: Draft, x_w: float, x_face: float, s: int, y_in: float, y0: float, r: float, half: float,
              robot_x: float) -> str:
    """An occluder beside the robot's path on side s hiding a walker (radius r) that stands at (x_w, s y0) until it
    walks straight across the path, from the robot's side: a box or a wall corner (a wall from the side wall in to
    |y| = y_in) with its face toward +x at x_face, or a pillar (a cylinder of radius
    0.3-0.5 m) on the line of sight from (robot_x, 0), where the robot is when the walker sets off, when that
    leaves the walker's way clear (else a wall corner); its kind."""
    kind = OCCLUDERS[int(rng.integers(0, 3))]
    if kind == "pillar":
        rad = _u(rng, 0.3, 0.5)
        w = np.array([x_w, s * y0])
        u = (w - np.array([robot_x, 0.0])) / max(float(np.hypot(x_w - robot_x, y0)), 1e-9)
        dist = max(rad + r + 0.1, (rad + r + 0.1) / max(u[0], 1e-9))   # its edge 0.1 m off the walker's way
        c = w - u * dist
        if dist <= 3.0 and abs(c[1]) + rad <= half - 0.05 and abs(c[1]) - rad >= 0.2:
            d.cylinder((c[0], c[1]), rad)
            return kind
        kind = "wall corner"
    if kind == "box":
        hx = _u(rng, 0.2, 0.6)
        y_out = min(half - 0.15, y0 + r + 0.1)
        d.box((x_face - hx, s * (y_in + y_out) / 2), (hx, (y_out - y_in) / 2))
    else:
        d.wall((x_face - 0.05, s * y_in), (x_face - 0.05, s * (half + 0.05)))
    return kind


def _fast(rng: np.random.Generator) -> Draft:
    """One ``fast`` world drawn from ``rng`` (the family's ``ranges``): the layout, its occluders and the walkers'
    events, timed for a robot speed drawn per walker.

    Length: one world's random draws in their fixed order (each seed's world depends on that order); to be split
    (issue 22)."""
    corridor = rng.random() < 0.5
    x_g = _u(rng, 8.0, 11.0)
    width = _u(rng, 2.0, 3.0) if corridor else _u(rng, 6.0, 8.0)
    half = width / 2
    back = 5.0                                                  # the floor reaches this far behind the start
    d = Draft(start=(0.0, 0.0, 0.0), goal=(_r(x_g), _r(_u(rng, -0.3, 0.3) if not corridor else 0.0)),
              bounds=(-1.0, x_g + 1.0, -half, half))
    names, probs = zip(*EVENTS)
    events = [names[int(rng.choice(4, p=probs))]]
    if rng.random() < 0.5:
        events.append(names[int(rng.choice(4, p=probs))])
    if events.count("pair") + len(events) > 3:                 # at most 3 walkers
        events = events[:1]
    side_walkers = sum(2 if e == "pair" else e == "side" for e in events)
    if corridor and side_walkers > 2:                          # a corridor's crossing has one mouth a side
        events = events[:1]
        side_walkers = sum(2 if e == "pair" else e == "side" for e in events)
    # a corridor's walkers from the side come from a room behind either wall through an opening in it at x_c
    # (rooms closed all round, so a robot that dodges into one can only come back the same way)
    x_c = _u(rng, 3.5, x_g - 2.0)
    gap = _u(rng, 1.4, 2.4)
    depth = _u(rng, 2.0, 3.0)
    crossing = corridor and side_walkers > 0
    for y in (-half, half):
        if crossing:
            y_out = y + (depth if y > 0 else -depth)
            d.wall((-back, y), (x_c - gap / 2, y))
            d.wall((x_c + gap / 2, y), (x_g + 5.0, y))
            x_end = x_c + gap / 2 + 0.3                          # no pocket reaching on toward the goal
            d.wall((x_c - 4.0, y), (x_c - 4.0, y_out))
            d.wall((x_c - 4.0, y_out), (x_end, y_out))
            d.wall((x_end, y_out), (x_end, y))
        else:
            d.wall((-back, y), (x_g + 5.0, y))
    walkers = []                                               # (draft index, description, timed-for speed)
    used_sides: list[int] = []

    def draw_walker():
        r = _u(rng, *PED_RADIUS_M)
        factor = _u(rng, *SPEED_FACTOR)
        return r, factor, factor * V_MAX_MPS, rng.random() < 0.5, _u(rng, *TIMED_FOR_MPS)

    def side_walker(k: int, s: int, x_meet: float, t_meet: float):
        r, factor, v, reactive, v_a = draw_walker()
        y_turn = r + ROBOT_RADIUS_M + v * _u(rng, *HIDE_LEAD_S)   # where it turns straight at the path
        if corridor:
            # along the far side of the wall, from behind its robot-side part, then through the opening: the
            # opening's near edge hides it until it turns
            x0 = x_c + _u(rng, -1.0, 1.0) * (gap / 2 - r - 0.15)
            y_turn = min(max(y_turn, half + r + 0.15), half + depth - r - 0.75)
            # ... and on into the room across, to stop at its end away from the goal, clear of the opening
            x1 = x0 + _u(rng, -0.2, 0.2)
            path = [(x0 - _u(rng, 1.0, 2.5), s * (y_turn + _u(rng, 0.2, 0.6))), (x0, s * y_turn),
                    (x1, -s * (half + 1.0)), (x_c - 3.0, -s * (half + depth / 2))]
            where = f"through the opening at x {x0:.1f} m, from behind the wall"
        else:
            x0 = x_meet
            y_turn = min(y_turn, half - r - 0.45)                 # room behind the occluder to stand in
        if t_meet is None:
            t_meet = x0 / v_a + _u(rng, -TIMING_JITTER_S, TIMING_JITTER_S)
        if not corridor:
            # it stands where the occluder hides it from the robot (at v_a) when it sets off
            x_face = x0 - r - _u(rng, 0.15, 0.4)
            y0 = y_turn + 0.3
            for _ in range(2):
                y0 = _stand_off(x0, x_face, y_turn, r, half, v_a * max(0.0, t_meet - y0 / v))
            path = [(x0, s * y0), (x0 + _u(rng, -0.5, 0.5), -s * (half - r - 0.15))]
            kind = _occluder(rng, d, x0, x_face, s, y_turn, y0, r, half, v_a * max(0.0, t_meet - y0 / v))
            where = f"from behind a {kind} at x {x0:.1f} m"
        # its centre crosses the robot's line at t_meet
        t0 = t_meet - (float(np.linalg.norm(np.subtract(path[1], path[0]))) + abs(path[1][1])) / v \
            if corridor else t_meet - abs(path[0][1]) / v
        d.pedestrian(f"side{k}", path, v, t0, r, reactive)
        walkers.append((len(d.pedestrians) - 1, f"from the {'left' if s > 0 else 'right'} {where}", v, factor,
                        reactive, v_a))
        return t_meet

    k = 0
    for e in events:
        if e in ("side", "pair"):
            s = _side(rng)
            if s in used_sides:
                s = -s
            if corridor and s in used_sides:
                continue
            x_meet = x_c if corridor else _u(rng, 3.0, x_g - 1.5)
            k += 1
            used_sides.append(s)
            t_meet = side_walker(k, s, x_meet, None)
            if e == "pair":                       # a second walker from the other side, about the same time
                k += 1
                used_sides.append(-s)
                side_walker(k, -s, x_meet + (0.0 if corridor else _u(rng, -0.6, 0.6)),
                            t_meet + _u(rng, -TIMING_JITTER_S, TIMING_JITTER_S))
                i, where, *rest = walkers[-1]
                walkers[-1] = (i, f"{where}, converging with side{k - 1}", *rest)
        elif e == "head-on":
            k += 1
            r, factor, v, reactive, v_a = draw_walker()
            if corridor or rng.random() < 0.4:
                # along the robot's lane from beyond the goal: seen once within the LiDAR's range
                x_m = _u(rng, 2.5, x_g - 1.0)
                t_m = x_m / v_a + _u(rng, -TIMING_JITTER_S, TIMING_JITTER_S)
                if corridor:
                    y = _lane(rng, width, r)
                    path = [(x_g + 4.0, y), (-back + 0.5, y)]
                else:
                    path = list(_on_line(rng, d.goal, r, x_m, x_g + 4.0, -back + 0.5))
                t0 = t_m - (x_g + 4.0 - x_m) / v
                where = "along the robot's lane from beyond the goal"
            else:
                # stands behind an occluder beside the path ahead, steps into the lane and walks at the robot
                s = _side(rng)
                x_h = _u(rng, 4.0, x_g - 0.5)
                y_in = min(r + ROBOT_RADIUS_M + v * _u(rng, *HIDE_LEAD_S), half - r - 0.45)
                y = _u(rng, -0.3, 0.3)
                gap_m = _u(rng, 2.0, 4.0)         # the robot is this far back when the walker steps into the lane
                t_in = (x_h - gap_m) / v_a + _u(rng, -TIMING_JITTER_S, TIMING_JITTER_S)
                x_face = x_h - r - _u(rng, 0.15, 0.4)
                y0 = y_in + 0.3
                for _ in range(2):
                    y0 = _stand_off(x_h, x_face, y_in, r, half, v_a * max(0.0, t_in - abs(y0 - s * y) / v))
                path = [(x_h, s * y0), (x_h, y), (-back + 0.5, y)]
                t0 = t_in - abs(s * y0 - y) / v
                kind = _occluder(rng, d, x_h, x_face, s, y_in, y0, r, half, v_a * max(0.0, t0))
                where = f"stepping out from behind a {kind} at x {x_h:.1f} m"
            d.pedestrian(f"headon{k}", path, v, t0, r, reactive)
            walkers.append((len(d.pedestrians) - 1, where, v, factor, reactive, v_a))
        else:
            k += 1
            r, factor, v, reactive, v_a = draw_walker()
            x_s = -_u(rng, 2.5, 4.5)
            # catches up with a robot at v_a at x_m (never, at the robot's speed or slower: then it follows)
            x_m = _u(rng, 2.0, x_g - 1.5)
            t0 = x_m / v_a - (x_m - x_s) / v if v > v_a else _u(rng, 0.0, 2.0)
            if corridor:
                y = _lane(rng, width, r)
                path = [(x_s, y), (x_g + 4.0, y)]
            else:
                path = list(_on_line(rng, d.goal, r, x_m, x_s, x_g + 4.0))
            d.pedestrian(f"behind{k}", path, v, t0, r, reactive)
            walkers.append((len(d.pedestrians) - 1, f"from {-x_s:.1f} m behind the start", v, factor, reactive, v_a))
    described = []
    for i, where, v, factor, reactive, v_a in walkers:
        seen = seen_for(d, d.pedestrians[i], v_a)
        described.append(f"{d.pedestrians[i]['name']} {where} at {v:.2f} m/s ({factor:.2f} x v_max)"
                         f"{'' if reactive else ', non-reactive'}, timed for a robot at {v_a:.2f} m/s"
                         + (f", in view {seen:.1f} s before it can reach the path" if seen is not None
                            else ", never on the straight path"))
    d.params = {"layout": (f"corridor {width:.2f} m wide" + (f", an opening {gap:.2f} m wide in both walls "
                                                              f"{x_c:.1f} m ahead into a room {depth:.2f} m deep "
                                                              "behind either" if crossing else "")) if corridor
                else f"open floor {width:.2f} m wide", "walkers": "; ".join(described)}
    d.requirement = lambda dr, limit: visible_in_time(dr, limit)
    return d


FAMILIES.add(Family(
    name="fast",
    summary="walkers 1-2x faster than the robot, from the side (also two converging), head-on and from behind, "
            "many emerging from behind an occluder",
    design="Walkers faster than the robot (1.0-2.0 times its 0.8 m/s top speed) close on it from the side (alone, "
           "or two converging from both sides), head-on or from behind, reactive and not, in a corridor or on open "
           "floor; many come out from behind an occluder (the edge of an opening in the corridor's wall, a box, a "
           "pillar, a wall corner) and are seen late. Each walker is timed for a robot driving straight at a speed "
           "drawn from 0.5-0.8 m/s. A distance barrier cannot hold its set against a person who closes faster than "
           "the robot can move away: contacts are classified at fault or passive. Every walker is in the LiDAR's "
           "view (within range, not hidden by walls, boxes, pillars or other walkers) for at least the last second "
           "before it can reach the robot's straight path, so an avoidable contact is the robot's.",
    ranges=("layout: corridor 2.0-3.0 m wide or open floor 6-8 m wide, 50/50; goal 8-11 m ahead; in a corridor "
            "with walkers from the side, an opening 1.4-2.4 m wide in both walls, 3.5 m ahead up to 2 m short of "
            "the goal, into a room behind either wall (2-3 m deep, from 4 m before the opening's centre to 0.3 m "
            "past its far edge)",
            "events: 1 or 2 (50/50; at most 3 walkers): from the side 30 %, a pair from both sides 25 %, head-on "
            "25 %, from behind 20 %",
            "walkers: 0.8-1.6 m/s (1.0-2.0 x v_max), radius 0.2-0.3 m, reactive 50/50; each timed for a robot "
            "driving straight at 0.5-0.8 m/s (drawn per walker)",
            "from the side: crosses the robot's line where that robot would be, +-0.5 s (on open floor 3 m ahead "
            "up to 1.5 m short of the goal, in a corridor at the opening; a pair's second walker +-0.5 s from the "
            "first, within 0.6 m); it turns straight at the line r + 0.15 m + (1.1-1.8 s) x its speed from it: in a "
            "corridor after coming 1-2.5 m along behind the wall in its room (turning at least r + 0.15 m beyond "
            "the wall) to the opening, then on into the room across to stop 3 m back from the opening's centre; on "
            "open floor from where it stands behind an occluder with its inner edge there: a box, a pillar (on the "
            "line of sight) or a wall corner (1/3 each)",
            "head-on: in a corridor along a lane from beyond the goal, its body on the robot's line (offset at "
            "most r + 0.1 m, a passage of 0.8 m left beside it), meeting that robot 2.5 m ahead up to 1 m short of "
            "the goal, +-0.5 s; on open floor 40 % so (through the robot's line there, slope up to 0.05), 60 % "
            "stepping out from behind an occluder 4 m ahead up to 0.5 m short of the goal into the robot's lane "
            "when that robot is 2-4 m away (+-0.5 s), then walking at it",
            "from behind: on the robot's line as head-on ones, starts 2.5-4.5 m behind the robot, timed to catch "
            "it 2 m ahead up to 1.5 m short of the goal (when faster than that robot; else 0-2 s in, following it)",
            f"checked: each walker within {LidarModel().range_max_m:g} m and unoccluded (walls, boxes, cylinders, "
            f"other walkers) for the last {VISIBLE_BEFORE_S:g} s before it can reach the robot's straight path, seen "
            f"from the robot on it at {PLAN_SPEED_MPS:g}-{V_MAX_MPS:g} m/s"),
    build=_fast,
    order=8,
))
