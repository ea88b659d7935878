"""Moving objects against walls, found by the free space that earlier scans saw (issue 25).

A walker closer to a wall than the clustering's breakpoint distance makes one cluster with it, longer than
compact_max_extent_m: a WALL. Track-aided segmentation (``Perception._segment``) splits a walker out of such a
cluster only when it already has a dynamic track; a walker who comes into view along a wall never gets one. In
corridor_00012 (dev, route layer on) a walker pressed against the wall by the crowd came 1.4 m towards the
robot for 1.5 s without a track, while big-cbf-plus stepped towards that wall, and walked into it (a passive contact).

Free-space carving (the "detection and tracking of moving objects" idea of Wang, Thorpe & Thrun 2003, here on raw
scans instead of a map): a return that lies where an earlier scan's beam passed on, beyond it, to a farther return
is on something that has moved into that space. For every point of an extended cluster the test looks at up to
three earlier scans (the stored scans nearest to history/3, 2 history/3 and history ago), each from its own sensor
pose in odom: the point's bearing falls between two beams of that scan; if both returned (finite, within range
limits, as ``geometry.scan_to_points`` takes them) and both ranges exceed the point's range by more than
``free_space_margin_m`` plus three range-noise standard deviations, the point is "in free space". Taking the
nearer of the two bracketing beams keeps a wall seen at a grazing angle out of it (its range grows monotonically
across the bracket, so one of the two is nearer than the point). A beam without a return is no evidence (it may be
a dropout), as Nav2's ``inf_is_valid: false``.

Runs of consecutive points in free space (one missing point bridged), with at least min_points points and at most
compact_max_extent_m across, are split out of their extended cluster as clusters of their own, marked partly hidden:
the usual tests then decide what they are. A clean arc is measured as a circle and tracked (and, once its track is
dynamic, track-aided segmentation keeps it apart from the wall); anything else (a piece of wall moved by odometry
error) is turned back into wall points by the rule for partly hidden clusters that are not a clean arc. The pieces
of the cluster on either side of each run stay wall points, however short: a few returns of wall left beside a
walker, measured as a small circle, became a phantom track sliding along with the walker (corridor_00012).

Limitations: a walker moving slower than free_space_margin_m per history (0.15 m/s with the defaults) is found only
where it has moved by more than the margin; the test uses odometry poses, so an odometry error above the margin
between two scans can mark pieces of wall (which then stay wall points, above).
"""
from __future__ import annotations

import math
from collections import deque

import numpy as np

from ..control.jit import kernel
from ..params.perception import PerceptionParams
from ..types import LaserScan
from .geometry import Cluster, ScanPoints, compact_mask


@kernel
def in_free_space(xy, ranges, sensors, a0, inc, past, n_beams, margin, sigma0, sigma_frac):
    """(n,) bool: whether each point ``xy`` (n, 2) [m, odom] at range ``ranges`` (n,) from the current sensor lies
    where an earlier scan's two bracketing beams both returned beyond it (module docstring). Earlier scans h:
    ``sensors`` (H, 2) their sensor positions [m, odom]; ``a0`` (H,) the odom bearing of their beam 0 [rad];
    ``inc`` (H,) their beam spacing [rad]; ``past`` (H, B) their ranges, NaN where a beam did not return;
    ``n_beams`` (H,) their beam counts. A 360-degree scan wraps its last beam to its first."""
    n = xy.shape[0]
    H = sensors.shape[0]
    out = np.zeros(n, np.bool_)
    two_pi = 2.0 * math.pi
    full = np.empty(H, np.bool_)                    # a 360-degree scan: its last beam wraps to its first
    for h in range(H):
        full[h] = n_beams[h] * inc[h] >= two_pi - 1e-6
    for i in range(n):
        need = margin + 3.0 * (sigma0 + sigma_frac * ranges[i])
        for h in range(H):
            dx = xy[i, 0] - sensors[h, 0]
            dy = xy[i, 1] - sensors[h, 1]
            r = math.sqrt(dx * dx + dy * dy)
            a = (math.atan2(dy, dx) - a0[h]) % two_pi
            j = int(math.floor(a / inc[h]))
            nb = n_beams[h]
            j2 = j + 1
            if full[h]:
                j = j % nb
                j2 = j2 % nb
            elif j < 0 or j2 >= nb:
                continue
            r1, r2 = past[h, j], past[h, j2]
            if r1 != r1 or r2 != r2:
                continue
            if min(r1, r2) > r + need:
                out[i] = True
                break
    return out


