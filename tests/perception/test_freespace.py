"""Free-space carving (bigcbf/perception/freespace.py): a walker against a wall, seen only as part of the wall's
cluster, is split out and tracked; a wall alone, passed by a moving robot, is never split."""
import math

import numpy as np

from bigcbf.params.perception import PerceptionParams
from bigcbf.perception.freespace import FreeSpace, in_free_space
from bigcbf.perception.geometry import ScanPoints
from bigcbf.perception.pipeline import Perception
from bigcbf.perception.synthetic import ray_scan
from bigcbf.types import LaserScan

WALL = (-2.0, 1.3, 12.0, 1.3)                    # a corridor wall 1.3 m left of the robot's line
R_WALKER = 0.25


def _drive(params, walker=True, steps=40, noise=0.01):
    """The robot drives +x at 0.4 m/s along y = 0; a walker (r 0.25 m, centre 0.02 m off the wall's face, so its
    returns join the wall's cluster) walks -x at 0.85 m/s from x = 8. Returns the reports of the last scans and the
    walker's positions."""
    per, rng = Perception(params), np.random.default_rng(3)
    out = []
    for k in range(steps):
        t = 0.1 * k
        pose = (0.4 * t, 0.0, 0.0)
        w = np.array([8.0 - 0.85 * t, 1.3 - R_WALKER - 0.02])
        circles = [(w[0], w[1], R_WALKER)] if walker else []
        obs = per.update(ray_scan(pose, circles=circles, segments=[WALL], stamp=t, noise=noise, rng=rng), pose)
        out.append((t, obs, w))
    return out


def _in_free_space_plain(xy, ranges, sensors, a0, inc, past, n_beams, rows, margin, sigma0, sigma_frac):
    """The free-space test written plainly in Python (the bearing's and the beam indices' wrap by ``%``): the
    reference the compiled kernel, whose wraps take the cheaper branch where they can, must equal."""
    out = np.zeros(len(xy), bool)
    for i in range(len(xy)):
        need = margin + 3.0 * (sigma0 + sigma_frac * ranges[i])
        for h in rows:
            dx, dy = xy[i, 0] - sensors[h, 0], xy[i, 1] - sensors[h, 1]
            r = math.sqrt(dx * dx + dy * dy)
            j = int(math.floor(((math.atan2(dy, dx) - a0[h]) % (2.0 * math.pi)) / inc[h]))
            nb, j2 = int(n_beams[h]), j + 1
            if n_beams[h] * inc[h] >= 2.0 * math.pi - 1e-6:
                j, j2 = j % nb, j2 % nb
            elif j < 0 or j2 >= nb:
                continue
            r1, r2 = past[h, j], past[h, j2]
            if not (math.isnan(r1) or math.isnan(r2)) and min(r1, r2) > r + need:
                out[i] = True
                break
    return out


def test_the_free_space_kernel_equals_the_plain_test():
    """Random points and stored scans (360-degree and partial, bearings of beam 0 far outside [-2 pi, 2 pi), beams
    without a return): the kernel's booleans are the plain form's, case by case."""
    rng = np.random.default_rng(7)
    for k in range(60):
        H, B = 5, 360
        nb = rng.choice([360, 270, 181], H).astype(np.int64)
        inc = np.where(nb == 360, 2.0 * np.pi / 360, rng.uniform(0.004, 0.02, H))
        past = rng.uniform(0.3, 9.0, (H, B))
        past[rng.random((H, B)) < 0.1] = np.nan
        sensors, a0 = rng.uniform(-1.0, 1.0, (H, 2)), rng.uniform(-20.0, 20.0, H)
        xy = rng.uniform(-6.0, 6.0, (80, 2))
        args = (xy, np.hypot(xy[:, 0], xy[:, 1]), sensors, a0, inc, past, nb, rng.permutation(H)[:3].astype(np.int64),
                0.15, 0.01, 0.005)
        want = _in_free_space_plain(*args)
        assert np.array_equal(in_free_space(*args), want), k
        assert 0 < want.sum() < len(want)


