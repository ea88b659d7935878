"""Issue 26: the compiled clustering, compactness test and wall points (geometry.cluster_points, compact_mask,
wall_candidates_many) give the bits of the numpy code they replaced (copied here as of d27bf46, the reference),
on random scenes of posts, boxes and walls, and on the scans ``bigcbf perf`` times."""
import numpy as np
import pytest

from bigcbf.params.perception import PerceptionParams
from bigcbf.perception import geometry as G
from bigcbf.perception.synthetic import box_segments, ray_scan

PR = PerceptionParams()


def ref_cluster_points(sp, params):
    n = len(sp.ranges)
    if n == 0:
        return []
    if n == 1:
        return [G.Cluster(np.array([0]), False)]
    p = sp.xy
    nxt = np.roll(np.arange(n), -1)
    d = np.linalg.norm(p[nxt] - p, axis=1)
    dbeam = (sp.beam[nxt] - sp.beam) % sp.n_beams
    dbeam[dbeam == 0] = sp.n_beams
    dphi = sp.angle_increment
    lam = params.cluster_lambda_rad
    abd = np.where((dbeam == 1) & (dphi < lam),
                   sp.ranges * np.sin(dphi) / np.sin(max(lam - dphi, 1e-9))
                   + 3 * (params.range_sigma_m + params.range_sigma_frac * sp.ranges), 0.0)
    join = d <= np.maximum(params.cluster_dist_m, abd)
    if join.all():
        return [G.Cluster(np.arange(n), False)]
    start = (int(np.flatnonzero(~join)[0]) + 1) % n
    order = np.roll(np.arange(n), -start)
    breaks = ~join[order]
    labels = np.concatenate([[0], np.cumsum(breaks[:-1])])
    bounds = np.flatnonzero(np.diff(labels)) + 1
    out = []
    for seg in np.split(order, bounds):
        first, last = seg[0], seg[-1]
        prev, nextp = (first - 1) % n, (last + 1) % n
        occ = False
        if (sp.beam[first] - sp.beam[prev]) % sp.n_beams == 1 and sp.ranges[prev] < sp.ranges[first]:
            occ = True
        if (sp.beam[nextp] - sp.beam[last]) % sp.n_beams == 1 and sp.ranges[nextp] < sp.ranges[last]:
            occ = True
        out.append(G.Cluster(seg, occ))
    return out


def ref_compact_mask(sp, clusters, params):
    m = len(clusters)
    if m == 0:
        return np.zeros(0, bool)
    limit = params.compact_max_extent_m
    n = np.array([len(c.idx) for c in clusters])
    starts = np.concatenate([[0], np.cumsum(n)[:-1]])
    P = sp.xy[np.concatenate([c.idx for c in clusters])]
    first = P[starts][np.repeat(np.arange(m), n)]
    d = np.sqrt((P[:, 0] - first[:, 0]) ** 2 + (P[:, 1] - first[:, 1]) ** 2)
    e1 = np.maximum.reduceat(d, starts)
    ok = (n >= params.min_points) & (e1 <= limit)
    for k in np.flatnonzero(ok & (e1 > limit / 2) & (n <= 400)):
        ok[k] = G.extent(P[starts[k]: starts[k] + n[k]], limit) <= limit
    return ok


def ref_wall_candidates_many(point_sets, robot_xy, spacing):
    sets = [q for q in point_sets if len(q)]
    if not sets:
        return np.zeros((0, 2))
    n = np.array([len(q) for q in sets])
    m = len(sets)
    starts = np.concatenate([[0], np.cumsum(n)[:-1]])
    ends = starts + n - 1
    Q = np.concatenate(sets)
    N = len(Q)
    g = np.repeat(np.arange(m), n)
    dx, dy = Q[:, 0] - robot_xy[0], Q[:, 1] - robot_xy[1]
    d2 = dx * dx + dy * dy
    dmin = np.minimum.reduceat(d2, starts)
    ar = np.arange(N)
    j = np.minimum.reduceat(np.where(d2 == dmin[g], ar, N), starts)
    step = np.zeros(N)
    if N > 1:
        e = np.diff(Q, axis=0)
        step[1:] = np.sqrt(e[:, 0] ** 2 + e[:, 1] ** 2)
    step[starts] = 0.0
    cs = np.cumsum(step)
    s_ = cs - cs[starts][g]
    bins = np.floor(np.abs(s_ - s_[j][g]) / spacing)
    jg = j[g]
    keep = np.zeros(N, bool)
    fwd = (ar > jg)
    keep[fwd] = bins[fwd] != bins[ar[fwd] - 1]
    bwd = (ar < jg)
    keep[bwd] = bins[bwd] != bins[ar[bwd] + 1]
    keep[j] = keep[starts] = keep[ends] = True
    sel = np.flatnonzero(keep)
    order = np.lexsort((sel, sel != jg[sel], g[sel]))
    return Q[sel[order]]


