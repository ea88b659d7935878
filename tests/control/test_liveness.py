"""Chatter and stall metrics (bigcbf/control/liveness.py) on synthetic histories with hand-computed values."""
import math

import numpy as np
import pytest

from bigcbf.control.liveness import (LivenessRecorder, lateral_reversals, lateral_sides, lateral_speed,
                                     mode_switches_per_min, no_progress_time, side_reversals)
from bigcbf.types import RobotState


def test_side_reversals_count_side_changes_through_neutral_modes():
    h = [(0.0, "GOAL"), (1.0, "PASS-L"), (2.0, "GOAL"), (3.0, "PASS-R"), (4.0, "SIDE-R"), (5.0, "YIELD"),
         (6.0, "SIDE-L"), (7.0, "REVERSE"), (8.0, "PASS-L")]
    # sided entries: L, R, R, L, L -> two changes of side
    assert side_reversals(h) == 2
    assert side_reversals([(0.0, "PASS-L"), (1.0, "SIDE-L"), (2.0, "GOAL")]) == 0
    assert side_reversals([(0.0, "PASS-L"), (0.5, "PASS-R"), (1.0, "YIELD"), (2.0, "SIDE-L")]) == 2
    assert side_reversals([(0.0, "DWA"), (1.0, "DWA-NONE"), (2.0, "DWA")]) == 0      # no sided modes
    assert side_reversals([]) == 0


def test_mode_switches_per_minute():
    h = [(0.0, "GOAL"), (1.0, "PASS-L"), (2.0, "GOAL"), (3.0, "PASS-R")]
    assert mode_switches_per_min(h, 30.0) == pytest.approx(6.0)          # 3 switches in half a minute
    assert mode_switches_per_min([(0.0, "GOAL")], 12.0) == 0.0
    assert mode_switches_per_min(h, 0.0) == 0.0


def test_lateral_speed_is_the_world_velocity_along_the_goal_basis_left_normal():
    # robot facing +y (theta = pi/2), goal straight along +x: d_g = (1, 0), n_g = (0, 1). Body (0.5, 0.2) is world
    # (-0.2, 0.5): 0.5 m/s to the left of the goal direction.
    assert lateral_speed((0.5, 0.2, 0.0), math.pi / 2, (0.0, 0.0), (1.0, 0.0)) == pytest.approx(0.5)
    # goal up and to the right at 45 degrees, robot facing +x, driving straight at it: no lateral part
    assert lateral_speed((0.3, 0.3, 0.0), 0.0, (1.0, 1.0), (2.0, 2.0)) == pytest.approx(0.0, abs=1e-12)
    # ... driving along +x instead: v_lat = (0.5, 0) . (-1, 1)/sqrt(2) = -0.3536 (to the right)
    assert lateral_speed((0.5, 0.0, 0.0), 0.0, (1.0, 1.0), (2.0, 2.0)) == pytest.approx(-0.5 / math.sqrt(2))
    assert lateral_speed((0.5, 0.0, 0.0), 0.0, (2.0, 2.0), (2.0, 2.0)) == 0.0


def test_lateral_reversals_need_the_dead_band_and_the_hold_time():
    dt = 0.05
    seq = ([0.3] * 20            # 1 s left: established L
           + [0.0] * 10          # neutral
           + [-0.3] * 20         # 1 s right: reversal 1
           + [0.05] * 20         # inside the 0.1 m/s dead band: neutral
           + [0.3] * 3           # 0.15 s left: shorter than the 0.25 s hold, ignored
           + [-0.3] * 10         # still right
           + [0.3] * 20)         # left again: reversal 2
    sides = lateral_sides(seq, np.full(len(seq), 5.0))
    assert lateral_reversals(sides, dt) == 2
    assert lateral_reversals(sides, dt, hold_s=0.1) == 4            # the blip counts with a 0.1 s hold
    # exactly the hold time (5 steps of 0.05 s) is enough
    assert lateral_reversals(lateral_sides([0.2] * 5 + [-0.2] * 5, [5.0] * 10), dt) == 1
    assert lateral_reversals(lateral_sides([0.2] * 5 + [-0.2] * 4, [5.0] * 9), dt) == 0
    # near the goal (0.5 m) every step is neutral
    assert lateral_reversals(lateral_sides([0.3] * 20 + [-0.3] * 20, [0.4] * 40), dt) == 0


def test_time_without_progress_is_the_union_of_stalled_two_second_windows():
    dt = 0.05
    t = np.round(np.arange(0, 20.0 + dt / 2, dt), 10)
    speed = 0.3
    # distance to the goal: 10 m, decreasing at 0.3 m/s except while stopped from 5 s to 12 s
    d = 10.0 - speed * (np.minimum(t, 5.0) + np.maximum(t - 12.0, 0.0))
    # a window [t-2, t] stalls when it holds less than 0.1 / 0.3 = 0.333 s of driving: it ends at t in
    # [6.70, 12.30] on the 0.05 s grid (t = 6.70: 0.30 s of driving from 4.70 to 5.00; t = 12.35: 0.35 s).
    # Union of those windows: [4.70, 12.30] -> 7.6 s for a 7 s stop.
    assert no_progress_time(t, d) == pytest.approx(7.6, abs=1e-9)
    # driving all the time: none
    assert no_progress_time(t, 10.0 - speed * t) == 0.0
    # a 1 s stop: every window still holds 1 s of driving (0.3 m): none
    d1 = 10.0 - speed * (np.minimum(t, 5.0) + np.maximum(t - 6.0, 0.0))
    assert no_progress_time(t, d1) == 0.0
    # moving away from the goal is no progress: the whole episode (its windows cover 0-20 s)
    assert no_progress_time(t, 10.0 + speed * t) == pytest.approx(20.0)
    assert no_progress_time(t[:30], d[:30]) == 0.0                       # shorter than a window


def test_recorder_combines_the_metrics():
    rec = LivenessRecorder(0.05)
    goal = (20.0, 0.0)
    for k in range(100):               # 5 s: weave +-0.3 m/s lateral every second, advancing at 0.5 m/s
        t = 0.05 * k
        vy = 0.3 if (k // 20) % 2 == 0 else -0.3
        rec.add(t, RobotState(0.5 * t, 0.0, 0.0), (0.5, vy, 0.0), goal, (0.5 * t, 0.0))
    m = rec.metrics([(0.0, "PASS-L"), (1.0, "PASS-R"), (2.0, "GOAL")], 5.0)
    # lateral sides L R L R L -> 4 reversals; modes L R -> 1; 2 switches in 5 s -> 24 / min; 1 m per 2 s: progress
    assert m == {"mode_switches_per_min": pytest.approx(24.0), "side_reversals": 1, "lateral_reversals": 4,
                 "no_progress_s": 0.0}
