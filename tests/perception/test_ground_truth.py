"""Ground-truth mode (debugging / ablations): same Obstacles layout as perception, from true geometry."""
import numpy as np
import pytest

from bigcbf.params.perception import PerceptionParams
from bigcbf.perception import ground_truth_obstacles, rectangle_segments, segment_points


def test_rectangle_segments_hand_values():
    s = rectangle_segments(1.0, 2.0, 0.5, 0.25, np.pi / 2)
    # yaw 90 deg: the corner (+0.5, +0.25) goes to (-0.25, +0.5) -> (0.75, 2.5)
    assert s.shape == (4, 4)
    assert s[0, :2] == pytest.approx([0.75, 2.5])
    assert np.allclose(s[:, 2:], np.roll(s[:, :2], -1, axis=0))       # closed polygon


def test_segment_points_hand_values():
    # segment (0, 1) -> (4, 1), robot at (1.05, 0), spacing 0.5: nearest point at s = 1.05, then every 0.5 m
    pts = segment_points(np.array([[0.0, 1.0, 4.0, 1.0]]), np.array([1.05, 0.0]), 0.5)
    assert sorted(np.round(pts[:, 0], 9).tolist()) == pytest.approx([0.05, 0.55, 1.05, 1.55, 2.05, 2.55, 3.05, 3.55])
    assert np.all(pts[:, 1] == 1.0)
    # robot beyond the end: the end point is the nearest one
    pts = segment_points(np.array([[0.0, 1.0, 4.0, 1.0]]), np.array([6.0, 0.0]), 1.0)
    assert np.max(pts[:, 0]) == pytest.approx(4.0)


def test_ground_truth_obstacles():
    p = PerceptionParams(max_tracks=2, wall_max_points=5)
    obs = ground_truth_obstacles(robot_xy=(0.0, 0.0), centers=[(3, 0), (1, 0), (2, 0)],
                                 velocities=[(0, 0), (1.0, 0), (0, 0.05)], radii=[0.2, 0.25, 0.3],
                                 segments=[(-2, 1, 2, 1)], params=p)
    tr = obs.subset(obs.ids >= 0)
    assert tr.ids.tolist() == [1, 2]                          # the two nearest (surface distance 0.75, 1.7)
    assert tr.static.tolist() == [False, True]                # 1 m/s dynamic, 0.05 m/s static
    assert tr.v[0] == pytest.approx([1.0, 0.0]) and tr.r.tolist() == [0.25, 0.3]
    assert np.allclose(tr.cov, p.ground_truth_cov_m2 * np.eye(2))
    w = obs.subset(obs.ids < 0)
    assert len(w) == 5 and w.p[0] == pytest.approx([0.0, 1.0])  # nearest wall point first
    assert np.all(w.r == 0) and np.all(w.static)


def test_static_circles_beyond_the_budget_are_wall_points_on_their_near_half():
    p = PerceptionParams(max_tracks=1, wall_max_points=24, wall_spacing_m=0.2)
    obs = ground_truth_obstacles(robot_xy=(0.0, 0.0), centers=[(1.0, 0.0), (0.0, 2.0), (0.0, -2.5)],
                                 velocities=[(0, 0), (0, 0), (1.0, 0)], radii=[0.2, 0.3, 0.25], params=p)
    tr = obs.subset(obs.ids >= 0)
    assert tr.ids.tolist() == [0]
    w = obs.subset(obs.ids < 0)
    # the static post at (0, 2), r 0.3: its nearest point (0, 1.7) and points every 0.2 m of arc over its near half
    # (k = floor(0.5 pi 0.3 / 0.2) = 2 each side: 5 points); the walker beyond the budget is not turned into points
    assert len(w) == 5
    assert w.p[0] == pytest.approx([0.0, 1.7])
    assert np.allclose(np.linalg.norm(w.p - [0.0, 2.0], axis=1), 0.3)
    assert np.all(w.p[:, 1] <= 2.0 + 1e-12)
