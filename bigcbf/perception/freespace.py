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

import numpy as np

from ..control.jit import kernel
from ..params.perception import PerceptionParams
from ..types import LaserScan
from .geometry import Cluster, ScanPoints, _take, compact_mask


@kernel
def in_free_space(xy, ranges, sensors, a0, inc, past, n_beams, rows, margin, sigma0, sigma_frac):
    """(n,) bool: whether each point ``xy`` (n, 2) [m, odom] at range ``ranges`` (n,) from the current sensor lies
    where an earlier scan's two bracketing beams both returned beyond it (module docstring). The stored scans h:
    ``sensors`` (H, 2) their sensor positions [m, odom]; ``a0`` (H,) the odom bearing of their beam 0 [rad];
    ``inc`` (H,) their beam spacing [rad]; ``past`` (H, B) their ranges, NaN where a beam did not return (and
    beyond their beam count); ``n_beams`` (H,) their beam counts; the earlier scans tested are ``rows`` (in that
    order). A 360-degree scan wraps its last beam to its first."""
    n = xy.shape[0]
    H = rows.shape[0]
    out = np.zeros(n, np.bool_)
    two_pi = 2.0 * math.pi
    full = np.empty(H, np.bool_)                    # a 360-degree scan: its last beam wraps to its first
    for q in range(H):
        h = rows[q]
        full[q] = n_beams[h] * inc[h] >= two_pi - 1e-6
    for i in range(n):
        need = margin + 3.0 * (sigma0 + sigma_frac * ranges[i])
        for q in range(H):
            h = rows[q]
            dx = xy[i, 0] - sensors[h, 0]
            dy = xy[i, 1] - sensors[h, 1]
            r = math.sqrt(dx * dx + dy * dy)
            a = math.atan2(dy, dx) - a0[h]
            if a < 0.0 and a >= -two_pi:                # a % two_pi, as Python's float mod gives it, cheaper
                a += two_pi
            elif not (a >= 0.0 and a < two_pi):
                a = a % two_pi
            j = int(math.floor(a / inc[h]))
            nb = n_beams[h]
            j2 = j + 1
            if full[q]:                                 # j % nb and j2 % nb
                if j >= 0 and j2 < 2 * nb:
                    if j >= nb:
                        j -= nb
                    if j2 >= nb:
                        j2 -= nb
                else:
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


@kernel
def _earlier(stamps, start, count, stamp, hist, rows):
    """The stored scans (ring slots start, start + 1, ... mod capacity, ``count`` of them, oldest first; all before
    ``stamp``) nearest to history/3, 2 history/3 and history before it, distinct, within 1.5 history (of equally
    near ones the first stored), into ``rows`` (3,); returns how many. One pass over the stored scans."""
    lo = stamp - 1.5 * hist
    targets = (stamp - hist / 3.0, stamp - 2.0 * hist / 3.0, stamp - hist)
    best = np.full(3, -1, np.int64)
    gap = np.full(3, np.inf)
    cap = stamps.shape[0]
    for q in range(count):
        s = (start + q) % cap
        t = stamps[s]
        if lo <= t and t < stamp:
            for j in range(3):
                d = abs(t - targets[j])
                if d < gap[j]:
                    gap[j], best[j] = d, s
    k = 0
    for j in range(3):
        b = best[j]
        if b < 0:
            continue
        seen = False
        for q in range(k):
            seen = seen or rows[q] == b
        if not seen:
            rows[k] = b
            k += 1
    return k


@kernel
def _carve(xy, ranges, idx, n, stamps, start, count, stamp, hist, sensors, a0, inc, past, n_beams, margin, sigma0,
           sigma_frac, min_points, max_extent):
    """:meth:`FreeSpace.split`'s test of the extended clusters (their point indices ``idx`` concatenated, n[c]
    each) against the earlier scans (:func:`_earlier` of the ring of stored scans): (K, 3) int64 rows [cluster,
    lo, hi), each cluster's runs of points in free space (:func:`in_free_space`, :func:`_runs`), in order."""
    rows = np.empty(3, np.int64)
    h = _earlier(stamps, start, count, stamp, hist, rows)
    N = idx.shape[0]
    if h == 0 or N == 0:
        return np.empty((0, 3), np.int64)
    pts, rng = _take(xy, idx, N), ranges[idx]
    free = in_free_space(pts, rng, sensors, a0, inc, past, n_beams, rows[:h], margin, sigma0, sigma_frac)
    out = np.empty((N, 3), np.int64)
    k = 0
    lo = 0
    for c in range(n.shape[0]):
        hi = lo + n[c]
        runs = _runs(free[lo:hi], pts[lo:hi], min_points, max_extent)
        for q in range(runs.shape[0]):
            out[k, 0], out[k, 1], out[k, 2] = c, runs[q, 0], runs[q, 1]
            k += 1
        lo = hi
    return out[:k]


