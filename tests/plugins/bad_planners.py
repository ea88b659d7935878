"""Planners that break the planner protocol in one way each (tests/test_cli_newcomer.py): the episode must stop
with one line naming the method and what was wrong, not a traceback from the CBF filter."""
import numpy as np

from bigcbf.control.planner import PlanInfo


class _Base:
    name = "bad"

    def __init__(self, params):
        self.params = params

    def reset(self, seed: int) -> None:
        pass


def _info():
    return PlanInfo(mode="BAD", planned=True, planner_ms=0.0)


class TwoVector(_Base):
    """A planar velocity (vx, vy) without the yaw rate."""

    def plan(self, t, state, obstacles, goal):
        return np.array([0.3, 0.0]), _info()


class NanCommand(_Base):
    """A NaN after the first second (a division by a zero distance, say)."""

    def plan(self, t, state, obstacles, goal):
        return np.array([0.3, 0.0, np.nan if t >= 1.0 else 0.0]), _info()


class CommandOnly(_Base):
    """The command alone, without the PlanInfo."""

    def plan(self, t, state, obstacles, goal):
        return np.array([0.3, 0.0, 0.0])


class DictInfo(_Base):
    """A dict where a PlanInfo belongs."""

    def plan(self, t, state, obstacles, goal):
        return np.array([0.3, 0.0, 0.0]), {"mode": "BAD"}


class NoPlan:
    """A class with reset but no plan."""

    def __init__(self, params):
        pass

    def reset(self, seed: int) -> None:
        pass


NOT_A_CLASS = 3
