"""Scan geometry: beams to points in odom, scan-order clustering, circle and rectangle fits, wall points.

Numpy, and compiled kernels (``bigcbf.control.jit.kernel``) for the per-point loops of clustering, the compactness
test and the wall points; no simulator import (this runs on the robot). Those kernels keep the numpy arithmetic's
order (sums as numpy's pairwise ``add.reduce``/``reduceat``, cumulative sums in order, transcendental functions
left to numpy): the results are the bits of the numpy code they replaced. The fits that
:func:`measure_clusters` runs for each cluster (the rectangle fit and its covariance, the fixed-radius refit; issue 26)
are compiled with their own sums, cos and sin: equal to their numpy references (:func:`fit_rectangle`,
:func:`rectangle_covariance`, :func:`fit_circle_fixed_radius`, which :func:`measure_compact` runs) to rounding
(tests/perception/test_geometry_compiled.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..control.jit import kernel

from ..params.perception import PerceptionParams
from ..types import LaserScan


def rot(theta: float) -> np.ndarray:
    """2-D rotation matrix R(theta)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


@dataclass(frozen=True)
class ScanPoints:
    """The valid returns of one scan, in scan order.

    xy (N,2) points in odom [m]; ranges (N,) [m]; beam (N,) beam indices; sensor (2,) laser origin in odom [m].
    """

    xy: np.ndarray
    ranges: np.ndarray
    beam: np.ndarray
    sensor: np.ndarray
    angle_increment: float
    n_beams: int


def scan_to_points(scan: LaserScan, pose: tuple[float, float, float], params: PerceptionParams) -> ScanPoints:
    """Valid beams (finite, within [range_min, range_max]) as points in odom.

    laser -> base_link by the mounting (laser_x_m, laser_y_m, laser_yaw_rad), base_link -> odom by the pose
    (x, y, theta) at the scan's stamp: p_odom = R(theta) (R(yaw_l) r [cos a, sin a] + t_l) + (x, y).
    The scan is taken as instantaneous (no per-beam motion correction).
    """
    r = np.ascontiguousarray(scan.ranges, dtype=float)
    n = len(r)
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    c, s = math.cos(th), math.sin(th)
    sx, sy = x + c * params.laser_x_m - s * params.laser_y_m, y + s * params.laser_x_m + c * params.laser_y_m
    beam, xy, rv = np.empty(n, np.int64), np.empty((n, 2)), np.empty(n)
    k = _scan_points(r, float(scan.range_min), float(scan.range_max), float(scan.angle_min),
                     float(scan.angle_increment), float(params.laser_yaw_rad), th, sx, sy, beam, xy, rv)
    return ScanPoints(xy[:k], rv[:k], beam[:k], np.array([sx, sy]), float(scan.angle_increment), n)


@kernel
def _scan_points(r, range_min, range_max, angle_min, angle_increment, yaw_l, th, sx, sy, beam, xy, rv):
    """:func:`scan_to_points`' valid beams (finite, within [range_min, range_max]) into beam[:k], their ranges into
    rv[:k] and their points sensor + r (cos a, sin a), a = angle_min + i angle_increment + yaw_l + theta, into
    xy[:k]; returns k."""
    k = 0
    for i in range(r.shape[0]):
        ri = r[i]
        if math.isfinite(ri) and ri >= range_min and ri <= range_max:
            a = angle_min + angle_increment * i + yaw_l + th
            beam[k], rv[k] = i, ri
            xy[k, 0] = sx + ri * math.cos(a)
            xy[k, 1] = sy + ri * math.sin(a)
            k += 1
    return k


@dataclass(frozen=True)
class Cluster:
    """One cluster: indices into ScanPoints (scan order, may wrap around), and whether a nearer return on the
    adjacent beam cuts it at its start or end (partial occlusion)."""

    idx: np.ndarray
    occluded: bool


def cluster_points(sp: ScanPoints, params: PerceptionParams) -> list[Cluster]:
    """Scan-order segmentation of the valid points into clusters.

    Consecutive points (i, i+1) join when d_i <= max(cluster_dist_m, r_i sin(dphi) / sin(lambda - dphi) + 3 sigma_r(r_i))
    (adaptive breakpoint detector, Borges & Aldon 2004; dphi the beam spacing), the adaptive term only for adjacent
    beams (missed beams between two points mean free space: then only cluster_dist_m). The scan is
    circular: the last point may join the first. A wall seen at a shallower angle than lambda breaks into fragments;
    the pipeline turns those into wall points (few points, or grazing spacing).
    """
    n = len(sp.ranges)
    if n == 0:
        return []
    if n == 1:
        return [Cluster(np.array([0]), False)]
    lam = params.cluster_lambda_rad
    dphi = sp.angle_increment
    order, bounds, occ = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.bool_)   # (filled in place:
    nb = _cluster_kernel(np.ascontiguousarray(sp.xy), np.ascontiguousarray(sp.ranges, dtype=float),  # no boxing)
                         np.ascontiguousarray(sp.beam, dtype=np.int64), int(sp.n_beams), dphi, lam,
                         *_sines(float(dphi), float(lam)), float(params.cluster_dist_m),
                         float(params.range_sigma_m), float(params.range_sigma_frac), order, bounds, occ)
    if nb < 0:                                                                     # (numpy's sines, as before)
        return [Cluster(np.arange(n), False)]
    cuts = [0, *bounds[:nb].tolist(), n]                      # the segments as views of ``order``, as np.split
    return [Cluster(order[cuts[s]:cuts[s + 1]], o) for s, o in enumerate(occ[:nb + 1].tolist())]


@lru_cache(maxsize=64)
def _sines(dphi: float, lam: float) -> tuple[float, float]:
    """numpy's sin(dphi) and sin(max(lam - dphi, 1e-9)) of :func:`cluster_points`, once per (dphi, lam)."""
    return float(np.sin(dphi)), float(np.sin(max(lam - dphi, 1e-9)))


@kernel
def _cluster_kernel(p, ranges, beam, n_beams, dphi, lam, sin_dphi, sin_rest, cluster_dist, sigma_r, sigma_frac,
                    order, bounds, occ):
    """:func:`cluster_points`'s joins and segments into ``order`` (the scan order rotated to start after a break),
    ``bounds`` (the segment bounds into it) and ``occ`` (each segment's occlusion flag), all (n,); returns the
    number of bounds, -1 without a break (one cluster of every point, in scan order). The numpy formulation's
    arithmetic, point by point."""
    n = p.shape[0]
    join = np.empty(n, np.bool_)
    first_break = -1
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        dx, dy = p[j, 0] - p[i, 0], p[j, 1] - p[i, 1]
        d = math.sqrt(dx * dx + dy * dy)
        db = (beam[j] - beam[i]) % n_beams
        if db == 0:
            db = n_beams
        abd = 0.0
        if db == 1 and dphi < lam:
            abd = ranges[i] * sin_dphi / sin_rest + 3 * (sigma_r + sigma_frac * ranges[i])
        thr = cluster_dist if cluster_dist >= abd else abd
        join[i] = d <= thr
        if not join[i] and first_break < 0:
            first_break = i
    if first_break < 0:
        return -1
    start = (first_break + 1) % n
    for k in range(n):
        order[k] = (k + start) % n
    nb = 0
    for k in range(n - 1):
        if not join[order[k]]:
            bounds[nb] = k + 1
            nb += 1
    for s in range(nb + 1):
        occ[s] = False
        lo = 0 if s == 0 else bounds[s - 1]
        hi = n - 1 if s == nb else bounds[s] - 1
        first, last = order[lo], order[hi]
        prev, nextp = (first - 1) % n, (last + 1) % n
        if (beam[first] - beam[prev]) % n_beams == 1 and ranges[prev] < ranges[first]:
            occ[s] = True
        if (beam[nextp] - beam[last]) % n_beams == 1 and ranges[nextp] < ranges[last]:
            occ[s] = True
    return nb


def _norms(v: np.ndarray) -> np.ndarray:
    return np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1])


