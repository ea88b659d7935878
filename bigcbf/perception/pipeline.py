"""LiDAR perception: scan -> points in odom -> clusters -> circles (compact round objects, walkers) and wall points
(every other surface) -> tracks (CV Kalman filters, static/dynamic hysteresis) -> Obstacles.

Per scan, with the robot pose (odometry) at the scan's stamp:

1. valid beams become points in odom (``geometry.scan_to_points``), so velocities are not fooled by the robot's
   own motion;
2. scan-order clustering (``geometry.cluster_points``), then track-aided segmentation (``Perception._segment``):
   the tracks are predicted to the scan's stamp, and a cluster that holds two known objects (points on the
   predicted circles of two confirmed tracks, e.g. a walker passing a post, two walkers side by side) or a walker
   inside an extended cluster (a walker along a wall) is split along them. Without it both tracks starved while the
   objects were close: crowd_00001 (dev), two walkers side by side made one 0.76 m cluster for a second, both
   tracks were deleted and a walker was re-acquired 0.46 m from the robot as a static object. Before that, the runs
   of an extended cluster's points that lie where earlier scans saw free space (something that moved there: a
   walker who came into view along a wall, never tracked) are split out as clusters of their own
   (``freespace.FreeSpace.split``, free-space carving);
3. a cluster longer than compact_max_extent_m is a WALL (walls, long or large obstacles). It is not forced into a
   circle nor tracked: it is represented by points (``geometry.wall_candidates``): its point nearest to the robot,
   points every wall_spacing_m along it and its two ends. Returns that cannot be trusted as one whole object are
   wall points too: clusters with fewer than min_points; compact clusters that are not a clean arc (the circle model
   lost to the rectangle model) and are either partly hidden by a nearer object or seen at a grazing angle (median
   point spacing above grazing_spacing_factor beam spacings), since their apparent centre would slide as the robot
   or an occluder moves (phantom velocities); and compact clusters that no single model explains: the winning
   model's RMS residual above fit_rms_ratio_max, or a dent in the outline above concavity_ratio_max, times the range
   noise's std there (two objects in one cluster; ``geometry.concavity``). A partly hidden arc is still a good
   measurement of its circle;
4. the other compact clusters are measured (``geometry.measure_clusters``, the batched ``measure_compact``): a
   centre, a radius, whether the circle model explained them outright (the object's shape evidence) and the centre's
   covariance from the fit itself (``geometry.circle_fit_covariance`` / ``rectangle_covariance``: range noise and
   beam spacing at its points; a far post seen by four beams scatters ten times more than a near one seen by
   thirty, and a fixed covariance made the far ones' jitter look like motion). They update or start tracks
   (``tracker.Tracker.step``); a circle the tracker can neither match nor start a track with (it lies inside a
   known object but its radius does not match) is represented by its wall points;
5. the output (``tracker.Tracker.report``) is a list of CIRCLES: the confirmed tracks that are dynamic or round, at
   most max_tracks, nearest first (ids >= 0, r > 0, cov = the filter's position covariance, static flag with
   hysteresis, v = 0 when static), CONCATENATED with the WALL POINTS (at most wall_max_points, within wall_range_m
   of the robot, nearest first; ids -1, r 0, v 0, static, cov from the scan: range noise along the beam and the
   beam's angular resolution across it, ``geometry.wall_point_covariance``), one CBF constraint each. The wall
   points come from the walls and rejected clusters of this scan and from the SURFACES of the tracks not reported
   as circles: a static track that is not round (a box, a wall's end, a bottleneck's jamb), the tracks beyond the
   budget, and the tentative tracks measured in this scan (an object seen for the first time is an obstacle
   before its track is confirmed). A track's surface is the cluster of its last measurement, so a static box
   hidden for a moment keeps its points while its track coasts.

Why wall points: the CBF adds one constraint per obstacle, and a circle around a wall would either swallow the
corridor or miss the wall's ends. A wall point has radius 0, so the robot keeps D = r_R + d0 + margin from the wall
surface; between two points wall_spacing_m apart the clearance loses at most D - sqrt(D^2 - (spacing/2)^2) (about
1.5 cm for D = 0.35 m and 0.2 m spacing). Nearest first with a cap keeps the QP small where it matters: around the
robot, on every nearby wall (each wall cluster contributes its nearest point).

Why a box is not a circle: the rectangle fit completes a box into a square of its long side (its depth is unseen),
and the circle around that square reaches (sqrt 2 - 1) / 2 of the side beyond each face: 0.15 m for a 0.76 m deep
bottleneck's jamb, whose circle (r ~ 0.53 m) closed a 1.1 m opening to 0.8 m for every method (doorway_00000 and
doorway_00001, dev). Its surface points are exact.

Why the budget is kept at eight circles (max_tracks, the paper's "at most eight tracked entities", Sec. V): beyond
it, a track is not dropped but reported by its surface points (a post field of 14-19 posts lost the far posts
from the output entirely before); the circles are what the CBF keeps one row each for (``control/cbf.py``).

Limitations (documented choices): a scan is taken as instantaneous (no per-beam motion correction); wall points come
from the current scan only (no map) or a track's last cluster; an object closer than the breakpoint distance
(~0.2-0.3 m at 2 m) to a wall or to another object that is not yet tracked merges with it into one cluster for
those scans (the merged returns are wall points) unless it has moved into space that earlier scans saw free; a
moving pedestrian is reported static (v = 0) until its speed has exceeded v_dynamic_mps and dynamic_sigma standard
deviations for n_dynamic updates (three updates for a walker measured well, i.e. near the robot).
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..control.jit import kernel
from ..params.perception import PerceptionParams
from ..types import LaserScan, Obstacles
from .geometry import (Cluster, _pairwise, _take, cluster_points, compact_mask, measure_clusters, scan_to_points,
                       select_wall_points, wall_candidates_many, wall_point_covariance)
from .freespace import FreeSpace
from .tracker import Tracker


def wall_obstacles(points: np.ndarray, cov_m2) -> Obstacles:
    """Wall points as obstacles: ids -1, radius 0, zero velocity, static; covariance ``cov_m2``: one per point
    (M, 2, 2) [m^2], or a number c for c I."""
    m = len(points)
    cov = (np.broadcast_to(float(cov_m2) * np.eye(2), (m, 2, 2)).copy() if np.ndim(cov_m2) == 0
           else np.asarray(cov_m2, float).reshape(m, 2, 2))
    return Obstacles(np.asarray(points, float).reshape(m, 2), np.zeros((m, 2)), cov, np.zeros(m),
                     np.ones(m, bool), np.full(m, -1, int))


@kernel
def _grazing(pts, ranges, factor):
    """Whether a cluster (points ``pts`` in scan order, their ``ranges``) is seen at a grazing angle: the (upper)
    median of the gaps between consecutive points (an order statistic: the same value however found) above
    ``factor`` (grazing_spacing_factor beam spacings) times the mean range (numpy's ``mean``: the pairwise sum over
    the count)."""
    n = pts.shape[0]
    gaps = np.empty(n - 1)
    for i in range(n - 1):
        dx, dy = pts[i + 1, 0] - pts[i, 0], pts[i + 1, 1] - pts[i, 1]
        gaps[i] = math.sqrt(dx ** 2 + dy ** 2)
    spacing = np.sort(gaps)[(n - 1) // 2]
    return spacing > factor * ((0.0 + _pairwise(ranges, 0, n)) / n)


@kernel
def _rejected(P, ranges, idx, n, occluded, arc_fit, rms, rms_expected, dents, grazing, rms_ratio, dent_ratio):
    """(m,) bool: the measured compact clusters (points P, n[j] each, their indices ``idx`` into the scan's
    ``ranges``) that :meth:`Perception.update` turns into wall points: not a clean arc and either partly hidden or
    seen at a grazing angle (:func:`_grazing`, factor ``grazing``), or the winning model's RMS residual above
    ``rms_ratio``, or the dent above ``dent_ratio``, times the noise's RMS there."""
    m = n.shape[0]
    out = np.empty(m, np.bool_)
    lo = 0
    for j in range(m):
        hi = lo + n[j]
        bad = rms[j] > rms_ratio * rms_expected[j] or dents[j] > dent_ratio * rms_expected[j]
        if not arc_fit[j] and not bad:
            bad = occluded[j] or _grazing(P[lo:hi], ranges[idx[lo:hi]], grazing)
        out[j] = bad
        lo = hi
    return out


