"""Scan geometry: frames, clustering, circle and rectangle fits, wall points."""
import numpy as np
import pytest

from bigcbf.params.perception import PerceptionParams
from bigcbf.perception.geometry import (cluster_points, extent, fit_circle, fit_circle_fixed_radius, fit_rectangle,
                                        measure_compact, scan_to_points, select_wall_points, wall_candidates)
from bigcbf.perception.synthetic import ANGLE_INC, ANGLE_MIN, N_BEAMS, box_segments, ray_scan
from bigcbf.types import LaserScan

PR = PerceptionParams()


def _scan(ranges):
    return LaserScan(stamp=0.0, angle_min=ANGLE_MIN, angle_increment=ANGLE_INC, range_min=0.12, range_max=8.0,
                     ranges=np.asarray(ranges, np.float32))


def test_scan_to_points_hand_values():
    r = np.full(N_BEAMS, np.inf)
    r[180] = 1.0          # beam angle 0 (straight ahead)
    r[90] = 2.0           # beam angle -pi/2 (right)
    r[10] = 0.05          # below range_min: invalid
    r[20] = 9.0           # beyond range_max: invalid
    sp = scan_to_points(_scan(r), (1.0, 2.0, np.pi / 2), PR)
    # laser at (0.0435, 0) in base_link; robot facing +y: laser origin (1, 2.0435) in odom
    assert sp.sensor == pytest.approx([1.0, 2.0435])
    assert list(sp.beam) == [90, 180]
    # beam -pi/2 of a robot facing +y points along +x: (1 + 2, 2.0435); beam 0 points along +y: (1, 3.0435)
    assert sp.xy[0] == pytest.approx([3.0, 2.0435], abs=1e-6)
    assert sp.xy[1] == pytest.approx([1.0, 3.0435], abs=1e-6)


def test_scan_to_points_laser_yaw_and_offset():
    p = PerceptionParams(laser_x_m=0.1, laser_y_m=0.05, laser_yaw_rad=np.pi / 2)
    r = np.full(N_BEAMS, np.inf)
    r[180] = 1.0
    sp = scan_to_points(_scan(r), (0.0, 0.0, 0.0), p)
    # laser at (0.1, 0.05) facing +y: its beam 0 ends at (0.1, 1.05)
    assert sp.sensor == pytest.approx([0.1, 0.05])
    assert sp.xy[0] == pytest.approx([0.1, 1.05], abs=1e-6)


def test_two_objects_two_clusters_and_wraparound():
    # a cylinder straight behind the robot spans beams at both ends of the scan (angle -pi .. pi): one cluster
    scan = ray_scan((0, 0, 0), circles=[(-2.0435 + 0.0435, 0.0, 0.3), (2.0, 1.0, 0.25)])
    sp = scan_to_points(scan, (0, 0, 0), PR)
    cl = cluster_points(sp, PR)
    assert len(cl) == 2
    behind = [c for c in cl if np.mean(sp.xy[c.idx, 0]) < 0][0]
    beams = set(sp.beam[behind.idx].tolist())
    assert 0 in beams and 359 in beams
    assert not any(c.occluded for c in cl)


def test_occluded_flag_when_a_nearer_object_cuts_the_cluster():
    # a pedestrian at 1.5 m partly hides one at 3 m
    scan = ray_scan((0, 0, 0), circles=[(1.5, 0.0, 0.25), (3.0, 0.3, 0.25)])
    sp = scan_to_points(scan, (0, 0, 0), PR)
    cl = cluster_points(sp, PR)
    far = [c for c in cl if np.mean(sp.ranges[c.idx]) > 2.5][0]
    near = [c for c in cl if np.mean(sp.ranges[c.idx]) < 2.0][0]
    assert far.occluded and not near.occluded


def test_missed_beams_mean_free_space():
    # two posts 0.3 m apart at 4 m: the beams between them miss; they must not merge although the adaptive
    # breakpoint distance at 4 m (4 sin 1deg / sin 9deg + 0.03 = 0.48 m) exceeds their gap
    scan = ray_scan((0, 0, 0), circles=[(4.0, -0.25, 0.05), (4.0, 0.25, 0.05)])
    sp = scan_to_points(scan, (0, 0, 0), PR)
    assert len(cluster_points(sp, PR)) == 2


def test_extent():
    pts = np.array([[0.0, 0.0], [0.3, 0.4], [0.6, 0.0]])
    assert extent(pts, 1.0) == pytest.approx(0.6)
    assert extent(pts, 0.4) > 0.4          # early exit still reports more than the limit