def extent(points: np.ndarray, limit: float) -> float:
    """The largest distance between two points, or a value > limit as soon as it exceeds limit (cheap for walls)."""
    e1 = float(np.max(_norms(points - points[0])))
    if e1 > limit or len(points) > 400:
        return e1
    dx = points[:, None, 0] - points[None, :, 0]
    dy = points[:, None, 1] - points[None, :, 1]
    return float(np.sqrt(np.max(dx * dx + dy * dy)))


def fit_circle(points: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Algebraic (Kasa) circle fit: the least-squares solution of 2 u uc + 2 v vc + c = u^2 + v^2 in coordinates
    (u, v) centred on the points' mean, in closed form: [[Suu, Suv], [Suv, Svv]] [uc, vc] = 1/2 [Suuu + Suvv,
    Svvv + Svuu], r^2 = uc^2 + vc^2 + (Suu + Svv) / n (S.. are sums over the points).

    Returns (center (2,), radius, rms of |p - center| - radius); radius = inf for (near-)collinear points.
    """
    n = len(points)
    m = points.mean(axis=0)
    u, v = points[:, 0] - m[0], points[:, 1] - m[1]
    uu, vv, uv = u * u, v * v, u * v
    suu, svv, suv = uu.sum(), vv.sum(), uv.sum()
    det = suu * svv - suv * suv
    if n < 3 or det <= 1e-10 * (suu + svv) ** 2:
        return m, float("inf"), float("inf")
    b1 = 0.5 * float(np.dot(u, uu + vv))
    b2 = 0.5 * float(np.dot(v, uu + vv))
    uc = (svv * b1 - suv * b2) / det
    vc = (suu * b2 - suv * b1) / det
    r = float(np.sqrt(uc * uc + vc * vc + (suu + svv) / n))
    res = np.sqrt((u - uc) ** 2 + (v - vc) ** 2) - r
    return m + np.array([uc, vc]), r, float(np.sqrt(np.mean(res * res)))


def fit_circle_fixed_radius(points: np.ndarray, radius: float, center0: np.ndarray,
                            iterations: int = 10) -> tuple[np.ndarray, float]:
    """Geometric circle fit with a fixed radius: the centre c minimising sum_i (|p_i - c| - radius)^2, by
    Gauss-Newton from center0. Returns (center, rms of |p - c| - radius)."""
    cx, cy = float(center0[0]), float(center0[1])
    px, py = points[:, 0], points[:, 1]
    for _ in range(iterations):
        ux, uy = cx - px, cy - py
        dist = np.maximum(np.sqrt(ux * ux + uy * uy), 1e-9)
        res = dist - radius
        jx, jy = ux / dist, uy / dist                              # d res / d c
        a, b, d = jx @ jx, jx @ jy, jy @ jy
        gx, gy = jx @ res, jy @ res
        det = a * d - b * b
        if det <= 1e-12:
            break
        sx, sy = -(d * gx - b * gy) / det, -(a * gy - b * gx) / det
        cx, cy = cx + sx, cy + sy
        if sx * sx + sy * sy < 1e-14:
            break
    res = np.sqrt((px - cx) ** 2 + (py - cy) ** 2) - radius
    return np.array([cx, cy]), float(np.sqrt(np.mean(res * res)))


#: Orientations searched by the rectangle fit: 0..90 degrees in 1-degree steps, then +-1 degree in 0.05-degree steps.
_COARSE = np.deg2rad(np.arange(90.0))
_COARSE_E1 = np.stack([np.cos(_COARSE), np.sin(_COARSE)], axis=1)
_COARSE_E2 = np.stack([-np.sin(_COARSE), np.cos(_COARSE)], axis=1)
_FINE = np.deg2rad(np.arange(-1.0, 1.0001, 0.05))


def _edge_distances(points: np.ndarray, e1: np.ndarray, e2: np.ndarray):
    """For K orientations (unit axes e1, e2 (K,2)): the bounding rectangle's limits along e1 and e2 and each point's
    distance to the nearest edge (K, n)."""
    a, b = e1 @ points.T, e2 @ points.T                                   # (K, n) (numpy's products: BLAS)
    K = len(a)
    amin, amax, bmin, bmax, d = np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.empty(a.shape)
    _edge_kernel(np.ascontiguousarray(a), np.ascontiguousarray(b), amin, amax, bmin, bmax, d)
    return amin, amax, bmin, bmax, d


@kernel
def _edge_kernel(a, b, amin, amax, bmin, bmax, d):
    """:func:`_edge_distances` after the projections a, b (K, n): the limits along each axis and each point's
    distance to the nearest edge, min(min(a - amin, amax - a), min(b - bmin, bmax - b)) (finite inputs)."""
    K, n = a.shape
    for k in range(K):
        lo_a, hi_a, lo_b, hi_b = a[k, 0], a[k, 0], b[k, 0], b[k, 0]
        for i in range(1, n):
            lo_a, hi_a = min(lo_a, a[k, i]), max(hi_a, a[k, i])
            lo_b, hi_b = min(lo_b, b[k, i]), max(hi_b, b[k, i])
        amin[k], amax[k], bmin[k], bmax[k] = lo_a, hi_a, lo_b, hi_b
        for i in range(n):
            d[k, i] = min(min(a[k, i] - lo_a, hi_a - a[k, i]), min(b[k, i] - lo_b, hi_b - b[k, i]))


def fit_rectangle(points: np.ndarray, sensor: np.ndarray, full: bool = False):
    """Rectangle (L-shape) fit: the orientation whose bounding rectangle the points hug best, i.e. the least sum of
    squared distances from each point to the nearest edge (a search-based L-shape fit in the manner of Zhang et al.
    2017, "Efficient L-shape fitting for vehicle detection using laser scanners", with a squared-distance criterion;
    1-degree search over 0..89 degrees, refined to 0.05 degree).

    A convex object seen from outside shows one or two faces, but its depth is unknown when one face shows, and the
    second face of an L seen at a grazing angle is sampled by few beams (its length is underestimated by up to one
    beam spacing along it). The rectangle is therefore completed into a square of its long side, extending away
    from the sensor: exact for square boxes, conservative for an L of an oblong box. Returns (center (2,),
    radius = half the square's diagonal, rms of the points' distance to the nearest edge); with ``full`` also the
    axes (2, 2) (rows e1, e2) and the points' extents (la, lb) along them.
    """
    *_, d = _edge_distances(points, _COARSE_E1, _COARSE_E2)
    ang = _COARSE[int(np.argmin(np.einsum("kn,kn->k", d, d)))] + _FINE
    c, sn = np.cos(ang), np.sin(ang)
    e1s, e2s = np.stack([c, sn], axis=1), np.stack([-sn, c], axis=1)
    amin, amax, bmin, bmax, d = _edge_distances(points, e1s, e2s)
    j = int(np.argmin(np.einsum("kn,kn->k", d, d)))
    e1, e2 = e1s[j], e2s[j]
    la, lb = float(amax[j] - amin[j]), float(bmax[j] - bmin[j])
    center = (amax[j] + amin[j]) / 2 * e1 + (bmax[j] + bmin[j]) / 2 * e2
    rms = float(np.sqrt(np.mean(d[j] ** 2)))
    short, long_ = min(la, lb), max(la, lb)
    normal = e2 if la >= lb else e1
    if normal @ (center - sensor) < 0:
        normal = -normal
    center = center + (long_ - short) / 2 * normal
    if full:
        return center, long_ / np.sqrt(2), rms, np.stack([e1, e2]), (la, lb)
    return center, long_ / np.sqrt(2), rms


#: the coarse search's axes as above, per component, for the compiled fit
_COARSE_COS, _COARSE_SIN = np.ascontiguousarray(_COARSE_E1[:, 0]), np.ascontiguousarray(_COARSE_E1[:, 1])


@kernel
def _rect_search(P, lo, n, e1x, e1y, e2x, e2y, best):
    """For orientations k (unit axes (e1x[k], e1y[k]), (e2x[k], e2y[k])): the sum over the points P[lo:lo+n] of the
    squared distance to the nearest edge of their bounding rectangle (``fit_rectangle``'s criterion); returns the
    first k with the least sum, and fills best = (amin, amax, bmin, bmax, sum) of it. Point by point, all
    orientations at once (each one's limits and sum in point order, as one orientation at a time)."""
    K = e1x.shape[0]
    amin, bmin = np.full(K, np.inf), np.full(K, np.inf)
    amax, bmax = np.full(K, -np.inf), np.full(K, -np.inf)
    ss = np.zeros(K)
    for i in range(lo, lo + n):
        px, py = P[i, 0], P[i, 1]
        for k in range(K):
            a = e1x[k] * px + e1y[k] * py
            b = e2x[k] * px + e2y[k] * py
            amin[k], amax[k], bmin[k], bmax[k] = min(amin[k], a), max(amax[k], a), min(bmin[k], b), max(bmax[k], b)
    for i in range(lo, lo + n):
        px, py = P[i, 0], P[i, 1]
        for k in range(K):
            a = e1x[k] * px + e1y[k] * py
            b = e2x[k] * px + e2y[k] * py
            d = min(min(a - amin[k], amax[k] - a), min(b - bmin[k], bmax[k] - b))
            ss[k] += d * d
    kbest = -1
    for k in range(K):
        if kbest < 0 or ss[k] < best[4]:
            kbest = k
            best[0], best[1], best[2], best[3], best[4] = amin[k], amax[k], bmin[k], bmax[k], ss[k]
    return kbest


@kernel
def _rect_fit(P, lo, n, sx, sy, coarse, ccos, csin, fine, out):
    """:func:`fit_rectangle` (its numpy reference) of the points P[lo:lo+n], seen from the sensor (sx, sy), compiled:
    out = (centre x, y, radius, rms, e1 x, y, e2 x, y, la, lb). The same search (1-degree steps over 0..89 degrees,
    then +-1 degree in 0.05-degree steps; ``ccos``, ``csin`` the coarse angles' cosines and sines), sums in point
    order, the fine angles' cos and sin of the compiled code: equal to the reference to rounding
    (tests/perception/test_geometry_compiled.py)."""
    best = np.empty(5)
    k = _rect_search(P, lo, n, ccos, csin, -csin, ccos, best)
    ang = coarse[k] + fine
    f1x, f1y = np.cos(ang), np.sin(ang)
    j = _rect_search(P, lo, n, f1x, f1y, -f1y, f1x, best)
    ux, uy, vx, vy = f1x[j], f1y[j], -f1y[j], f1x[j]
    amin, amax, bmin, bmax = best[0], best[1], best[2], best[3]
    la, lb = amax - amin, bmax - bmin
    ma, mb = (amax + amin) / 2, (bmax + bmin) / 2
    cx, cy = ma * ux + mb * vx, ma * uy + mb * vy
    short, long_ = min(la, lb), max(la, lb)
    nx, ny = (vx, vy) if la >= lb else (ux, uy)
    if nx * (cx - sx) + ny * (cy - sy) < 0:
        nx, ny = -nx, -ny
    shift = (long_ - short) / 2
    out[0], out[1] = cx + shift * nx, cy + shift * ny
    out[2] = long_ / math.sqrt(2.0)
    out[3] = math.sqrt(best[4] / n)
    out[4], out[5], out[6], out[7], out[8], out[9] = ux, uy, vx, vy, la, lb


@kernel
def _rect_cov(P, lo, n, sx, sy, e1x, e1y, e2x, e2y, la, lb, angle_increment, range_sigma, range_frac, sigma_max,
              C):
    """:func:`rectangle_covariance` (its numpy reference) compiled, into C (2, 2)."""
    r = 0.0
    for i in range(lo, lo + n):
        r += math.sqrt((P[i, 0] - sx) ** 2 + (P[i, 1] - sy) ** 2)
    r /= n
    sr = range_sigma + range_frac * r
    end = sr * sr + (r * angle_increment) ** 2 / 12.0
    v1 = v2 = 0.5 * end
    if lb < la:
        v2 += (la - lb) ** 2 / 12.0
    else:
        v1 += (lb - la) ** 2 / 12.0
    c11 = v1 * e1x * e1x + v2 * e2x * e2x
    c12 = v1 * e1x * e1y + v2 * e2x * e2y
    c22 = v1 * e1y * e1y + v2 * e2y * e2y
    lam = 0.5 * (c11 + c22) + math.sqrt(0.25 * (c11 - c22) ** 2 + c12 * c12)
    if lam > sigma_max ** 2:
        k = sigma_max ** 2 / lam
        c11, c12, c22 = c11 * k, c12 * k, c22 * k
    C[0, 0], C[0, 1], C[1, 0], C[1, 1] = c11, c12, c12, c22


@kernel
def _fixed_radius_fit(P, lo, n, radius, cx, cy, iterations, out):
    """:func:`fit_circle_fixed_radius` (its numpy reference) of P[lo:lo+n] from the centre (cx, cy), compiled: out =
    (centre x, y, rms)."""
    for _ in range(iterations):
        a = b = d = gx = gy = 0.0
        for i in range(lo, lo + n):
            ux, uy = cx - P[i, 0], cy - P[i, 1]
            dist = max(math.sqrt(ux * ux + uy * uy), 1e-9)
            res = dist - radius
            jx, jy = ux / dist, uy / dist
            a += jx * jx
            b += jx * jy
            d += jy * jy
            gx += jx * res
            gy += jy * res
        det = a * d - b * b
        if det <= 1e-12:
            break
        sx, sy = -(d * gx - b * gy) / det, -(a * gy - b * gx) / det
        cx, cy = cx + sx, cy + sy
        if sx * sx + sy * sy < 1e-14:
            break
    ss = 0.0
    for i in range(lo, lo + n):
        res = math.sqrt((P[i, 0] - cx) ** 2 + (P[i, 1] - cy) ** 2) - radius
        ss += res * res
    out[0], out[1], out[2] = cx, cy, math.sqrt(ss / n)


def point_variances(points: np.ndarray, normals: np.ndarray, sensor: np.ndarray, angle_increment: float,
                    params: PerceptionParams) -> np.ndarray:
    """Variance [m^2] of each LiDAR point's offset along the model's surface normal there (unit ``normals`` (n,2)):
    the range noise along the beam, sigma_r = range_sigma_m + range_sigma_frac r, and the beam's angular
    resolution across it, sigma_t = r dphi / sqrt(12) (as ``wall_point_covariance``), projected on the normal:
    sigma_r^2 cos^2 a + sigma_t^2 sin^2 a, a the angle between the beam and the normal."""
    b = points - sensor
    r = np.sqrt(b[:, 0] * b[:, 0] + b[:, 1] * b[:, 1])
    cos = (b[:, 0] * normals[:, 0] + b[:, 1] * normals[:, 1]) / np.maximum(r, 1e-12)
    cos2 = np.minimum(cos * cos, 1.0)
    sr = params.range_sigma_m + params.range_sigma_frac * r
    return sr * sr * cos2 + (r * angle_increment) ** 2 / 12.0 * (1.0 - cos2)


def circle_fit_covariance(points: np.ndarray, center: np.ndarray, radius: float, sensor: np.ndarray,
                          angle_increment: float, params: PerceptionParams, fit_radius: bool = True) -> np.ndarray:
    """Covariance (2, 2) [m^2] of a circle fit's centre: the weighted least-squares covariance (J^T W J)^-1 of the
    geometric fit (residuals e_i = |p_i - c| - r, J_i = d e_i / d(c_x, c_y, r) = (-n_i, -1) with n_i the outward
    normal at point i, W = diag(1 / var_i) from :func:`point_variances`), its centre block; with the radius free
    (``fit_radius``) the radius's uncertainty is marginalised in, which is what makes a short arc's centre
    uncertain along the line of sight. With the radius clamped (not fitted) the centre moves one for one with the
    unknown radius along the line of sight: a uniform spread over [radius_min_m, radius_max_m] is added there.
    Standard deviations are capped at radius_max_m (the centre lies within that of the seen surface)."""
    u = points - center
    d = np.maximum(np.sqrt(u[:, 0] * u[:, 0] + u[:, 1] * u[:, 1]), 1e-12)
    nrm = u / d[:, None]
    w = 1.0 / np.maximum(point_variances(points, nrm, sensor, angle_increment, params), 1e-12)
    J = np.column_stack([-nrm, -np.ones(len(points))])
    A = (J * w[:, None]).T @ J
    cap = params.radius_max_m ** 2
    try:
        C = np.linalg.inv(A)[:2, :2] if fit_radius else np.linalg.inv(A[:2, :2])
    except np.linalg.LinAlgError:
        return cap * np.eye(2)
    if not fit_radius:
        ray = center - sensor
        ray = ray / max(float(np.linalg.norm(ray)), 1e-12)
        C = C + (params.radius_max_m - params.radius_min_m) ** 2 / 12.0 * np.outer(ray, ray)
    C = 0.5 * (C + C.T)
    if not np.all(np.isfinite(C)):
        return cap * np.eye(2)
    return _cap_std(C, params.radius_max_m)


def _cap_std(C: np.ndarray, sigma_max: float) -> np.ndarray:
    """Scale a 2x2 covariance down so that its largest standard deviation is at most sigma_max."""
    a, b, c = C[0, 0], C[0, 1], C[1, 1]
    lam = 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b)
    return C * (sigma_max ** 2 / lam) if lam > sigma_max ** 2 else C


def rectangle_covariance(points: np.ndarray, axes: np.ndarray, lengths: tuple[float, float], sensor: np.ndarray,
                         angle_increment: float, params: PerceptionParams) -> np.ndarray:
    """Covariance (2, 2) [m^2] of a rectangle fit's centre (``fit_rectangle``). Along each of the rectangle's axes
    e_k (``axes`` (2, 2), rows) the centre is the middle of the points' extent: each end is known to within the
    range noise and the beam spacing at the cluster's range (the silhouette lies between two beams: a uniform
    spread of r dphi), and the depth that no beam sees is unknown: the rectangle was completed into a square of
    its long side (``fit_rectangle``), so along the shorter extent the centre may lie anywhere over the missing
    length (long - short), a uniform spread (long - short)^2 / 12."""
    r = float(np.mean(np.linalg.norm(points - sensor, axis=1)))
    sr = params.range_sigma_m + params.range_sigma_frac * r
    end = sr * sr + (r * angle_increment) ** 2 / 12.0                 # one end of the extent
    la, lb = lengths
    short, long_ = min(la, lb), max(la, lb)
    var = np.full(2, 0.5 * end)                                        # the middle of two ends: (2 end) / 4
    var[int(np.argmin([la, lb]))] += (long_ - short) ** 2 / 12.0
    C = axes.T @ np.diag(var) @ axes
    return _cap_std(0.5 * (C + C.T), params.radius_max_m)


@dataclass(frozen=True)
class Measurement:
    center: np.ndarray       # (2,) odom [m]
    radius: float            # [m]
    arc_fit: bool            # True: the circle model won; False: the rectangle model
    cov: np.ndarray = None   # (2, 2) covariance of the centre [m^2] (circle_fit_covariance / rectangle_covariance)
    rms: float = 0.0         # RMS residual of the winning model [m]
    rms_expected: float = 0.0  # the RMS residual the sensor's noise alone would give there [m]
    round: bool = False      # the circle model explained the points outright: won, and without the tie tolerance


def measure_compact(points: np.ndarray, sensor: np.ndarray, params: PerceptionParams,
                    occluded: bool = False, angle_increment: float = 2 * np.pi / 360) -> Measurement:
    """Centre, radius and centre covariance of a compact cluster: the better of a circle model and a rectangle
    model.

    The centroid of an arc seen from one side is biased toward the sensor (by 2r/pi for a half circle), so it is
    not used. Circle model: the algebraic fit (``fit_circle``); when its radius falls outside [radius_min_m,
    radius_max_m] or its centre is not behind the surface the sensor sees (noise on a short arc), the radius is
    clamped to that range and the centre refitted with that radius (``fit_circle_fixed_radius``). Rectangle model:
    ``fit_rectangle`` (boxes, flat faces), its circumscribed circle. The circle model wins when

    * its RMS residual is at most the rectangle's (plus the range noise's std at the cluster's mean range when the
      radius was not clamped: near-ties go
      to the circle), and
    * the points span, seen from its centre, at least fit_min_arc_rad and, unless the cluster is partly hidden
      (``occluded``), at least fit_span_ratio of the arc that beams angle_increment apart sample on a circle of
      that radius at that distance d: min(2 acos(r/d), 2 asin((r - d dphi)/r)) (the visible arc, less one beam
      spacing at each silhouette). A flat face fits a wide circle with a narrow arc; a real circle shows nearly
      half of itself.

    The radius is clamped to [radius_min_m, radius_max_m]. The centre's covariance is the winning model's
    (``circle_fit_covariance``, ``rectangle_covariance``): a far post seen by four beams is a much poorer
    measurement than a near one seen by thirty, and the tracker weighs (and gates) it accordingly. ``rms`` is the
    winning model's RMS residual and ``rms_expected`` the range noise's std at the cluster's mean range: a cluster
    that no model explains (two objects merged, ``Perception``) has rms far above it. ``round``: the circle model
    won outright (also without the tie tolerance, or it fit within the noise): the evidence the tracker uses for the
    object's shape (a box seen by few beams often wins the circle model on the tie tolerance only).

    Length: the docstring is over half of it (the choice between the models stated in full); the code is 38 lines.
    """
    dx, dy = points[:, 0] - sensor[0], points[:, 1] - sensor[1]
    dist = np.sqrt(dx * dx + dy * dy)
    k = int(np.argmin(dist))
    near = points[k]
    ray = (near - sensor) / max(float(dist[k]), 1e-9)
    c, r, rms = fit_circle(points)
    sigma = params.range_sigma_m + params.range_sigma_frac * float(dist.mean())
    tol = sigma
    fitted = True
    if not (np.isfinite(r) and params.radius_min_m <= r <= params.radius_max_m and ray @ (c - near) > 0):
        r = float(np.clip(r if np.isfinite(r) else params.radius_max_m, params.radius_min_m, params.radius_max_m))
        c, rms = fit_circle_fixed_radius(points, r, near + r * ray)
        tol = 0.0
        fitted = False
    if tol > 0 and rms <= tol:
        rect = None                         # rms <= rms_rect + tol holds whatever the rectangle: skip its search
        rms_rect = np.inf
    else:
        rect = fit_rectangle(points, sensor, full=True)
        rms_rect = rect[2]
    if rms <= rms_rect + tol and ray @ (c - near) > 0:
        u = points - c
        mid = u.mean(axis=0)
        span = float(np.ptp(np.arctan2(u[:, 0] * mid[1] - u[:, 1] * mid[0], u @ mid)))  # angles about mid
        need = params.fit_min_arc_rad
        if not occluded:
            d = float(np.linalg.norm(c - sensor))
            sampled = min(np.arccos(min(r / d, 1.0)), np.arcsin(np.clip((r - d * angle_increment) / r, 0.0, 1.0)))
            need = max(need, params.fit_span_ratio * 2 * sampled)
        if span >= need:
            cov = circle_fit_covariance(points, c, r, sensor, angle_increment, params, fit_radius=fitted)
            return Measurement(c, r, True, cov, float(rms), sigma, bool(rms <= rms_rect))
    if rect is None:
        rect = fit_rectangle(points, sensor, full=True)
    rc, rr, rms_rect, axes, lengths = rect
    cov = rectangle_covariance(points, axes, lengths, sensor, angle_increment, params)
    return Measurement(rc, float(np.clip(rr, params.radius_min_m, params.radius_max_m)), False, cov,
                       float(rms_rect), sigma)


@dataclass(frozen=True)
class Measurements:
    """The measurements of m compact clusters (:func:`measure_clusters`), as arrays: each cluster's
    :class:`Measurement` (``center`` (m, 2), ``radius``, ``arc_fit``, ``cov`` (m, 2, 2), ``rms``, ``rms_expected``,
    ``round`` (m,)), and the clusters themselves: their ``points`` (N, 2) concatenated, n[j] each, ``idx`` (N,)
    the points' indices into the ScanPoints, ``occluded`` (m,). Iterates as the m Measurement objects."""

    points: np.ndarray
    n: np.ndarray
    idx: np.ndarray
    occluded: np.ndarray
    center: np.ndarray
    radius: np.ndarray
    arc_fit: np.ndarray
    cov: np.ndarray
    rms: np.ndarray
    rms_expected: np.ndarray
    round: np.ndarray

    def __len__(self) -> int:
        return len(self.n)

    def __iter__(self):
        for j in range(len(self.n)):
            yield Measurement(self.center[j], float(self.radius[j]), bool(self.arc_fit[j]), self.cov[j],
                              float(self.rms[j]), float(self.rms_expected[j]), bool(self.round[j]))


def measure_clusters(sp: ScanPoints, clusters: list, params: PerceptionParams) -> tuple[Measurements, np.ndarray]:
    """:func:`measure_compact` and :func:`concavity` (k = 2) of many compact clusters at once, compiled over their
    concatenated points: the algebraic circle fits, the fixed-radius refits and the arc terms (:func:`_fits`), the
    arc spans (numpy's arctan2, arccos and arcsin between the kernels), the model choice with the rectangle fits
    and the covariances (:func:`_models`; a clamped circle's covariance is :func:`_clamped_circle_cov`'s numpy).
    Same results as calling the two per cluster (to rounding: sums run in another order); the per-cluster functions
    stay the reference (``tests/perception/test_geometry.py``).

    ``clusters``: Cluster objects of at least 3 points. Returns (measurements, dents [m])."""
    pr = params
    m = len(clusters)
    n = np.array([len(c.idx) for c in clusters], np.int64)
    idx = np.concatenate([c.idx for c in clusters]) if m else np.zeros(0, np.int64)
    P = _take(sp.xy, idx, len(idx))
    occluded = np.array([cl.occluded for cl in clusters], np.bool_)
    if m == 0:
        z = np.zeros(0)
        return Measurements(P, n, idx, occluded, np.zeros((0, 2)), z, np.zeros(0, bool), np.zeros((0, 2, 2)), z, z,
                            np.zeros(0, bool)), z
    sx, sy = float(sp.sensor[0]), float(sp.sensor[1])
    fit, A, dents, ay, ax, cos_arg, sin_arg = _fits(P, n, sx, sy, float(pr.range_sigma_m), float(pr.range_sigma_frac),
                                                    float(pr.radius_min_m), float(pr.radius_max_m),
                                                    float(sp.angle_increment))
    center, radius, arc_fit, cov, rms, round_, clamped = _models(
        P, n, np.arctan2(ay, ax), np.arccos(cos_arg), np.arcsin(sin_arg), occluded, fit, A, sx, sy,
        float(sp.angle_increment), float(pr.range_sigma_m), float(pr.range_sigma_frac), float(pr.radius_min_m),
        float(pr.radius_max_m), float(pr.fit_min_arc_rad), float(pr.fit_span_ratio), _COARSE, _COARSE_COS,
        _COARSE_SIN, _FINE)
    if clamped.any():                                     # a won circle of clamped radius (rare): numpy's inverse
        for j in np.flatnonzero(clamped).tolist():
            cov[j] = _clamped_circle_cov(A[0, j], A[1, j], A[2, j], fit[:2, j], sp.sensor, pr)
    return Measurements(P, n, idx, occluded, center, radius, arc_fit, cov, rms, fit[_SIGMA], round_), dents


@kernel
def _clip(x, lo, hi):
    """``np.clip`` of one number (NaN stays NaN)."""
    x = lo if x < lo else x
    return hi if x > hi else x


#: the rows of :func:`_fits`' per-cluster results: centre x, y, radius, RMS residual, tie tolerance, range noise's
#: std, radius fitted (1) or clamped (0), centre behind the nearest point (1) or not (0)
_CX, _CY, _R, _RMS, _TOL, _SIGMA, _FITTED, _BEHIND = range(8)


@kernel
def _fits(P, n, sx, sy, sigma0, sigma_frac, r_min, r_max, dphi):
    """The first part of :func:`measure_clusters` over clusters of n[j] points of P seen from (sx, sy): the
    algebraic circle fits (:func:`_kasa_fits`), the radius clamped and the centre refitted where the fit is not
    usable (:func:`_fixed_radius_fit`, 10 iterations from the nearest point pushed back by the radius along its
    ray), then :func:`_arc_terms`. Returns (fit (8, m): the per-cluster results, rows ``_CX`` ... ``_BEHIND``;
    A, dents, ay, ax, cos_arg, sin_arg as :func:`_arc_terms`)."""
    m, N = n.shape[0], P.shape[0]
    near, ray, c = np.empty((m, 2)), np.empty((m, 2)), np.empty((m, 2))
    sigma, r, rms, tol, fitted = np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m, np.bool_)
    _kasa_fits(P, n, sx, sy, sigma0, sigma_frac, r_min, r_max, near, ray, sigma, c, r, rms, fitted, tol)
    fit3 = np.empty(3)
    start = 0
    for j in range(m):
        if not fitted[j]:                                  # clamp the radius and refit the centre (rare)
            rj = _clip(r[j] if math.isfinite(r[j]) else r_max, r_min, r_max)
            _fixed_radius_fit(P, start, n[j], rj, near[j, 0] + rj * ray[j, 0], near[j, 1] + rj * ray[j, 1], 10,
                              fit3)
            c[j, 0], c[j, 1], r[j], rms[j] = fit3[0], fit3[1], rj, fit3[2]
        start += n[j]
    ay, ax, A, dents = np.empty(N), np.empty(N), np.empty((6, m)), np.zeros(m)
    behind, cos_arg, sin_arg = np.empty(m, np.bool_), np.empty(m), np.empty(m)
    _arc_terms(P, n, c, near, ray, r, sx, sy, dphi, sigma0, sigma_frac, ay, ax, A, dents, behind, cos_arg, sin_arg)
    fit = np.empty((8, m))
    for j in range(m):
        fit[_CX, j], fit[_CY, j], fit[_R, j], fit[_RMS, j] = c[j, 0], c[j, 1], r[j], rms[j]
        fit[_TOL, j], fit[_SIGMA, j] = tol[j], sigma[j]
        fit[_FITTED, j], fit[_BEHIND, j] = 1.0 if fitted[j] else 0.0, 1.0 if behind[j] else 0.0
    return fit, A, dents, ay, ax, cos_arg, sin_arg


