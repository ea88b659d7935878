"""Chatter and stall metrics of an episode: mode switches per minute, left/right reversals, time without progress.

The paper defines none of these (its Sec. IV metrics are success, time, clearance, E_CBF, CBF activity and QP
infeasibility); they measure what a user of a sampling or behavior planner complains about first: a robot that
keeps changing its mind, weaves, or stands still. Definitions:

**Mode switches per minute.** The number of changes of the planner's mode label during the episode (the entries
of the mode history after the first) divided by the episode's duration in minutes. It counts every label the
method reports (BIG-CBF's behaviors and its REVERSE fallback; DWA's DWA/DWA-NONE; a shield's NOMINAL/backup
labels), so it compares a method with itself, not methods with different vocabularies.

**Side reversals (from the modes).** A mode is *left* (PASS-L, SIDE-L), *right* (PASS-R, SIDE-R), or *neutral*
(every other label: GOAL, YIELD, REVERSE, and all labels of methods without sided modes). Keep only the sided
entries of the mode history, in order; each change of side between consecutive sided entries is one reversal,
whatever neutral modes lie between them and however long they last:
PASS-L -> GOAL -> PASS-R is 1, PASS-L -> SIDE-L is 0, PASS-L -> PASS-R -> YIELD -> SIDE-L is 2. A method without
sided modes always has 0; for it (and for every method alike) use the lateral reversals.

**Lateral reversals (from the command).** Defined for every method from what the robot is told to do: at each
control step, the lateral component of the filtered command u_safe (the body twist sent to the wheels) in the
odom frame, relative to the goal direction seen from the robot, v_lat = (R(theta) [vx, vy]) . n_g, with n_g the
left normal of the unit vector d_g from the robot's position p to the goal (the goal basis
``eq:goal_basis`` (9)). The step's side is +1 (left) if v_lat >= ``LATERAL_DEAD_BAND_MPS``, -1 (right) if
v_lat <= -``LATERAL_DEAD_BAND_MPS``, else 0; steps closer to the goal than ``LATERAL_NEAR_GOAL_M`` count as 0
(the goal direction turns quickly there). A side becomes *established* once it has held for
``LATERAL_HOLD_S`` without interruption (n consecutive steps of period T_C last n T_C); each established side that
differs from the previously established one is one reversal (neutral stretches in between do not reset it).
Because the frame is the goal direction *from the current position*, one pass around an obstacle followed by
a straight run to the goal is no reversal (driving straight at the goal has v_lat = 0), while weaving left and
right in front of an obstacle is, whatever the method (DWA, MPPI and APF weave through u_in; CBF-only through the
filter's sliding).

**Time without progress.** With the true distance to the goal d(t) sampled at every control step: a window
[t - W, t] (W = ``PROGRESS_WINDOW_S`` = 2 s, ending at a control step, t - W >= the first sample) *stalls* if the
distance decreased by less than ``PROGRESS_MIN_M`` = 0.1 m over it, d(t - W) - d(t) < 0.1 m (0.05 m/s on
average; the robot drives at up to 0.8 m/s). The time without progress is the length of the union of all stalled
windows. A robot that stops for S >= W seconds in the middle of a drive at speed v contributes about S plus
0.1 m / v (the window's edges reach just past the stop); stops shorter than about W - 0.1 m / v seconds do not
count. Detours that lead away from the goal count as no progress too: it is progress *toward the goal*.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from .behaviors import goal_basis

LEFT_MODES = frozenset({"PASS-L", "SIDE-L"})
RIGHT_MODES = frozenset({"PASS-R", "SIDE-R"})

LATERAL_DEAD_BAND_MPS = 0.10    # |v_lat| below this is "no side" [m/s]
LATERAL_HOLD_S = 0.25           # a side counts once held this long [s] (5 control steps at T_C = 0.05 s)
LATERAL_NEAR_GOAL_M = 0.5       # closer to the goal than this: no side [m]
PROGRESS_WINDOW_S = 2.0         # W [s]
PROGRESS_MIN_M = 0.1            # a window stalls if the goal distance decreased by less than this [m]
_EPS_T = 1e-6


def mode_side(mode: str) -> int:
    """+1 for a left mode, -1 for a right mode, 0 for a neutral one (see the module docstring)."""
    return 1 if mode in LEFT_MODES else -1 if mode in RIGHT_MODES else 0


def mode_switches_per_min(mode_history: Sequence[tuple[float, str]], duration_s: float) -> float:
    """Changes of the mode label per minute of episode (``mode_history``: [(t, mode)] at each change)."""
    switches = max(len(mode_history) - 1, 0)
    return 60.0 * switches / duration_s if duration_s > 0 else 0.0


def side_reversals(mode_history: Sequence[tuple[float, str]]) -> int:
    """Left/right reversals of the mode history: side changes between consecutive sided modes."""
    sides = [s for s in (mode_side(m) for _, m in mode_history) if s != 0]
    return sum(a != b for a, b in zip(sides, sides[1:]))


def lateral_speed(u_body, theta: float, p, goal) -> float:
    """v_lat = (R(theta) [vx, vy]) . n_g: the command's world-frame velocity along the left normal of the goal
    direction seen from ``p`` [m/s] (0 at the goal itself)."""
    vx, vy = float(u_body[0]), float(u_body[1])
    c, s = math.cos(theta), math.sin(theta)
    _, n_g, dist = goal_basis(np.asarray(p, float), np.asarray(goal, float))
    if float(dist) <= 0.0:
        return 0.0
    return (c * vx - s * vy) * float(n_g[0]) + (s * vx + c * vy) * float(n_g[1])


def lateral_sides(v_lat, goal_dist, dead_band: float = LATERAL_DEAD_BAND_MPS,
                  near_goal_m: float = LATERAL_NEAR_GOAL_M) -> np.ndarray:
    """Each step's side (+1, -1, 0) from its lateral speed, with the dead band and the near-goal exclusion."""
    v = np.asarray(v_lat, float)
    side = np.where(v >= dead_band, 1, np.where(v <= -dead_band, -1, 0))
    return np.where(np.asarray(goal_dist, float) < near_goal_m, 0, side)


