"""The six feedback behaviors of BIG-CBF and the reverse-release fallback (eq:online_behavior_command, eq:goal_basis,
eq:behavior_subgoals, eq:behavior_feedback).

Modes: GOAL, PASS-L, PASS-R, SIDE-L, SIDE-R, YIELD (the behavior set B), plus REVERSE, the fallback used when every
regular behavior is rejected. A policy maps (robot position, obstacles, goal) to a world-frame translational velocity
v_b (eq:behavior_feedback); the body command is u = [R(theta)^T v_b, 0]: the behaviors are purely translational
(holonomic base, 360 degree LiDAR), yaw is not commanded.

Choices the paper leaves open (documented here, parameters in StackParams):

* Locally relevant obstacle i of eq:behavior_subgoals: seen from the robot along the goal direction d_g, with
  along-track distance s_i = (p_i - p).d_g and cross-track offset c_i = (p_i - p).n_g, it is the nearest (smallest s_i)
  obstacle that is not yet behind the robot (s_i > -(r_R + r_i)), within the look-ahead (s_i - r_i <
  ``relevant_range_m``) and in the way: |c_i| < r_R + r_i + d0 + ``in_way_margin_m``, i.e. driving straight to the
  goal would bring the footprint closer than d0 + 0.15 m to it, about the imagination's own margin for a static
  obstacle (the barrier test of eq:behavior_acceptance (22)). Wall points (radius 0) take part like any obstacle. (With
  d_pass_min, 0.30 m, as the band, both posts beside a 1 m gap were "in the way" of a robot centred in it, and PASS
  steered around the outside of one of them, into it: docs/fidelity.md, "Behavior imagination and selection".)
* The forward component of PASS's subgoal: eq:behavior_subgoals's 0.85 d_g, or, for a relevant obstacle alone in
  its group (one the footprint can pass on either side: a post, a person), its along-track distance s_i when that
  is farther (g = p + max(0.85, s_i) d_g + sigma max(d_pass, ...) n_g): the pass aims at the point beside the
  obstacle. With 0.85 m the pass dives at 45 degrees or more whatever the distance, which clips whatever stands
  between the robot and a farther post (the posts of the row it is passing through). A group (a wall, a wide body
  seen as LiDAR points) keeps the paper's 0.85 m: the pass around a group's end must turn early, and aiming beside
  a 2.7 m wide obstacle's face 3 m ahead made the pass too shallow to clear its end (required_sidestepping: 5 of
  50 seeds timed out where 1 had).
* d_pass of eq:behavior_subgoals, per side sigma: the lateral shift that puts the robot's footprint, with
  eq:behavior_subgoals's 0.35 m clearance, beside the relevant obstacle's *group* on side sigma, d_pass =
  max(d_pass_min, max_{j in G(i)} (sigma c_j + r_j) + r_R + 0.35). The group G(i) is the set of obstacles connected to i
  by gaps the robot cannot pass through (gap < 2 (r_R + d0) + 0.1 m; see :func:`obstacle_groups`). The paper's scenes
  are circles, where G(i) = {i} and the offset is max(d_pass_min, sigma c_i + r_i + r_R + 0.35), i.e.
  eq:behavior_subgoals's floor r_R + r_i + 0.35 for an obstacle dead ahead, widened for one offset towards side sigma. A
  LiDAR sees a wide obstacle or a wall as many points of radius 0: without the group, PASS would aim 0.5 m beside the
  nearest point of a 2.5 m wide obstacle and run into it; with it, PASS aims past the structure's end on its side.
* Without a relevant obstacle there is nothing to pass: PASS-sigma keeps only its goal-directed component
  (g = p + 0.85 d_g), so a robot that has completed a pass heads for the goal instead of drifting sideways; a
  PASS mode and GOAL then differ only near the goal, where the selection prefers GOAL (PASS overshoots).
* YIELD (zero command) is a candidate only while a dynamic obstacle is tracked ("YIELD intentionally suppresses
  movement when dynamic obstacles are present"); in a static scene standing still would never resolve anything.
* Inside the goal region (eq:goal_region, ||p - p_g|| <= eps_g) every policy commands zero.
* REVERSE (reverse-release fallback): a constant world-frame release velocity ``release_v`` chosen by the
  imagination when the fallback is invoked (:func:`bigcbf.control.imagination.choose_release`) from a predefined
  fan of candidates: the *push* (below), straight back from the goal, seven more headings 45 degrees apart
  around it, all at ``v_release_mps``, and standing still. Without a chosen velocity (e.g. a direct call), the
  push: move at ``v_release_mps`` away from the obstacles closer than r_R + r_i + d0 + ``release_range_m``,
  weighted by how deep they are inside that range; if none is that close (or their pushes cancel), straight
  back away from the goal. "Away" from a moving obstacle (speed above ``RELEASE_MOVING_MPS``) means out of its
  path, perpendicular to its velocity (to the side the robot is already on; to the obstacle's right when
  exactly on its path). The push alone is myopic: in the blind corner it backed the robot off a wall corner
  into the path of the person it was releasing from, and the hard CBF then chased it down a side corridor
  ahead of the person for 8 s.
"""
from __future__ import annotations

