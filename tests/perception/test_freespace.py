"""Free-space carving (bigcbf/perception/freespace.py): a walker against a wall, seen only as part of the wall's
cluster, is split out and tracked; a wall alone, passed by a moving robot, is never split."""
import math

import numpy as np

from bigcbf.params.perception import PerceptionParams
from bigcbf.perception.freespace import in_free_space
from bigcbf.perception.pipeline import Perception
from bigcbf.perception.synthetic import ray_scan

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


def test_point_in_free_space_by_hand():
    """One earlier scan from the origin, beams every 90 degrees, all returning at 5 m: a point 2 m along beam 0's
    bearing between beams 0 and 1 (45 degrees) is in free space (both bracketing beams reach 5 m > 2 m + margin);
    a point 4.95 m out is not (within the margin); with beam 1 missing (NaN) there is no evidence."""
    sensors, a0, inc = np.zeros((1, 2)), np.zeros(1), np.array([math.pi / 2])
    past = np.full((1, 4), 5.0)
    n = np.array([4], np.int64)
    xy = np.array([[2 * math.cos(math.pi / 4), 2 * math.sin(math.pi / 4)],
                   [4.95 * math.cos(math.pi / 4), 4.95 * math.sin(math.pi / 4)]])
    r = np.array([2.0, 4.95])
    assert in_free_space(xy, r, sensors, a0, inc, past, n, 0.15, 0.0, 0.0).tolist() == [True, False]
    past[0, 1] = np.nan
    assert in_free_space(xy, r, sensors, a0, inc, past, n, 0.15, 0.0, 0.0).tolist() == [False, False]
    past[0, 1] = 5.0                                  # the last beam wraps to the first in a 360-degree scan
    xy3 = np.array([[2 * math.cos(-math.pi / 4), 2 * math.sin(-math.pi / 4)]])
    assert in_free_space(xy3, r[:1], sensors, a0, inc, past, n, 0.15, 0.0, 0.0).tolist() == [True]


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
