"""Encounters: the obstacle a robot is passing, kept across behavior selections and across changing track ids
(issue 25, item 1). ``big-cbf-plus``'s rule ``encounter_commitment`` keeps the passing side per encounter; the
metric ``switches_per_encounter`` (:class:`EncounterSideRecorder`) counts side switches per encounter for every
method that has sided modes. Neither the paper's ``big-cbf`` nor ``big-cbf-noshared`` reads this module.

**An encounter** is one obstacle the robot has to get past, as a group: it opens when the locally relevant
obstacle i of ``eq:behavior_subgoals`` (10) (the nearest obstacle ahead that the straight line to the goal passes
too close to; ``behaviors.relevant_obstacle`` with the rules' look-ahead and "in the way" band) is not a member of
an open encounter. Its members are i's *group* (``behaviors.obstacle_groups``: the obstacles the footprint cannot
pass between, i.e. a post, a person, a group of posts, a wall or a wide body seen as LiDAR points). So a group of
posts is one encounter, a walker being overtaken is one encounter for as long as it is being overtaken.

**Re-identification at every update** (the obstacles change: tracks get new ids after an occlusion, wall points
slide along a wall as the robot moves). An obstacle belongs to an open encounter when

* it is a track (id >= 0) whose id is one of the encounter's track ids at its last sighting, or
* it lies within ``gate_m`` (0.5 m) of a member's *predicted* position (its last position moved on with its last
  velocity, ``eq:obs_prop`` (2)): a new track within the gate of the lost one's predicted position inherits its
  encounter; wall points (id -1, not tracked) are joined the same way.

The encounter's members then become the union of the groups of the obstacles that belong to it (a wall's newly
seen points join through their group). When the relevant obstacle's group overlaps several open encounters, they
merge into the oldest (which keeps a committed side: its own, else the first committed one's).

**An encounter ends** when it is *behind* the robot: every member's projection on the robot's goal direction d_g
(``eq:goal_basis`` (9)) is behind the robot by its clearance, (p_m - p) . d_g < -(r_R + r_m + d0); or when it is
*lost*: none of its members has been seen for ``lost_s`` (1 s). The *current* encounter is the relevant obstacle's
encounter, or, while no obstacle is in the way (e.g. during the pass, once the robot has moved beside it), the last
current one until it ends.

**Commitment** (the rule, :class:`~bigcbf.control.selection.BehaviorSelector`): the first left or right mode
(PASS-L/SIDE-L or PASS-R/SIDE-R) selected during an encounter commits it to that side; while the current
encounter is committed, the opposite side's modes are not candidates (GOAL and YIELD remain). The commitment is
released when every candidate on the committed side fails the safety test of ``eq:behavior_acceptance`` (22) at
``commit_release_selections`` consecutive selections (K = 5, 2.5 s at T_B = 0.5 s; a selection at which the side
passes again takes one back, so alternating rejections release it too), and at the end of the encounter, and, as COMPASS (kjungmo/compass) lets a challenger class win, when the evidence for the other side
(:func:`accumulate_evidence`, a leaky sum of its cost advantage) reaches ``commit_evidence_js``: a side that is
safe but leads nowhere (a wall beside a doorway) is given up when the other side stays clearly better for a while,
not for a one-selection advantage (the flips measured in issue 25 were one about every second).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..params.stack import PlusRules, StackParams
from ..types import Obstacles
from .behaviors import goal_basis, obstacle_groups, relevant_obstacle
from .liveness import mode_side

EVIDENCE_LEAK = 0.7   # lambda: the share of the evidence kept from one selection to the next [-]
EVIDENCE_MAX = 10.0   # e_max: the evidence is clipped to [0, e_max] [J s]
EVIDENCE_CAP = 1.0    # D - D_floor counts at most this much per selection [J] (COMPASS's costs are normalized)
GATE_M = 0.5     # a new obstacle within this of a member's predicted position belongs to its encounter [m]
LOST_S = 1.0     # an encounter none of whose members was seen for this long ends [s]


@dataclass
class Encounter:
    """One encounter (module docstring). ``side``: the committed side (+1 left, -1 right, 0 none); ``blocked``: the
    consecutive selections at which every candidate on ``side`` failed the safety test."""

    key: int
    t_start: float
    t_seen: float
    ids: frozenset                       # track ids (>= 0) of its members at the last sighting
    p: np.ndarray                        # (K, 2) member positions at the last sighting [m]
    v: np.ndarray                        # (K, 2) their velocities [m/s]
    r: np.ndarray                        # (K,) their radii [m]
    side: int = 0
    blocked: int = 0
    evidence: float = 0.0

    def predicted(self, t: float) -> np.ndarray:
        """The members' positions predicted to time t (constant velocity, ``eq:obs_prop`` (2))."""
        return self.p + self.v * max(t - self.t_seen, 0.0)


