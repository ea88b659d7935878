"""Perception faults: inputs the planners and the CBF filter must not act on, and what they do instead.

An obstacle estimate is faulty when any of its numbers is not finite (NaN, +-inf in p, v, cov or r) or when it is
implausible for a ground robot's surroundings:

- |p| (either coordinate) > ``MAX_POSITION_M`` (1e4 m; the scenarios' world is +-1e3 m, odometry drifts little),
- ||v|| > ``MAX_SPEED_MPS`` (50 m/s; people walk at ~1.5, a car in a car park at ~5),
- r < 0 or r > ``MAX_RADIUS_M`` (100 m),
- cov not symmetric (|c01 - c10| > 1e-9 (1 + max|c|)), not positive semi-definite (an eigenvalue below
  -1e-12 (1 + max|c|)), or an eigenvalue above ``MAX_COVARIANCE_M2`` (1e4 m^2: a 100 m standard deviation).

The robot state (pose and twist from odometry) and the goal are checked the same way (finite, positions within
``MAX_POSITION_M``, speeds within ``MAX_SPEED_MPS``).

What happens then (the semantics every method shares, chosen because it is the safe one): the step is a
*perception fault*. Nothing is known about where the faulty obstacle is, and the faulty number may belong to the
very obstacle the robot is about to hit, so dropping the obstacle and filtering with the rest is not safe; the
robot brakes: the CBF filter outputs u = 0 (inside the actuator box, which the parameters require to contain 0),
reports ``FilterInfo.fallback == "perception-fault"`` with the reason, and the episode counts these steps
(``perception_faults``). Every planner returns u_in = 0 with mode ``"FAULT"`` for such a step without touching its
internal state (so that a planner's warm start, e.g. MPPI's sequence, is not poisoned by a NaN), and resumes
with the next valid estimates.
"""
from __future__ import annotations

import math

import numpy as np

from ..types import Obstacles, RobotState
from .jit import kernel

MAX_POSITION_M = 1e4
MAX_SPEED_MPS = 50.0
MAX_RADIUS_M = 100.0
MAX_COVARIANCE_M2 = 1e4
#: the planners' mode label for a step they braked through (planner.fail_safe)
FAULT_MODE = "FAULT"


def bad_obstacles(obstacles: Obstacles) -> tuple[np.ndarray, list[str]]:
    """Which obstacles are faulty (M,) bool, and one reason per faulty obstacle (module docstring)."""
    p, v, cov, r = (np.asarray(obstacles.p, float), np.asarray(obstacles.v, float), np.asarray(obstacles.cov, float),
                    np.asarray(obstacles.r, float))
    M = len(r)
    if M == 0:
        return np.zeros(0, bool), []
    with np.errstate(invalid="ignore", over="ignore"):
        checks = [
            (~np.isfinite(p).all(axis=1), "non-finite position"),
            (~np.isfinite(v).all(axis=1), "non-finite velocity"),
            (~np.isfinite(cov).all(axis=(1, 2)), "non-finite covariance"),
            (~np.isfinite(r), "non-finite radius"),
        ]
        bad = np.zeros(M, bool)
        for mask, _ in checks:
            bad |= mask
        ok = ~bad
        pc, vc, cc, rc = (np.where(ok[:, None], p, 0.0), np.where(ok[:, None], v, 0.0),
                          np.where(ok[:, None, None], cov, 0.0), np.where(ok, r, 0.0))
        a, b1, b2, c = cc[:, 0, 0], cc[:, 0, 1], cc[:, 1, 0], cc[:, 1, 1]
        scale = 1.0 + np.abs(cc).max(axis=(1, 2))
        b = 0.5 * (b1 + b2)
        disc = np.sqrt(0.25 * (a - c) ** 2 + b * b)
        lam_min, lam_max = 0.5 * (a + c) - disc, 0.5 * (a + c) + disc
        checks += [
            (np.abs(pc).max(axis=1) > MAX_POSITION_M, f"position beyond {MAX_POSITION_M:g} m"),
            (np.hypot(vc[:, 0], vc[:, 1]) > MAX_SPEED_MPS, f"speed above {MAX_SPEED_MPS:g} m/s"),
            ((rc < 0) | (rc > MAX_RADIUS_M), f"radius outside [0, {MAX_RADIUS_M:g}] m"),
            (np.abs(b1 - b2) > 1e-9 * scale, "asymmetric covariance"),
            (lam_min < -1e-12 * scale, "covariance not positive semi-definite"),
            (lam_max > MAX_COVARIANCE_M2, f"covariance above {MAX_COVARIANCE_M2:g} m^2"),
        ]
    bad = np.zeros(M, bool)
    reasons: list[str] = []
    for i in range(M):
        why = [what for mask, what in checks if mask[i]]
        if why:
            bad[i] = True
            reasons.append(f"obstacle {i} (id {int(obstacles.ids[i])}): {', '.join(why)}")
    return bad, reasons


