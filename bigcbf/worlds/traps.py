"""The ``traps`` world family: a concave obstacle on the start-goal line, its open side toward the robot: a
U-shaped pocket (walls on three sides) or an L-shaped dead end (a back wall and one side arm), shallow, medium or
deeper than the 1.2 m a 0.8 m/s robot covers in a 1.5 s look-ahead, in a walled lane with room to go around.

One file per family: importing the module registers the family in ``bigcbf.worlds.FAMILIES`` (the package
imports every module it holds), with the ranges ``bigcbf scenarios generate --list`` shows.
"""
from __future__ import annotations

import math

import numpy as np

from .generator import FAMILIES, Family
from .geometry import Draft, _polyline_points, _primitives, _r, _side, _u, distance

#: the depth classes (drawn with equal probability): interior depth from the opening to the back wall's face [m];
#: "deep" is deeper than 1.5 s x 0.8 m/s = 1.2 m, what a 1.5 s look-ahead at the speed limit reaches
DEPTHS = {"shallow": (0.4, 0.8), "medium": (0.8, 1.2), "deep": (1.3, 2.5)}


def first_hit(d: Draft) -> int | None:
    """The index (in ``d.boxes``) of the first box the straight line from the start to the goal runs into (sampled
    every 1 cm), or None if it runs into none."""
    seg = _polyline_points([d.start[:2], d.goal], 0.01)
    boxes, _ = _primitives(Draft(start=d.start, goal=d.goal, bounds=d.bounds, boxes=d.boxes))
    hits = [np.flatnonzero(distance(seg, boxes[k:k + 1], np.zeros((0, 3))) <= 0.0) for k in range(len(boxes))]
    firsts = [(h[0], k) for k, h in enumerate(hits) if len(h)]
    return min(firsts)[1] if firsts else None


def _onto_back_wall(d: Draft, time_limit: float) -> str | None:
    """The family's own requirement: driving straight at the goal leads into the trap, onto its back wall."""
    return None if first_hit(d) == 0 else "the straight line to the goal does not run into the trap's back wall"


def _traps(rng: np.random.Generator) -> Draft:
    shape = "U" if rng.random() < 0.6 else "L"
    depth_class = ("shallow", "medium", "deep")[int(rng.integers(0, 3))]
    depth = _u(rng, *DEPTHS[depth_class])
    width = _u(rng, 0.9, 2.2)                   # interior width between the wall faces [m]
    t = _u(rng, 0.10, 0.20)                     # wall thickness [m]
    x_open = _u(rng, 1.8, 3.5)                  # the opening, ahead of the start [m]
    phi = _u(rng, -0.3, 0.3)                    # the trap's yaw against the lane's axis [rad]
    behind = _u(rng, 0.8, 2.5)                  # goal behind the back wall's outer face [m]
    gap = _u(rng, 1.1, 2.2)                     # lane wall to the trap's widest point, each side [m]
    y_s = _u(rng, -0.3, 0.3)
    arm = _side(rng)                            # the L's arm: on the left (+1) or the right (-1)
    # the line from the start enters the pocket: its opening centre is this far from the line (L: toward its arm)
    off = _u(rng, -0.25, 0.25) * width if shape == "U" else arm * _u(rng, 0.0, 0.35) * width
    c, s = math.cos(phi), math.sin(phi)
    reach = depth + t                            # along the trap's axis, from the opening to the back's outer face
    half = width / 2 + t                         # across it, to the arms' outer faces
    y_open = y_s + off
    x_back = x_open + reach * c
    x_g = x_back + half * abs(s) + behind
    y_g = _r(y_s + _u(rng, -0.3, 0.3))
    # the trap's extent across the lane, rotated; the lane leaves ``gap`` beside it on both sides
    corners = [(u * c - v * s, u * s + v * c) for u in (0.0, reach) for v in (-half, half)]
    ys = [y_open + q[1] for q in corners]
    half_w = max(abs(min(ys)), abs(max(ys)), abs(y_g) + 0.8) + gap

    def world(u: float, v: float) -> tuple[float, float]:
        return (x_open + u * c - v * s, y_open + u * s + v * c)

    d = Draft(start=(0.0, _r(y_s), 0.0), goal=(_r(x_g), y_g), bounds=(-1.0, x_g + 1.5, -half_w, half_w),
              needs_detour=True, requirement=_onto_back_wall)
    d.wall((-1.0, -half_w), (x_g + 1.5, -half_w))
    d.wall((-1.0, half_w), (x_g + 1.5, half_w))
    # boxes (the straight-line check counts boxes, not the lane's walls): the back wall first (``first_hit``; its
    # inner face at ``depth``, spanning both arms' outer faces), then the arm(s) from the opening to the back wall
    d.box(world(depth + t / 2, 0.0), (t / 2, half), phi)
    for side in ((-1, 1) if shape == "U" else (arm,)):
        d.box(world(depth / 2, side * (width / 2 + t / 2)), (depth / 2, t / 2), phi)
    d.params = {"trap": ("U-shaped pocket" if shape == "U" else
                         f"L-shaped dead end, its arm on the {'left' if arm > 0 else 'right'}"),
                "depth": f"{depth:.2f} m ({depth_class})", "interior width": f"{width:.2f} m",
                "opening": f"{x_open:.2f} m ahead, its centre {off:+.2f} m beside the start-goal line",
                "yaw": f"{math.degrees(phi):+.0f} deg", "goal": f"{behind:.2f} m behind the back wall",
                "lane width": f"{2 * half_w:.2f} m"}
    return d


FAMILIES.add(Family(
    name="traps",
    summary="a U-shaped pocket or an L-shaped dead end on the start-goal line, open toward the robot",
    design="A concave obstacle stands on the straight line from the start to the goal with its open side toward "
           "the robot: a U-shaped pocket (a back wall and two side arms) or an L-shaped dead end (a back wall and "
           "one arm). Driving toward the goal leads into it; the way out is back through the opening and around "
           "the outside, where the walled lane leaves more than a metre on both sides. A third of the traps are "
           "deeper than the 1.2 m that a 1.5 s look-ahead at 0.8 m/s reaches, so a planner that only looks that "
           "far ahead sees no way out from inside.",
    ranges=("shape: U-shaped pocket (60 %) or L-shaped dead end (40 %, its arm on either side)",
            "depth (opening to back wall): shallow 0.4-0.8 m, medium 0.8-1.2 m or deep 1.3-2.5 m, a third each",
            "interior width: 0.9-2.2 m; wall thickness 0.10-0.20 m; yaw against the lane: -17..+17 deg",
            "opening 1.8-3.5 m ahead, its centre within a quarter width of the start-goal line (L: up to 0.35 "
            "width toward its arm); the straight line to the goal runs into the back wall (redrawn otherwise)",
            "goal 0.8-2.5 m behind the back wall",
            "lane: 1.1-2.2 m free beside the trap on both sides; start and goal up to 0.3 m off the axis"),
    build=_traps,
    order=7,
))