def test_circle_fit_exact_on_partial_arc_and_centroid_biased():
    # 90-degree arc of the circle c = (2, 1), r = 0.25, facing the origin
    th = np.linspace(np.pi - np.pi / 4, np.pi + np.pi / 4, 12) + np.arctan2(1, 2)
    pts = np.c_[2 + 0.25 * np.cos(th), 1 + 0.25 * np.sin(th)]
    c, r, rms = fit_circle(pts)
    assert c == pytest.approx([2.0, 1.0], abs=1e-9) and r == pytest.approx(0.25, abs=1e-9) and rms < 1e-9
    # the centroid of the 12 points sits r * mean(cos(theta_i - theta_mid)) = 0.2207 m from the centre (continuous
    # arc: r sin(45deg)/(pi/4) = 0.225 m): a centroid "centre" would be wrong by 0.22 m
    bias = 0.25 * np.mean(np.cos(np.linspace(-np.pi / 4, np.pi / 4, 12)))
    assert bias == pytest.approx(0.2207, abs=1e-4)
    assert np.linalg.norm(pts.mean(axis=0) - [2, 1]) == pytest.approx(bias, abs=1e-9)
    m = measure_compact(pts, np.zeros(2), PR)
    assert m.arc_fit and m.center == pytest.approx([2.0, 1.0], abs=1e-6) and m.radius == pytest.approx(0.25)


def test_circle_fit_collinear_is_infinite():
    c, r, rms = fit_circle(np.c_[np.linspace(0, 1, 5), np.zeros(5)])
    assert r == np.inf


def test_fixed_radius_fit_recovers_centre():
    th = np.linspace(2.8, 3.5, 7)
    pts = np.c_[3 + 0.3 * np.cos(th), 0.3 * np.sin(th)]
    c, rms = fit_circle_fixed_radius(pts, 0.3, pts[3] + np.array([0.1, 0.05]))
    assert c == pytest.approx([3.0, 0.0], abs=1e-6) and rms < 1e-6


def test_rectangle_fit_l_shape_and_single_face():
    # an L: two faces of a 0.4 m square box centred at (2, 1), seen corner-on: corner (1.8, 0.8)
    t = np.linspace(0, 0.4, 9)
    L = np.r_[np.c_[1.8 + t[::-1], np.full(9, 0.8)], np.c_[np.full(8, 1.8), 0.8 + t[1:]]]
    c, r, rms = fit_rectangle(L, np.zeros(2))
    assert c == pytest.approx([2.0, 1.0], abs=1e-3) and r == pytest.approx(0.2 * np.sqrt(2), abs=1e-3)
    assert rms < 1e-6
    # a single face x = 2, y in [-0.2, 0.2], seen from the origin: completed into a square behind it,
    # centre (2.2, 0), radius 0.2 sqrt 2
    F = np.c_[np.full(9, 2.0), np.linspace(-0.2, 0.2, 9)]
    c, r, _ = fit_rectangle(F, np.zeros(2))
    assert c == pytest.approx([2.2, 0.0], abs=1e-3) and r == pytest.approx(0.2 * np.sqrt(2), abs=1e-3)
    m = measure_compact(F, np.zeros(2), PR)
    assert not m.arc_fit and m.center == pytest.approx([2.2, 0.0], abs=1e-3)


def test_box_in_a_scan_measured_by_its_rectangle():
    # a 0.4 m square box yawed 30 degrees at (2.5, 0.5), seen from the origin: corner-on L
    pose = (0.0, 0.0, 0.0)
    scan = ray_scan(pose, segments=box_segments(2.5, 0.5, 0.2, 0.2, np.pi / 6))
    sp = scan_to_points(scan, pose, PR)
    (cl,) = cluster_points(sp, PR)
    m = measure_compact(sp.xy[cl.idx], sp.sensor, PR)
    assert not m.arc_fit
    assert m.center == pytest.approx([2.5, 0.5], abs=0.03)
    assert m.radius == pytest.approx(0.2 * np.sqrt(2), abs=0.03)


