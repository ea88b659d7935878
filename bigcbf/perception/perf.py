"""Speed (and tracking accuracy) of the perception pipeline, for ``bigcbf perf``.

Scene: an 8 m x 6 m room with a wall stub and a box, three pedestrians walking smooth loops at 0.6-1.3 m/s, the
robot driving and turning through it (nobody collides); synthetic scans (exact ray casting, ``synthetic.ray_scan``,
1 cm range noise) at 10 Hz, generated before timing. Figures:

* perception_ms: median wall time of ``Perception.update`` per scan;
* perception_pos_rmse_m, perception_vel_rmse_mps: errors of the pedestrians' tracks against the truth, over the
  scans where a pedestrian has been visible for at least 1 s (a track within 0.5 m of it).
"""
from __future__ import annotations

import time

import numpy as np

from .pipeline import Perception
from .synthetic import box_segments, ray_scan

_WALLS = [(-1.0, -3.0, 7.0, -3.0), (7.0, -3.0, 7.0, 3.0), (7.0, 3.0, -1.0, 3.0), (-1.0, 3.0, -1.0, -3.0),
          (3.0, 3.0, 3.0, 2.2)] + box_segments(0.0, -0.5, 0.2, 0.2, 0.3)
#: pedestrians on ellipses: centre, semi-axes (m), angular rate (rad/s), phase
_ELLIPSES = (((4.5, 0.0), (1.5, 0.8), 0.8, 0.0), ((1.8, 1.3), (1.2, 0.6), -1.1, 1.0),
             ((5.3, -2.0), (1.0, 0.5), 1.2, 2.0))


def _pedestrians(t: float) -> np.ndarray:
    """(3, 4): x, y, vx, vy of three pedestrians walking smooth loops at 0.6-1.3 m/s."""
    out = []
    for (cx, cy), (a, b), w, ph in _ELLIPSES:
        th = w * t + ph
        out.append((cx + a * np.cos(th), cy + b * np.sin(th), -a * w * np.sin(th), b * w * np.cos(th)))
    return np.array(out)


def _robot(t: float) -> tuple[float, float, float]:
    """The robot drives back and forth along the bottom of the room, turning."""
    return (1.5 + 1.2 * np.sin(0.2 * t), -1.9 + 0.3 * np.sin(0.3 * t), 0.8 * np.sin(0.3 * t))


def bench(quick: bool = False) -> dict:
    n = 100 if quick else 400
    dt = 0.1
    rng = np.random.default_rng(0)
    frames = []
    for k in range(n):
        t = k * dt
        pose = _robot(t)
        peds = _pedestrians(t)
        scan = ray_scan(pose, [(x, y, 0.25) for x, y, _, _ in peds], _WALLS, stamp=t, noise=0.01, rng=rng)
        frames.append((scan, pose, peds))
    perc = Perception()
    times, pos_sq, vel_sq = [], [], []
    seen = np.full(3, np.inf)
    for scan, pose, peds in frames:
        t0 = time.perf_counter()
        obs = perc.update(scan, pose)
        times.append(time.perf_counter() - t0)
        tr = obs.subset(obs.ids >= 0)
        for i, (x, y, vx, vy) in enumerate(peds):
            d = np.linalg.norm(tr.p - (x, y), axis=1) if len(tr) else np.array([np.inf])
            if d.min() > 0.5:
                seen[i] = np.inf
                continue
            seen[i] = min(seen[i], scan.stamp)
            if scan.stamp - seen[i] >= 1.0:
                j = int(np.argmin(d))
                pos_sq.append(d[j] ** 2)
                vel_sq.append(float(np.sum((tr.v[j] - (vx, vy)) ** 2)))
    return {"perception_ms": round(1e3 * float(np.median(times)), 4),
            "perception_pos_rmse_m": round(float(np.sqrt(np.mean(pos_sq))), 4) if pos_sq else float("nan"),
            "perception_vel_rmse_mps": round(float(np.sqrt(np.mean(vel_sq))), 4) if vel_sq else float("nan")}