@kernel
def _with_walls(p, v, cov, r, static, ids, wall_pts, wall_cov):
    """``circles.concat(wall_obstacles(wall_pts, wall_cov))`` compiled: the arrays (p, v, cov, r, static, ids) of
    the circles followed by the wall points (velocity 0, radius 0, static, id -1, covariance ``wall_cov``)."""
    k, m = r.shape[0], wall_pts.shape[0]
    po, vo, co = np.empty((k + m, 2)), np.zeros((k + m, 2)), np.empty((k + m, 2, 2))
    ro, so, io = np.zeros(k + m), np.ones(k + m, np.bool_), np.full(k + m, -1, ids.dtype)
    for i in range(k):
        po[i], vo[i], co[i], ro[i], so[i], io[i] = p[i], v[i], cov[i], r[i], static[i], ids[i]
    for i in range(m):
        po[k + i], co[k + i] = wall_pts[i], wall_cov[i]
    return po, vo, co, ro, so, io


@kernel
def _split_candidates(owner, idx, n, static, compact):
    """(len(n),) bool: the clusters (n[k] points each, their point indices concatenated in ``idx``) that
    :meth:`Perception._segment` examines: points on two tracks' surfaces (``owner`` >= 0: the track index of
    each point), or on a dynamic track's while the cluster is extended."""
    m = n.shape[0]
    out = np.zeros(m, np.bool_)
    start = 0
    for k in range(m):
        lo, hi, walker = -1, -1, False
        for i in idx[start:start + n[k]]:
            o = owner[i]
            if o < 0:
                continue
            lo = o if lo < 0 else min(lo, o)
            hi = max(hi, o)
            walker = walker or not static[o]
        out[k] = hi >= 0 and (lo != hi or (walker and not compact[k]))
        start += n[k]
    return out