def test_wall_candidates_hand_values():
    # a wall y = 1 sampled every 0.05 m from x = -2 to 2 (scan order); robot at (0.31, 0)
    x = np.round(np.arange(-2.0, 2.0001, 0.05), 10)
    pts = np.c_[x, np.ones_like(x)]
    out = wall_candidates(pts, np.array([0.31, 0.0]), 0.21)
    assert out[0] == pytest.approx([0.3, 1.0])           # the nearest point first
    xs = np.sort(out[:, 0])
    # forward: first points past 0.21, 0.42, 0.63 m of path -> x = 0.55, 0.75, 0.95; backward: 0.05, -0.15; and the
    # two ends -2 and 2
    for v in (0.55, 0.75, 0.95, 0.05, -0.15, -2.0, 2.0):
        assert np.min(np.abs(xs - v)) < 1e-9
    gaps = np.diff(xs)
    assert gaps[1:-1].min() >= 0.2 - 1e-9 and gaps.max() <= 0.25 + 1e-9
    # a 0.4 m face seen square-on: its nearest point and both ends (no bin starts within 0.2 m of the middle)
    face = np.c_[np.full(9, 2.0), np.linspace(-0.2, 0.2, 9)]
    out = wall_candidates(face, np.zeros(2), 0.2)
    assert out[0] == pytest.approx([2.0, 0.0]) and sorted(out[1:, 1].tolist()) == pytest.approx([-0.2, 0.2])


def test_select_wall_points_nearest_first_bounded():
    pts = np.c_[np.linspace(-5, 5, 101), np.ones(101)]
    p = PerceptionParams(wall_max_points=10, wall_range_m=3.0)
    sel = select_wall_points(pts, np.zeros(2), p)
    d = np.linalg.norm(sel, axis=1)
    assert len(sel) == 10 and np.all(np.diff(d) >= 0) and d[0] == pytest.approx(1.0)
    far = select_wall_points(pts + [0, 5], np.zeros(2), p)
    assert len(far) == 0                                    # all beyond wall_range_m


def test_wall_point_covariance_by_hand():
    from bigcbf.perception.geometry import wall_point_covariance
    p = PerceptionParams(range_sigma_m=0.005, range_sigma_frac=0.005)
    dphi = np.pi / 180
    # straight ahead along +y at 2 m: along the beam (0.005 + 0.01)^2, across it (2 dphi)^2 / 12
    cov = wall_point_covariance(np.array([[0.0, 2.0], [3.0, 3.0]]), np.zeros(2), dphi, p)
    np.testing.assert_allclose(cov[0], np.diag([(2 * dphi) ** 2 / 12, 0.015 ** 2]), atol=1e-15)
    # at 45 degrees: eigenvalues the same two variances at that range, eigenvector of the larger along the beam
    r = np.hypot(3.0, 3.0)
    w, v = np.linalg.eigh(cov[1])
    np.testing.assert_allclose(sorted(w), sorted([(r * dphi) ** 2 / 12, (0.005 + 0.005 * r) ** 2]), rtol=1e-12)
    assert abs(abs(v[:, np.argmax(w)] @ np.array([1, 1]) / np.sqrt(2)) - 1) < 1e-12


# --- measurement covariances, fit quality and concavity (how much a cluster's centre can be trusted) -------------

