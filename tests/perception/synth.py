"""Helpers for the perception tests: synthetic scans (exact ray casting, bigcbf.perception.synthetic) fed to a
Perception along scripted robot and pedestrian trajectories."""
from __future__ import annotations

import numpy as np

from bigcbf.perception.synthetic import box_segments as box  # noqa: F401  (re-exported for the tests)
from bigcbf.perception.synthetic import ray_scan  # noqa: F401


def simulate(perception, duration, robot, circles=lambda t: [], segments=(), dt=0.1, noise=0.0, seed=0):
    """Feed scans at 1/dt Hz for ``duration`` s. robot(t) -> pose, circles(t) -> [(cx, cy, r)], static segments.
    Returns a list of (t, pose, obstacles)."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(int(round(duration / dt)) + 1):
        t = k * dt
        pose = robot(t)
        scan = ray_scan(pose, circles(t), segments, stamp=t, noise=noise, rng=rng)
        out.append((t, pose, perception.update(scan, pose)))
    return out


def tracks(obs):
    """The tracked entities (ids >= 0) of an Obstacles."""
    return obs.subset(obs.ids >= 0)


def walls(obs):
    """The wall points (ids -1) of an Obstacles."""
    return obs.subset(obs.ids < 0)


def track_near(obs, xy, tol=0.3):
    """The index (in tracks(obs)) of the track within tol of xy, or None."""
    tr = tracks(obs)
    if len(tr) == 0:
        return None
    d = np.linalg.norm(tr.p - np.asarray(xy), axis=1)
    k = int(np.argmin(d))
    return k if d[k] <= tol else None
