"""The BIG-CBF planner (and its NoShared ablation): behavior selection every T_B, the selected feedback policy
regenerated at every control tick (eq:online_behavior_command (8)). Its u_in goes to the common CbfFilter.

Three methods, one implementation: ``big-cbf`` is the paper as written (every rule of ours off,
:data:`~bigcbf.params.stack.PAPER_RULES`), ``big-cbf-noshared`` the same with the imagination's fixed 0.30 m margin
and nothing else different, and ``big-cbf-plus`` (:class:`BigCbfPlusPlanner`) BIG-CBF with our rules beyond the
paper, each a named switch of :class:`~bigcbf.params.stack.PlusRules` (``[methods.big-cbf-plus]``).

What a selection keeps: the mode, and when the mode is the REVERSE fallback, the release velocity the
imagination chose for it (:func:`~bigcbf.control.imagination.choose_release`); no imagined trajectory or command
is replayed."""
from __future__ import annotations

import dataclasses
import time
import numpy as np

from ..params.stack import PAPER_RULES, PlusRules, StackParams
from ..types import Obstacles, RobotState
from .behaviors import REVERSE, behavior_command
from .encounters import EncounterTracker, meeting_side
from .executed_speed import judge_at_executed_speed, speed_params
from .governor import GOVERNED_MODES, govern_command
from .imagination import Imagination, choose_release, imagine
from .planner import PlanInfo, clip_command, fail_safe
from .selection import BehaviorSelector, Selection

_T_EPS = 1e-6   # tolerance of the selection clock [s] (control ticks are floats)


