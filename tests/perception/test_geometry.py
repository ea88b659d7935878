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
    # forward: first points past 0.21, 0.42, 0.63 m of path -> x = 0.55, 0.75, 0.95; backward: 0.05, -0.15
    for v in (0.55, 0.75, 0.95, 0.05, -0.15):
        assert np.min(np.abs(xs - v)) < 1e-9
    gaps = np.diff(xs)
    assert gaps.min() >= 0.2 - 1e-9 and gaps.max() <= 0.25 + 1e-9


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
