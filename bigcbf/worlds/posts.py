"""The ``posts`` world family: staggered rows of round posts across a walled lane (gaps 0.8-1.2 m; the first row
sometimes mirror-symmetric about the start-goal line, with a post or a gap on it).

One file per family: importing the module registers the family in ``bigcbf.worlds.FAMILIES`` (the package
imports every module it holds), with the ranges ``bigcbf scenarios generate --list`` shows.
"""
from __future__ import annotations

import math

import numpy as np

from .generator import FAMILIES, Family
from .geometry import Draft, _r, _u


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


FAMILIES.add(Family(
    name="posts",
    summary="staggered rows of round posts across a walled lane",
    design="Rows of round posts stand across a walled lane, each row staggered by half a pitch against the one "
           "before, so that no straight line threads all rows: the robot has to pick a gap in every row and "
           "shift sideways between rows. When the first row is symmetric about the start-goal line (a post or "
           "a gap on it), neither side is better, and a planner that keeps changing its mind stalls in front of it.",
    ranges=("rows: 2-4", "gap between posts of a row: 0.8-1.2 m (surface to surface)", "post radius: 0.08-0.20 m",
            "row spacing: 1.2-2.0 m", "first row: 50 % symmetric about the start-goal line (a post or a gap on it)",
            "lane width: 5-7 m, walls on both sides; start and goal up to 0.4 m off the axis"),
    build=_posts,
    order=1,
))
