"""Candidates judged at the speed the filter will execute them (issue 25, item 1; ``big-cbf-plus``'s rule
``executed_speed``; the paper's ``big-cbf`` never calls this module).

**Why.** The imagination (``eq:behavior_rollout`` (12)) drives every candidate at its speed limit v_b^max of
``eq:behavior_feedback`` (11) (0.8 m/s GOAL and PASS, 0.55 m/s SIDE). The shared radius m_i of
``eq:uncertainty_margin`` (21) grows with that speed (tau95 ||R(A u + d) - v_i|| and e_exec(u)): a gap or a slow
walker's free side that is wide enough at 0.3-0.5 m/s is rejected by ``eq:behavior_acceptance`` (22) at full speed,
although the hard CBF, which evaluates D_i^exec at the command it gets, would let a slower command through. Slowing
the rollout down inside the same N steps (the speed governor, ``governor.py``) shortens the look-ahead with the
speed: a slow GOAL's 1.5 s rollout ends before the wall it is heading for and stays acceptable (docs/fidelity.md,
"Liveness").

**The rule.** After the imagination, every available moving candidate (GOAL, PASS, SIDE) that
``eq:behavior_acceptance`` (22) rejected is imagined again with its speed limits scaled by s in ``SCALES`` (0.6, then
0.35 of v_b^max; fastest first) and a horizon of ceil(N / s) steps, so that the rollout covers the same distance,
v_b^max N dt, as the full-speed one: the look-ahead does not collapse with the speed. The same policies, prediction,
shared barrier and acceptance test (only the speed limits and N differ). The first scale at which it is accepted
replaces its row, if it stays outside every inflated radius (min h >= 0: the filter's own condition; the
tolerance eps_h of ``eq:behavior_acceptance`` (22) is not granted to a re-judged candidate, whose slow rollout
covers the same distance: accepted only within the tolerance, it crept into a pocket where the filter held it,
clutter_00003 of the dev split, stopped 14.8 s): h_min, acceptance and the cost ``eq:behavior_cost`` (14), whose summed terms (W of
``eq:analytic_workload`` (24), P, S of ``eq:behavior_terms`` (13)) are rescaled by N / ceil(N / s) to the
standard horizon's time (a slow candidate earns the progress it makes in N dt, not in its longer horizon; F is a
fraction). Selected, the mode runs with the scaled speed limit until the next selection
(:class:`~bigcbf.control.big_cbf.BigCbfPlanner`). The stored path and margins of a replaced row are the slow
rollout's first N steps (what ``PlanInfo`` shows). A candidate rejected at every scale stays rejected.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..params.stack import MAX_N, PlusRules, StackParams
from ..types import Obstacles, RobotState
from .imagination import Imagination, imagine

#: the fractions of v_b^max a rejected candidate is judged at again, fastest first [-]
SCALES = (0.6, 0.35)
_MOVING = ("GOAL", "PASS-L", "PASS-R", "SIDE-L", "SIDE-R")
_PARAMS: dict[tuple[int, float], tuple[StackParams, StackParams]] = {}


def speed_params(params: StackParams, scale: float) -> StackParams:
    """``params`` with the behaviors' speed limits (v_max_mps, v_side_mps) scaled by ``scale`` and the imagination
    horizon N lengthened to ceil(N / scale) (at most MAX_N): the same look-ahead distance. Cached (one object per
    params and scale, so the imagination's per-params constants are reused)."""
    if scale == 1.0:
        return params
    key = (id(params), float(scale))
    hit = _PARAMS.get(key)
    if hit is None or hit[0] is not params:
        if len(_PARAMS) > 64:
            _PARAMS.clear()
        slow = dataclasses.replace(params, v_max_mps=params.v_max_mps * scale, v_side_mps=params.v_side_mps * scale,
                                   N=min(int(math.ceil(params.N / scale - 1e-9)), MAX_N))
        hit = (params, slow)
        _PARAMS[key] = hit
    return hit[1]


def judge_at_executed_speed(img: Imagination, state: RobotState, obstacles: Obstacles, goal, params: StackParams, *,
                            shared: bool, current: str | None, rules: PlusRules,
                            score_steps: int | None = None) -> tuple[Imagination, np.ndarray]:
    """The rule (module docstring): ``img`` with the rejected moving candidates re-judged at ``SCALES``, and each
    row's speed scale (B,) (1.0 where the row is the full-speed one). ``score_steps`` (the rule long_horizon,
    ``imagination.imagine``) is lengthened with the horizon: the same distance."""
    scale = np.ones(len(img.modes))
    todo = [b for b, m in enumerate(img.modes) if m in _MOVING and img.available[b] and not img.accepted[b]]
    if not todo:
        return img, scale
    out = _copy(img)
    for s in SCALES:
        if not todo:
            break
        slow_p = speed_params(params, s)
        modes = tuple(img.modes[b] for b in todo)
        steps = None if score_steps is None else min(int(math.ceil(score_steps / s - 1e-9)), slow_p.N)
        slow = imagine(state, obstacles, goal, slow_p, modes=modes, shared=shared, current=current, rules=rules,
                       score_steps=steps)
        left = []
        for k, b in enumerate(todo):
            if slow.accepted[k] and slow.h_min[k] >= 0.0:      # the filter's own test, without eps_h (docstring)
                _replace_row(out, b, slow, k, params, score_steps, steps)
                scale[b] = s
            else:
                left.append(b)
        todo = left
    return out, scale


def _copy(img: Imagination) -> Imagination:
    """A copy whose arrays can be written row by row."""
    kw = {f.name: getattr(img, f.name) for f in dataclasses.fields(img)}
    for k, v in kw.items():
        if isinstance(v, np.ndarray):
            kw[k] = v.copy()
    if img.params_stall is not None:
        kw["params_stall"] = (img.params_stall[0], np.array(img.params_stall[1], copy=True))
    return Imagination(**kw)


def _replace_row(out: Imagination, b: int, slow: Imagination, k: int, params: StackParams,
                 score_steps: int | None = None, slow_steps: int | None = None) -> None:
    """Row b of ``out`` from row k of the slow imagination ``slow`` (module docstring: summed terms rescaled to the
    standard horizon's time, the path and margins truncated to its N steps; with the rule long_horizon the summed
    terms are over the score steps, ``score_steps`` here and ``slow_steps`` there)."""
    N = params.N
    f = N / (slow.u.shape[1]) if score_steps is None else score_steps / slow_steps   # N / ceil(N / s)
    W, P, S = slow.W[k] * f, slow.P[k] * f, slow.S[k] * f
    out.W[b], out.P[b], out.F[b], out.S[b] = W, P, slow.F[k], S
    out.J[b] = (params.w_W * W - params.w_P * P + params.w_F * slow.F[k] + params.w_sw * slow.C_sw[k]
                + params.w_S * S)
    out.h_min[b], out.accepted[b] = slow.h_min[k], slow.accepted[k]
    out.p[b], out.theta[b], out.u[b] = slow.p[k, :N + 1], slow.theta[k, :N + 1], slow.u[k, :N]
    if out.margin is not None and slow.margin is not None:
        out.margin[b] = slow.margin[k, :N + 1]
    if out.deficit is not None and slow.deficit is not None:
        out.deficit[b] = slow.deficit[k]
    if out.params_stall is not None and slow.params_stall is not None:
        out.params_stall[1][b] = slow.params_stall[1][k]
    if out.along is not None and slow.along is not None:
        out.along[b] = slow.along[k] * f