def accumulate_evidence(evidence: float, advantage: float, params: StackParams) -> float:
    """COMPASS's leaky evidence (kjungmo/compass, Sec. "Accumulating Evidence"), per selection:
    e <- clip(lambda e + min(D - D_floor, D_cap) T_B, 0, e_max), D = J_keep - J_other the other side's advantage
    in ``eq:behavior_cost`` (14) (the best viable mode the commitment allows against the best of the other side),
    D_floor = w_sw (a side flip undoes a maneuver: it is charged as a second switch), lambda = ``EVIDENCE_LEAK``,
    D_cap = ``EVIDENCE_CAP``. COMPASS normalizes its costs to [0, 1]; J is not normalized, and next to an obstacle
    W of ``eq:analytic_workload`` (24) makes single selections' D jump by 5-10 (traced while overtaking a slow
    walker in a 2 m corridor), so the cap makes the evidence a matter of time: with T_B = 0.5 s, at most 0.5 per
    selection, 0.5, 0.85, 1.10, 1.27, ... (limit 1.67) over consecutive selections; 1.2 takes four in a row (2 s).
    A constant advantage D reaches a threshold E only if min(D - w_sw, D_cap) T_B / (1 - lambda) > E."""
    e = EVIDENCE_LEAK * evidence + min(advantage - params.w_sw, EVIDENCE_CAP) * params.T_B_s   # D = inf: the cap
    return float(min(max(e, 0.0), EVIDENCE_MAX))


#: |e| below this: the person walks on the robot's goal line and neither side is preferred (the scores decide) [m]
MEETING_BAND_M = 0.1
#: a person within this angle of the goal line's axis walks along the path (head-on or ahead) [rad]
MEETING_AXIS_RAD = math.pi / 6


def meeting_side(p, goal, obstacles: Obstacles, params: StackParams) -> int:
    """The rule ``meeting_side`` (``PlusRules``): the side (+1 left, -1 right, 0 none) away from the nearest person
    who walks along the robot's path and will meet it soon. With d_g, n_g of ``eq:goal_basis`` (9), a tracked
    obstacle i (id >= 0) counts when it moves at ``cbf_velocity_min_speed_mps`` or more within ``MEETING_AXIS_RAD``
    of the d_g axis (head-on, or ahead in the robot's direction), is ahead, s_i = (p_i - p) . d_g > 0, and closes on
    the robot moving at v_max along d_g within two imagination horizons, s_i <= 2 N dt (v_max - v_i . d_g). Its
    lateral offset e_i = (p_i - p) . n_g (its current one: a walker along a path keeps its line, and the lateral
    velocity of a track is its noisiest part) decides for the nearest such person in s_i: -sign(e_i) when
    |e_i| >= ``MEETING_BAND_M``, else 0.

    Why (measured in docs/fidelity.md): the imagination's horizon (N dt = 1.5 s) ends before a head-on meeting
    that is 2 s away, so the first side is picked by differences that have nothing to do with the person (in a 2 m
    corridor, the two SIDE rollouts' wall terms), and the commitment rules then keep it; on the nine, every one of
    big-cbf-plus's corridor meetings with infeasible filter steps had first sidestepped toward the person."""
    M = len(obstacles)
    if not M:
        return 0
    p = np.asarray(p, float).reshape(2)
    d_g, n_g, dist = goal_basis(p, goal)
    if dist <= 0.0:
        return 0
    rel = obstacles.p - p
    s = rel @ d_g
    e = rel @ n_g
    v_al = obstacles.v @ d_g
    speed = np.hypot(obstacles.v[:, 0], obstacles.v[:, 1])
    along = np.abs(v_al) >= speed * math.cos(MEETING_AXIS_RAD)
    closing = params.v_max_mps - v_al
    horizon = 2.0 * params.N * params.dt_s
    ok = ((obstacles.ids >= 0) & (speed >= params.cbf_velocity_min_speed_mps) & along & (s > 0)
          & (closing > 0) & (s <= horizon * closing))
    if not ok.any():
        return 0
    k = int(np.flatnonzero(ok)[np.argmin(s[ok])])
    return 0 if abs(float(e[k])) < MEETING_BAND_M else -int(np.sign(e[k]))