@kernel
def _models(P, n, ang, acos, asin, occluded, fit, A, sx, sy, dphi, sigma0, sigma_frac, r_min, r_max, min_arc,
            span_ratio, coarse, ccos, csin, fine):
    """The second part of :func:`measure_clusters`: the arc spans (:func:`_arc_need`), then per cluster the model
    that wins (:func:`measure_compact`'s rule: the rectangle fit :func:`_rect_fit` unless the circle fits within
    the noise ``tol``) and its measurement: the circle's (its covariance :func:`_fitted_circle_cov` when its radius
    was fitted; ``clamped`` marks those whose radius was clamped, left to the caller) or the rectangle's (radius
    clipped to [r_min, r_max], covariance :func:`_rect_cov`); ``fit``: :func:`_fits`' per-cluster results. Returns
    (center, radius, arc_fit, cov, rms, round, clamped)."""
    m = n.shape[0]
    span, need = np.empty(m), np.empty(m)
    _arc_need(ang, n, acos, asin, occluded, min_arc, span_ratio, span, need)
    center, radius, cov, rms_w = np.empty((m, 2)), np.empty(m), np.zeros((m, 2, 2)), np.empty(m)
    arc_fit, round_, clamped = np.zeros(m, np.bool_), np.zeros(m, np.bool_), np.zeros(m, np.bool_)
    rect = np.empty(10)
    lo = 0
    for j in range(m):
        nj = n[j]
        cx, cy, r, rms, tol = fit[_CX, j], fit[_CY, j], fit[_R, j], fit[_RMS, j], fit[_TOL, j]
        fitted_rect = False
        rms_rect = np.inf
        if not (tol > 0 and rms <= tol):
            _rect_fit(P, lo, nj, sx, sy, coarse, ccos, csin, fine, rect)
            fitted_rect, rms_rect = True, rect[3]
        if rms <= rms_rect + tol and fit[_BEHIND, j] != 0.0 and span[j] >= need[j]:
            center[j, 0], center[j, 1], radius[j], rms_w[j] = cx, cy, r, rms
            arc_fit[j], round_[j] = True, rms <= rms_rect
            if fit[_FITTED, j] != 0.0:
                _fitted_circle_cov(A[0, j], A[1, j], A[2, j], A[3, j], A[4, j], A[5, j], r_max, cov[j])
            else:
                clamped[j] = True
        else:
            if not fitted_rect:
                _rect_fit(P, lo, nj, sx, sy, coarse, ccos, csin, fine, rect)
            _rect_cov(P, lo, nj, sx, sy, rect[4], rect[5], rect[6], rect[7], rect[8], rect[9], dphi, sigma0,
                      sigma_frac, r_max, cov[j])
            center[j, 0], center[j, 1], radius[j], rms_w[j] = rect[0], rect[1], _clip(rect[2], r_min, r_max), rect[3]
        lo += nj
    return center, radius, arc_fit, cov, rms_w, round_, clamped


