"""GROUND-TRUTH MODE: obstacles straight from the simulator's true state, for debugging and ablations only.

This is NOT perception: nothing here looks at a scan. The benchmark runs with LiDAR perception (``Perception``);
use this only where a run is explicitly flagged as ground truth. It produces the same Obstacles layout as
``Perception.update`` so the stack cannot tell the difference in shape:

* circular objects (pedestrians, cylinders; boxes by their circumscribed circle if the caller wishes) -> tracks:
  true centre and velocity, covariance ground_truth_cov_m2 I, static = (speed < v_static_mps) unless given, ids =
  the caller's indices (stable), at most max_tracks nearest to the robot (surface distance); the static ones
  beyond that budget become wall points on the half of their circle that faces the robot, as the pipeline
  reports the tracks beyond its budget by their surface (``Tracker.report``);
* straight surfaces (wall and box faces as segments, see ``rectangle_segments``) -> wall points exactly as in
  perception: each segment's point nearest to the robot and points every wall_spacing_m along it from there, then
  the wall_max_points nearest within wall_range_m (ids -1, r 0, v 0, static, covariance wall_cov_m2 I).
Pure numpy; the caller (sim/episode layer) reads the true geometry from the simulator.
"""
from __future__ import annotations

import numpy as np

from ..params.perception import PerceptionParams
from ..types import Obstacles
from .geometry import rot, select_wall_points
from .pipeline import wall_obstacles


def rectangle_segments(cx: float, cy: float, half_x: float, half_y: float, yaw: float = 0.0) -> np.ndarray:
    """The four sides (4, 4) [x0, y0, x1, y1] of a rectangle (a box, or a wall of half length L/2 + t/2 and half
    thickness t/2), counter-clockwise."""
    corners = np.array([[half_x, half_y], [-half_x, half_y], [-half_x, -half_y], [half_x, -half_y]]) @ rot(yaw).T
    corners += np.array([cx, cy])
    return np.hstack([corners, np.roll(corners, -1, axis=0)])


def segment_points(segments: np.ndarray, robot_xy: np.ndarray, spacing: float) -> np.ndarray:
    """For each segment (K, 4): its point nearest to robot_xy and the points at multiples of ``spacing`` from it
    along the segment in both directions (within the segment). Returns (P, 2)."""
    seg = np.asarray(segments, float).reshape(-1, 4)
    if len(seg) == 0:
        return np.zeros((0, 2))
    a, b = seg[:, :2], seg[:, 2:]
    ab = b - a
    length = np.linalg.norm(ab, axis=1)
    u = ab / np.maximum(length, 1e-12)[:, None]
    s0 = np.clip(np.einsum("ij,ij->i", robot_xy - a, u), 0.0, length)     # arc position of the nearest point
    n_max = int(np.ceil(length.max() / spacing)) + 1
    k = np.arange(-n_max, n_max + 1)
    s = s0[:, None] + k[None, :] * spacing                                  # (K, 2n+1)
    ok = (s >= -1e-12) & (s <= length[:, None] + 1e-12)
    pts = a[:, None, :] + s[..., None] * u[:, None, :]
    return pts[ok]


def arc_points(centers: np.ndarray, radii: np.ndarray, robot_xy: np.ndarray, spacing: float) -> np.ndarray:
    """For each circle (K, 2), (K,): its point nearest to robot_xy and points every ``spacing`` of arc length from
    it in both directions over the half of the circle that faces robot_xy. Returns (P, 2)."""
    c = np.asarray(centers, float).reshape(-1, 2)
    r = np.asarray(radii, float).reshape(-1)
    out = []
    for ck, rk in zip(c, r):
        to = np.asarray(robot_xy, float) - ck
        phi0 = np.arctan2(to[1], to[0])
        k = int(np.floor(0.5 * np.pi * rk / spacing))
        phi = phi0 + np.arange(-k, k + 1) * spacing / max(rk, 1e-12)
        out.append(ck + rk * np.stack([np.cos(phi), np.sin(phi)], axis=1))
    return np.concatenate(out) if out else np.zeros((0, 2))


def ground_truth_obstacles(robot_xy, centers, velocities, radii, segments=None, static=None,
                           params: PerceptionParams = PerceptionParams()) -> Obstacles:
    """GROUND-TRUTH MODE (module docstring). centers, velocities (N,2) [m, m/s] in odom; radii (N,) [m];
    segments (K,4) [m]; static (N,) bool or None."""
    robot_xy = np.asarray(robot_xy, float).reshape(2)
    p = np.asarray(centers, float).reshape(-1, 2)
    n = len(p)
    v = np.asarray(velocities, float).reshape(n, 2)
    r = np.asarray(radii, float).reshape(n)
    st = (np.linalg.norm(v, axis=1) < params.v_static_mps) if static is None else np.asarray(static, bool).reshape(n)
    ranked = np.argsort(np.linalg.norm(p - robot_xy, axis=1) - r, kind="stable")
    order, beyond = ranked[: params.max_tracks], ranked[params.max_tracks:]
    cov = np.broadcast_to(params.ground_truth_cov_m2 * np.eye(2), (len(order), 2, 2)).copy()
    tracks = Obstacles(p[order], v[order], cov, r[order], st[order], order.astype(int))
    segs = np.zeros((0, 4)) if segments is None else np.asarray(segments, float).reshape(-1, 4)
    beyond = beyond[st[beyond]]
    cands = np.concatenate([segment_points(segs, robot_xy, params.wall_spacing_m),
                            arc_points(p[beyond], r[beyond], robot_xy, params.wall_spacing_m)])
    wall = select_wall_points(cands, robot_xy, params)
    return tracks.concat(wall_obstacles(wall, params.wall_cov_m2))