def lateral_reversals(sides, dt: float, hold_s: float = LATERAL_HOLD_S) -> int:
    """Reversals of the established side in a sequence of per-step sides (+1, -1, 0) of period ``dt``."""
    need = max(1, math.ceil(hold_s / dt - 1e-9))
    established = 0
    reversals = 0
    run_side, run_len = 0, 0
    for s in np.asarray(sides, int):
        if s == run_side:
            run_len += 1
        else:
            run_side, run_len = int(s), 1
        if run_side != 0 and run_len == need:
            if established != 0 and run_side != established:
                reversals += 1
            established = run_side
    return reversals


def no_progress_time(t, goal_dist, window_s: float = PROGRESS_WINDOW_S, min_decrease_m: float = PROGRESS_MIN_M) -> float:
    """Length [s] of the union of the windows [t_k - W, t_k] over which the goal distance decreased by less than
    ``min_decrease_m`` (samples ``t`` increasing; a window starts at a sample)."""
    t = np.asarray(t, float)
    d = np.asarray(goal_dist, float)
    if len(t) < 2:
        return 0.0
    j = np.searchsorted(t, t - window_s - _EPS_T, side="left")     # first sample at or after t_k - W
    ok = (t - window_s >= t[0] - _EPS_T) & (np.abs(t[np.minimum(j, len(t) - 1)] - (t - window_s)) <= _EPS_T)
    stalled = ok & (d[np.minimum(j, len(t) - 1)] - d < min_decrease_m)
    total, cur_a, cur_b = 0.0, None, None
    for k in np.flatnonzero(stalled):
        a, b = t[j[k]], t[k]
        if cur_b is not None and a <= cur_b + _EPS_T:
            cur_b = max(cur_b, b)
        else:
            if cur_b is not None:
                total += cur_b - cur_a
            cur_a, cur_b = a, b
    if cur_b is not None:
        total += cur_b - cur_a
    return float(total)


class LivenessRecorder:
    """Collects what the metrics need at each control step and computes them at the end of an episode."""

    def __init__(self, dt: float):
        self.dt = float(dt)
        self.t: list[float] = []
        self.v_lat: list[float] = []
        self.odom_goal_dist: list[float] = []
        self.true_goal_dist: list[float] = []

    def add(self, t: float, state, u_safe, goal, true_xy) -> None:
        """One control step: the controller's state (odom pose), the command sent, the goal, the true position."""
        p = (state.px, state.py)
        self.t.append(float(t))
        self.v_lat.append(lateral_speed(u_safe, state.theta, p, goal))
        self.odom_goal_dist.append(math.hypot(goal[0] - p[0], goal[1] - p[1]))
        self.true_goal_dist.append(math.hypot(goal[0] - true_xy[0], goal[1] - true_xy[1]))

    def metrics(self, mode_history, duration_s: float) -> dict:
        sides = lateral_sides(self.v_lat, self.odom_goal_dist)
        return dict(mode_switches_per_min=mode_switches_per_min(mode_history, duration_s),
                    side_reversals=side_reversals(mode_history),
                    lateral_reversals=lateral_reversals(sides, self.dt),
                    no_progress_s=round(no_progress_time(self.t, self.true_goal_dist), 4))
