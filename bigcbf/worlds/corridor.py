"""The ``corridor`` world family: corridors 1.6-3.0 m wide with walkers both ways at 0.3-1.3 m/s; in most of them a
slow walker (0.2-0.35 m/s) ahead of the robot in its direction, slow enough that following it to the goal misses the
time limit, so the robot has to overtake.

One file per family: importing the module registers the family in ``bigcbf.worlds.FAMILIES`` (the package
imports every module it holds), with the ranges ``bigcbf scenarios generate --list`` shows.
"""
from __future__ import annotations

import numpy as np

from .generator import FAMILIES, Family
from .geometry import Draft, MIN_PASSAGE_M, PED_RADIUS_M, PLAN_SPEED_MPS, _r, _side, _u


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


FAMILIES.add(Family(
    name="corridor",
    summary="corridors 1.6-3.0 m wide with walkers both ways, often a slow one ahead",
    design="A straight corridor with walkers in both directions, each direction keeping to one side, each walker "
           "in a lane that leaves a passage of at least 0.8 m on its other side. In most worlds a slow walker (0.2-0.35 m/s) goes ahead of the robot, its way, "
           "slow enough that following it to the goal misses the time limit: the robot has to commit to one "
           "side and overtake, between the walkers coming the other way.",
    ranges=("width: 1.6-3.0 m", "length: 12.5-16.5 m (goal 9-13 m ahead)",
            "slow walker ahead: 70 % of worlds, 0.2-0.35 m/s (at most the speed that forces overtaking)",
            "other walkers: 1-4, 75 % coming the other way (0.3-1.3 m/s, timed to meet the robot), 25 % ahead of "
            "it walking its way faster (0.6-1.3 m/s)", "each walker reactive or not, 50/50; radius 0.2-0.3 m",
            "walkers going the robot's way keep to one side (drawn), the others to the other side"),
    build=_corridor,
    order=3,
))
