"""Issue 26: the compiled clustering, compactness test, cluster measurements and wall points
(geometry.cluster_points, compact_mask, measure_clusters, wall_candidates_many) give the bits of the numpy code they replaced (copied here as of d27bf46, the reference),
on random scenes of posts, boxes and walls, and on the scans ``bigcbf perf`` times."""
import numpy as np
import pytest

from bigcbf.params.perception import PerceptionParams
from bigcbf.perception import geometry as G, pipeline
from bigcbf.perception.synthetic import box_segments, ray_scan
from bigcbf.perception.kalman import static_update

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


def ref_edge_distances(points: np.ndarray, e1: np.ndarray, e2: np.ndarray):
    a, b = e1 @ points.T, e2 @ points.T                                   # (K, n)
    amin, amax = a.min(axis=1), a.max(axis=1)
    bmin, bmax = b.min(axis=1), b.max(axis=1)
    d = np.minimum(np.minimum(a - amin[:, None], amax[:, None] - a), np.minimum(b - bmin[:, None], bmax[:, None] - b))
    return amin, amax, bmin, bmax, d


def ref_fit_rectangle(points: np.ndarray, sensor: np.ndarray, full: bool = False):
    *_, d = ref_edge_distances(points, G._COARSE_E1, G._COARSE_E2)
    ang = G._COARSE[int(np.argmin(np.einsum("kn,kn->k", d, d)))] + G._FINE
    c, sn = np.cos(ang), np.sin(ang)
    e1s, e2s = np.stack([c, sn], axis=1), np.stack([-sn, c], axis=1)
    amin, amax, bmin, bmax, d = ref_edge_distances(points, e1s, e2s)
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


def ref_circle_cov_from_sums(a11, a12, a22, a13, a23, a33, fit_radius, center, sensor, params) -> np.ndarray:
    """circle_fit_covariance from the entries of J^T W J (closed-form inverses)."""
    cap = params.radius_max_m ** 2
    if fit_radius:
        # centre block of the inverse of [[a11, a12, a13], [a12, a22, a23], [a13, a23, a33]]: cofactors / det
        c11 = a22 * a33 - a23 * a23
        c12 = -(a12 * a33 - a23 * a13)
        c22 = a11 * a33 - a13 * a13
        det = a11 * c11 + a12 * c12 + a13 * (a12 * a23 - a22 * a13)
        if not det > 0:
            return cap * np.eye(2)
        C = np.array([[c11, c12], [c12, c22]]) / det
    else:
        det = a11 * a22 - a12 * a12
        if not det > 0:
            return cap * np.eye(2)
        C = np.array([[a22, -a12], [-a12, a11]]) / det
        ray = center - sensor
        ray = ray / max(float(np.linalg.norm(ray)), 1e-12)
        C = C + (params.radius_max_m - params.radius_min_m) ** 2 / 12.0 * np.outer(ray, ray)
    if not np.all(np.isfinite(C)):
        return cap * np.eye(2)
    return G._cap_std(C, params.radius_max_m)


