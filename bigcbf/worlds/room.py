"""The ``room`` world family: a closed room with furniture-like boxes and posts, random start, goal and start
heading, an obstacle near the straight line between them, sometimes 1-2 walkers.

One file per family: importing the module registers the family in ``bigcbf.worlds.FAMILIES`` (the package
imports every module it holds), with the ranges ``bigcbf scenarios generate --list`` shows.
"""
from __future__ import annotations

import math

import numpy as np

from .generator import FAMILIES, Family
from .geometry import Draft, FOOTPRINT_M, PED_RADIUS_M, _r, _side, _u


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


FAMILIES.add(Family(
    name="room",
    summary="a closed room with furniture, random start, goal and heading",
    design="A closed rectangular room with furniture-like boxes and round posts, one of them near the straight "
           "line from the start to the goal. Start and goal are anywhere in the room at least 4 m apart, and the "
           "robot starts facing any direction (it drives holonomically). Sometimes one or two people walk across "
           "the room.",
    ranges=("room: 6-10 m x 5-8 m", "obstacles: 2-7 (boxes of half size 0.2-0.7 m x 0.2-0.5 m, posts of radius "
            "0.15-0.35 m)", "start-goal distance: at least 4 m and half the room's diagonal",
            "walkers: 0 (50 %), 1 or 2 (25 % each), crossing the start-goal line, reactive 50/50"),
    build=_room,
    order=6,
))