def _scans():
    """Random scenes (posts, boxes, walls, some scans with dropouts), then the perf bench's scans."""
    rng = np.random.default_rng(11)
    for trial in range(40):
        circles = [(rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(0.05, 0.4)) for _ in range(rng.integers(0, 12))]
        segs = []
        for _ in range(rng.integers(0, 5)):
            segs += box_segments(rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(0.1, 0.5),
                                 rng.uniform(0.1, 0.5), rng.uniform(0, np.pi))
        if trial % 3:
            segs += [(-6.0, -6.0, 6.0, -6.0), (-6.0, 6.0, 6.0, 6.0), (6.0, -6.0, 6.0, 6.0)]
        pose = (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-np.pi, np.pi))
        scan = ray_scan(pose, circles, segs, noise=0.01 * (trial % 2), rng=rng)
        if trial % 4 == 0:
            r = scan.ranges.copy()
            r[rng.random(len(r)) < 0.1] = np.inf
            scan = scan.__class__(scan.stamp, scan.angle_min, scan.angle_increment, scan.range_min,
                                  scan.range_max, r)
        yield scan, pose
    from bigcbf.perception import perf
    for k in range(0, 400, 7):
        t = 0.1 * k
        pose = perf._robot(t)
        peds = perf._pedestrians(t)
        yield ray_scan(pose, [(x, y, 0.25) for x, y, _, _ in peds], perf._WALLS, stamp=t, noise=0.01, rng=rng), pose


@pytest.mark.parametrize("params", [PR, PerceptionParams(cluster_dist_m=0.3, min_points=5)])
def test_compiled_geometry_is_the_numpy_code_bit_for_bit(params):
    for scan, pose in _scans():
        sp = G.scan_to_points(scan, pose, params)
        got, want = G.cluster_points(sp, params), ref_cluster_points(sp, params)
        assert len(got) == len(want)
        for a, b in zip(got, want):
            assert np.array_equal(a.idx, b.idx) and a.idx.dtype == b.idx.dtype and a.occluded == b.occluded
        assert np.array_equal(G.compact_mask(sp, want, params), ref_compact_mask(sp, want, params))
        sets = [sp.xy[c.idx] for c in want] + [np.zeros((0, 2))]
        robot = np.array(pose[:2])
        for spacing in (0.2, 0.05):
            a = G.wall_candidates_many(sets, robot, spacing)
            b = ref_wall_candidates_many(sets, robot, spacing)
            assert a.shape == b.shape and np.array_equal(a, b)


def test_degenerate_scans():
    sp = G.scan_to_points(ray_scan((0.0, 0.0, 0.0)), (0.0, 0.0, 0.0), PR)        # nothing in range
    assert G.cluster_points(sp, PR) == [] and len(G.compact_mask(sp, [], PR)) == 0
    assert G.wall_candidates_many([], np.zeros(2), 0.2).shape == (0, 2)
    sp = G.scan_to_points(ray_scan((0.0, 0.0, 0.0), segments=[(-9, -1, 9, -1), (-9, 1, 9, 1), (2, -9, 2, 9),
                                                               (-2, -9, -2, 9)]), (0.0, 0.0, 0.0), PR)
    got, want = G.cluster_points(sp, PR), ref_cluster_points(sp, PR)     # a closed room: one cluster all round
    assert len(got) == len(want) and all(np.array_equal(a.idx, b.idx) for a, b in zip(got, want))