class BigCbfPlanner:
    """BIG-CBF (``shared=True``) or BIG-CBF-NoShared (``shared=False``). Deterministic: ``reset(seed)`` ignores the
    seed.

    NoShared as the paper writes it (Sec. IV-C, "Ablation design"; Sec. V for the hardware): "the same behavior
    library, feedback policies, horizon, switching logic, and final hard CBF as BIG-CBF, but replaces the
    imagination-layer uncertainty construction in [eq:uncertainty_margin (21)] with a fixed 0.30-m geometric margin".
    Checked against this code: the two variants share the behaviors and policies (``behaviors``), N and dt, the
    scoring (eq:behavior_terms (13), eq:behavior_cost (14), eq:analytic_workload (24)) and the selector (dwell,
    switching threshold), the reverse-release fallback and the rollouts' execution model (A, d of
    eq:execution (1), which propagates the imagined robot in both), and
    the common CbfFilter with the full shared D_i^exec. The one difference is in ``imagine`` (and the fallback's
    release rollout, which uses the same barrier): D_i^img = r_R + r_i + d0 + ``noshared_margin_m`` (0.30 m) instead
    of r_R + r_i + d0 + kappa_img m_i (tests/control/test_paper_fidelity.py: with equal margins the two select the
    same behaviors). kappa_img does not scale the fixed margin: kappa_img is the layer scaling of
    the shared m_i, which NoShared does not use ("a fixed 0.30 m margin", also with the hardware preset's
    kappa_img = 0.8). (Before issue 24 NoShared also widened the "in the way" band of PASS to its margin; that band
    is now a rule of ``big-cbf-plus``, which has no NoShared variant.)

    The first call selects; later selections happen on the grid t_0 + n T_B (with a tolerance for float
    clocks). ``last_imagination`` and ``last_selection`` keep the latest cycle for inspection.
    """

    def __init__(self, params: StackParams, *, shared: bool = True, rules: PlusRules = PAPER_RULES):
        if not isinstance(rules, PlusRules):
            raise TypeError(f"rules must be PlusRules, got {type(rules).__name__}")
        self.params = params
        self.shared = shared
        self.rules = rules
        self.name = "big-cbf" if shared else "big-cbf-noshared"
        self.score_steps: int | None = None      # the rule long_horizon (big-cbf-plus): see BigCbfPlusPlanner
        self.release_params = params             # ... whose reverse release keeps the stack's horizon
        self.selector = BehaviorSelector(params, rules)
        # the rule encounter_commitment (big-cbf-plus): the obstacle being passed, across selections (encounters.py)
        self.encounters = EncounterTracker(params, rules) if rules.encounter_commitment else None
        self.reset(0)

    #: PASS-L/SIDE-L and PASS-R/SIDE-R are sided modes: episodes report switches per encounter (encounters.py)
    sided_modes = True

    def reset(self, seed: int) -> None:
        self.selector.reset()
        if self.encounters is not None:
            self.encounters.reset()
        self._speed_params = self.params     # the selected mode's speed limits (rule executed_speed)
        self._next_t: float | None = None
        self._path: np.ndarray | None = None
        self._release_v: np.ndarray | None = None
        self._margins: np.ndarray | None = None
        self.last_imagination: Imagination | None = None
        self.last_selection: Selection | None = None

    @property
    def mode(self) -> str | None:
        return self.selector.mode

    def select(self, t: float, state: RobotState, obstacles: Obstacles, goal) -> Selection:
        """One behavior-selection cycle (eq:behavior_rollout (12), eq:behavior_terms (13), eq:behavior_cost (14),
        eq:behavior_acceptance (22), eq:analytic_workload (24)): imagine, score, select; keeps only the mode."""
        p = self.params
        img = imagine(state, obstacles, goal, p, shared=self.shared, current=self.selector.mode, rules=self.rules,
                      score_steps=self.score_steps)
        scale = None
        if self.rules.executed_speed:          # rejected candidates judged again at slower speeds (executed_speed.py)
            img, scale = judge_at_executed_speed(img, state, obstacles, goal, p, shared=self.shared,
                                                 current=self.selector.mode, rules=self.rules,
                                                 score_steps=self.score_steps)
        enc = None if self.encounters is None else self.encounters.update(t, state.p, goal, obstacles)
        lean = meeting_side(state.p, goal, obstacles, p) if self.rules.meeting_side else 0
        sel = self.selector.select(t, img, enc, lean)
        self._speed_params = (p if scale is None or sel.mode not in img.modes
                              else speed_params(p, float(scale[img.index(sel.mode)])))
        if sel.mode == REVERSE:     # the fallback is no candidate: its release is chosen only when it is used
            self._release_v, rel, best = choose_release(state, obstacles, goal, self.release_params,
                                                        shared=self.shared, rules=self.rules)
            self._path = rel.p[best]
            self._margins = rel.margin[best].ravel()
        else:
            self._release_v = None
            self._path = img.p[img.index(sel.mode)]
            scored = None if self.score_steps is None else self.score_steps + 1      # the margins of the scored steps
            self._margins = img.margin[img.index(sel.mode)][:scored].ravel()
        self.last_imagination, self.last_selection = img, sel
        return sel

    @fail_safe
    def plan(self, t: float, state: RobotState, obstacles: Obstacles, goal) -> tuple[np.ndarray, PlanInfo]:
        t0 = time.perf_counter()
        goal = np.asarray(goal, float).reshape(2)
        planned = self._next_t is None or t >= self._next_t - _T_EPS
        if planned:
            self.select(t, state, obstacles, goal)
            nxt = t if self._next_t is None else self._next_t
            while nxt <= t + _T_EPS:
                nxt += self.params.T_B_s
            self._next_t = nxt
        mode = self.selector.mode
        u = clip_command(behavior_command(mode, state, obstacles, goal, self._speed_params,
                                          release_v=self._release_v, rules=self.rules),
                         self.params)  # eq:online_behavior_command (8)
        if self.rules.speed_governor and mode in GOVERNED_MODES:
            u = govern_command(state, obstacles, u, self.params)[0]                           # governor.py
        return u, PlanInfo(mode=mode, planned=planned, planner_ms=(time.perf_counter() - t0) * 1e3, path=self._path,
                           margins_img=self._margins if planned else None)


class BigCbfPlusPlanner(BigCbfPlanner):
    """``big-cbf-plus``: BIG-CBF with our rules beyond the paper, each a named switch of its parameters
    (:class:`~bigcbf.params.stack.PlusRules`, ``[methods.big-cbf-plus]`` of a run configuration; default: BIG-CBF as
    it was before issue 24, every switch on but the speed governor). The shared imagination margin, as BIG-CBF."""

    params_type = PlusRules

    def __init__(self, params: StackParams, rules: PlusRules | None = None):
        rules = PlusRules() if rules is None else rules
        # the rule long_horizon: the imagination (and all that reads its horizon) looks long_horizon_s ahead
        planner_params = dataclasses.replace(params, N=rules.rollout_steps(params)) if rules.long_horizon else params
        super().__init__(planner_params, shared=True, rules=rules)
        self.name = "big-cbf-plus"
        # ... to test the barrier against the people who move; it scores, and releases, over the stack's N steps
        if rules.long_horizon:
            self.score_steps, self.release_params = params.N, params
        # the common filter with its velocity-aware rows and its last resort (methods.filter_params)
        self.filter_params = dataclasses.replace(params, cbf_last_resort=self.rules.last_resort,
                                                 cbf_velocity_rows=params.cbf_velocity_rows or self.rules.velocity_rows,
                                                 cbf_slowdown=params.cbf_slowdown or self.rules.slowdown)
