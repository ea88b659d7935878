"""The ``doorway`` world family: a cross wall with a door (thin) or a bottleneck (0.6-1.5 m deep), 0.8-1.2 m wide,
on the way to the goal, with pedestrians coming through it against the robot (and sometimes one with it).

One file per family: importing the module registers the family in ``bigcbf.worlds.FAMILIES`` (the package
imports every module it holds), with the ranges ``bigcbf scenarios generate --list`` shows.
"""
from __future__ import annotations

import math

import numpy as np

from .generator import FAMILIES, Family
from .geometry import Draft, PED_RADIUS_M, PLAN_SPEED_MPS, _r, _side, _u


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


FAMILIES.add(Family(
    name="doorway",
    summary="a door or bottleneck 0.8-1.2 m wide with counter-flow pedestrians",
    design="A cross wall blocks a walled lane except for one opening, a door in a thin wall or a bottleneck up to "
           "1.5 m deep, on the way from the start to the goal, barely wide enough for the robot or for one "
           "pedestrian. Pedestrians on the far side come through it toward the robot around the time it arrives (sometimes one also goes through with the "
           "robot): the robot has to wait for the opening to clear, or take it first, without meeting anyone "
           "inside.",
    ranges=("opening: 0.8-1.2 m wide, door (0.10-0.25 m deep) or bottleneck (0.6-1.5 m deep), 50/50",
            "the start-goal line crosses the cross wall (3.5-5 m ahead) within 0.25 m of the opening's centre",
            "counter-flow pedestrians: 1-3, 0.5-1.3 m/s, walking from the start, the last 2-3 m straight at the "
            "opening, reaching it 1-3.5 s apart around when the robot would; reactive 50/50", "a pedestrian going the robot's way: 30 % of worlds, ahead of the robot from the start (0.5-1.0 m/s)",
            "lane width 5-7 m; goal 2.5-4 m past the opening"),
    build=_doorway,
    order=4,
))
