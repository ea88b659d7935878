"""The six feedback behaviors of BIG-CBF and the reverse-release fallback (eq:online_behavior_command, eq:goal_basis,
eq:behavior_subgoals, eq:behavior_feedback).

Modes: GOAL, PASS-L, PASS-R, SIDE-L, SIDE-R, YIELD (the behavior set B), plus REVERSE, the fallback used when every
regular behavior is rejected. A policy maps (robot position, obstacles, goal) to a world-frame translational velocity
v_b (eq:behavior_feedback); the body command is u = [R(theta)^T v_b, 0]: the behaviors are purely translational
(holonomic base, 360 degree LiDAR), yaw is not commanded.

Choices the paper leaves open, one each (``big-cbf``, every rule of ours off; docs/fidelity.md, "paper silent"):

* Locally relevant obstacle i of eq:behavior_subgoals (10): seen from the robot along the goal direction d_g, with
  along-track distance s_i = (p_i - p).d_g and cross-track offset c_i = (p_i - p).n_g, it is the nearest (smallest
  s_i) obstacle that is not yet behind the robot (s_i > -(r_R + r_i)), within the look-ahead (s_i - r_i < v_max N dt,
  the distance the imagination's horizon covers at full speed: 1.2 m with Table I) and in the way: |c_i| < r_R + r_i
  + d0, i.e. driving straight to the goal would violate eq:true_safety_requirement (6). Wall points (radius 0) take
  part like any obstacle (walls: no other handling).
* d_pass of eq:behavior_subgoals (10), "the minimum lateral passing offset": a constant, ``d_pass_min_m`` = 0.30 m
  (below the floor r_R + r_i + 0.35 >= 0.50 m, so the floor decides); PASS's forward component is the paper's 0.85 m.

Our rules beyond the paper (``big-cbf-plus``, switches of :class:`~bigcbf.params.stack.PlusRules`):

* ``in_way_band`` (0.15 m beyond r_R + r_i + d0) and ``fixed_lookahead`` (3 m): the relevant obstacle as it was
  before issue 24. (With d_pass_min, 0.30 m, as the band, both posts beside a 1 m gap were "in the way" of a robot
  centred in it, and PASS steered around the outside of one of them, into it: docs/fidelity.md.)
* ``pass_forward_beside``: the forward component of PASS's subgoal, for a relevant obstacle alone in
  its group (one the footprint can pass on either side: a post, a person), its along-track distance s_i when that
  is farther (g = p + max(0.85, s_i) d_g + sigma max(d_pass, ...) n_g): the pass aims at the point beside the
  obstacle. With 0.85 m the pass dives at 45 degrees or more whatever the distance, which clips whatever stands
  between the robot and a farther post (the posts of the row it is passing through). A group (a wall, a wide body
  seen as LiDAR points) keeps the paper's 0.85 m: the pass around a group's end must turn early, and aiming beside
  a 2.7 m wide obstacle's face 3 m ahead made the pass too shallow to clear its end (required_sidestepping: 5 of
  50 seeds timed out where 1 had).
* ``pass_group_reach``: d_pass per side sigma, the lateral shift that puts the robot's footprint, with
  eq:behavior_subgoals's 0.35 m clearance, beside the relevant obstacle's *group* on side sigma, d_pass =
  max(d_pass_min, max_{j in G(i)} (sigma c_j + r_j) + r_R + 0.35). The group G(i) is the set of obstacles connected to i
  by gaps the robot cannot pass through (gap < 2 (r_R + d0) + 0.1 m; see :func:`obstacle_groups`). The paper's scenes
  are circles, where G(i) = {i} and the offset is max(d_pass_min, sigma c_i + r_i + r_R + 0.35), i.e.
  eq:behavior_subgoals's floor r_R + r_i + 0.35 for an obstacle dead ahead, widened for one offset towards side sigma. A
  LiDAR sees a wide obstacle or a wall as many points of radius 0: without the group, PASS would aim 0.5 m beside the
  nearest point of a 2.5 m wide obstacle; with it, PASS aims past the structure's end on its side.
* ``release_fan``, ``release_sideways``: the REVERSE release (below).

Both:

* Without a relevant obstacle there is nothing to pass: PASS-sigma keeps only its goal-directed component
  (g = p + 0.85 d_g), so a robot that has completed a pass heads for the goal instead of drifting sideways; a
  PASS mode and GOAL then differ only near the goal, where the selection prefers GOAL (PASS overshoots).
* YIELD (zero command) is a candidate only while a dynamic obstacle is tracked ("YIELD intentionally suppresses
  movement when dynamic obstacles are present"); in a static scene standing still would never resolve anything.
* Inside the goal region (eq:goal_region, ||p - p_g|| <= eps_g) every policy commands zero.
* REVERSE (reverse-release fallback): a constant world-frame release velocity ``release_v`` chosen by the
  imagination when the fallback is invoked (:func:`bigcbf.control.imagination.choose_release`). The paper's
  "predefined reverse-release fallback" (one choice, ``big-cbf``) is the *push*: move at ``v_release_mps`` away
  from the obstacles closer than r_R + r_i + d0 + ``release_range_m``, along p - p_i, weighted by how deep they are
  inside that range; if none is that close (or their pushes cancel), straight back away from the goal. With the
  rule ``release_fan`` it is chosen from a fan of candidates: the push, straight back from the goal, seven more
  headings 45 degrees apart around it, all at ``v_release_mps``, and standing still. With the rule
  ``release_sideways``, "away" from a moving obstacle (speed above ``RELEASE_MOVING_MPS``) means out of its
  path, perpendicular to its velocity (to the side the robot is already on; to the obstacle's right when
  exactly on its path). With the rule ``release_ahead`` an obstacle pushes by where it comes within the
  imagination's horizon (:func:`closest_approach_c`), not by where it is now. The push alone is myopic: in the blind corner it backed the robot off a wall corner
  into the path of the person it was releasing from, and the hard CBF then chased it down a side corridor
  ahead of the person for 8 s.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..params.stack import PAPER_RULES, PlusRules, StackParams
from ..types import Obstacles, RobotState
from . import kernels
from .jit import kernel

BEHAVIORS: tuple[str, ...] = ("GOAL", "PASS-L", "PASS-R", "SIDE-L", "SIDE-R", "YIELD")
REVERSE = "REVERSE"
MODES: tuple[str, ...] = BEHAVIORS + (REVERSE,)
MODE_INDEX = {m: i for i, m in enumerate(MODES)}

# eq:behavior_subgoals coefficients per mode index (GOAL, PASS-L, PASS-R, SIDE-L, SIDE-R, YIELD, REVERSE)
FORWARD_M = np.array([0.0, 0.85, 0.85, 0.45, 0.45, 0.0, 0.0])   # along d_g [m]
SIGMA = np.array([0.0, 1.0, -1.0, 1.0, -1.0, 0.0, 0.0])         # +1 left, -1 right
IS_GOAL = np.array([True, False, False, False, False, False, False])
IS_PASS = np.array([False, True, True, False, False, False, False])
IS_SIDE = np.array([False, False, False, True, True, False, False])
SIDE_LATERAL_M = 0.80          # eq:behavior_subgoals SIDE lateral offset [m]
PASS_EXTRA_M = 0.35            # eq:behavior_subgoals PASS floor r_R + r_i + 0.35 [m]
GAIN_NEAR_PER_S = 2.0          # eq:behavior_feedback (2 1/s) ||e_b||
GAIN_LIN_PER_S = 0.35          # eq:behavior_feedback (0.35 1/s) e_b
_TINY = 1e-12
RELEASE_MOVING_MPS = 0.2       # obstacles faster than this are released from sideways (see REVERSE above)
# what the compiled policy does per mode index: GOAL heads for p_g, PASS uses the relevant obstacle, FIXED (SIDE,
# YIELD) a fixed subgoal in the goal basis, REVERSE the fallback's velocity
GOAL_KIND, PASS_KIND, FIXED_KIND, REVERSE_KIND = 0, 1, 2, 3
KIND = np.array([GOAL_KIND, PASS_KIND, PASS_KIND, FIXED_KIND, FIXED_KIND, FIXED_KIND, REVERSE_KIND])
LATERAL_M = np.where(IS_SIDE, SIDE_LATERAL_M * SIGMA, 0.0)     # SIDE's lateral offset along n_g [m], 0 otherwise


def speed_limits(params: StackParams) -> np.ndarray:
    """v_b^max per mode index [m/s] (eq:behavior_feedback): 0.8 for GOAL/PASS, 0.55 for SIDE, 0 for YIELD, release
    speed."""
    v, vs = params.v_max_mps, params.v_side_mps
    return np.array([v, v, v, vs, vs, 0.0, params.v_release_mps])


def mode_indices(modes) -> np.ndarray:
    return np.array([MODE_INDEX[m] for m in modes], dtype=int)


def goal_basis(p, goal) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """eq:goal_basis: d_g = (p_g - p)/||p_g - p||, n_g = [-d_g,y, d_g,x] (left normal). Returns d_g, n_g (..., 2) and
    the distance ||p_g - p|| (...). At the goal itself d_g = 0."""
    e = np.asarray(goal, float) - np.asarray(p, float)
    dist = np.hypot(e[..., 0], e[..., 1])
    d = e / np.maximum(dist, _TINY)[..., None]
    n = np.stack([-d[..., 1], d[..., 0]], -1)
    return d, n, dist


def obstacle_groups(obs_p, obs_r, params: StackParams) -> np.ndarray:
    """Group labels (M,): obstacles i, j are connected when the gap between them, ||p_i - p_j|| - r_i - r_j, is
    smaller than 2 (r_R + d0) + 0.1 m (the robot's footprint with its base clearance cannot pass between them);
    groups are the connected components, labelled in the order of their lowest member (as
    ``scipy.sparse.csgraph.connected_components`` labels them; compiled: :func:`_components`)."""
    p = np.asarray(obs_p, float).reshape(-1, 2)
    if len(p) <= 1:
        return np.zeros(len(p), int)
    r = np.asarray(obs_r, float)
    unc = params.uncertainty
    gap = np.hypot(*(p[:, None, :] - p[None, :, :]).transpose(2, 0, 1)) - r[:, None] - r[None, :]
    labels = np.empty(len(p), np.int32)
    _components(gap < 2 * (unc.r_robot_m + unc.d0_m) + 0.1, labels)
    return labels


@kernel
def _components(adj, labels):
    """Connected components of the symmetric adjacency ``adj`` (M, M) into ``labels``: nodes in index order, each
    unlabelled one starts the next label and a depth-first search gives it to its component."""
    M = adj.shape[0]
    labels[:] = -1
    stack = np.empty(M, np.int64)
    nxt = 0
    for v in range(M):
        if labels[v] >= 0:
            continue
        labels[v] = nxt
        top = 0
        stack[0] = v
        while top >= 0:
            u = stack[top]
            top -= 1
            for w in range(M):
                if adj[u, w] and labels[w] < 0:
                    labels[w] = nxt
                    top += 1
                    stack[top] = w
        nxt += 1


def alone_in_group(groups) -> np.ndarray:
    """(M,) bool: obstacle i is the only member of its group (:func:`obstacle_groups`), one the footprint can pass
    on either side; PASS aims beside such an obstacle (module docstring)."""
    groups = np.asarray(groups, int)
    return np.bincount(groups)[groups] == 1 if len(groups) else np.zeros(0, bool)


# ------------------------------------------------------------------------------------------------------------------
# The policies pi_b, compiled (numba, jit.kernel): one implementation. The execution loop (behavior_command, every
# control tick) and the imagination's rollout (imagination._rollout, every imagined step, all candidates at once)
# both evaluate them through PolicyData.velocity, i.e. _policy_rows; subgoal_error, relevant_obstacle and
# feedback_velocity run the same kernels, one term each. The arithmetic keeps the order of the numpy formulation
# of the execution path it replaced (d_g = e / ||e||, s_i - r_i < range, max(0.85, s_i), the saturation of
# eq:behavior_feedback (11) as a magnitude): the commands executed are the bits they were (checked on 3000 random
# scenes when it was introduced, issue 22), while the rollout, which had its own algebraically rearranged copy,
# now imagines exactly the command the robot gets (tests/control/test_control_policy.py).

_outside_goal_region = kernel(kernels.outside_goal_region)      # eq:goal_region (5), compiled once more


@kernel
def _basis(px, py, goal):
    """eq:goal_basis (9) for a robot at (px, py): e = p_g - p, ||e||, d_g = e / ||e|| (0 at the goal itself);
    n_g = (-d_g,y, d_g,x)."""
    ex, ey = goal.real - px, goal.imag - py
    dist = math.hypot(ex, ey)
    return ex, ey, dist, ex / max(dist, _TINY), ey / max(dist, _TINY)


@kernel
def _track(z, px, py, dx, dy):
    """An obstacle at z seen from (px, py) in the goal basis: along-track s = (p_i - p).d_g and cross-track
    c = (p_i - p).n_g."""
    rx, ry = z.real - px, z.imag - py
    return rx * dx + ry * dy, rx * -dy + ry * dx


@kernel
def _relevant(px, py, dx, dy, obs_z, obs_r, geo):
    """eq:behavior_subgoals (10): the locally relevant obstacle (module docstring): its index (-1 for none), s_i and
    c_i (0 for none). The nearest in s_i wins, ties to the lower index. geo: :func:`policy_geometry` (the look-ahead
    geo[2] and the band geo[3] follow the rules' ``fixed_lookahead`` and ``in_way_band``)."""
    r_robot, d0, reach, band = geo[0], geo[1], geo[2], geo[3]
    j, s_j, c_j = -1, np.inf, 0.0
    for m in range(obs_r.shape[0]):
        s, c = _track(obs_z[m], px, py, dx, dy)
        r = obs_r[m]
        if s > -(r_robot + r) and s - r < reach and abs(c) < r_robot + r + d0 + band and s < s_j:
            j, s_j, c_j = m, s, c
    return j, (s_j if j >= 0 else 0.0), c_j


@kernel
def _pass_offset(sigma, px, py, dx, dy, j, obs_z, obs_r, groups, geo):
    """eq:behavior_subgoals (10) lateral PASS offset max(d_pass, r_R + r_j + 0.35) [m] around relevant obstacle j.
    The paper's (rule ``pass_group_reach`` off, geo[6] = 0): d_pass = d_pass_min, a constant. With the rule:
    d_pass = max(d_pass_min, extent + r_R + 0.35), the extent being how far j's group reaches towards side sigma,
    max over m in G(j) of sigma c_m + r_m (module docstring)."""
    if geo[6] == 0.0:
        return max(geo[4], geo[0] + obs_r[j] + PASS_EXTRA_M)
    extent = -np.inf
    for m in range(obs_r.shape[0]):
        if groups[m] == groups[j]:
            extent = max(extent, sigma * _track(obs_z[m], px, py, dx, dy)[1] + obs_r[m])
    r_robot = geo[0]
    return max(max(geo[4], extent + r_robot + PASS_EXTRA_M), r_robot + obs_r[j] + PASS_EXTRA_M)


@kernel
def _subgoal(kind, forward, lateral, sigma, px, py, ex, ey, dx, dy, obs_z, obs_r, groups, alone, geo):
    """eq:behavior_subgoals (10): e_b = g_b - p of one row (:func:`subgoal_error`); e = p_g - p and d_g from
    :func:`_basis`."""
    if kind == GOAL_KIND:
        return ex, ey
    if kind == PASS_KIND:
        j, s_j, _ = _relevant(px, py, dx, dy, obs_z, obs_r, geo)
        offset = 0.0
        if j >= 0:
            offset = _pass_offset(sigma, px, py, dx, dy, j, obs_z, obs_r, groups, geo)
            if geo[7] != 0.0 and alone[j]:   # rule pass_forward_beside, a lone obstacle: forward max(0.85, s_i)
                forward = max(forward, s_j)
        lateral = sigma * offset
    return forward * dx + lateral * -dy, forward * dy + lateral * dx


@kernel
def _feedback(ex, ey, v_max):
    """eq:behavior_feedback (11) for one row: both terms are parallel to e, so v = e/||e|| min(v_max, min(v_max,
    2||e||) + 0.35||e||)."""
    n = math.hypot(ex, ey)
    k = min(min(v_max, GAIN_NEAR_PER_S * n) + GAIN_LIN_PER_S * n, v_max) / max(n, _TINY)
    return ex * k, ey * k


@kernel
def _row_subgoal(b, kind, coef, pz, goal, obs_z, obs_r, groups, alone, geo):
    """Row b's subgoal error e_b (eq:goal_basis (9), eq:behavior_subgoals (10), :func:`_subgoal`) and its distance
    to the goal ||p_g - p||. coef (4, B): forward, SIDE lateral, sigma, v_b^max (:func:`mode_rows`)."""
    px, py = pz[b].real, pz[b].imag
    ex, ey, dist, dx, dy = _basis(px, py, goal)
    sx, sy = _subgoal(kind[b], coef[0, b], coef[1, b], coef[2, b], px, py, ex, ey, dx, dy, obs_z, obs_r, groups,
                      alone, geo)
    return sx, sy, dist


@kernel
def _policy_rows(kind, coef, pz, goal, obs_z, obs_r, groups, alone, release, geo, out):
    """pi_b of every row b into ``out`` (B,) complex world velocities [m/s]: zero inside the goal region
    (eq:goal_region (5)), ``release[b]`` for a REVERSE row, else eq:behavior_feedback (11) towards the subgoal of
    eq:behavior_subgoals (10)."""
    for b in range(pz.shape[0]):
        sx, sy, dist = _row_subgoal(b, kind, coef, pz, goal, obs_z, obs_r, groups, alone, geo)
        if not _outside_goal_region(dist, geo[5]):
            out[b] = 0j
        elif kind[b] == REVERSE_KIND:
            out[b] = release[b]
        else:
            vx, vy = _feedback(sx, sy, coef[3, b])
            out[b] = complex(vx, vy)


@kernel
def _subgoal_rows(kind, coef, pz, goal, obs_z, obs_r, groups, alone, geo, out):
    """:func:`_subgoal` of every row into ``out`` (B, 2)."""
    for b in range(pz.shape[0]):
        out[b, 0], out[b, 1], _ = _row_subgoal(b, kind, coef, pz, goal, obs_z, obs_r, groups, alone, geo)


@kernel
def _relevant_rows(pz, dz, obs_z, obs_r, geo, out_j, out_c):
    """:func:`_relevant` of every row (robot pz[b], direction d_g = dz[b]) into out_j, out_c."""
    for b in range(pz.shape[0]):
        out_j[b], _, out_c[b] = _relevant(pz[b].real, pz[b].imag, dz[b].real, dz[b].imag, obs_z, obs_r, geo)


@kernel
def _feedback_rows(e, v_max, out):
    """:func:`_feedback` of every row of e (B, 2) into ``out`` (B, 2)."""
    for b in range(e.shape[0]):
        out[b] = _feedback(e[b, 0], e[b, 1], v_max[b])


def _planar(a) -> np.ndarray:
    """Real 2-vectors (..., 2) as complex numbers x + i y (exact)."""
    a = np.asarray(a, float)
    return a[..., 0] + 1j * a[..., 1]


def mode_rows(mode_idx, params: StackParams) -> tuple[np.ndarray, np.ndarray]:
    """The per-row constants of the compiled policy for mode indices (B,): kind (B,) and coef (4, B) = the
    eq:behavior_subgoals (10) forward [m] and SIDE lateral [m] offsets, sigma, v_b^max of eq:behavior_feedback (11)
    [m/s]."""
    mode_idx = np.asarray(mode_idx, int).reshape(-1)
    coef = np.stack([FORWARD_M[mode_idx], LATERAL_M[mode_idx], SIGMA[mode_idx], speed_limits(params)[mode_idx]])
    return KIND[mode_idx], np.ascontiguousarray(coef)


def lookahead_m(params: StackParams, rules: PlusRules = PAPER_RULES) -> float:
    """How far ahead the locally relevant obstacle is looked for [m] (its surface, s_i - r_i): the distance the
    imagination's horizon covers at full speed, v_max N dt (paper silent; 1.2 m with Table I), or the rule
    ``fixed_lookahead``'s ``relevant_range_m``."""
    return rules.relevant_range_m if rules.fixed_lookahead else params.v_max_mps * params.N * params.dt_s


def in_way_band_m(rules: PlusRules = PAPER_RULES) -> float:
    """The band beyond r_R + r_i + d0 within which an obstacle is "in the way" of the goal line [m]: 0 (paper
    silent: the clearance of eq:true_safety_requirement (6)), or the rule ``in_way_band``'s ``in_way_margin_m``."""
    return rules.in_way_margin_m if rules.in_way_band else 0.0


def policy_geometry(params: StackParams, rules: PlusRules = PAPER_RULES) -> np.ndarray:
    """The geometry and switches the compiled policy reads (8,): r_R, d0, the look-ahead (:func:`lookahead_m`), the
    in-the-way band (:func:`in_way_band_m`), d_pass_min_m, eps_g_m [m], and the rules ``pass_group_reach`` and
    ``pass_forward_beside`` (1.0 on, 0.0 off)."""
    unc = params.uncertainty
    return np.array([unc.r_robot_m, unc.d0_m, lookahead_m(params, rules), in_way_band_m(rules),
                     params.d_pass_min_m, params.eps_g_m, float(rules.pass_group_reach),
                     float(rules.pass_forward_beside)])


def relevant_obstacle(p, d_g, obs_p, obs_r, params: StackParams, rules: PlusRules = PAPER_RULES):
    """The locally relevant obstacle of eq:behavior_subgoals (10) for each row (see the module docstring).

    p, d_g (B, 2) (d_g from :func:`goal_basis`); obs_p (M, 2); obs_r (M,). Returns (index (B,) with -1 for none,
    c_i (B,), r_i (B,)), c_i = (p_i - p).n_g and r_i being 0 where there is none."""
    p = np.atleast_2d(np.asarray(p, float))
    obs_r = np.asarray(obs_r, float).reshape(-1)
    j, c = np.empty(len(p), np.int64), np.empty(len(p))
    _relevant_rows(_planar(p), _planar(np.atleast_2d(d_g)), _planar(np.reshape(obs_p, (-1, 2))), obs_r,
                   policy_geometry(params, rules), j, c)
    return j, c, np.where(j >= 0, obs_r[np.maximum(j, 0)] if len(obs_r) else 0.0, 0.0)


def subgoal_error(mode_idx, p, goal, obs_p, obs_r, params: StackParams, groups=None,
                  rules: PlusRules = PAPER_RULES) -> np.ndarray:
    """eq:behavior_subgoals (10): e_b = g_b - p (B, 2) for each row's mode:
    GOAL p_g - p; PASS-sigma 0.85 d_g + sigma max(d_pass, r_R + r_i + 0.35) n_g (0.85 d_g without a relevant
    obstacle; with the rule ``pass_forward_beside`` max(0.85, s_i) d_g beside a lone obstacle, s_i its along-track
    distance, and with ``pass_group_reach`` d_pass from the group's reach, see the module docstring);
    SIDE-sigma 0.45 d_g + 0.80 sigma n_g;
    YIELD 0. (REVERSE rows get 0; their velocity comes from :func:`release_velocity`.)
    ``groups``: labels from :func:`obstacle_groups` (computed here when not given)."""
    p = np.atleast_2d(np.asarray(p, float))
    data = PolicyData.build(mode_idx, goal, obs_p, obs_r, params, groups=groups, rules=rules)
    out = np.empty((len(p), 2))
    _subgoal_rows(data.kind, data.coef, _planar(p), data.goal, _planar(np.reshape(obs_p, (-1, 2))), data.obs_r,
                  data.groups, data.alone, data.geometry, out)
    return out


def feedback_velocity(e, v_max) -> np.ndarray:
    """eq:behavior_feedback (11): v_b = sat_{v_max}[ e/||e|| min(v_max, 2||e||) + 0.35 e ] (world frame, m/s).

    Both terms are parallel to e, so v_b = e/||e|| min(v_max, min(v_max, 2||e||) + 0.35||e||). e (B, 2), v_max (B,).
    """
    e = np.ascontiguousarray(np.atleast_2d(np.asarray(e, float)))
    out = np.empty_like(e)
    _feedback_rows(e, np.ascontiguousarray(np.broadcast_to(np.asarray(v_max, float), len(e))), out)
    return out


def release_directions_c(qz: np.ndarray, obs_vz: np.ndarray | None) -> np.ndarray:
    """:func:`release_directions` on complex planar vectors: qz (B, M) = p - p_i, obs_vz (M,) -> (B, M)."""
    n = qz / np.maximum(np.abs(qz), _TINY)
    if obs_vz is None:
        return n
    speed = np.abs(obs_vz)
    right = -1j * obs_vz / np.maximum(speed, _TINY)            # the obstacle's right-hand normal (unit)
    lateral = qz.real * right.real + qz.imag * right.imag
    side = np.where(lateral >= 0, right, -right)
    return np.where(speed > RELEASE_MOVING_MPS, side, n)


def release_directions(q, obs_v) -> np.ndarray:
    """Unit directions (B, M, 2) in which to release from each obstacle: along q = p - p_i for a slow obstacle;
    for a moving one, perpendicular to its velocity, towards the robot's side of its path."""
    q = np.asarray(q, float)
    qz = q[..., 0] + 1j * q[..., 1]
    vz = None if obs_v is None else np.asarray(obs_v, float)[:, 0] + 1j * np.asarray(obs_v, float)[:, 1]
    d = release_directions_c(qz, vz)
    return np.stack([d.real, d.imag], -1)


def closest_approach_c(qz: np.ndarray, obs_vz: np.ndarray, horizon_s: float) -> np.ndarray:
    """The least distance [m] between a robot standing still and obstacles moving at constant velocity over the
    next ``horizon_s`` [s]: q(t) = qz - obs_vz t, t in [0, horizon_s]; qz (B, M) = p - p_i (complex), obs_vz (M,)
    complex [m/s] -> (B, M). A receding or static obstacle's is its distance now (the rule ``release_ahead``)."""
    vz = np.asarray(obs_vz, complex)[None]
    t = np.clip((qz.real * vz.real + qz.imag * vz.imag) / np.maximum(np.abs(vz) ** 2, _TINY), 0.0, horizon_s)
    return np.abs(qz - vz * t)


def release_velocity_c(pz, goal: complex, obs_z, obs_r, params: StackParams, obs_vz=None, ahead_vz=None,
                       ahead_s: float = 0.0) -> np.ndarray:
    """The reverse-release fallback's push velocity (module docstring) on complex planar vectors: robot positions
    pz (B,), goal p_g, obstacle positions obs_z (M,), radii (M,), velocities obs_vz (M,) or None -> (B,) [m/s].
    ``ahead_vz`` (M,) with ``ahead_s`` > 0 (the rule ``release_ahead``): an obstacle pushes by how deep its closest
    approach over the next ahead_s comes inside r_R + r_i + d0 + release_range_m (:func:`closest_approach_c`),
    not by where it is now."""
    unc = params.uncertainty
    g = goal - pz
    back = -g / np.maximum(np.abs(g), _TINY)                       # -d_g (0 at the goal itself)
    direction = back
    if len(obs_r):
        qz = pz[:, None] - obs_z[None]
        dist = (np.abs(qz) if ahead_vz is None or not ahead_s > 0
                else closest_approach_c(qz, ahead_vz, float(ahead_s)))
        w = np.maximum(unc.r_robot_m + np.asarray(obs_r, float)[None] + unc.d0_m + params.release_range_m
                       - dist, 0.0)
        if w.any():                     # (usually nothing is that close: skip the directions)
            push = (w * release_directions_c(qz, obs_vz)).sum(axis=1)
            npush = np.abs(push)
            direction = np.where(npush > 1e-9, push / np.maximum(npush, _TINY), back)
    return params.v_release_mps * direction


def release_velocity(p, goal, obs_p, obs_r, params: StackParams, obs_v=None, ahead_v=None,
                     ahead_s: float = 0.0) -> np.ndarray:
    """The reverse-release fallback's push velocity (B, 2) [m/s] (see the module docstring): positions p (B, 2),
    obstacles obs_p (M, 2), obs_r (M,), obs_v (M, 2) or None (the directions: sideways from movers), ahead_v (M, 2)
    or None with ahead_s (the rule ``release_ahead``: :func:`release_velocity_c`)."""
    v = release_velocity_c(_planar(np.atleast_2d(p)), complex(*np.asarray(goal, float).reshape(2)),
                           _planar(np.reshape(obs_p, (-1, 2))), obs_r, params,
                           None if obs_v is None else _planar(obs_v),
                           None if ahead_v is None else _planar(np.reshape(ahead_v, (-1, 2))), ahead_s)
    return np.stack([v.real, v.imag], -1)


@dataclass(frozen=True)
class PolicyData:
    """What an evaluation of the behavior policies pi_b needs besides where the robot and the obstacles are at that
    moment (the pattern of Nav2 MPPI's ``CriticData``: one bundle, built once, handed to every evaluation).

    The execution loop builds one per control tick (one row, the latest obstacles: eq:online_behavior_command (8));
    the imagination one per rollout (a row per candidate, the obstacle groups from the obstacles at k = 0) and
    evaluates it at every imagined step with the predicted obstacles O^k (eq:behavior_rollout (12)).
    """

    kind: np.ndarray                 # (B,) GOAL_KIND, PASS_KIND, FIXED_KIND or REVERSE_KIND (:func:`mode_rows`)
    coef: np.ndarray                 # (4, B) forward [m], SIDE lateral [m], sigma, v_b^max [m/s]
    goal: complex                    # p_g
    obs_r: np.ndarray                # (M,) radii [m]
    groups: np.ndarray               # (M,) int64 labels of :func:`obstacle_groups` (PASS reads them)
    alone: np.ndarray                # (M,) bool, :func:`alone_in_group`
    obs_vz: np.ndarray | None        # (M,) complex velocities [m/s] (the push), or None
    release: np.ndarray              # (B,) complex chosen REVERSE velocities [m/s] (0 where none or ``push``)
    push: bool                       # REVERSE rows without a chosen velocity: the push, at each evaluation
    geometry: np.ndarray             # (8,) :func:`policy_geometry`
    params: StackParams

    @classmethod
    def build(cls, mode_idx, goal, obs_p, obs_r, params: StackParams, *, groups=None, obs_v=None,
              release=None, rows=None, rules: PlusRules = PAPER_RULES) -> "PolicyData":
        """``mode_idx`` (B,); obstacles at the start obs_p (M, 2), obs_r (M,), obs_v (M, 2) or None; ``groups``
        (computed from obs_p when a PASS row needs them: the rules ``pass_group_reach`` or ``pass_forward_beside``);
        ``release``: a complex REVERSE velocity, one for all rows or one per row (None: the push, which reads obs_v
        only with the rule ``release_sideways``); ``rows``: :func:`mode_rows` of ``mode_idx`` when already at hand;
        ``rules``: our rules beyond the paper (:class:`~bigcbf.params.stack.PlusRules`; default every one off)."""
        kind, coef = mode_rows(mode_idx, params) if rows is None else rows
        obs_r = np.ascontiguousarray(obs_r, dtype=float).reshape(-1)
        if groups is None:
            grouped = rules.pass_group_reach or rules.pass_forward_beside
            groups = (obstacle_groups(obs_p, obs_r, params) if grouped and len(obs_r) and np.any(kind == PASS_KIND)
                      else np.zeros(len(obs_r), int))
        groups = np.ascontiguousarray(groups, dtype=np.int64)
        push = release is None and bool(np.any(kind == REVERSE_KIND))
        release = np.array(np.broadcast_to(np.asarray(0j if release is None else release, complex), kind.shape))
        return cls(kind, coef, complex(*np.asarray(goal, float).reshape(2)), obs_r, groups, alone_in_group(groups),
                   None if obs_v is None or not rules.release_sideways else _planar(obs_v), release, push,
                   policy_geometry(params, rules), params)

    def velocity(self, pz, obs_z) -> np.ndarray:
        """pi_b of every row as world-frame velocities (B,) complex [m/s] (eq:goal_basis (9), eq:behavior_subgoals
        (10), eq:behavior_feedback (11), zero inside eq:goal_region (5)) for robot positions pz (B,) complex and
        obstacle positions obs_z (M,) complex. REVERSE rows: ``release``, or the push from pz and obs_z."""
        pz = np.ascontiguousarray(pz, dtype=complex)
        obs_z = np.ascontiguousarray(obs_z, dtype=complex)
        release = (release_velocity_c(pz, self.goal, obs_z, self.obs_r, self.params, self.obs_vz) if self.push
                   else self.release)
        out = np.empty(len(pz), complex)
        _policy_rows(self.kind, self.coef, pz, self.goal, obs_z, self.obs_r, self.groups, self.alone, release,
                     self.geometry, out)
        return out


def policy_velocity(mode_idx, p, goal, obs_p, obs_r, params: StackParams, groups=None, obs_v=None,
                    release_v=None, rules: PlusRules = PAPER_RULES) -> np.ndarray:
    """The behavior policies pi_b as world-frame translational velocities (B, 2) [m/s] (eq:goal_basis (9),
    eq:behavior_subgoals (10), eq:behavior_feedback (11)), zero inside the goal region; REVERSE rows use the
    fallback: ``release_v`` (2,) when given, else the push. (:meth:`PolicyData.velocity` on real arrays.)"""
    p = np.atleast_2d(np.asarray(p, float))
    obs_p = np.reshape(np.asarray(obs_p, float), (-1, 2))
    release = None if release_v is None else complex(*np.asarray(release_v, float).reshape(2))
    data = PolicyData.build(mode_idx, goal, obs_p, obs_r, params, groups=groups, obs_v=obs_v, release=release,
                            rules=rules)
    v = data.velocity(_planar(p), _planar(obs_p))
    return np.stack([v.real, v.imag], -1)


def body_command(theta, v_world) -> np.ndarray:
    """u = [R(theta)^T v, 0] (B, 3): the body twist realizing a world-frame velocity (yaw not commanded)."""
    return kernels.body_from_world(theta, np.atleast_2d(np.asarray(v_world, float)))


def behavior_command(mode: str, state: RobotState, obstacles: Obstacles, goal, params: StackParams,
                     groups=None, release_v=None, rules: PlusRules = PAPER_RULES) -> np.ndarray:
    """eq:online_behavior_command: u_in = pi_b(x(t), O(t), p_g), the selected policy regenerated from the latest
    estimates (3,).
    ``groups``: obstacle group labels (:func:`obstacle_groups`), computed from ``obstacles`` when not given;
    ``release_v``: the REVERSE fallback's chosen world velocity (2,) (the push when None); ``rules``: our rules
    beyond the paper (default every one off: the paper's policies)."""
    if mode not in MODE_INDEX:
        raise ValueError(f"unknown behavior mode {mode!r}; known: {', '.join(MODES)}")
    v = policy_velocity(np.array([MODE_INDEX[mode]]), state.p[None], goal, obstacles.p, obstacles.r, params, groups,
                        obstacles.v, release_v, rules)
    return body_command(np.array([state.theta]), v)[0]