class Perception:
    """Obstacle estimates from LiDAR scans and odometry (module docstring). Not thread-safe; one per robot."""

    def __init__(self, params: PerceptionParams = PerceptionParams()):
        self.params = params
        self.tracker = Tracker(params)
        self.free_space = FreeSpace(params)
        self._last_ms = 0.0
        self._stamp: float | None = None
        #: The wall points of the last update (odom), for debugging and visualisation.
        self.last_wall_points = np.zeros((0, 2))

    def reset(self) -> None:
        """Forget every track (ids restart at 0)."""
        self.tracker.reset()
        self.free_space.reset()
        self._stamp = None
        self._last_ms = 0.0
        self.last_wall_points = np.zeros((0, 2))

    @property
    def last_ms(self) -> float:
        """Wall-clock time of the last ``update`` [ms]."""
        return self._last_ms

    def _segment(self, sp, clusters: list, is_compact: np.ndarray) -> tuple[list, np.ndarray]:
        """Track-aided segmentation: a cluster that holds known objects (points on the predicted circles of
        confirmed tracks, ``Tracker.surface_owner``) is split along them: a compact cluster on two or more tracks'
        surfaces (a walker beside a post or another walker), and the walkers (dynamic tracks) in an extended
        cluster (walkers side by side, a walker along a wall). Each such track's points (at least min_points)
        become a cluster of their own, marked partly hidden (its arc is cut where the other object begins); the
        rest stays one cluster. Returns the clusters and their compact flags (``geometry.compact_mask``).

        Length: to be split (issue 22): finding the clusters that need a split and splitting them are separable
        steps."""
        pr = self.params
        T = self.tracker
        if len(clusters) == 0 or not T.confirmed.any():
            return clusters, is_compact
        owner = T.surface_owner(sp.xy)
        if len(owner) == 0 or owner.max() < 0:
            return clusters, is_compact
        # only clusters with points on two tracks, or on a walker while extended, can need a split
        check = np.flatnonzero(_split_candidates(
            np.asarray(owner, np.int64), np.asarray(np.concatenate([cl.idx for cl in clusters]), np.int64),
            np.array([len(cl.idx) for cl in clusters], np.int64), np.ascontiguousarray(T.static, dtype=np.bool_),
            np.ascontiguousarray(is_compact, dtype=np.bool_)))
        if len(check) == 0:
            return clusters, is_compact
        out, flags, new = [], [], []
        split_set = set(check.tolist())
        for k, cl in enumerate(clusters):
            if k not in split_set:
                out.append(cl)
                flags.append(bool(is_compact[k]))
                continue
            own = owner[cl.idx]
            ids, counts = np.unique(own[own >= 0], return_counts=True)
            keep = counts >= 2                                      # a track with one point there: noise
            ids, counts = ids[keep], counts[keep]
            pick = (counts >= pr.min_points) & (~T.static[ids] if not is_compact[k] else len(ids) >= 2)
            split = ids[pick]
            if len(split) == 0 or (len(split) == 1 and counts[pick][0] == len(own)):
                out.append(cl)
                flags.append(bool(is_compact[k]))
                continue
            taken = np.zeros(len(own), bool)
            for i in split:
                part = own == i
                taken |= part
                out.append(Cluster(cl.idx[part], True))
                flags.append(None)
                new.append(len(out) - 1)
            if np.any(~taken):
                out.append(Cluster(cl.idx[~taken], cl.occluded))
                flags.append(None)
                new.append(len(out) - 1)
        if new:
            sub = compact_mask(sp, [out[i] for i in new], pr)
            for i, c in zip(new, sub):
                flags[i] = bool(c)
        return out, np.array(flags, bool)

    def update(self, scan: LaserScan, pose: tuple[float, float, float]) -> Obstacles:
        """Process one scan taken at ``scan.stamp`` [s] with the robot at ``pose`` = (x [m], y [m], theta [rad]) in
        odom at that stamp; returns the obstacle estimates in odom (tracks, then wall points)."""
        t0 = time.perf_counter()
        pr = self.params
        if len(pose) != 3 or not (math.isfinite(float(pose[0])) and math.isfinite(float(pose[1]))
                                  and math.isfinite(float(pose[2]))):
            raise ValueError(f"pose must be three finite numbers (x, y, theta), got {pose!r}")
        if not math.isfinite(scan.stamp):
            raise ValueError(f"scan stamp must be finite, got {scan.stamp!r}")
        if np.ndim(scan.ranges) != 1 or not scan.angle_increment > 0:
            raise ValueError("scan needs a 1-D ranges array and angle_increment > 0")
        if self._stamp is not None and scan.stamp < self._stamp:
            raise ValueError(f"scan stamp {scan.stamp} is before the previous one {self._stamp}; call reset() first")
        self._stamp = float(scan.stamp)
        robot = np.array([float(pose[0]), float(pose[1])])

        sp = scan_to_points(scan, pose, pr)
        self.tracker.predict(float(scan.stamp))
        clusters = cluster_points(sp, pr)
        clusters, is_compact = self.free_space.split(sp, clusters, compact_mask(sp, clusters, pr), float(scan.stamp))
        self.free_space.add(scan, sp, float(pose[2]) + pr.laser_yaw_rad)
        clusters, is_compact = self._segment(sp, clusters, is_compact)
        flags = is_compact.tolist()
        walls = [_take(sp.xy, cl.idx, len(cl.idx)) for cl, c in zip(clusters, flags) if not c]    # in scan order
        ms, dents = measure_clusters(sp, [cl for cl, c in zip(clusters, flags) if c], pr)
        bad = _rejected(ms.points, sp.ranges, ms.idx, ms.n, ms.occluded, ms.arc_fit, ms.rms, ms.rms_expected, dents,
                        float(pr.grazing_spacing_factor * sp.angle_increment), float(pr.fit_rms_ratio_max),
                        float(pr.concavity_ratio_max))
        compact, lo = [], 0                                         # the measured ones' point sets (views)
        for hi, b in zip(np.cumsum(ms.n).tolist(), bad.tolist()):
            (walls if b else compact).append(ms.points[lo:hi])
            lo = hi
        good = ~bad
        rejected = self.tracker.step(float(scan.stamp), ms.center[good], ms.radius[good], robot, ms.cov[good],
                                     ms.round[good], compact)
        walls += [compact[k] for k in rejected]
        circles, surfaces = self.tracker.report(robot)
        walls += surfaces
        wall_pts = select_wall_points(wall_candidates_many(walls, robot, pr.wall_spacing_m), robot, pr)
        self.last_wall_points = wall_pts
        wall_cov = wall_point_covariance(wall_pts, sp.sensor, sp.angle_increment, pr)
        out = Obstacles(*_with_walls(circles.p, circles.v, circles.cov, circles.r, circles.static, circles.ids,
                                     np.ascontiguousarray(wall_pts, dtype=float), wall_cov))
        self._last_ms = 1e3 * (time.perf_counter() - t0)
        return out