def test_point_in_free_space_by_hand():
    """One earlier scan from the origin, beams every 90 degrees, all returning at 5 m: a point 2 m along beam 0's
    bearing between beams 0 and 1 (45 degrees) is in free space (both bracketing beams reach 5 m > 2 m + margin);
    a point 4.95 m out is not (within the margin); with beam 1 missing (NaN) there is no evidence."""
    sensors, a0, inc = np.zeros((1, 2)), np.zeros(1), np.array([math.pi / 2])
    past = np.full((1, 4), 5.0)
    n, rows = np.array([4], np.int64), np.array([0], np.int64)
    xy = np.array([[2 * math.cos(math.pi / 4), 2 * math.sin(math.pi / 4)],
                   [4.95 * math.cos(math.pi / 4), 4.95 * math.sin(math.pi / 4)]])
    r = np.array([2.0, 4.95])
    assert in_free_space(xy, r, sensors, a0, inc, past, n, rows, 0.15, 0.0, 0.0).tolist() == [True, False]
    past[0, 1] = np.nan
    assert in_free_space(xy, r, sensors, a0, inc, past, n, rows, 0.15, 0.0, 0.0).tolist() == [False, False]
    past[0, 1] = 5.0                                  # the last beam wraps to the first in a 360-degree scan
    xy3 = np.array([[2 * math.cos(-math.pi / 4), 2 * math.sin(-math.pi / 4)]])
    assert in_free_space(xy3, r[:1], sensors, a0, inc, past, n, rows, 0.15, 0.0, 0.0).tolist() == [True]
    # a stored scan not in ``rows`` is not looked at: here one whose beams all return at 1 m
    two = (np.zeros((2, 2)), np.zeros(2), np.full(2, math.pi / 2), np.vstack([past, np.ones((1, 4))]),
           np.full(2, 4, np.int64))
    assert in_free_space(xy, r, *two, np.array([1, 0]), 0.15, 0.0, 0.0).tolist() == [True, False]
    assert in_free_space(xy, r, *two, np.array([1]), 0.15, 0.0, 0.0).tolist() == [False, False]


def ref_earlier(scans, stamp, hist):
    """freespace.FreeSpace._earlier as of 96c6b28 (over the stored scans' stamps, oldest first): the indices of the
    picked scans."""
    lo = stamp - 1.5 * hist
    targets = (stamp - hist / 3.0, stamp - 2.0 * hist / 3.0, stamp - hist)
    best = [None, None, None]
    gap = [math.inf, math.inf, math.inf]
    for i, t in enumerate(scans):
        if lo <= t < stamp:
            for j in range(3):
                d = abs(t - targets[j])
                if d < gap[j]:
                    gap[j], best[j] = d, i
    picked = []
    for s in best:
        if s is not None and s not in picked:
            picked.append(s)
    return picked


def _ring(fs):
    """The stored scans of a FreeSpace, oldest first: (stamps, sensors, a0, inc, n_beams, ranges (their beams))."""
    slots = (fs._start + np.arange(fs._count)) % len(fs._stamps)
    return [(fs._stamps[s], fs._sensors[s].tolist(), fs._a0[s], fs._inc[s], fs._nb[s],
             fs._past[s, :fs._nb[s]].tolist()) for s in slots]


def test_earlier_scans_and_the_ring_by_hand_and_against_the_reference():
    """freespace._earlier (compiled, issue 26) picks what the former Python loop picked: by hand (ties to the first
    stored, distinct, only within 1.5 history and before the stamp) and on random rings (wrapped, with equal
    stamps)."""
    from bigcbf.perception.freespace import _earlier
    rows = np.empty(3, np.int64)
    stamps = np.array([-0.25, 0.0, 0.25, 0.5, 0.625, 0.875, 0.875, 1.0])   # targets 0.75, 0.5, 0.25 (window -0.125)
    assert rows[:_earlier(stamps, 0, 8, 1.0, 0.75, rows)].tolist() == [4, 3, 2]      # 0.625 and 0.875 tie: 0.625
    assert rows[:_earlier(np.array([0.5, 0.875]), 0, 2, 1.0, 0.75, rows)].tolist() == [1, 0]      # distinct
    assert _earlier(np.array([1.0, -0.25]), 0, 2, 1.0, 0.75, rows) == 0
    rng = np.random.default_rng(2)
    for _ in range(2000):
        cap = int(rng.integers(1, 12))
        count = int(rng.integers(0, cap + 1))
        start = int(rng.integers(0, cap))
        ordered = np.round(np.sort(rng.uniform(0, 3, count)), int(rng.integers(0, 3)))   # rounding: ties
        ring = np.full(cap, np.nan)
        ring[(start + np.arange(count)) % cap] = ordered
        stamp, hist = float(rng.uniform(0.5, 3.5)), float(rng.choice([0.3, 1.0, 2.0]))
        k = _earlier(ring, start, count, stamp, hist, rows)
        want = [(start + i) % cap for i in ref_earlier(ordered.tolist(), stamp, hist)]
        assert rows[:k].tolist() == want