class FreeSpace:
    """The earlier scans the free-space test compares with (module docstring); one per :class:`Perception`."""

    def __init__(self, params: PerceptionParams):
        self.params = params
        self._scans: deque = deque()

    def reset(self) -> None:
        self._scans.clear()

    def add(self, scan: LaserScan, sp: ScanPoints, theta_odom: float) -> None:
        """Remember ``scan`` for later tests: its valid returns ``sp`` (``geometry.scan_to_points``; the other beams
        NaN) and the laser's yaw in odom ``theta_odom`` [rad]."""
        r = np.full(sp.n_beams, np.nan)
        r[sp.beam] = sp.ranges
        self._scans.append((float(scan.stamp), sp.sensor, float(scan.angle_min) + theta_odom, sp.angle_increment, r))
        keep = 1.5 * self.params.free_space_history_s          # the oldest scan a test may use
        while self._scans and self._scans[0][0] < scan.stamp - keep:
            self._scans.popleft()

    def _earlier(self, stamp: float) -> list:
        """The stored scans (all before ``stamp``) nearest to history/3, 2 history/3 and history before it, distinct,
        within 1.5 history (of equally near ones the first stored). One pass over the stored scans."""
        hist = self.params.free_space_history_s
        lo = stamp - 1.5 * hist
        targets = (stamp - hist / 3.0, stamp - 2.0 * hist / 3.0, stamp - hist)
        best = [None, None, None]
        gap = [math.inf, math.inf, math.inf]
        for s in self._scans:
            t = s[0]
            if lo <= t < stamp:
                for j in range(3):
                    d = abs(t - targets[j])
                    if d < gap[j]:
                        gap[j], best[j] = d, s
        picked = []
        for s in best:
            if s is not None and all(s is not p for p in picked):
                picked.append(s)
        return picked

    def split(self, sp: ScanPoints, clusters: list, is_compact: np.ndarray,
              stamp: float) -> tuple[list, np.ndarray]:
        """The extended clusters' runs of points in free space split out (module docstring). Returns the clusters
        and their compact flags (``geometry.compact_mask`` for a run split out; the wall's pieces stay extended)."""
        pr = self.params
        if pr.free_space_history_s <= 0 or not clusters or bool(is_compact.all()):
            return clusters, is_compact
        earlier = self._earlier(stamp)
        if not earlier:
            return clusters, is_compact
        ext = [k for k, c in enumerate(is_compact) if not c]
        idx = np.concatenate([clusters[k].idx for k in ext])
        width = max(len(s[4]) for s in earlier)
        past = np.full((len(earlier), width), np.nan)
        for h, s in enumerate(earlier):
            past[h, :len(s[4])] = s[4]
        free = in_free_space(np.ascontiguousarray(sp.xy[idx]), np.ascontiguousarray(sp.ranges[idx], dtype=float),
                             np.array([s[1] for s in earlier]), np.array([s[2] for s in earlier]),
                             np.array([s[3] for s in earlier]), past, np.array([len(s[4]) for s in earlier], np.int64),
                             float(pr.free_space_margin_m), float(pr.range_sigma_m), float(pr.range_sigma_frac))
        if not free.any():
            return clusters, is_compact
        runs, start = {}, 0
        for k in ext:
            n = len(clusters[k].idx)
            runs[k] = _runs(free[start:start + n], np.ascontiguousarray(sp.xy[clusters[k].idx]), int(pr.min_points),
                            float(pr.compact_max_extent_m)).tolist()
            start += n
        if not any(runs.values()):
            return clusters, is_compact
        out, flags = [], []                     # flags: compact, extended (False) or a run to measure (None)
        for k, cl in enumerate(clusters):
            if not runs.get(k):
                out.append(cl)
                flags.append(bool(is_compact[k]))
                continue
            prev = 0
            for lo, hi in runs[k]:
                if lo > prev:
                    out.append(Cluster(cl.idx[prev:lo], cl.occluded))
                    flags.append(False)                    # the wall's pieces stay wall points
                out.append(Cluster(cl.idx[lo:hi], True))
                flags.append(None)
                prev = hi
            if prev < len(cl.idx):
                out.append(Cluster(cl.idx[prev:], cl.occluded))
                flags.append(False)
        new = [i for i, f in enumerate(flags) if f is None]
        for i, c in zip(new, compact_mask(sp, [out[i] for i in new], pr)):
            flags[i] = bool(c)
        return out, np.array(flags, bool)


@kernel
def _runs(free, pts, min_points, max_extent):
    """(K, 2) int64 rows [lo, hi): the runs of ``free`` points (in scan order; one missing point bridged) with at least
    ``min_points`` free points and at most ``max_extent`` [m] between their ends (numpy's hypot of the ends'
    difference)."""
    n = free.shape[0]
    out = np.empty((n, 2), np.int64)
    k = 0
    i = 0
    while i < n:
        if not free[i]:
            i += 1
            continue
        lo, hi, count = i, i + 1, 1
        j = i + 1
        while j < n:
            if free[j]:
                hi, count = j + 1, count + 1
                j += 1
            elif j + 1 < n and free[j + 1]:
                j += 1                                     # bridge one point
            else:
                break
        if count >= min_points and np.hypot(pts[hi - 1, 0] - pts[lo, 0], pts[hi - 1, 1] - pts[lo, 1]) <= max_extent:
            out[k, 0], out[k, 1] = lo, hi
            k += 1
        i = hi
    return out[:k]
