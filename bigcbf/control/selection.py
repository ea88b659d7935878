"""Behavior selection (eq:behavior_cost (14) ranking of the candidates accepted by eq:behavior_acceptance (22)),
with a minimum dwell time, a relative switching-improvement threshold, and the reverse-release fallback."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..params.stack import PAPER_RULES, PlusRules, StackParams
from .behaviors import MODE_INDEX, REVERSE, SIGMA
from .encounters import EVIDENCE_LEAK, accumulate_evidence
from .imagination import Imagination


@dataclass(frozen=True)
class Selection:
    mode: str
    reason: str   # "initial", "best", "kept-dwell", "kept-threshold", "current-rejected", "fallback"
    switched: bool


def _sides(img: Imagination) -> np.ndarray:
    """(B,) the side of each candidate mode: +1 left (PASS-L, SIDE-L), -1 right, 0 none."""
    return np.array([SIGMA[MODE_INDEX[m]] for m in img.modes])


class BehaviorSelector:
    """Keeps b_cur and decides, at each selection, between keeping it and switching.

    Rules, in order:
    1. No candidate viable (eq:behavior_acceptance (22) rejects all, or only unavailable or frozen ones remain):
       REVERSE (fallback).
    2. No retained regular mode yet, or the retained one is REVERSE or now rejected: the lowest-J accepted one.
    3. The retained mode was selected less than ``dwell_s`` ago: keep it.
    4. Switch only if the best accepted J beats J_cur by more than switch_rel |J_cur| + switch_abs; else keep.
    J already contains w_sw C_sw (eq:behavior_cost (14)). Ties go to the first mode in the behavior order
    (deterministic).

    Rules 3 and 4 are the paper's "minimum dwell time and a relative switching-improvement threshold" (values paper
    silent: ``StackParams.dwell_s``, ``switch_rel``, ``switch_abs``); rule 1 its fallback; rule 2 (a rejected
    retained mode is replaced at once, the dwell notwithstanding) is paper silent: a rejected candidate cannot be
    kept.

    Side commitment (a rule of ours, ``PlusRules.side_commitment``, off in ``big-cbf``; the switching threshold
    applied to the side): once a left or right mode (PASS/SIDE-L or -R)
    has been selected, "the best" in rules 2 and 4 is taken among the accepted modes on that side or on none
    (GOAL, YIELD), and an opposite-side mode replaces it only if it beats it by the switching threshold plus w_sw
    (a side flip undoes a manoeuvre: it is charged as a second switch). The side is released when GOAL is
    selected. Without this, the symmetric scenes the paper targets (an obstacle square on
    the goal line) tie PASS-L with PASS-R and SIDE-L with SIDE-R, and a forced switch (the retained mode
    rejected) could flip sides, undoing the manoeuvre; the paper's liveness argument rests on commitment.

    Frozen candidates (our choice; the paper invokes the fallback "if all regular behaviors fail the acceptance
    test"): with the speed governor (``bigcbf.control.governor``) a behavior whose direction is blocked does not
    run into the inflated radius, where eq:behavior_acceptance (22) would reject it; it slows down to a stop in front of
    it. A moving behavior (GOAL, PASS, SIDE) whose governed rollout gains less progress than the freeze speed would over
    the horizon, v_freeze N dt, both in goal distance (P_b of eq:behavior_terms (13)) and along its own maneuver, and
    does not end in the goal region, can no more proceed than a rejected one, so it is treated as one
    (:attr:`bigcbf.control.imagination.Imagination.viable`): it is not retained, and when no candidate is left the
    reverse-release fallback is invoked, as when all are rejected. YIELD is exempt (standing still is what it does). Rules 1-4 read "viable" for "accepted".
    This is part of the rule ``PlusRules.speed_governor``; without it "viable" is "accepted".

    Encounter commitment (a rule of ours, ``PlusRules.encounter_commitment``, off in ``big-cbf``;
    ``bigcbf.control.encounters``): ``select`` is given the current encounter. While it is committed to a side, the
    opposite side's modes are not viable (rules 1-4 choose among the rest: that side, GOAL, YIELD, else the
    fallback), unless the committed side is blocked: a count that rises by one at each selection at which every
    candidate on that side fails eq:behavior_acceptance (22) and falls by one (not below 0) at each at which one
    passes has reached ``commit_release_selections`` (K; K consecutive rejections, or more when they alternate with
    passes: a side that is rejected, passes once after a REVERSE and is rejected again must not hold the robot
    forever, as on the dev world clutter_00008) while a candidate on the other side passes (with both sides
    rejected, e.g. behind a walker in a corridor too narrow to overtake in, there is nothing to switch to), or the
    evidence for the other side (the leaky sum of its cost
    advantage beyond w_sw, :func:`~bigcbf.control.encounters.accumulate_evidence`; the full per-selection cap when
    only the other side has a viable mode) has reached ``commit_evidence_js``; either releases the commitment. The
    first sided mode
    selected during an encounter commits it. While an encounter is current, the side commitment above takes its
    side from the encounter (none for an uncommitted one), not from the last sided mode.

    Meeting side (a rule of ours, ``PlusRules.meeting_side``, off in ``big-cbf``): while no side is held (neither
    the side commitment nor a committed encounter), and ``select`` is given a side ``lean`` away from a person
    walking along the path (``bigcbf.control.encounters.meeting_side``), the other side's modes are not viable at
    this selection if a mode on ``lean``'s side is; the side then chosen is held by the rules above.
    """

    def __init__(self, params: StackParams, rules: PlusRules = PAPER_RULES):
        self.params = params
        self.rules = rules
        self.reset()

    def reset(self) -> None:
        self.mode: str | None = None
        self.t_switch = -math.inf
        self.side = 0.0          # +1 left, -1 right, 0 uncommitted

    def _best(self, img: Imagination, J: np.ndarray) -> str:
        """The lowest-J accepted mode, honouring the side commitment (class docstring)."""
        p = self.params
        best = int(np.argmin(J))
        if self.side == 0 or not self.rules.side_commitment:
            return img.modes[best]
        side = _sides(img)
        own = np.where(side != -self.side, J, np.inf)
        k = int(np.argmin(own))
        if not np.isfinite(own[k]) or k == best:
            return img.modes[best]
        if J[best] < own[k] - p.switch_rel * abs(own[k]) - p.switch_abs - p.w_sw:
            return img.modes[best]
        return img.modes[k]

    def _encounter_viable(self, img: Imagination, acc: np.ndarray, enc) -> np.ndarray:
        """The encounter commitment (class docstring): ``acc`` without the committed encounter's opposite side;
        counts the selections at which its own side failed eq:behavior_acceptance (22) and releases it after K."""
        side = _sides(img)
        if enc.side != 0:
            if (np.asarray(img.accepted) & (side == enc.side)).any():
                enc.blocked = max(enc.blocked - 1, 0)
            else:
                enc.blocked += 1
            J = np.where(acc, img.J, np.inf)
            j_keep, j_other = J[side != -enc.side].min(initial=np.inf), J[side == -enc.side].min(initial=np.inf)
            if np.isfinite(j_other):                              # the evidence for the other side (encounters.py)
                enc.evidence = accumulate_evidence(enc.evidence, j_keep - j_other, self.params)
            else:
                enc.evidence *= EVIDENCE_LEAK
            other_ok = (np.asarray(img.accepted) & (side == -enc.side)).any()
            if ((enc.blocked >= self.rules.commit_release_selections and other_ok)
                    or enc.evidence >= self.rules.commit_evidence_js):
                enc.side, enc.blocked, enc.evidence = 0, 0, 0.0
        self.side = float(enc.side)
        return acc & (side != -enc.side) if enc.side != 0 else acc

    def select(self, t: float, img: Imagination, encounter=None, lean: int = 0) -> Selection:
        """One selection (class docstring); ``encounter``: the current encounter
        (:class:`~bigcbf.control.encounters.Encounter`) under the rule ``encounter_commitment``, else None;
        ``lean``: the side of the rule ``meeting_side`` (``encounters.meeting_side``; 0: none)."""
        p = self.params
        acc = img.viable
        if encounter is not None and self.rules.encounter_commitment:
            acc = self._encounter_viable(img, acc, encounter)
        if lean and self.rules.meeting_side and self.side == 0 and (encounter is None or encounter.side == 0):
            side = _sides(img)
            if (acc & (side == lean)).any():     # the first side away from the person, when it has a candidate
                acc = acc & (side != -lean)
        prev = self.mode
        if not acc.any():
            sel = Selection(REVERSE, "fallback", prev != REVERSE)
        else:
            J = np.where(acc, img.J, np.inf)
            best = self._best(img, J)
            if prev is None:
                sel = Selection(best, "initial", True)
            elif prev == REVERSE or prev not in img.modes or not acc[img.index(prev)]:
                sel = Selection(best, "current-rejected" if prev != REVERSE else "best", best != prev)
            elif best == prev:
                sel = Selection(prev, "best", False)
            elif t - self.t_switch < p.dwell_s - 1e-9:
                sel = Selection(prev, "kept-dwell", False)
            else:
                j_cur, j_best = float(img.J[img.index(prev)]), float(img.J[img.index(best)])
                if j_best < j_cur - p.switch_rel * abs(j_cur) - p.switch_abs:
                    sel = Selection(best, "best", True)
                else:
                    sel = Selection(prev, "kept-threshold", False)
        if sel.switched:
            self.t_switch = t
        self.mode = sel.mode
        if sel.mode in MODE_INDEX and SIGMA[MODE_INDEX[sel.mode]] != 0:
            self.side = float(SIGMA[MODE_INDEX[sel.mode]])
            if encounter is not None and self.rules.encounter_commitment and encounter.side == 0:
                encounter.side = int(self.side)
        elif sel.mode == "GOAL":
            self.side = 0.0
        return sel
