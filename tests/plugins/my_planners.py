"""A planner of a user's own, outside the bigcbf package (the tests put this folder on PYTHONPATH): what
docs/extending.md shows. ``--method my_planners:GoalSeeker`` selects it; ``[methods."my_planners:GoalSeeker"]``
in a run configuration sets its parameters."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bigcbf.control.planner import PlanInfo
from bigcbf.params.stack import StackParams
from bigcbf.types import Obstacles, RobotState


@dataclass(frozen=True)
class GoalSeekerParams:
    speed_mps: float = 0.5          # cruising speed [m/s]

    def __post_init__(self):
        if not 0 < self.speed_mps <= 2.0:
            raise ValueError(f"speed_mps must be in (0, 2], got {self.speed_mps}")


class GoalSeeker:
    """Straight to the goal at a constant speed; the common CBF filter keeps it safe."""

    name = "goal-seeker"
    params_type = GoalSeekerParams

    def __init__(self, params: StackParams, own: GoalSeekerParams = GoalSeekerParams()):
        self.params, self.own = params, own

    def reset(self, seed: int) -> None:
        pass

    def plan(self, t: float, state: RobotState, obstacles: Obstacles, goal) -> tuple[np.ndarray, PlanInfo]:
        e = np.asarray(goal, float) - state.p
        dist = float(np.hypot(*e))
        v = e / dist * min(self.own.speed_mps, dist) if dist > 1e-9 else np.zeros(2)
        c, s = np.cos(state.theta), np.sin(state.theta)
        u = np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], 0.0])      # world -> body frame
        return u, PlanInfo(mode="SEEK", planned=True, planner_ms=0.0, path=np.array([state.p, goal]))


def not_a_planner(params):
    return object()