def ref_measure_clusters(sp, clusters, params):
    """geometry.measure_clusters as of d27bf46."""
    m = len(clusters)
    if m == 0:
        return [], np.zeros(0)
    pr = params
    n = np.array([len(c.idx) for c in clusters])
    starts = np.concatenate([[0], np.cumsum(n)[:-1]])
    idx = np.concatenate([c.idx for c in clusters])
    g = np.repeat(np.arange(m), n)
    P = sp.xy[idx]
    px, py = P[:, 0], P[:, 1]
    sensor = sp.sensor
    dx, dy = px - sensor[0], py - sensor[1]
    dist = np.sqrt(dx * dx + dy * dy)
    # nearest point of each cluster (the first one at the minimum, as np.argmin)
    dmin = np.minimum.reduceat(dist, starts)
    cand = np.where(dist == dmin[g], np.arange(len(idx)), len(idx))
    k_near = np.minimum.reduceat(cand, starts)
    near = P[k_near]
    ray = (near - sensor) / np.maximum(dmin, 1e-9)[:, None]
    sigma = pr.range_sigma_m + pr.range_sigma_frac * np.add.reduceat(dist, starts) / n
    # algebraic (Kasa) circle fits, as fit_circle
    mean = np.add.reduceat(P, starts) / n[:, None]
    u, v = px - mean[g, 0], py - mean[g, 1]
    uu, vv, uv = u * u, v * v, u * v
    suu, svv, suv = np.add.reduceat(uu, starts), np.add.reduceat(vv, starts), np.add.reduceat(uv, starts)
    w = uu + vv
    b1, b2 = 0.5 * np.add.reduceat(u * w, starts), 0.5 * np.add.reduceat(v * w, starts)
    det = suu * svv - suv * suv
    good = (n >= 3) & (det > 1e-10 * (suu + svv) ** 2)
    sdet = np.where(good, det, 1.0)
    uc = np.where(good, (svv * b1 - suv * b2) / sdet, 0.0)
    vc = np.where(good, (suu * b2 - suv * b1) / sdet, 0.0)
    r = np.where(good, np.sqrt(uc * uc + vc * vc + (suu + svv) / n), np.inf)
    c = mean + np.stack([uc, vc], axis=1)
    res = np.sqrt((u - uc[g]) ** 2 + (v - vc[g]) ** 2) - np.where(good, r, 0.0)[g]
    rms = np.where(good, np.sqrt(np.add.reduceat(res * res, starts) / n), np.inf)
    behind = np.einsum("ij,ij->i", ray, c - near) > 0
    fitted = np.isfinite(r) & (pr.radius_min_m <= r) & (r <= pr.radius_max_m) & behind
    tol = np.where(fitted, sigma, 0.0)
    for j in np.flatnonzero(~fitted):                    # clamp the radius and refit the centre (rare)
        rj = float(np.clip(r[j] if np.isfinite(r[j]) else pr.radius_max_m, pr.radius_min_m, pr.radius_max_m))
        pts = P[starts[j]: starts[j] + n[j]]
        cj, rmsj = G.fit_circle_fixed_radius(pts, rj, near[j] + rj * ray[j])
        c[j], r[j], rms[j] = cj, rj, rmsj
    behind = np.einsum("ij,ij->i", ray, c - near) > 0
    # arc span seen from the centre, as measure_compact
    u2x, u2y = px - c[g, 0], py - c[g, 1]
    midx, midy = np.add.reduceat(u2x, starts) / n, np.add.reduceat(u2y, starts) / n
    ang = np.arctan2(u2x * midy[g] - u2y * midx[g], u2x * midx[g] + u2y * midy[g])
    span = np.maximum.reduceat(ang, starts) - np.minimum.reduceat(ang, starts)
    dc = np.linalg.norm(c - sensor, axis=1)
    rr = np.where(np.isfinite(r), r, 1.0)
    sampled = np.minimum(np.arccos(np.minimum(rr / np.maximum(dc, 1e-12), 1.0)),
                         np.arcsin(np.clip((rr - dc * sp.angle_increment) / rr, 0.0, 1.0)))
    occluded = np.array([cl.occluded for cl in clusters])
    need = np.where(occluded, pr.fit_min_arc_rad,
                    np.maximum(pr.fit_min_arc_rad, pr.fit_span_ratio * 2 * sampled))
    # point weights for the circle covariances (point_variances with the outward normals)
    d2 = np.maximum(np.sqrt(u2x * u2x + u2y * u2y), 1e-12)
    nx, ny = u2x / d2, u2y / d2
    cos = (dx * nx + dy * ny) / np.maximum(dist, 1e-12)
    cos2 = np.minimum(cos * cos, 1.0)
    sr = pr.range_sigma_m + pr.range_sigma_frac * dist
    wt = 1.0 / np.maximum(sr * sr * cos2 + (dist * sp.angle_increment) ** 2 / 12.0 * (1.0 - cos2), 1e-12)
    a11, a12, a22 = (np.add.reduceat(wt * nx * nx, starts), np.add.reduceat(wt * nx * ny, starts),
                     np.add.reduceat(wt * ny * ny, starts))
    a13, a23, a33 = np.add.reduceat(wt * nx, starts), np.add.reduceat(wt * ny, starts), np.add.reduceat(wt, starts)
    # dents (concavity, k = 2): the point two ahead against the chord from two before to two after
    dents = np.zeros(m)
    N = len(idx)
    if N > 4:
        ia = np.arange(N - 4)
        same = g[ia] == g[ia + 4]
        if same.any():
            ia = ia[same]
            a_, b_, c_ = P[ia], P[ia + 2], P[ia + 4]
            ex, ey = c_[:, 0] - a_[:, 0], c_[:, 1] - a_[:, 1]
            length = np.maximum(np.sqrt(ex * ex + ey * ey), 1e-12)
            side_b = ex * (b_[:, 1] - a_[:, 1]) - ey * (b_[:, 0] - a_[:, 0])
            side_s = ex * (sensor[1] - a_[:, 1]) - ey * (sensor[0] - a_[:, 0])
            np.maximum.at(dents, g[ia], -np.sign(side_s) * side_b / length)
    out = []
    for j in range(m):
        pts = P[starts[j]: starts[j] + n[j]]
        if tol[j] > 0 and rms[j] <= tol[j]:
            rect, rms_rect = None, np.inf
        else:
            rect = ref_fit_rectangle(pts, sensor, full=True)
            rms_rect = rect[2]
        if rms[j] <= rms_rect + tol[j] and behind[j] and span[j] >= need[j]:
            cov = ref_circle_cov_from_sums(a11[j], a12[j], a22[j], a13[j], a23[j], a33[j], bool(fitted[j]),
                                        c[j], sensor, pr)
            out.append(G.Measurement(c[j].copy(), float(r[j]), True, cov, float(rms[j]), float(sigma[j]),
                                   bool(rms[j] <= rms_rect)))
            continue
        if rect is None:
            rect = ref_fit_rectangle(pts, sensor, full=True)
        rc, rrad, rms_rect, axes, lengths = rect
        cov = G.rectangle_covariance(pts, axes, lengths, sensor, sp.angle_increment, pr)
        out.append(G.Measurement(rc, float(np.clip(rrad, pr.radius_min_m, pr.radius_max_m)), False, cov,
                               float(rms_rect), float(sigma[j])))
    return out, dents


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
        mask = ref_compact_mask(sp, want, params)
        assert np.array_equal(G.compact_mask(sp, want, params), mask)
        compact = [c for c, k in zip(want, mask) if k and len(c.idx) >= 3]
        (ms, dents), (ms0, dents0) = G.measure_clusters(sp, compact, params), ref_measure_clusters(sp, compact, params)
        assert np.array_equal(dents, dents0) and len(ms) == len(ms0)
        for a, b in zip(ms, ms0):
            # the rectangle fits, their covariances and the fixed-radius refits are compiled with their own sums
            # (issue 26): equal to rounding; the rest of the measurement bit for bit
            np.testing.assert_allclose(a.center, b.center, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(a.cov, b.cov, rtol=1e-9, atol=1e-15)
            np.testing.assert_allclose((a.radius, a.rms), (b.radius, b.rms), rtol=1e-9, atol=1e-12)
            assert (a.arc_fit, a.rms_expected, a.round) == (b.arc_fit, b.rms_expected, b.round)
        # the pipeline's test of the measurements (compiled, issue 26) against its former Python loop
        assert np.array_equal(ms.points, sp.xy[ms.idx]) and ms.n.tolist() == [len(c.idx) for c in compact]
        args = (ms.points, sp.ranges, ms.idx, ms.n, ms.occluded, ms.arc_fit, ms.rms, ms.rms_expected, dents,
                float(params.grazing_spacing_factor * sp.angle_increment), float(params.fit_rms_ratio_max),
                float(params.concavity_ratio_max))
        assert np.array_equal(pipeline._rejected(*args), ref_rejected(*args))
        sets = [sp.xy[c.idx] for c in want] + [np.zeros((0, 2))]
        robot = np.array(pose[:2])
        for spacing in (0.2, 0.05):
            a = G.wall_candidates_many(sets, robot, spacing)
            b = ref_wall_candidates_many(sets, robot, spacing)
            assert a.shape == b.shape and np.array_equal(a, b)


def test_compiled_rectangle_and_refit_match_their_numpy_references():
    """geometry._rect_fit, _rect_cov and _fixed_radius_fit (what measure_clusters runs) against fit_rectangle,
    rectangle_covariance and fit_circle_fixed_radius on noisy L-shapes, faces and arcs at random poses."""
    rng = np.random.default_rng(11)
    out, C, fit3 = np.empty(10), np.empty((2, 2)), np.empty(3)
    for trial in range(200):
        th, w, h = rng.uniform(0, np.pi), rng.uniform(0.1, 0.8), rng.uniform(0.1, 0.8)
        c = rng.uniform(-4, 4, 2)
        s = np.linspace(0, 1, rng.integers(4, 30))
        e1, e2 = np.array([np.cos(th), np.sin(th)]), np.array([-np.sin(th), np.cos(th)])
        pts = c + np.r_[np.outer(s * w, e1), np.outer(s * h, e2)[1:] if trial % 3 else np.zeros((0, 2))]
        pts = pts + rng.normal(0, 0.01, pts.shape)
        sensor = c - 3.0 * (e1 + e2) / np.sqrt(2)
        P = np.ascontiguousarray(np.r_[rng.normal(size=(3, 2)), pts])         # at an offset in a longer array
        G._rect_fit(P, 3, len(pts), float(sensor[0]), float(sensor[1]), G._COARSE, G._COARSE_COS, G._COARSE_SIN,
                    G._FINE, out)
        center, radius, rms, axes, (la, lb) = G.fit_rectangle(pts, sensor, full=True)
        np.testing.assert_allclose(out[:2], center, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(out[2:4], (radius, rms), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(out[4:8], axes.ravel(), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(out[8:], (la, lb), rtol=1e-9, atol=1e-12)
        G._rect_cov(P, 3, len(pts), float(sensor[0]), float(sensor[1]), *out[4:10], np.deg2rad(0.5), PR.range_sigma_m,
                    PR.range_sigma_frac, PR.radius_max_m, C)
        np.testing.assert_allclose(C, G.rectangle_covariance(pts, axes, (la, lb), sensor, np.deg2rad(0.5), PR),
                                   rtol=1e-9, atol=1e-15)
        r0 = rng.uniform(0.1, 0.4)
        arc = c + r0 * np.c_[np.cos(s * 2), np.sin(s * 2)] + rng.normal(0, 0.01, (len(s), 2))
        start = c + rng.normal(0, 0.05, 2)
        G._fixed_radius_fit(np.ascontiguousarray(arc), 0, len(arc), r0, float(start[0]), float(start[1]), 10, fit3)
        cf, rmsf = G.fit_circle_fixed_radius(arc, r0, start)
        np.testing.assert_allclose(fit3, (*cf, rmsf), rtol=1e-9, atol=1e-12)


def ref_scan_to_points(scan, pose, params):
    """geometry.scan_to_points as of d3b5ed9 (numpy)."""
    r = np.asarray(scan.ranges, dtype=float)
    ok = np.isfinite(r) & (r >= scan.range_min) & (r <= scan.range_max)
    beam = np.flatnonzero(ok)
    rv = r[beam]
    x, y, th = (float(v) for v in pose)
    a = scan.angle_min + scan.angle_increment * beam + params.laser_yaw_rad + th
    t_l = G.rot(th) @ np.array([params.laser_x_m, params.laser_y_m])
    sensor = np.array([x, y]) + t_l
    return np.stack([sensor[0] + rv * np.cos(a), sensor[1] + rv * np.sin(a)], axis=1), rv, beam, sensor


def test_compiled_scan_points_match_the_numpy_formulation():
    """scan_to_points (compiled: geometry._scan_points) on the test scans (dropouts, infinities, out of range)
    with a mounted laser: the same beams and ranges, the points and the sensor to rounding."""
    mount = PerceptionParams(laser_x_m=0.09, laser_y_m=-0.02, laser_yaw_rad=0.3)
    n = 0
    for scan, pose in _scans():
        r = np.array(scan.ranges, float)
        r[::17] = scan.range_max * 2
        r[::29] = -1.0
        scan = scan.__class__(scan.stamp, scan.angle_min, scan.angle_increment, scan.range_min, scan.range_max, r)
        for params in (PR, mount):
            sp = G.scan_to_points(scan, pose, params)
            xy, rv, beam, sensor = ref_scan_to_points(scan, pose, params)
            assert np.array_equal(sp.beam, beam) and np.array_equal(sp.ranges, rv) and sp.n_beams == len(r)
            np.testing.assert_allclose(sp.xy, xy, rtol=0, atol=1e-12)
            np.testing.assert_allclose(sp.sensor, sensor, rtol=0, atol=1e-15)
            n += len(beam)
    assert n > 1000


def test_degenerate_scans():
    sp = G.scan_to_points(ray_scan((0.0, 0.0, 0.0)), (0.0, 0.0, 0.0), PR)        # nothing in range
    assert G.cluster_points(sp, PR) == [] and len(G.compact_mask(sp, [], PR)) == 0
    assert G.wall_candidates_many([], np.zeros(2), 0.2).shape == (0, 2)
    sp = G.scan_to_points(ray_scan((0.0, 0.0, 0.0), segments=[(-9, -1, 9, -1), (-9, 1, 9, 1), (2, -9, 2, 9),
                                                               (-2, -9, -2, 9)]), (0.0, 0.0, 0.0), PR)
    got, want = G.cluster_points(sp, PR), ref_cluster_points(sp, PR)     # a closed room: one cluster all round
    assert len(got) == len(want) and all(np.array_equal(a.idx, b.idx) for a, b in zip(got, want))


def ref_surface_owner(self, points):
    """tracker.Tracker.surface_owner as of d27bf46."""
    out = np.full(len(points), -1)
    conf = np.flatnonzero(self.confirmed)
    if len(conf) == 0 or len(points) == 0:
        return out
    c, r = self.x[conf, :2], self.r[conf]
    lam = np.linalg.eigvalsh(self.P[conf, :2, :2])[:, -1]
    tol = self.params.merge_tol_m + 2.0 * np.sqrt(np.maximum(lam, 0.0))
    d = np.abs(np.sqrt((points[:, None, 0] - c[None, :, 0]) ** 2 + (points[:, None, 1] - c[None, :, 1]) ** 2)
               - r[None, :])
    best = np.argmin(d, axis=1)
    ok = d[np.arange(len(points)), best] <= tol[best]
    out[ok] = conf[best[ok]]
    return out


def ref_split_candidates(owner, idx, n, static, compact):
    """The cluster selection of pipeline.Perception._segment as of d27bf46."""
    owned = np.flatnonzero(owner >= 0)
    label = np.empty(len(owner), int)
    label[idx] = np.repeat(np.arange(len(n)), n)
    lo = np.full(len(n), np.iinfo(int).max)
    hi = np.full(len(n), -1)
    np.minimum.at(lo, label[owned], owner[owned])
    np.maximum.at(hi, label[owned], owner[owned])
    walker = np.zeros(len(n), bool)
    dyn = owned[~static[owner[owned]]]
    walker[label[dyn]] = True
    return (hi >= 0) & ((lo != hi) | (walker & ~compact))


def ref_grazing(pts, ranges, factor):
    """pipeline._grazing as of d27bf46 (then Perception._grazing, ``factor`` grazing_spacing_factor times the beam
    spacing)."""
    step = np.diff(pts, axis=0)
    gaps = np.sqrt(step[:, 0] ** 2 + step[:, 1] ** 2)
    spacing = float(np.partition(gaps, len(gaps) // 2)[len(gaps) // 2])
    return spacing > factor * float(np.mean(ranges))


def ref_rejected(P, ranges, idx, n, occluded, arc_fit, rms, rms_expected, dents, grazing, rms_ratio, dent_ratio):
    """pipeline._rejected: the test of Perception.update's loop over the measurements as of 96c6b28."""
    out, lo = [], 0
    for j, k in enumerate(n):
        pts = P[lo:lo + k]
        out.append(bool((not arc_fit[j] and (occluded[j] or ref_grazing(pts, ranges[idx[lo:lo + k]], grazing)))
                        or rms[j] > rms_ratio * rms_expected[j] or dents[j] > dent_ratio * rms_expected[j]))
        lo += k
    return np.array(out, bool)


def ref_measurements(sp, clusters, params):
    """ref_measure_clusters as geometry.measure_clusters returns it (geometry.Measurements)."""
    ms, dents = ref_measure_clusters(sp, clusters, params)
    idx = np.concatenate([c.idx for c in clusters]) if clusters else np.zeros(0, np.int64)
    arrays = [np.array([getattr(m, f) for m in ms], dtype=t).reshape((len(ms),) + s) for f, t, s in
              (("center", float, (2,)), ("radius", float, ()), ("arc_fit", bool, ()), ("cov", float, (2, 2)),
               ("rms", float, ()), ("rms_expected", float, ()), ("round", bool, ()))]
    return G.Measurements(sp.xy[idx], np.array([len(c.idx) for c in clusters], np.int64), idx,
                          np.array([c.occluded for c in clusters], bool), *arrays), np.asarray(dents, float)


def _episode_frames(name, seconds):
    """The (scan, odometry pose) pairs the perception got in the first ``seconds`` of a big-cbf episode."""
    from bigcbf.episode import Episode
    from bigcbf.params.stack import SIMULATION
    from bigcbf.scenario import load_scenario
    ep = Episode(load_scenario(name, 0), "big-cbf", 0, SIMULATION, perception="lidar", time_limit_s=seconds)
    frames = []
    update = ep.perception.update

    def record(scan, pose):
        frames.append((scan, pose))
        return update(scan, pose)

    ep.perception.update = record
    ep.run()
    return frames


@pytest.mark.parametrize("source", ["perf", "mixed_dense_traffic", "francis2023_narrow_doorway", "multi_static_clutter"])
def test_whole_pipeline_is_the_numpy_pipeline(monkeypatch, source):
    """Perception.update with every compiled piece against the same pipeline run on the reference copies: on the
    perf bench's scans and on the simulated LiDAR of three episodes (walkers, walls, doors). Bit for bit until the
    tracker's measurement update was compiled (issue 26: ``tracker._measurement_update`` sums its small matrix
    products in its own order, not BLAS's); since, the same tracks and classes, the estimates equal to rounding."""
    from bigcbf.perception import perf, pipeline
    from bigcbf.perception.tracker import Tracker
    rng = np.random.default_rng(3)
    frames = []
    for k in range(150 if source == "perf" else 0):
        t = 0.1 * k
        pose = perf._robot(t)
        peds = perf._pedestrians(t)
        frames.append((ray_scan(pose, [(x, y, 0.25) for x, y, _, _ in peds], perf._WALLS, stamp=t, noise=0.01,
                                rng=rng), pose))
    if source != "perf":
        frames = _episode_frames(source, 6.0)
    perc = pipeline.Perception()
    got = [perc.update(*f) for f in frames]
    monkeypatch.setattr(pipeline, "cluster_points", ref_cluster_points)
    monkeypatch.setattr(pipeline, "compact_mask", ref_compact_mask)
    monkeypatch.setattr(pipeline, "measure_clusters", ref_measurements)
    monkeypatch.setattr(pipeline, "wall_candidates_many", ref_wall_candidates_many)
    monkeypatch.setattr(pipeline, "_split_candidates", ref_split_candidates)
    monkeypatch.setattr(Tracker, "surface_owner", ref_surface_owner)
    monkeypatch.setattr(Tracker, "associate", ref_associate)
    monkeypatch.setattr(pipeline, "select_wall_points", ref_select_wall_points)
    monkeypatch.setattr(pipeline, "wall_point_covariance", ref_wall_point_covariance)
    monkeypatch.setattr(Tracker, "step", ref_step)
    monkeypatch.setattr(pipeline, "_rejected", ref_rejected)
    perc = pipeline.Perception()
    want = [perc.update(*f) for f in frames]
    n_tracks = 0
    for a, b in zip(got, want):
        n_tracks += int((a.ids >= 0).sum())
        for field in ("static", "ids"):
            assert np.array_equal(getattr(a, field), getattr(b, field)), field
        for field in ("p", "v", "cov", "r"):     # (largest difference measured: 9e-15)
            np.testing.assert_allclose(getattr(a, field), getattr(b, field), rtol=1e-9, atol=1e-12, err_msg=field)
    assert n_tracks > (200 if source == "perf" else 20)     # tracks were reported: the tracker is compared too


def ref_associate(self, z, radii, R=None):
    """tracker.Tracker.associate as of d27bf46."""
    from scipy.optimize import linear_sum_assignment
    from bigcbf.perception.kalman import mahalanobis2
    n, m = len(self), len(z)
    if n == 0 or m == 0:
        return np.zeros(0, int), np.zeros(0, int)
    pr = self.params
    if R is None:
        R = self.measurement_covariance(None, m)
    y = z[None, :, :] - self.x[:, None, :2]
    dist = np.linalg.norm(y, axis=2)
    S = self.P[:, None, :2, :2] + R[None, :, :, :]
    d2 = mahalanobis2(y, S)
    ok = ((d2 <= pr.gate_chi2) | (dist <= pr.gate_min_m)) & (dist <= pr.gate_max_m)
    ok &= np.abs(radii[None, :] - self.r[:, None]) <= pr.gate_radius_m
    cost = np.where(ok, dist, 1e9)
    rows, cols = linear_sum_assignment(cost)
    good = ok[rows, cols]
    return rows[good], cols[good]


def ref_hysteresis_step(static, n_dyn, n_stat, speed, sigma, params):
    """classify.hysteresis_step as of d27bf46."""
    fast = (speed > params.v_dynamic_mps) & (speed > params.dynamic_sigma * sigma)
    slow = speed < params.v_static_mps
    n_dyn = np.where(static & fast, n_dyn + 1, 0)
    n_stat = np.where(~static & slow, n_stat + 1, 0)
    to_dyn = static & (n_dyn >= params.n_dynamic)
    to_stat = ~static & (n_stat >= params.n_static)
    static = (static & ~to_dyn) | to_stat
    n_dyn = np.where(to_dyn, 0, n_dyn)
    n_stat = np.where(to_stat, 0, n_stat)
    return static, n_dyn, n_stat


def ref_step(self, t: float, z: np.ndarray, radii: np.ndarray, robot_xy: np.ndarray, cov: np.ndarray | None = None,
         round_: np.ndarray | None = None, surface: list | None = None) -> np.ndarray:
    """tracker.Tracker.step as of d27bf46 (with the associate of this commit's reference)."""
    pr = self.params
    z = np.asarray(z, float).reshape(-1, 2)
    m = len(z)
    radii = np.asarray(radii, float).reshape(-1)
    R = self.measurement_covariance(cov, m)
    rnd = np.ones(m) if round_ is None else np.asarray(round_, float).reshape(m)
    surf = np.empty(m, object)
    for k in range(m):
        surf[k] = np.zeros((0, 2)) if surface is None else surface[k]
    self.predict(t)
    rows, cols = self.associate(z, radii, R)
    if len(rows):
        x, P = _kf_update(self.x[rows], self.P[rows], z[cols], R[cols])
        self.x[rows], self.P[rows] = x, P
        self.xs[rows], self.Ps[rows] = static_update(self.xs[rows], self.Ps[rows], x[:, :2], P[:, :2, :2], z[cols],
                                                     R[cols], pr.gate_chi2)   # Tracker._update_static_filter of d27bf46
        a = pr.radius_smoothing
        self.r[rows] = (1 - a) * self.r[rows] + a * radii[cols]
        b = pr.shape_smoothing
        self.roundness[rows] = (1 - b) * self.roundness[rows] + b * rnd[cols]
        self.surface[rows] = surf[cols]
        self.hits[rows] += 1
        self.misses[rows] = 0
        self.last_hit[rows] = t
        self.confirmed[rows] |= self.hits[rows] >= pr.confirm_hits
        v = x[:, 2:]
        st, nd, ns = ref_hysteresis_step(self.static[rows], self.n_dyn[rows], self.n_stat[rows],
                                     np.linalg.norm(v, axis=1), _speed_sigma(v, P[:, 2:, 2:]), pr)
        # the classification starts once the velocity rests on more than classify_after_hits measurements: a
        # young track's velocity is the difference of two or three noisy centres (module docstring)
        young = self.hits[rows] <= pr.classify_after_hits
        st = np.where(young, self.static[rows], st)
        nd = np.where(young, 0, nd)
        ns = np.where(young, 0, ns)
        self.static[rows], self.n_dyn[rows], self.n_stat[rows] = st, nd, ns
        self.P_hit[rows] = np.where(st[:, None, None], self.Ps[rows], P[:, :2, :2])
        self.sv_hit[rows] = np.sqrt(np.linalg.eigvalsh(P[:, 2:, 2:])[:, -1])
    missed = np.ones(len(self), bool)
    missed[rows] = False
    self.misses[missed] += 1
    alive = np.where(self.confirmed, t - self.last_hit <= pr.coast_s + 1e-9,
                     self.misses <= pr.tentative_max_misses)
    if not alive.all():                       # (all alive: the arrays stay as they are)
        self._keep(alive)
    # births from unclaimed clusters, unless the centre lies inside a known object's circle (a split cluster)
    free = np.ones(len(z), bool)
    free[cols] = False
    rejected = np.zeros(len(z), bool)
    if free.any() and len(self):
        d = np.linalg.norm(z[:, None, :] - self.x[None, :, :2], axis=2)
        rejected |= free & (d < np.maximum(self.r[None, :], radii[:, None])).any(axis=1)
        free &= ~rejected
    if free.any():
        self._append(z[free], radii[free], R[free], rnd[free], surf[free], t)
    if len(self) > pr.max_candidates:
        keep = np.argsort(self.surface_distance(robot_xy), kind="stable")[: pr.max_candidates]
        self._keep(np.sort(keep))
    return np.flatnonzero(rejected)


def _kf_update(*args):
    from bigcbf.perception.kalman import kf_update
    return kf_update(*args)


def _speed_sigma(*args):
    from bigcbf.perception.classify import speed_sigma
    return speed_sigma(*args)


def test_hysteresis_step_is_the_numpy_rules():
    from bigcbf.perception.classify import hysteresis_step
    rng = np.random.default_rng(0)
    for _ in range(50):
        N = int(rng.integers(0, 9))
        args = (rng.random(N) < 0.5, rng.integers(0, 4, N), rng.integers(0, 4, N), rng.uniform(0, 1, N),
                rng.uniform(0, 0.3, N))
        for a, b in zip(hysteresis_step(*args, PR), ref_hysteresis_step(*args, PR)):
            assert np.array_equal(a, b) and a.dtype == b.dtype


def ref_select_wall_points(candidates, robot_xy, params):
    """geometry.select_wall_points as of d27bf46."""
    if len(candidates) == 0 or params.wall_max_points == 0:
        return np.zeros((0, 2))
    d = np.linalg.norm(candidates - robot_xy, axis=1)
    order = np.argsort(d, kind="stable")
    order = order[d[order] <= params.wall_range_m][: params.wall_max_points]
    return candidates[order]


def ref_wall_point_covariance(points, sensor, angle_increment, params):
    """geometry.wall_point_covariance as of d27bf46."""
    d = np.asarray(points, float).reshape(-1, 2) - np.asarray(sensor, float)
    r = np.hypot(d[:, 0], d[:, 1])
    c, s = d[:, 0] / np.maximum(r, 1e-12), d[:, 1] / np.maximum(r, 1e-12)
    sr2 = (params.range_sigma_m + params.range_sigma_frac * r) ** 2
    st2 = (r * angle_increment) ** 2 / 12.0
    cov = np.empty((len(r), 2, 2))
    cov[:, 0, 0] = c * c * sr2 + s * s * st2
    cov[:, 1, 1] = s * s * sr2 + c * c * st2
    cov[:, 0, 1] = cov[:, 1, 0] = c * s * (sr2 - st2)
    return cov


@pytest.mark.parametrize("params", [PR, PerceptionParams(wall_max_points=5, wall_range_m=1.5)])
def test_wall_point_selection_and_covariances(params):
    rng = np.random.default_rng(2)
    for _ in range(60):
        n = int(rng.integers(0, 60))
        pts = rng.uniform(-4, 4, (n, 2))
        if n > 3:
            pts[1] = pts[0]                                  # a tie: the stable order decides
        robot, sensor = rng.uniform(-1, 1, 2), rng.uniform(-1, 1, 2)
        a, b = G.select_wall_points(pts, robot, params), ref_select_wall_points(pts, robot, params)
        assert a.shape == b.shape and np.array_equal(a, b)
        a, b = G.wall_point_covariance(pts, sensor, 0.0175, params), ref_wall_point_covariance(pts, sensor, 0.0175,
                                                                                               params)
        assert np.array_equal(a, b)
    assert np.array_equal(G.wall_point_covariance(np.zeros((1, 2)), np.zeros(2), 0.0175, PR),
                          ref_wall_point_covariance(np.zeros((1, 2)), np.zeros(2), 0.0175, PR))


def test_segment_sums_are_numpy_reduceat_and_mean_bit_for_bit():
    """geometry._segsum / _pairwise (numpy's pairwise summation, its recursion on an explicit stack) against
    np.add.reduceat and np.mean, for segments of 1 to 3000 elements of mixed magnitudes."""
    rng = np.random.default_rng(1)
    for _ in range(300):
        n = int(rng.integers(1, 3000))
        a = rng.normal(size=n) * 10.0 ** rng.integers(-5, 5, size=n)
        cuts = np.sort(rng.choice(np.arange(1, n), size=min(5, n - 1), replace=False)) if n > 2 else []
        st = np.concatenate([[0], cuts]).astype(np.int64)
        en = np.concatenate([st[1:], [n]])
        assert np.array_equal(np.add.reduceat(a, st), [G._segsum(a, s, e - s) for s, e in zip(st, en)])
        assert np.mean(a) == (0.0 + G._pairwise(a, 0, n)) / n


def test_output_with_walls_is_the_concatenation():
    """pipeline._with_walls (issue 26) gives circles.concat(wall_obstacles(points, cov)) bit for bit: with circles
    and wall points, and with either empty."""
    from bigcbf.types import Obstacles
    rng = np.random.default_rng(8)
    for k, m in ((3, 5), (0, 4), (2, 0), (0, 0)):
        circles = (Obstacles(rng.normal(size=(k, 2)), rng.normal(size=(k, 2)), rng.normal(size=(k, 2, 2)),
                             rng.uniform(0.1, 0.5, k), rng.random(k) < 0.5, rng.permutation(9)[:k]) if k
                   else Obstacles.empty())
        pts, cov = rng.normal(size=(m, 2)), rng.normal(size=(m, 2, 2))
        want = circles.concat(pipeline.wall_obstacles(pts, cov))
        got = Obstacles(*pipeline._with_walls(circles.p, circles.v, circles.cov, circles.r, circles.static,
                                              circles.ids, pts, cov))
        for f in ("p", "v", "cov", "r", "static", "ids"):
            a, b = getattr(got, f), getattr(want, f)
            assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b), f


def ref_rect_search(P, lo, n, e1x, e1y, e2x, e2y, best):
    """geometry._rect_search as of 96c6b28 (one orientation at a time), run as Python."""
    kbest = -1
    for k in range(e1x.shape[0]):
        amin = bmin = np.inf
        amax = bmax = -np.inf
        for i in range(lo, lo + n):
            a = e1x[k] * P[i, 0] + e1y[k] * P[i, 1]
            b = e2x[k] * P[i, 0] + e2y[k] * P[i, 1]
            amin, amax, bmin, bmax = min(amin, a), max(amax, a), min(bmin, b), max(bmax, b)
        ss = 0.0
        for i in range(lo, lo + n):
            a = e1x[k] * P[i, 0] + e1y[k] * P[i, 1]
            b = e2x[k] * P[i, 0] + e2y[k] * P[i, 1]
            d = min(min(a - amin, amax - a), min(b - bmin, bmax - b))
            ss += d * d
        if kbest < 0 or ss < best[4]:
            kbest = k
            best[0], best[1], best[2], best[3], best[4] = amin, amax, bmin, bmax, ss
    return kbest


def test_rectangle_search_all_orientations_at_once_is_one_at_a_time():
    """geometry._rect_search (issue 26: the orientations in the inner loop) gives the orientation, limits and sum
    of its former form bit for bit, on the coarse and a fine set of axes, for noisy L-shapes, faces and arcs,
    including ties (a square seen square-on)."""
    rng = np.random.default_rng(21)
    c, s = G._COARSE_COS, G._COARSE_SIN
    fine = np.deg2rad(37.0) + G._FINE
    fc, fs = np.cos(fine), np.sin(fine)
    for trial in range(120):
        n = int(rng.integers(3, 40))
        if trial % 3 == 0:
            P = np.cumsum(rng.normal(size=(n, 2)) * 0.03, axis=0)
        elif trial % 3 == 1:
            th = rng.uniform(0, 2 * np.pi, n)
            P = rng.uniform(0.05, 0.4) * np.column_stack([np.cos(th), np.sin(th)])
        else:
            P = np.column_stack([np.r_[np.zeros(n // 2), np.linspace(0, 0.5, n - n // 2)],
                                 np.r_[np.linspace(0, 0.5, n // 2), np.zeros(n - n // 2)]])
        P = np.ascontiguousarray(np.r_[rng.normal(size=(2, 2)), P + rng.uniform(-5, 5, 2)])
        for axes in ((c, s, -s, c), (fc, fs, -fs, fc)):
            got, want = np.full(5, np.nan), np.full(5, np.nan)
            assert G._rect_search(P, 2, n, *axes, got) == ref_rect_search(P, 2, n, *axes, want)
            assert np.array_equal(got, want)