import numpy as np

from ..params.stack import StackParams
from ..types import Obstacles, RobotState
from . import kernels

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
    groups are the connected components (scipy.sparse.csgraph)."""
    from scipy.sparse.csgraph import connected_components

    p = np.asarray(obs_p, float).reshape(-1, 2)
    if len(p) <= 1:
        return np.zeros(len(p), int)
    r = np.asarray(obs_r, float)
    unc = params.uncertainty
    gap = np.hypot(*(p[:, None, :] - p[None, :, :]).transpose(2, 0, 1)) - r[:, None] - r[None, :]
    return connected_components(gap < 2 * (unc.r_robot_m + unc.d0_m) + 0.1, directed=False)[1]


def alone_in_group(groups) -> np.ndarray:
    """(M,) bool: obstacle i is the only member of its group (:func:`obstacle_groups`), one the footprint can pass
    on either side; PASS aims beside such an obstacle (module docstring)."""
    groups = np.asarray(groups, int)
    return np.bincount(groups)[groups] == 1 if len(groups) else np.zeros(0, bool)


def group_extent(sigma, j, c, obs_r, groups) -> np.ndarray:
    """max_{m in G(j_b)} (sigma_b c_{b,m} + r_m) per row b: how far the relevant obstacle's group reaches
    towards side sigma_b, measured from the robot across the goal line. c (B, M); j (B,), -1 for none (0)."""
    if c.shape[1] == 0:
        return np.zeros(len(j))
    same = groups[np.maximum(j, 0)][:, None] == groups[None, :]
    ext = np.max(np.where(same, np.asarray(sigma, float)[:, None] * c + np.asarray(obs_r, float)[None, :],
                          -np.inf), axis=1)
    return np.where(j >= 0, ext, 0.0)


def relevant_obstacle(p, d_g, n_g, obs_p, obs_r, params: StackParams, *, with_offsets: bool = False):
    """The locally relevant obstacle of eq:behavior_subgoals for each row (see the module docstring).

    p, d_g, n_g (B, 2); obs_p (M, 2); obs_r (M,). Returns (index (B,) with -1 for none, c_i (B,), r_i (B,)),
    c_i and r_i being 0 where there is none; with ``with_offsets`` also the cross-track offsets c (B, M) and the
    relevant obstacle's along-track distance s_i (B,) (0 where there is none).
    """
    p = np.atleast_2d(np.asarray(p, float))
    B, M = len(p), len(obs_r)
    if M == 0:
        out = (np.full(B, -1), np.zeros(B), np.zeros(B))
        return out + (np.zeros((B, 0)), np.zeros(B)) if with_offsets else out
    unc = params.uncertainty
    rel = np.asarray(obs_p, float)[None, :, :] - p[:, None, :]
    s = rel[..., 0] * d_g[:, None, 0] + rel[..., 1] * d_g[:, None, 1]
    c = rel[..., 0] * n_g[:, None, 0] + rel[..., 1] * n_g[:, None, 1]
    r = np.asarray(obs_r, float)[None, :]
    relevant = ((s > -(unc.r_robot_m + r)) & (s - r < params.relevant_range_m)
                & (np.abs(c) < unc.r_robot_m + r + unc.d0_m + params.in_way_margin_m))
    key = np.where(relevant, s, np.inf)
    j = np.argmin(key, axis=1)
    rows = np.arange(B)
    has = np.isfinite(key[rows, j])
    out = np.where(has, j, -1), np.where(has, c[rows, j], 0.0), np.where(has, r[0, j], 0.0)
    return out + (c, np.where(has, s[rows, j], 0.0)) if with_offsets else out


def pass_offset(extent, r_rel, has_rel, params: StackParams) -> np.ndarray:
    """eq:behavior_subgoals lateral PASS offset max(d_pass, r_R + r_i + 0.35) [m], with d_pass = max(d_pass_min,
    extent + r_R + 0.35), ``extent`` being the group's reach towards the side (:func:`group_extent`; for a lone
    obstacle sigma c_i + r_i); 0 without a relevant obstacle."""
    unc = params.uncertainty
    d_pass = np.maximum(params.d_pass_min_m, extent + unc.r_robot_m + PASS_EXTRA_M)
    return np.where(has_rel, np.maximum(d_pass, unc.r_robot_m + r_rel + PASS_EXTRA_M), 0.0)


def subgoal_error(mode_idx, p, goal, obs_p, obs_r, params: StackParams, groups=None) -> np.ndarray:
    """eq:behavior_subgoals: e_b = g_b - p (B, 2) for each row's mode:
    GOAL p_g - p; PASS-sigma max(0.85, s_i) d_g + sigma max(d_pass, r_R + r_i + 0.35) n_g (0.85 d_g without a
    relevant obstacle or when it is part of a group; s_i its along-track distance, see the module docstring);
    SIDE-sigma 0.45 d_g + 0.80 sigma n_g;
    YIELD 0. (REVERSE rows get 0; their velocity comes from :func:`release_velocity`.)
    ``groups``: labels from :func:`obstacle_groups` (computed here when not given)."""
    mode_idx = np.asarray(mode_idx, int)
    p = np.atleast_2d(np.asarray(p, float))
    d_g, n_g, _ = goal_basis(p, goal)
    sigma = SIGMA[mode_idx]
    lateral = np.where(IS_SIDE[mode_idx], SIDE_LATERAL_M * sigma, 0.0)
    forward = FORWARD_M[mode_idx]
    if np.any(IS_PASS[mode_idx]):
        j, c_rel, r_rel, c, s_rel = relevant_obstacle(p, d_g, n_g, obs_p, obs_r, params, with_offsets=True)
        if groups is None:
            groups = obstacle_groups(obs_p, obs_r, params)
        ext = group_extent(sigma, j, c, obs_r, groups)
        lateral = np.where(IS_PASS[mode_idx], sigma * pass_offset(ext, r_rel, j >= 0, params), lateral)
        alone = alone_in_group(groups)
        lone_rel = (j >= 0) & alone[np.maximum(j, 0)] if len(alone) else np.zeros(len(j), bool)
        forward = np.where(IS_PASS[mode_idx] & lone_rel, np.maximum(forward, s_rel), forward)
    e = forward[:, None] * d_g + lateral[:, None] * n_g
    return np.where(IS_GOAL[mode_idx, None], np.asarray(goal, float) - p, e)


def feedback_velocity(e, v_max) -> np.ndarray:
    """eq:behavior_feedback: v_b = sat_{v_max}[ e/||e|| min(v_max, 2||e||) + 0.35 e ] (world frame, m/s).

    Both terms are parallel to e, so v_b = e/||e|| min(v_max, min(v_max, 2||e||) + 0.35||e||). e (B, 2), v_max (B,).
    """
    e = np.atleast_2d(np.asarray(e, float))
    n = np.hypot(e[:, 0], e[:, 1])
    v_max = np.asarray(v_max, float)
    mag = np.minimum(np.minimum(v_max, GAIN_NEAR_PER_S * n) + GAIN_LIN_PER_S * n, v_max)
    return e * (mag / np.maximum(n, _TINY))[:, None]


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


def release_velocity(p, goal, obs_p, obs_r, params: StackParams, obs_v=None) -> np.ndarray:
    """The reverse-release fallback's push velocity (B, 2) [m/s] (see the module docstring)."""
    p = np.atleast_2d(np.asarray(p, float))
    unc = params.uncertainty
    pz = p[:, 0] + 1j * p[:, 1]
    g = complex(*np.asarray(goal, float).reshape(2)) - pz
    back = -g / np.maximum(np.abs(g), _TINY)                       # -d_g (0 at the goal itself)
    direction = back
    if len(obs_r):
        op = np.asarray(obs_p, float)
        qz = pz[:, None] - (op[:, 0] + 1j * op[:, 1])[None]
        w = np.maximum(unc.r_robot_m + np.asarray(obs_r, float)[None] + unc.d0_m + params.release_range_m
                       - np.abs(qz), 0.0)
        if w.any():                     # (usually nothing is that close: skip the directions)
            vz = None if obs_v is None else np.asarray(obs_v, float) @ np.array([1.0, 1j])
            push = (w * release_directions_c(qz, vz)).sum(axis=1)
            npush = np.abs(push)
            direction = np.where(npush > 1e-9, push / np.maximum(npush, _TINY), back)
    v = params.v_release_mps * direction
    return np.stack([v.real, v.imag], -1)