@kernel
def _pairwise_block(a, lo, n):
    """numpy's ``pairwise_sum`` of a[lo:lo+n] for n <= 128 (numpy/_core/src/umath/loops_utils.h): a plain sum
    below 8 elements, else 8 partial sums combined as ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7)), then
    the remainder."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - (n % 8):
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@kernel
def _pairwise(a, lo, n):
    """numpy's pairwise summation of a[lo:lo+n]: :func:`_pairwise_block` up to 128 elements, beyond that the sum of
    the two halves (the first rounded down to a multiple of 8), recursively; the recursion is run on an explicit
    stack (numba's cache mishandles a recursive kernel called from another module's kernel)."""
    if n <= 128:
        return _pairwise_block(a, lo, n)
    s_lo, s_n = np.empty(64, np.int64), np.empty(64, np.int64)
    s_stage, s_left = np.zeros(64, np.int64), np.empty(64)
    top, ret = 0, 0.0
    s_lo[0], s_n[0], s_stage[0] = lo, n, 0
    while top >= 0:
        m = s_n[top]
        if m <= 128:
            ret = _pairwise_block(a, s_lo[top], m)
            top -= 1
            continue
        n2 = m // 2
        n2 -= n2 % 8
        if s_stage[top] == 0:            # the first half
            s_stage[top] = 1
            s_lo[top + 1], s_n[top + 1], s_stage[top + 1] = s_lo[top], n2, 0
            top += 1
        elif s_stage[top] == 1:          # the second half
            s_left[top] = ret
            s_stage[top] = 2
            s_lo[top + 1], s_n[top + 1], s_stage[top + 1] = s_lo[top] + n2, m - n2, 0
            top += 1
        else:                            # both: their sum
            ret = s_left[top] + ret
            top -= 1
    return ret


@kernel
def _segsum(a, lo, n):
    """``np.add.reduceat``'s sum of one segment a[lo:lo+n]: its first element plus the pairwise sum of the rest."""
    return a[lo] + _pairwise(a, lo + 1, n - 1)


