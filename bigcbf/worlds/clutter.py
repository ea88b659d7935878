"""The ``clutter`` world family: random cylinders and boxes covering 5-20 % of a walled lane (BARN-like density).

One file per family: importing the module registers the family in ``bigcbf.worlds.FAMILIES`` (the package
imports every module it holds), with the ranges ``bigcbf scenarios generate --list`` shows.
"""
from __future__ import annotations

import math

import numpy as np

from .generator import FAMILIES, Family
from .geometry import Draft, FOOTPRINT_M, _r, _u


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


FAMILIES.add(Family(
    name="clutter",
    summary="random cylinders and boxes in a walled lane (BARN-like density)",
    design="Cylinders and boxes of random size and orientation are scattered over a walled lane, overlapping "
           "freely (which makes clusters and dead ends), up to a drawn share of its area, as in BARN's "
           "generated worlds. The start and the goal are kept clear.",
    ranges=("covered share of the cluttered area: 5-20 %", "cylinders (60 %): radius 0.10-0.35 m",
            "boxes (40 %): half sizes 0.1-0.5 m, any yaw", "lane: 10.5-13.5 m long, 5-7 m wide",
            "goal 8-11 m ahead, up to 1 m off the axis"),
    build=_clutter,
    order=2,
))