def test_walker_against_a_wall_is_tracked_with_free_space_carving():
    """With the carving the walker is reported as a moving circle within 0.2 m of its centre, moving towards the
    robot, for most of the last second; without it (free_space_history_s 0) it is never a circle."""
    def tracked(params):
        hits = 0
        for t, obs, w in _drive(params)[-10:]:
            ok = obs.ids >= 0
            d = np.hypot(*(obs.p[ok] - w).T) if ok.any() else np.array([np.inf])
            j = int(np.argmin(d))
            hits += bool(d[j] < 0.2 and obs.v[ok][j][0] < -0.4)
        return hits
    assert tracked(PerceptionParams()) >= 8
    assert tracked(PerceptionParams(free_space_history_s=0.0)) == 0


def test_a_static_wall_passed_by_a_moving_robot_is_not_split():
    """The wall alone, the robot driving along it (grazing beams ahead and behind): no circle is ever reported."""
    for _, obs, _ in _drive(PerceptionParams(), walker=False):
        assert not (obs.ids >= 0).any()


def test_free_runs_by_hand_and_compiled_as_written():
    """freespace._runs (compiled, issue 26): a hand-made case: free points 2-6 with point 4 missing are one run, 9
    alone is too short, and a run wider than the extent limit is none; and on random free masks (bridged gaps,
    short runs, runs too wide) the compiled kernel gives what its own source gives run as Python."""
    from bigcbf.perception.freespace import _runs
    free = np.zeros(12, bool)
    free[[2, 3, 5, 6, 9]] = True
    pts = np.column_stack([np.arange(12) * 0.05, np.zeros(12)])
    assert _runs(free, pts, 3, 0.9).tolist() == [[2, 7]]
    assert _runs(free, pts, 3, 0.1).tolist() == []
    pr = PerceptionParams()
    rng = np.random.default_rng(5)
    for _ in range(500):
        n = int(rng.integers(1, 60))
        free = rng.random(n) < rng.uniform(0.2, 0.9)
        pts = np.cumsum(rng.uniform(0.0, 0.12, (n, 2)), axis=0)
        args = (free, pts, pr.min_points, pr.compact_max_extent_m)
        assert _runs(*args).tolist() == _runs.py_func(*args).tolist()


def test_the_ring_keeps_the_last_scans_in_order():
    """FreeSpace.add keeps the scans of the last 1.5 history in order, through the ring's growth in slots and in
    beams (a wider scan), each scan's ranges NaN where a beam did not return."""
    rng = np.random.default_rng(4)
    fs, kept = FreeSpace(PerceptionParams(free_space_history_s=2.0)), []
    for k in range(60):
        n = 8 if k < 25 else 12                                           # a wider scan from scan 25 on
        r = rng.uniform(0.5, 5.0, n)
        r[rng.random(n) < 0.3] = np.inf
        beam = np.flatnonzero(np.isfinite(r))
        sp = ScanPoints(np.zeros((len(beam), 2)), r[beam], beam, rng.uniform(-1, 1, 2), 2 * math.pi / n, n)
        scan = LaserScan(0.1 * k, -math.pi, 2 * math.pi / n, 0.1, 10.0, r)
        fs.add(scan, sp, 0.25 * k)
        kept.append((0.1 * k, sp.sensor.tolist(), -math.pi + 0.25 * k, 2 * math.pi / n, n,
                     np.where(np.isfinite(r), r, np.nan).tolist()))
        kept = [s for s in kept if s[0] >= 0.1 * k - 3.0]
        got = _ring(fs)
        assert len(got) == len(kept)
        for a, b in zip(got, kept):
            assert a[:5] == b[:5] and np.array_equal(a[5], b[5], equal_nan=True)
    assert len(fs._stamps) > 16 and fs._past.shape[1] == 12              # it grew in both