@kernel
def _kasa_fits(P, n, sx, sy, sigma0, sigma_frac, r_min, r_max, near, ray, sigma, c, r, rms, fitted, tol):
    """The first block of :func:`measure_clusters` over clusters of n[c] points of P: each one's nearest point and
    the unit ray to it, the range-noise std at its mean range, and its algebraic circle fit (centre, radius, RMS
    residual; inf radius and rms for (near-)collinear points), in the numpy formulation's order (sums as
    ``np.add.reduceat``), into the output arrays (m, 2) near, ray, c and (m,) sigma, r, rms; ``fitted``: the fit
    is usable as it is (a finite radius within [r_min, r_max], its centre behind the nearest point), ``tol``
    sigma where fitted, else 0."""
    m, N = n.shape[0], P.shape[0]
    dist, t0, t1, t2, t3, t4 = np.empty(N), np.empty(N), np.empty(N), np.empty(N), np.empty(N), np.empty(N)
    start = 0
    for j in range(m):
        k = n[j]
        end = start + k
        kn, dmin = start, np.inf
        for i in range(start, end):
            dx, dy = P[i, 0] - sx, P[i, 1] - sy
            dist[i] = math.sqrt(dx * dx + dy * dy)
            if dist[i] < dmin:
                dmin, kn = dist[i], i
            t0[i], t1[i] = P[i, 0], P[i, 1]
        near[j, 0], near[j, 1] = P[kn, 0], P[kn, 1]
        dm = max(dmin, 1e-9)
        ray[j, 0], ray[j, 1] = (P[kn, 0] - sx) / dm, (P[kn, 1] - sy) / dm
        sigma[j] = sigma0 + sigma_frac * _segsum(dist, start, k) / k
        mx, my = _segsum(t0, start, k) / k, _segsum(t1, start, k) / k
        for i in range(start, end):
            u, v = P[i, 0] - mx, P[i, 1] - my
            t0[i], t1[i], t2[i] = u * u, v * v, u * v
            w = t0[i] + t1[i]
            t3[i], t4[i] = u * w, v * w
        suu, svv, suv = _segsum(t0, start, k), _segsum(t1, start, k), _segsum(t2, start, k)
        b1, b2 = 0.5 * _segsum(t3, start, k), 0.5 * _segsum(t4, start, k)
        det = suu * svv - suv * suv
        good = k >= 3 and det > 1e-10 * ((suu + svv) * (suu + svv))
        uc = (svv * b1 - suv * b2) / det if good else 0.0
        vc = (suu * b2 - suv * b1) / det if good else 0.0
        r[j] = math.sqrt(uc * uc + vc * vc + (suu + svv) / k) if good else np.inf
        c[j, 0], c[j, 1] = mx + uc, my + vc
        rg = r[j] if good else 0.0
        for i in range(start, end):
            res = math.sqrt(((P[i, 0] - mx) - uc) ** 2 + ((P[i, 1] - my) - vc) ** 2) - rg
            t0[i] = res * res
        rms[j] = math.sqrt(_segsum(t0, start, k) / k) if good else np.inf
        behind = ray[j, 0] * (c[j, 0] - near[j, 0]) + ray[j, 1] * (c[j, 1] - near[j, 1]) > 0
        fitted[j] = math.isfinite(r[j]) and r_min <= r[j] and r[j] <= r_max and behind
        tol[j] = sigma[j] if fitted[j] else 0.0
        start = end