class FreeSpace:
    """The earlier scans the free-space test compares with (module docstring), in a ring of arrays (oldest first
    from slot ``_start``, ``_count`` of them; grown when full or when a scan has more beams); one per
    :class:`Perception`."""

    def __init__(self, params: PerceptionParams):
        self.params = params
        self.reset()

    def reset(self) -> None:
        self._start = self._count = 0
        self._alloc(16, 0)

    def _alloc(self, cap: int, width: int) -> None:
        """(Re)allocate the ring with ``cap`` slots of ``width`` beams, the stored scans moved to slots 0, 1, ..."""
        old = [getattr(self, k, None) for k in ("_stamps", "_sensors", "_a0", "_inc", "_nb", "_past")]
        self._stamps, self._sensors = np.empty(cap), np.empty((cap, 2))
        self._a0, self._inc = np.empty(cap), np.empty(cap)
        self._nb, self._past = np.zeros(cap, np.int64), np.full((cap, width), np.nan)
        if self._count:
            slots = (self._start + np.arange(self._count)) % len(old[0])
            for new, prev in zip((self._stamps, self._sensors, self._a0, self._inc, self._nb), old):
                new[:self._count] = prev[slots]
            self._past[:self._count, :old[5].shape[1]] = old[5][slots]
        self._start = 0

    def add(self, scan: LaserScan, sp: ScanPoints, theta_odom: float) -> None:
        """Remember ``scan`` for later tests: its valid returns ``sp`` (``geometry.scan_to_points``; the other beams
        NaN) and the laser's yaw in odom ``theta_odom`` [rad]."""
        cap = len(self._stamps)
        if self._count == cap or sp.n_beams > self._past.shape[1]:
            self._alloc(2 * cap if self._count == cap else cap, max(sp.n_beams, self._past.shape[1]))
        keep = 1.5 * self.params.free_space_history_s          # the oldest scan a test may use
        self._start, self._count = _push(self._stamps, self._sensors, self._a0, self._inc, self._nb, self._past,
                                         self._start, self._count, float(scan.stamp), sp.sensor,
                                         float(scan.angle_min) + theta_odom, sp.angle_increment, sp.n_beams, sp.beam,
                                         sp.ranges, float(scan.stamp - keep))

    def split(self, sp: ScanPoints, clusters: list, is_compact: np.ndarray,
              stamp: float) -> tuple[list, np.ndarray]:
        """The extended clusters' runs of points in free space split out (module docstring). Returns the clusters
        and their compact flags (``geometry.compact_mask`` for a run split out; the wall's pieces stay extended)."""
        pr = self.params
        if pr.free_space_history_s <= 0 or not clusters or bool(is_compact.all()) or not self._count:
            return clusters, is_compact
        ext = [k for k, c in enumerate(is_compact.tolist()) if not c]
        idx = [clusters[k].idx for k in ext]
        found = _carve(sp.xy, sp.ranges, np.concatenate(idx), np.array([len(i) for i in idx], np.int64),
                       self._stamps, self._start, self._count, float(stamp), float(pr.free_space_history_s),
                       self._sensors, self._a0, self._inc, self._past, self._nb, float(pr.free_space_margin_m),
                       float(pr.range_sigma_m), float(pr.range_sigma_frac), int(pr.min_points),
                       float(pr.compact_max_extent_m))
        if len(found) == 0:
            return clusters, is_compact
        runs = {}
        for c, lo, hi in found.tolist():
            runs.setdefault(ext[c], []).append((lo, hi))
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
def _push(stamps, sensors, a0s, incs, nbs, past, start, count, stamp, sensor, a0, inc, nb, beam, ranges, oldest):
    """:meth:`FreeSpace.add` into the ring (``start``, ``count``; a free slot after its last scan): the scan's
    stamp, sensor, beam-0 bearing, beam spacing, beam count and ranges (NaN where a beam did not return), then the
    scans stamped before ``oldest`` dropped, oldest first. Returns the ring's (start, count)."""
    cap = stamps.shape[0]
    s = (start + count) % cap
    count += 1
    stamps[s], sensors[s, 0], sensors[s, 1], a0s[s], incs[s], nbs[s] = stamp, sensor[0], sensor[1], a0, inc, nb
    past[s, :] = np.nan
    for i in range(beam.shape[0]):
        past[s, beam[i]] = ranges[i]
    while count > 0 and stamps[start] < oldest:
        start = (start + 1) % cap
        count -= 1
    return start, count


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