def state_fault(state: RobotState, goal=None) -> str | None:
    """Why the robot state or the goal cannot be used (module docstring), or None."""
    x = (state.px, state.py, state.theta, state.vx, state.vy, state.wz)
    if not all(math.isfinite(float(v)) for v in x):
        return "non-finite robot state"
    if max(abs(state.px), abs(state.py)) > MAX_POSITION_M:
        return f"robot position beyond {MAX_POSITION_M:g} m"
    if math.hypot(state.vx, state.vy) > MAX_SPEED_MPS:
        return f"robot speed above {MAX_SPEED_MPS:g} m/s"
    if goal is not None:
        g = np.asarray(goal, float).reshape(-1)
        if g.shape != (2,) or not np.isfinite(g).all() or np.abs(g).max() > MAX_POSITION_M:
            return "goal not a finite position within bounds"
    return None


def perception_fault(state: RobotState, obstacles: Obstacles, goal=None) -> str | None:
    """The reason this step is a perception fault (module docstring), or None when every input is usable."""
    why = state_fault(state, goal)
    if why is not None:
        return why
    if len(obstacles) == 0:
        return None
    p, v, cov, r = obstacles.p, obstacles.v, obstacles.cov, obstacles.r
    with np.errstate(over="ignore", invalid="ignore"):
        usable = _plainly_usable(p, v, cov, r)
    if usable:
        return None
    bad, reasons = bad_obstacles(obstacles)
    if not bad.any():
        return None
    more = f" (and {len(reasons) - 1} more)" if len(reasons) > 1 else ""
    return reasons[0] + more


def _plainly_usable(p, v, cov, r) -> bool:
    """Every number finite and within the bounds, in one compiled pass (the usual case; :func:`_usable`)."""
    return bool(_usable(np.asarray(p, float), np.asarray(v, float), np.asarray(cov, float), np.asarray(r, float),
                        MAX_POSITION_M, MAX_SPEED_MPS / math.sqrt(2), MAX_RADIUS_M, MAX_COVARIANCE_M2))


@kernel
def _usable(p, v, cov, r, max_pos, max_v, max_r, max_cov):
    """M >= 1 obstacles: every position, velocity, covariance and radius finite; |p| <= max_pos and |v| <= max_v per
    component; 0 <= r <= max_r; each covariance symmetric to the bit, with a, c >= 0, a c >= b^2 and a + c <= max_cov
    (a, b, c its entries). The comparisons of the numpy formulation it replaced, element by element."""
    for i in range(p.shape[0]):
        for k in range(2):
            if not (math.isfinite(p[i, k]) and abs(p[i, k]) <= max_pos and math.isfinite(v[i, k])
                    and abs(v[i, k]) <= max_v):
                return False
            for j in range(2):
                if not math.isfinite(cov[i, k, j]):
                    return False
        if not (math.isfinite(r[i]) and 0 <= r[i] <= max_r):
            return False
        a, b, b2, c = cov[i, 0, 0], cov[i, 0, 1], cov[i, 1, 0], cov[i, 1, 1]
        if b != b2 or a < 0 or c < 0 or not a * c >= b * b or a + c > max_cov:
            return False
    return True