@kernel
def _arc_terms(P, n, c, near, ray, r, sx, sy, dphi, sigma0, sigma_frac, ay, ax, A, dents, behind, cos_arg, sin_arg):
    """The second block of :func:`measure_clusters`: per point the arguments (y, x) of the angle between the point
    and the cluster's mean direction seen from its centre c (for numpy's arctan2), per cluster the entries a11, a12,
    a22, a13, a23, a33 (6, m) of J^T W J for its circle covariance (``point_variances`` weights, outward normals),
    and the dents of :func:`concavity` (k = 2; ``dents`` starts at 0); per cluster also whether its centre lies
    behind its nearest point, and the arguments of the arccos and arcsin of the arc a circle of its radius shows
    the sensor at its distance (``sampled`` in :func:`measure_clusters`); numpy's order throughout."""
    m, N = n.shape[0], P.shape[0]
    t = np.empty((6, N))
    g = np.empty(N, np.int64)
    start = 0
    for j in range(m):
        k = n[j]
        end = start + k
        for i in range(start, end):
            g[i] = j
            t[0, i], t[1, i] = P[i, 0] - c[j, 0], P[i, 1] - c[j, 1]
        midx, midy = _segsum(t[0], start, k) / k, _segsum(t[1], start, k) / k
        for i in range(start, end):
            ux, uy = t[0, i], t[1, i]
            ay[i] = ux * midy - uy * midx
            ax[i] = ux * midx + uy * midy
            dx, dy = P[i, 0] - sx, P[i, 1] - sy
            dist = math.sqrt(dx * dx + dy * dy)
            d2 = max(math.sqrt(ux * ux + uy * uy), 1e-12)
            nx, ny = ux / d2, uy / d2
            cos = (dx * nx + dy * ny) / max(dist, 1e-12)
            cos2 = min(cos * cos, 1.0)
            sr = sigma0 + sigma_frac * dist
            wt = 1.0 / max(sr * sr * cos2 + (dist * dphi) ** 2 / 12.0 * (1.0 - cos2), 1e-12)
            t[0, i], t[1, i], t[2, i] = wt * nx * nx, wt * nx * ny, wt * ny * ny
            t[3, i], t[4, i], t[5, i] = wt * nx, wt * ny, wt
        for q in range(6):
            A[q, j] = _segsum(t[q], start, k)
        behind[j] = ray[j, 0] * (c[j, 0] - near[j, 0]) + ray[j, 1] * (c[j, 1] - near[j, 1]) > 0
        ex, ey = c[j, 0] - sx, c[j, 1] - sy
        dc = math.sqrt(ex * ex + ey * ey)
        rr = r[j] if math.isfinite(r[j]) else 1.0
        cos_arg[j] = min(rr / max(dc, 1e-12), 1.0)
        sin_arg[j] = min(max((rr - dc * dphi) / rr, 0.0), 1.0)
        start = end
    for i in range(N - 4):
        if g[i] != g[i + 4]:
            continue
        ex, ey = P[i + 4, 0] - P[i, 0], P[i + 4, 1] - P[i, 1]
        length = max(math.sqrt(ex * ex + ey * ey), 1e-12)
        side_b = ex * (P[i + 2, 1] - P[i, 1]) - ey * (P[i + 2, 0] - P[i, 0])
        side_s = ex * (sy - P[i, 1]) - ey * (sx - P[i, 0])
        sg = 1.0 if side_s > 0 else (-1.0 if side_s < 0 else (0.0 if side_s == 0 else np.nan))
        val = -sg * side_b / length
        cur = dents[g[i]]
        if not (cur >= val or cur != cur):
            dents[g[i]] = val


