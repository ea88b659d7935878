"""The method registry: name -> factory(StackParams) -> Planner. Baselines register here from their own modules
(``METHODS.register("dwa", make_dwa)``); every method's u_in goes through the same CbfFilter."""
from __future__ import annotations

import time
from typing import Callable

import numpy as np

from ..params.stack import StackParams
from ..registry import Registry
from ..types import Obstacles, RobotState
from .behaviors import behavior_command
from .big_cbf import BigCbfPlanner
from .planner import PlanInfo, Planner, clip_command, fail_safe

METHODS: Registry[Callable[[StackParams], Planner]] = Registry("method")


class CbfOnlyPlanner:
    """CBF-only: the GOAL feedback policy (Eqs. 6-8 with b = GOAL) straight into the common CBF filter."""

    name = "cbf-only"

    def __init__(self, params: StackParams):
        self.params = params

    def reset(self, seed: int) -> None:
        """Stateless and deterministic: nothing to reset."""

    @fail_safe
    def plan(self, t: float, state: RobotState, obstacles: Obstacles, goal) -> tuple[np.ndarray, PlanInfo]:
        t0 = time.perf_counter()
        u = clip_command(behavior_command("GOAL", state, obstacles, np.asarray(goal, float).reshape(2), self.params),
                         self.params)
        return u, PlanInfo(mode="GOAL", planned=True, planner_ms=(time.perf_counter() - t0) * 1e3, path=None)


METHODS.register("big-cbf", lambda params: BigCbfPlanner(params, shared=True))
METHODS.register("big-cbf-noshared", lambda params: BigCbfPlanner(params, shared=False))
METHODS.register("cbf-only", CbfOnlyPlanner)

from . import baselines as _baselines  # noqa: E402  (the five comparison methods register themselves here)

_baselines.register(METHODS)
