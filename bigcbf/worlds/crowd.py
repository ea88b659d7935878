"""The ``crowd`` world family: 3-10 pedestrians crossing, meeting and cutting diagonally across the robot's way, a
drawn share of them non-reactive (they ignore the robot).

One file per family: importing the module registers the family in ``bigcbf.worlds.FAMILIES`` (the package
imports every module it holds), with the ranges ``bigcbf scenarios generate --list`` shows.
"""
from __future__ import annotations

import numpy as np

from .generator import FAMILIES, Family
from .geometry import Draft, PED_RADIUS_M, _polyline_points, _r, _side, _u


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


FAMILIES.add(Family(
    name="crowd",
    summary="3-10 pedestrians crossing, meeting and cutting across, reactive and not",
    design="Open floor between two walls; pedestrians cross the robot's way from both sides, come head-on from "
           "beyond the goal, or cut diagonally, timed to reach the robot's way around when it gets there. A "
           "drawn share of them ignore the robot (non-reactive); the others step aside (social force).",
    ranges=("pedestrians: 3-10 (60 % crossing, 25 % head-on, 15 % diagonal), 0.5-1.3 m/s, radius 0.2-0.3 m",
            "non-reactive share: drawn in 0-60 %", "timing: each reaches the robot's way 2 s before to 1.5 s after a "
            "robot at 0.55 m/s would", "floor: 10.5-13.5 m long, 5-7 m wide; goal 8-11 m ahead"),
    build=_crowd,
    order=5,
))