@kernel
def _arc_need(ang, n, acos, asin, occluded, min_arc, span_ratio, span, need):
    """Per cluster (n[c] points): the span of its points' angles ``ang`` and the span an arc needs to count as
    one (``fit_min_arc_rad`` when partly hidden, else at least ``fit_span_ratio`` times twice the arc the sensor
    can sample, min(acos, asin)), into span and need."""
    start = 0
    for j in range(n.shape[0]):
        lo, hi = ang[start], ang[start]
        for i in range(start + 1, start + n[j]):
            lo, hi = min(lo, ang[i]), max(hi, ang[i])
        span[j] = hi - lo
        sampled = min(acos[j], asin[j])
        need[j] = min_arc if occluded[j] else max(min_arc, span_ratio * 2 * sampled)
        start += n[j]


@kernel
def _fitted_circle_cov(a11, a12, a22, a13, a23, a33, sigma_max, C):
    """The covariance of a fitted circle's centre, into C (2, 2): the centre block of the inverse of
    [[a11, a12, a13], [a12, a22, a23], [a13, a23, a33]] (cofactors / det; cap^2 I when not positive definite or
    not finite), then :func:`_cap_std`; numpy's scalar arithmetic in its order."""
    cap = sigma_max ** 2
    c11 = a22 * a33 - a23 * a23
    c12 = -(a12 * a33 - a23 * a13)
    c22 = a11 * a33 - a13 * a13
    det = a11 * c11 + a12 * c12 + a13 * (a12 * a23 - a22 * a13)
    x11, x12, x22 = c11 / det, c12 / det, c22 / det
    if not det > 0 or not (math.isfinite(x11) and math.isfinite(x12) and math.isfinite(x22)):
        C[0, 0], C[0, 1], C[1, 0], C[1, 1] = cap, 0.0, 0.0, cap
        return
    lam = 0.5 * (x11 + x22) + math.sqrt(0.25 * (x11 - x22) ** 2 + x12 * x12)
    k = sigma_max ** 2 / lam if lam > sigma_max ** 2 else 1.0
    if lam > sigma_max ** 2:
        x11, x12, x22 = x11 * k, x12 * k, x22 * k
    C[0, 0], C[0, 1], C[1, 0], C[1, 1] = x11, x12, x12, x22


def _clamped_circle_cov(a11, a12, a22, center, sensor, params) -> np.ndarray:
    """circle_fit_covariance of a circle whose radius was clamped (not fitted), from the entries of J^T W J
    (closed-form inverse); the fitted ones are :func:`_fitted_circle_cov`."""
    cap = params.radius_max_m ** 2
    det = a11 * a22 - a12 * a12
    if not det > 0:
        return cap * np.eye(2)
    C = np.array([[a22, -a12], [-a12, a11]]) / det
    ray = center - sensor
    ray = ray / max(float(np.linalg.norm(ray)), 1e-12)
    C = C + (params.radius_max_m - params.radius_min_m) ** 2 / 12.0 * np.outer(ray, ray)
    if not np.all(np.isfinite(C)):
        return cap * np.eye(2)
    return _cap_std(C, params.radius_max_m)


def concavity(points: np.ndarray, sensor: np.ndarray, k: int = 2) -> float:
    """How far [m] the cluster's outline (points in scan order) dents away from the sensor: the largest distance of
    a point p_i behind the chord from p_(i-k) to p_(i+k), counted positive away from the sensor (0 when no point
    is). A convex object seen from outside (a post, a box, a person) bulges toward the sensor everywhere, so this is
    noise only; where two objects meet in one cluster (a pedestrian beside a post, two posts a few cm apart) the
    outline steps back into the gap between them. k = 2 skips one point, so that one noisy return does not make
    a dent."""
    n = len(points)
    if n < 2 * k + 1:
        return 0.0
    a, b, c = points[: n - 2 * k], points[k: n - k], points[2 * k:]
    ex, ey = c[:, 0] - a[:, 0], c[:, 1] - a[:, 1]
    length = np.maximum(np.sqrt(ex * ex + ey * ey), 1e-12)
    side_b = ex * (b[:, 1] - a[:, 1]) - ey * (b[:, 0] - a[:, 0])
    side_s = ex * (sensor[1] - a[:, 1]) - ey * (sensor[0] - a[:, 0])
    return float(max(np.max(-np.sign(side_s) * side_b / length), 0.0))


def wall_candidates(points: np.ndarray, robot_xy: np.ndarray, spacing: float) -> np.ndarray:
    """Points of one cluster (scan order) that represent its surface: the point nearest to the robot, then, walking
    along the cluster in both directions, the first point past every multiple of ``spacing`` of path length, and
    the cluster's two end points (a wall's end at a door, a box's corners: between the nearest point and an end
    closer than ``spacing`` no bin would start, and a 0.4 m box face seen square-on would be one point)."""
    n = len(points)
    if n <= 1:
        return points
    dx, dy = points[:, 0] - robot_xy[0], points[:, 1] - robot_xy[1]
    j = int(np.argmin(dx * dx + dy * dy))
    step = np.diff(points, axis=0)
    s = np.zeros(n)
    np.cumsum(np.sqrt(step[:, 0] ** 2 + step[:, 1] ** 2), out=s[1:])
    bins = np.floor(np.abs(s - s[j]) / spacing)                       # path-length bin counted from point j
    keep = np.zeros(n, bool)
    keep[j] = True
    keep[j + 1:] = bins[j + 1:] != bins[j:-1]                         # forward: first point of each new bin
    keep[:j] = bins[:j] != bins[1:j + 1]                              # backward, likewise
    keep[0] = keep[-1] = True
    order = np.flatnonzero(keep)
    return points[np.concatenate([[j], order[order != j]])]


