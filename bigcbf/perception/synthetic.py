"""Synthetic LiDAR scans by exact ray-circle and ray-segment intersection (no physics, no simulator), shaped like
the simulated LiDAR: 360 beams, angle_min = -pi, increment 2 pi / 360, range 0.12..8 m, float32 ranges, inf for a
miss. Used by the perception tests and by ``bigcbf perf`` (perception_ms); handy to try parameters on a laptop.
"""
from __future__ import annotations

import numpy as np

from ..params.perception import X3_LASER_MOUNT
from ..types import LaserScan

N_BEAMS = 360
ANGLE_MIN = -np.pi
ANGLE_INC = 2 * np.pi / N_BEAMS
RANGE_MIN, RANGE_MAX = 0.12, 8.0
LASER = X3_LASER_MOUNT              # laser pose in base_link: x [m], y [m], yaw [rad] (Rosmaster X3 model)


def box_segments(cx: float, cy: float, hx: float, hy: float, yaw: float = 0.0) -> list[tuple[float, ...]]:
    """The four sides (x0, y0, x1, y1) of a rectangle with centre (cx, cy), half sizes (hx, hy), rotated by yaw."""
    c, s = np.cos(yaw), np.sin(yaw)
    loc = [(hx, hy), (-hx, hy), (-hx, -hy), (hx, -hy)]
    pts = [(cx + c * a - s * b, cy + s * a + c * b) for a, b in loc]
    return [(*pts[k], *pts[(k + 1) % 4]) for k in range(4)]


def sensor_origin(pose, laser=LASER) -> np.ndarray:
    """The laser's origin in odom for the robot pose (x, y, theta)."""
    x, y, th = pose
    return np.array([x + np.cos(th) * laser[0] - np.sin(th) * laser[1],
                     y + np.sin(th) * laser[0] + np.cos(th) * laser[1]])


def ray_scan(pose, circles=(), segments=(), stamp: float = 0.0, noise: float = 0.0,
             rng: np.random.Generator | None = None, laser=LASER) -> LaserScan:
    """The scan seen from robot pose (x, y, theta): circles (cx, cy, r), segments (x0, y0, x1, y1), all in odom.

    Each beam's range is the nearest positive intersection t of o + t d with the circles |p - c| = r
    (t = -b -+ sqrt(b^2 - |o - c|^2 + r^2), b = d.(o - c)) and segments (solving o + t d = p0 + s (p1 - p0),
    s in [0, 1]); Gaussian range noise of std ``noise`` is added; out of [0.12, 8] m reads inf.
    """
    o = sensor_origin(pose, laser)
    a = ANGLE_MIN + ANGLE_INC * np.arange(N_BEAMS) + laser[2] + pose[2]
    d = np.stack([np.cos(a), np.sin(a)], axis=1)
    best = np.full(N_BEAMS, np.inf)
    for cx, cy, r in circles:
        oc = o - np.array([cx, cy])
        b = d @ oc
        disc = b * b - (oc @ oc - r * r)
        sq = np.sqrt(np.maximum(disc, 0.0))
        for t in (-b - sq, -b + sq):
            hit = (disc >= 0) & (t > 1e-9)
            best = np.where(hit & (t < best), t, best)
    for x0, y0, x1, y1 in segments:
        e = np.array([x1 - x0, y1 - y0])
        w = np.array([x0, y0]) - o
        den = -d[:, 0] * e[1] + d[:, 1] * e[0]                              # det [d, -e]
        ok = np.abs(den) > 1e-12
        den = np.where(ok, den, 1.0)
        t = (-w[0] * e[1] + w[1] * e[0]) / den
        s = (d[:, 0] * w[1] - d[:, 1] * w[0]) / den
        hit = ok & (t > 1e-9) & (s >= 0) & (s <= 1)
        best = np.where(hit & (t < best), t, best)
    if noise > 0:
        best = best + (rng if rng is not None else np.random.default_rng(0)).normal(0, noise, N_BEAMS)
    best[(best > RANGE_MAX) | (best < RANGE_MIN)] = np.inf
    return LaserScan(stamp=float(stamp), angle_min=ANGLE_MIN, angle_increment=ANGLE_INC, range_min=RANGE_MIN,
                     range_max=RANGE_MAX, ranges=best.astype(np.float32))