def policy_velocity(mode_idx, p, goal, obs_p, obs_r, params: StackParams, groups=None, obs_v=None,
                    release_v=None) -> np.ndarray:
    """The behavior policies pi_b as world-frame translational velocities (B, 2) [m/s] (eq:goal_basis,
    eq:behavior_subgoals, eq:behavior_feedback), zero inside the
    goal region; REVERSE rows use the fallback: ``release_v`` (2,) when given, else the push."""
    mode_idx = np.asarray(mode_idx, int)
    p = np.atleast_2d(np.asarray(p, float))
    v = feedback_velocity(subgoal_error(mode_idx, p, goal, obs_p, obs_r, params, groups),
                          speed_limits(params)[mode_idx])
    is_rev = mode_idx == MODE_INDEX[REVERSE]
    if np.any(is_rev):
        rv = (release_velocity(p, goal, obs_p, obs_r, params, obs_v) if release_v is None
              else np.broadcast_to(np.asarray(release_v, float).reshape(2), p.shape))
        v = np.where(is_rev[:, None], rv, v)
    dist = kernels.goal_distance(p, goal)
    return np.where(kernels.outside_goal_region(dist, params.eps_g_m)[:, None], v, 0.0)   # eq:goal_region


def body_command(theta, v_world) -> np.ndarray:
    """u = [R(theta)^T v, 0] (B, 3): the body twist realizing a world-frame velocity (yaw not commanded)."""
    return kernels.body_from_world(theta, np.atleast_2d(np.asarray(v_world, float)))


def behavior_command(mode: str, state: RobotState, obstacles: Obstacles, goal, params: StackParams,
                     groups=None, release_v=None) -> np.ndarray:
    """eq:online_behavior_command: u_in = pi_b(x(t), O(t), p_g), the selected policy regenerated from the latest
    estimates (3,).
    ``groups``: obstacle group labels (:func:`obstacle_groups`), computed from ``obstacles`` when not given;
    ``release_v``: the REVERSE fallback's chosen world velocity (2,) (the push when None)."""
    if mode not in MODE_INDEX:
        raise ValueError(f"unknown behavior mode {mode!r}; known: {', '.join(MODES)}")
    v = policy_velocity(np.array([MODE_INDEX[mode]]), state.p[None], goal, obstacles.p, obstacles.r, params, groups,
                        obstacles.v, release_v)
    return body_command(np.array([state.theta]), v)[0]