def test_circle_fit_covariance_by_hand():
    """n points evenly spread over a whole circle, seen from its centre (every beam along the circle's normal, so
    each point's variance is sigma_r^2 at range r): J^T W J = (1/sigma^2) [[n/2, 0, 0], [0, n/2, 0], [0, 0, n]]
    (sum n_x^2 = n/2, sum n_x = 0), whose centre block of the inverse is 2 sigma^2 / n I."""
    from bigcbf.perception.geometry import circle_fit_covariance
    p = PerceptionParams(range_sigma_m=0.005, range_sigma_frac=0.005)
    n, r = 24, 0.5
    th = 2 * np.pi * np.arange(n) / n
    pts = np.c_[r * np.cos(th), r * np.sin(th)]
    cov = circle_fit_covariance(pts, np.zeros(2), r, np.zeros(2), np.pi / 180, p)
    sigma2 = (0.005 + 0.005 * r) ** 2
    np.testing.assert_allclose(cov, 2 * sigma2 / n * np.eye(2), rtol=1e-9, atol=1e-15)
    # with the radius clamped (not fitted) the 2x2 block alone is inverted, plus a uniform spread of the radius over
    # [radius_min_m, radius_max_m] along the line of sight (here the centre is the sensor: the ray is undefined and
    # taken as 0, so only the block remains)
    cov_fixed = circle_fit_covariance(pts, np.zeros(2), r, np.zeros(2), np.pi / 180, p, fit_radius=False)
    np.testing.assert_allclose(cov_fixed, 2 * sigma2 / n * np.eye(2), rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("dist, radius", [(1.0, 0.25), (3.0, 0.2), (5.0, 0.15)])
def test_circle_fit_covariance_matches_the_scatter_of_noisy_fits(dist, radius):
    """A post seen by a noisy LiDAR (range std 5 mm + 0.5 %, the perception's own model): the fitted centres'
    normalised squared errors e^T C^-1 e average about 2 (chi-square with 2 dof), far or near; a fixed covariance
    cannot (a far post seen by 4-6 beams scatters several times more than a near one seen by 30). (The scan here
    is exact in angle: the beam-width term of the point variances and the model error fit_model_sigma_m, which
    real scans need, make C a little larger than the scatter.)"""
    p = PerceptionParams()
    rng = np.random.default_rng(3)
    c_true = np.array([dist * np.cos(0.3), dist * np.sin(0.3)])
    nees, err = [], []
    for _ in range(300):
        r_true = ray_scan((0, 0, 0), [(*c_true, radius)]).ranges.astype(float)
        ok = np.isfinite(r_true)
        noisy = r_true.copy()
        noisy[ok] += rng.normal(0, 1, ok.sum()) * (p.range_sigma_m + p.range_sigma_frac * r_true[ok])
        sp = scan_to_points(_scan(noisy), (0, 0, 0), p)
        (cl,) = cluster_points(sp, p)
        m = measure_compact(sp.xy[cl.idx], sp.sensor, p, cl.occluded, sp.angle_increment)
        e = m.center - c_true
        C = m.cov
        nees.append(float(e @ np.linalg.solve(C, e)))
        err.append(e)
    assert 1.0 < np.mean(nees) < 3.5, np.mean(nees)        # the Kasa fit scatters a little more than the geometric
                                                            # fit's covariance near the sensor (3.2 at 1 m)
    print(f"post r={radius} at {dist} m: centre error rms {np.sqrt(np.mean(np.sum(np.square(err), 1))):.3f} m, "
          f"mean NEES {np.mean(nees):.2f}")


def test_rectangle_covariance_by_hand():
    """One face of a square box seen head-on (la = 0.4 m along y, lb = 0 along x): across the face the centre is
    the middle of two ends (each end: sigma_r^2 + (r dphi)^2 / 12, halved), along the line of sight it may lie
    anywhere over the unseen depth: + (0.4 - 0)^2 / 12."""
    from bigcbf.perception.geometry import rectangle_covariance
    p = PerceptionParams(range_sigma_m=0.005, range_sigma_frac=0.005)
    F = np.c_[np.full(9, 2.0), np.linspace(-0.2, 0.2, 9)]
    axes = np.array([[0.0, 1.0], [1.0, 0.0]])                 # e1 along the face (y), e2 along x
    cov = rectangle_covariance(F, axes, (0.4, 0.0), np.zeros(2), np.pi / 180, p)
    r = float(np.mean(np.linalg.norm(F, axis=1)))
    end = (0.005 + 0.005 * r) ** 2 + (r * np.pi / 180) ** 2 / 12
    np.testing.assert_allclose(cov, np.diag([end / 2 + 0.4 ** 2 / 12, end / 2]), rtol=1e-12)
    # measure_compact gives the same covariance for that face (the rectangle model wins there)
    m = measure_compact(F, np.zeros(2), p)
    assert not m.arc_fit
    np.testing.assert_allclose(m.cov, cov, rtol=1e-6, atol=1e-15)


def test_concavity_convex_objects_versus_two_merged_posts():
    from bigcbf.perception.geometry import concavity
    # a post, a box seen corner-on and a flat face: they bulge toward the sensor, no dent
    for circles, segs in (([(2.0, 0.3, 0.25)], []), ([], box_segments(2.5, 0.5, 0.2, 0.2, np.pi / 6)),
                          ([], [(2.0, -0.4, 2.0, 0.4)])):
        sp = scan_to_points(ray_scan((0, 0, 0), circles, segs), (0, 0, 0), PR)
        (cl,) = cluster_points(sp, PR)
        assert concavity(sp.xy[cl.idx], sp.sensor) < 1e-6
    # two posts (r 0.15 m) touching side by side at 2 m: one cluster whose outline steps back where they meet
    sp = scan_to_points(ray_scan((0, 0, 0), [(2.0, -0.15, 0.15), (2.0, 0.15, 0.15)]), (0, 0, 0), PR)
    (cl,) = cluster_points(sp, PR)
    dent = concavity(sp.xy[cl.idx], sp.sensor)
    assert PR.concavity_ratio_max * (PR.range_sigma_m + PR.range_sigma_frac * 2.0) < dent < 0.15
    # by hand: the points (0, 1), (1, 2), (2, 1), (3, 2), (4, 1) seen from (2, -5): p_2 = (2, 1) lies 1 m in front
    # of the chord from p_0 to p_4 (no dent there); p_1 and p_3 lie 1 m behind their chords (p_(-1).. undefined:
    # only interior points with two neighbours each side count): the dent is 1 m
    pts = np.array([[0.0, 1.0], [1.0, 2.0], [2.0, 1.0], [3.0, 2.0], [4.0, 1.0]])
    assert concavity(pts, np.array([2.0, -5.0]), k=1) == pytest.approx(1.0)
    assert concavity(pts, np.array([2.0, -5.0]), k=2) == pytest.approx(0.0)


def test_one_object_versus_two_in_a_cluster():
    """The two checks of the pipeline (fit_rms_ratio_max, concavity_ratio_max; units: the range noise's std at the
    cluster's range) on noisy scans: a post and a box pass both, two posts touching fail one. (A walker passing
    just behind a post can pass both: the tracker's ``merged`` catches that case from the two known tracks.)"""
    from bigcbf.perception.geometry import concavity
    rng = np.random.default_rng(0)
    cases = {"post": ([(2.5, 0.0, 0.2)], []), "box": ([], box_segments(2.5, 0.5, 0.25, 0.2, 0.4)),
             "two posts": ([(2.5, -0.2, 0.2), (2.5, 0.2, 0.2)], [])}
    for name, (circles, segs) in cases.items():
        for _ in range(20):
            r = ray_scan((0, 0, 0), circles, segs).ranges.astype(float)
            ok = np.isfinite(r)
            r[ok] += rng.normal(0, 1, ok.sum()) * (PR.range_sigma_m + PR.range_sigma_frac * r[ok])
            sp = scan_to_points(_scan(r), (0, 0, 0), PR)
            (cl,) = cluster_points(sp, PR)
            pts = sp.xy[cl.idx]
            m = measure_compact(pts, sp.sensor, PR, cl.occluded, sp.angle_increment)
            bad = (m.rms > PR.fit_rms_ratio_max * m.rms_expected
                   or concavity(pts, sp.sensor) > PR.concavity_ratio_max * m.rms_expected)
            assert bad == (name == "two posts"), name


def test_batched_functions_equal_the_per_cluster_reference():
    """measure_clusters, wall_candidates_many and compact_mask (array operations over all clusters of a scan, what
    the pipeline runs) give what measure_compact, concavity, wall_candidates and extent give cluster by cluster."""
    from bigcbf.perception.geometry import (compact_mask, concavity, measure_clusters, wall_candidates_many)
    rng = np.random.default_rng(5)
    for trial in range(12):
        circles = [(rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(0.05, 0.4)) for _ in range(10)]
        segs = []
        for _ in range(4):
            segs += box_segments(rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(0.1, 0.5), rng.uniform(0.1, 0.5),
                                 rng.uniform(0, np.pi))
        segs += [(-6.0, -6.0, 6.0, -6.0), (-6.0, 6.0, 6.0, 6.0)]
        pose = (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-np.pi, np.pi))
        scan = ray_scan(pose, circles, segs, noise=0.01, rng=rng)
        sp = scan_to_points(scan, pose, PR)
        clusters = cluster_points(sp, PR)
        mask = compact_mask(sp, clusters, PR)
        ref = np.array([len(c.idx) >= PR.min_points and extent(sp.xy[c.idx], PR.compact_max_extent_m)
                        <= PR.compact_max_extent_m for c in clusters])
        assert np.array_equal(mask, ref)
        compact = [c for c, k in zip(clusters, mask) if k]
        ms, dents = measure_clusters(sp, compact, PR)
        for cl, m, dent in zip(compact, ms, dents):
            pts = sp.xy[cl.idx]
            r = measure_compact(pts, sp.sensor, PR, cl.occluded, sp.angle_increment)
            assert m.arc_fit == r.arc_fit and m.round == r.round
            np.testing.assert_allclose(m.center, r.center, atol=1e-9)
            np.testing.assert_allclose(m.cov, r.cov, rtol=1e-6, atol=1e-12)
            assert m.radius == pytest.approx(r.radius, abs=1e-9) and m.rms == pytest.approx(r.rms, abs=1e-9)
            assert dent == pytest.approx(concavity(pts, sp.sensor), abs=1e-9)
        sets = [sp.xy[c.idx] for c in clusters]
        robot = np.array(pose[:2])
        np.testing.assert_allclose(wall_candidates_many(sets, robot, 0.2),
                                   np.concatenate([wall_candidates(q, robot, 0.2) for q in sets]), atol=1e-12)