def wall_candidates_many(point_sets: list, robot_xy: np.ndarray, spacing: float) -> np.ndarray:
    """:func:`wall_candidates` of many clusters at once (array operations over their concatenated points),
    concatenated in the same order: cluster by cluster, each one's nearest point first."""
    sets = [q for q in point_sets if len(q)]
    if not sets:
        return np.zeros((0, 2))
    n = np.array([len(q) for q in sets], np.int64)
    return _wall_candidates_kernel(np.ascontiguousarray(np.concatenate(sets), dtype=float), n, float(robot_xy[0]),
                                   float(robot_xy[1]), float(spacing))


@kernel
def _wall_candidates_kernel(Q, n, rx, ry, spacing):
    """:func:`wall_candidates_many`'s points of Q (clusters of n[c] points), cluster by cluster, each one's nearest
    point first; the path length is one cumulative sum over all of Q, as in numpy."""
    N = Q.shape[0]
    out = np.empty(N, np.int64)
    cs = np.empty(N)             # the cumulative sum of the steps, 0 at each cluster's first point
    acc = 0.0
    nxt_start, c = 0, 0
    for i in range(N):
        if i == nxt_start:
            nxt_start += n[c]
            c += 1
        else:
            ex, ey = Q[i, 0] - Q[i - 1, 0], Q[i, 1] - Q[i - 1, 1]
            acc += math.sqrt(ex ** 2 + ey ** 2)
        cs[i] = acc
    k = 0
    start = 0
    for c in range(n.shape[0]):
        m = n[c]
        end = start + m - 1
        j = start
        best = np.inf
        for i in range(start, end + 1):
            d2 = (Q[i, 0] - rx) * (Q[i, 0] - rx) + (Q[i, 1] - ry) * (Q[i, 1] - ry)
            if d2 < best:
                best, j = d2, i
        base = cs[start]
        sj = cs[j] - base
        out[k] = j
        k += 1
        prev_bin = 0.0
        for i in range(start, end + 1):
            b_i = math.floor(abs((cs[i] - base) - sj) / spacing)
            if i == j:
                prev_bin = b_i
                continue
            keep = i == start or i == end
            if i > j:
                keep = keep or b_i != prev_bin
            elif i < j:
                b_next = math.floor(abs((cs[i + 1] - base) - sj) / spacing)
                keep = keep or b_i != b_next
            if keep:
                out[k] = i
                k += 1
            prev_bin = b_i
        start = end + 1
    return _take(Q, out, k)


@kernel
def _take(points, sel, k):
    """points[sel[:k]] (rows of (N, 2) points)."""
    res = np.empty((k, 2))
    for q in range(k):
        res[q, 0], res[q, 1] = points[sel[q], 0], points[sel[q], 1]
    return res


def compact_mask(sp: ScanPoints, clusters: list, params: PerceptionParams) -> np.ndarray:
    """(len(clusters),) bool: which clusters are compact objects: at least min_points points and an extent (largest
    distance between two of their points, :func:`extent`) of at most compact_max_extent_m. The extent is bounded
    by the largest distance d1 from the cluster's first point (d1 <= extent <= 2 d1), so only clusters with
    limit / 2 < d1 <= limit need the pairwise distances."""
    m = len(clusters)
    if m == 0:
        return np.zeros(0, bool)
    limit = params.compact_max_extent_m
    n = np.array([len(c.idx) for c in clusters], np.int64)
    ok = np.empty(m, np.bool_)
    _compact_kernel(sp.xy, np.concatenate([c.idx for c in clusters]), n, float(limit), int(params.min_points), ok)
    return ok


@kernel
def _compact_kernel(xy, idx, n, limit, min_points, ok):
    """:func:`compact_mask` into ``ok`` over the points xy[idx] of clusters of n[c] points (their indices
    concatenated in ``idx``; :func:`extent` inlined)."""
    m = n.shape[0]
    start = 0
    for c in range(m):
        k = n[c]
        fx, fy = xy[idx[start], 0], xy[idx[start], 1]
        e1 = -np.inf
        for i in range(start, start + k):
            d = math.sqrt((xy[idx[i], 0] - fx) ** 2 + (xy[idx[i], 1] - fy) ** 2)
            e1 = d if d > e1 or d != d else e1
        ok[c] = k >= min_points and e1 <= limit
        if ok[c] and e1 > limit / 2 and k <= 400:     # extent(): the pairwise distances
            best = -np.inf
            for i in range(start, start + k):
                for j in range(start, start + k):
                    dx = xy[idx[i], 0] - xy[idx[j], 0]
                    dy = xy[idx[i], 1] - xy[idx[j], 1]
                    v = dx * dx + dy * dy
                    best = v if v > best or v != v else best
            ok[c] = math.sqrt(best) <= limit
        start += k


def select_wall_points(candidates: np.ndarray, robot_xy: np.ndarray, params: PerceptionParams) -> np.ndarray:
    """The at most wall_max_points candidates nearest to the robot, within wall_range_m, nearest first."""
    if len(candidates) == 0 or params.wall_max_points == 0:
        return np.zeros((0, 2))
    return _nearest_within(np.ascontiguousarray(candidates, dtype=float), float(robot_xy[0]), float(robot_xy[1]),
                           float(params.wall_range_m), int(params.wall_max_points))


@kernel
def _nearest_within(points, rx, ry, reach, most):
    """:func:`select_wall_points`' choice: the points within ``reach`` of (rx, ry), nearest first (a stable sort:
    ties in the given order), at most ``most``."""
    n = points.shape[0]
    out = np.empty(n, np.int64)
    d = np.empty(n)
    for i in range(n):
        dx, dy = points[i, 0] - rx, points[i, 1] - ry
        d[i] = math.sqrt(dx * dx + dy * dy)
    order = np.argsort(d, kind="mergesort")
    k = 0
    for i in order:
        if k >= most:
            break
        if d[i] <= reach:
            out[k] = i
            k += 1
    return _take(points, out, k)


def wall_point_covariance(points: np.ndarray, sensor: np.ndarray, angle_increment: float,
                          params: PerceptionParams) -> np.ndarray:
    """Position covariance (M, 2, 2) [m^2] of LiDAR points at ``points`` (M, 2) seen from ``sensor`` (2,) (odom):
    along the beam the range noise, sigma_r = range_sigma_m + range_sigma_frac r; across it the beam's angular
    resolution at that range, sigma_t = r dphi / sqrt(12) (the return may come from anywhere within one angular step
    dphi = ``angle_increment``: a uniform spread of width r dphi); rotated to the beam's bearing phi:
    Sigma = R(phi) diag(sigma_r^2, sigma_t^2) R(phi)^T."""
    d = np.ascontiguousarray(np.asarray(points, float).reshape(-1, 2) - np.asarray(sensor, float))
    r = np.hypot(d[:, 0], d[:, 1])
    cov = np.empty((len(r), 2, 2))
    _beam_covariances(d, r, float(angle_increment), float(params.range_sigma_m), float(params.range_sigma_frac), cov)
    return cov


@kernel
def _beam_covariances(d, r, dphi, sigma0, sigma_frac, cov):
    """:func:`wall_point_covariance` after the ranges r = |d| (numpy's hypot): R(phi) diag(sigma_r^2, sigma_t^2)
    R(phi)^T per point, in the numpy formulation's order."""
    for i in range(r.shape[0]):
        rm = max(r[i], 1e-12)
        c, s = d[i, 0] / rm, d[i, 1] / rm
        sr2 = (sigma0 + sigma_frac * r[i]) ** 2
        st2 = (r[i] * dphi) ** 2 / 12.0
        cov[i, 0, 0] = c * c * sr2 + s * s * st2
        cov[i, 1, 1] = s * s * sr2 + c * c * st2
        cov[i, 0, 1] = cov[i, 1, 0] = c * s * (sr2 - st2)