class EncounterTracker:
    """The open encounters and the current one (module docstring). ``rules`` gives the relevant obstacle's
    look-ahead and band (``behaviors.relevant_obstacle``)."""

    def __init__(self, params: StackParams, rules: PlusRules | None = None, *, gate_m: float = GATE_M,
                 lost_s: float = LOST_S):
        self.params = params
        self.rules = PlusRules() if rules is None else rules
        self.gate_m = float(gate_m)
        self.lost_s = float(lost_s)
        self.reset()

    def reset(self) -> None:
        self.open: list[Encounter] = []
        self.current: Encounter | None = None
        self.opened = 0                  # encounters opened so far

    def _members(self, enc: Encounter, t: float, obstacles: Obstacles) -> np.ndarray:
        """(M,) bool: the current obstacles that belong to ``enc`` (same track id, or within the gate of a member's
        predicted position)."""
        same_id = np.isin(obstacles.ids, list(enc.ids)) & (obstacles.ids >= 0)
        pred = enc.predicted(t)
        d = np.hypot(*(obstacles.p[:, None, :] - pred[None, :, :]).transpose(2, 0, 1))     # (M, K)
        return same_id | (d.min(axis=1) < self.gate_m)

    def _set_members(self, enc: Encounter, t: float, obstacles: Obstacles, sel: np.ndarray) -> None:
        enc.t_seen = t
        enc.ids = frozenset(int(i) for i in obstacles.ids[sel] if i >= 0)
        enc.p, enc.v, enc.r = obstacles.p[sel].copy(), obstacles.v[sel].copy(), np.asarray(obstacles.r)[sel].copy()

    def _behind(self, enc: Encounter, t: float, p: np.ndarray, d_g: np.ndarray) -> bool:
        unc = self.params.uncertainty
        s = (enc.predicted(t) - p) @ d_g
        return bool(np.all(s < -(unc.r_robot_m + enc.r + unc.d0_m)))

    def update(self, t: float, p, goal, obstacles: Obstacles) -> Encounter | None:
        """Re-identify the open encounters in ``obstacles``, open one for the relevant obstacle if needed, end the
        ones behind the robot or lost; returns the current encounter (None: none)."""
        p = np.asarray(p, float).reshape(2)
        d_g, _, _ = goal_basis(p, goal)
        M = len(obstacles)
        groups = obstacle_groups(obstacles.p, obstacles.r, self.params) if M else np.zeros(0, int)
        belongs = {}
        for enc in self.open:                                  # re-identification
            sel = self._members(enc, t, obstacles) if M else np.zeros(0, bool)
            if sel.any():
                sel = np.isin(groups, groups[sel])             # the whole groups of what belongs to it
                self._set_members(enc, t, obstacles, sel)
                belongs[enc.key] = sel
        j = relevant_obstacle(p[None], d_g[None], obstacles.p, obstacles.r, self.params, self.rules)[0][0] if M else -1
        if j >= 0:
            hits = [e for e in self.open if e.key in belongs and belongs[e.key][j]]
            if hits:
                self.current = self._merge(hits, t, obstacles, groups == groups[j])
            else:
                self.current = Encounter(self.opened, t, t, frozenset(), np.zeros((0, 2)), np.zeros((0, 2)),
                                         np.zeros(0))
                self._set_members(self.current, t, obstacles, groups == groups[j])
                self.open.append(self.current)
                self.opened += 1
        keep = []
        for enc in self.open:
            if self._behind(enc, t, p, d_g) or t - enc.t_seen > self.lost_s:
                if enc is self.current:
                    self.current = None
            else:
                keep.append(enc)
        self.open = keep
        return self.current

    def _merge(self, hits: list[Encounter], t: float, obstacles: Obstacles, sel: np.ndarray) -> Encounter:
        """Several open encounters overlap the relevant obstacle's group: the oldest absorbs the others."""
        hits = sorted(hits, key=lambda e: e.key)
        keep = hits[0]
        if len(hits) > 1:
            if keep.side == 0:
                committed = [e for e in hits if e.side != 0]
                cur = [e for e in committed if e is self.current]
                keep.side = (cur or committed or [keep])[0].side
            self.open = [e for e in self.open if e not in hits[1:]]
        self._set_members(keep, t, obstacles, sel | self._members(keep, t, obstacles))
        return keep


class EncounterSideRecorder:
    """The metric ``switches_per_encounter`` of an episode (README, metrics glossary), for a method with sided modes
    (PASS-L/SIDE-L left, PASS-R/SIDE-R right: ``liveness.mode_side``). At every planning cycle: the current encounter
    (:class:`EncounterTracker` with ``big-cbf-plus``'s default look-ahead and band, whatever the method, so every
    method is measured against the same encounters) and the method's mode. A *side switch* is a change between left
    and right among the sided modes selected while the same encounter is current (neutral modes in between do not
    reset it); an encounter counts once a sided mode was selected during it. ``encounters`` and
    ``encounter_side_switches`` are counts; ``switches_per_encounter`` is their ratio (0.0 with no encounter)."""

    def __init__(self, params: StackParams):
        self.tracker = EncounterTracker(params, PlusRules())
        self.last_side: dict[int, int] = {}
        self.switches = 0
        self._mode: str | None = None

    def add(self, t: float, state, obstacles: Obstacles, goal, mode: str, planned: bool = True) -> None:
        """One control step. The tracker is updated at the steps that ran a planning cycle (``planned``; BIG-CBF's
        selections, every T_B, where its mode can change, as its own tracker is) and whenever the mode changed;
        other steps are skipped (updating at every control step cost 0.4 ms a step)."""
        if not planned and mode == self._mode:
            return
        self._mode = mode
        enc = self.tracker.update(t, (state.px, state.py), goal, obstacles)
        s = mode_side(mode)
        if enc is None or s == 0:
            return
        prev = self.last_side.get(enc.key)
        self.switches += prev is not None and prev != s
        self.last_side[enc.key] = s

    def metrics(self) -> dict:
        n = len(self.last_side)
        return dict(encounters=n, encounter_side_switches=int(self.switches),
                    switches_per_encounter=self.switches / n if n else 0.0)


#: EpisodeResult's fields for a method without sided modes: not applicable
NO_SIDES = dict(encounters=None, encounter_side_switches=None, switches_per_encounter=None)
