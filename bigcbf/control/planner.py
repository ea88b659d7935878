"""The planner protocol every method implements (BIG-CBF and each baseline) and its info record."""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from ..params.stack import StackParams
from ..types import Obstacles, RobotState
from .faults import FAULT_MODE, perception_fault

_TINY = 1e-12


@dataclass
class PlanInfo:
    """What a planner did in one call."""

    mode: str                          # behavior mode (BIG-CBF) or a method-specific label
    planned: bool                      # an expensive planning cycle (e.g. a behavior selection) ran in this call
    planner_ms: float                  # time of this call [ms]
    path: np.ndarray | None = None     # (K, 2) imagined/predicted path of the selected option (odom) [m], for videos
    #: the imagination layer's margins kappa_img m_i (eq:shared_barrier (20)) of the selected option's rollout, over its
    #: steps and obstacles [m] (flat), when a selection ran this call; None for methods without an imagination layer.
    #: For BIG-CBF-NoShared the fixed margin that replaces them.
    margins_img: np.ndarray | None = None


@runtime_checkable
class Planner(Protocol):
    """Called every control tick T_C with the latest estimates; returns u_in (3,), a body twist (vx, vy, wz)."""

    name: str

    def reset(self, seed: int) -> None:
        ...

    def plan(self, t: float, state: RobotState, obstacles: Obstacles,
             goal: np.ndarray) -> tuple[np.ndarray, PlanInfo]:
        ...


def clip_command(u, params: StackParams) -> np.ndarray:
    """Clip a body twist (..., 3) to the translational speed limit v_max_mps and the actuator box: every method's
    u_in passes through this, so that the common filter's own box clip never counts in E_CBF for one method
    and not another."""
    u = np.array(u, float)
    n = np.hypot(u[..., 0], u[..., 1])
    scale = np.minimum(1.0, params.v_max_mps / np.maximum(n, _TINY))
    u[..., 0] *= scale
    u[..., 1] *= scale
    return np.clip(u, np.asarray(params.u_min, float), np.asarray(params.u_max, float))


def fail_safe(plan):
    """Decorate a planner's ``plan``: on a perception fault (``bigcbf.control.faults``: non-finite or implausible
    obstacle estimates, robot state or goal) return u_in = 0 with mode "FAULT" without calling ``plan``, so the
    planner's internal state (warm starts, selection clock) never sees the faulty numbers."""
    @functools.wraps(plan)
    def guarded(self, t: float, state: RobotState, obstacles: Obstacles, goal) -> tuple[np.ndarray, PlanInfo]:
        t0 = time.perf_counter()
        if perception_fault(state, obstacles, goal) is None:
            return plan(self, t, state, obstacles, goal)
        return np.zeros(3), PlanInfo(mode=FAULT_MODE, planned=False, planner_ms=(time.perf_counter() - t0) * 1e3,
                                     path=None)
    return guarded
