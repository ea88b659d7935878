"""Closed-loop behavior imagination and scoring (eq:behavior_rollout (12), eq:behavior_terms (13),
eq:behavior_cost (14), eq:behavior_acceptance (22), eq:analytic_workload (24)), vectorized over behaviors and
obstacles.

For every candidate b the imagined robot starts at the current state; at each step k = 0..N-1 the command
u_k^b = pi_b(x_k^b, O^k, p_g) is regenerated from the imagined state and the predicted obstacles
(eq:behavior_rollout (12)), the robot is propagated over dt with the nominal execution model of eq:execution (1)
(A, d; the bounded residual r is unknown and enters only the uncertainty radius through e_exec), and the obstacles
follow eq:obs_prop (2) and eq:cov_prop (3).

Commands exist for k = 0..N-1 (as in the paper's sums); the barrier test (eq:behavior_acceptance (22)) takes the
minimum over the states k = 0..N and all obstacles, the terminal state's m_i (eq:uncertainty_margin (21)) using the
last command u_{N-1}, the one
that brought the robot there. A robot already deeper than eps_h inside an inflated radius therefore rejects
every behavior and triggers the reverse-release fallback.

Freezing (F of eq:behavior_terms (13)) counts the steps with ||u_xy|| < v_freeze taken *outside* the goal region:
standing still at the goal is the objective, not the "persistent stagnation" F is meant to penalize (without this, every
behavior that arrives within the horizon would be penalized against ones that circle the goal).

The policy is not written here: each step calls ``behaviors.PolicyData.velocity``, the compiled policy the
execution loop calls too, for all behaviors at once; the rest of the loop body is one numpy op per term over (B,)
or (B, M) arrays (no per-behavior Python); tests check it against a per-behavior reference built from
``behaviors.behavior_command`` and ``uncertainty``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..params.stack import PAPER_RULES, PlusRules, StackParams
from ..types import Obstacles, RobotState
from .behaviors import (BEHAVIORS, PASS_KIND, REVERSE, PolicyData, _policy_rows, goal_basis, mode_indices,
                        mode_rows, obstacle_groups, release_velocity)
from .faults import perception_fault
from .governor import GOVERNED_MODES, govern_c, obstacle_sigma_term
from .jit import kernel
from .prediction import predict_obstacles, q_sigma_for
from . import kernels
from .uncertainty import has_dynamic, kappa_img

_TINY = 1e-12


@dataclass
class Imagination:
    """The rollouts and scores of one behavior-selection cycle (row b = ``modes[b]``)."""

    modes: tuple[str, ...]
    p: np.ndarray          # (B, N+1, 2) imagined positions [m]
    theta: np.ndarray      # (B, N+1) imagined yaw [rad]
    u: np.ndarray          # (B, N, 3) regenerated commands u_k, k = 0..N-1
    h_min: np.ndarray      # (B,) min over k = 0..N and i of h^img [m^2] (+inf without obstacles)
    W: np.ndarray          # (B,) W~ of eq:analytic_workload (24)
    P: np.ndarray          # (B,) progress [m] (eq:behavior_terms (13))
    F: np.ndarray          # (B,) freezing fraction (eq:behavior_terms (13))
    S: np.ndarray          # (B,) smoothness (eq:behavior_terms (13))
    C_sw: np.ndarray       # (B,) switching indicator (eq:behavior_terms (13))
    J: np.ndarray          # (B,) cost of eq:behavior_cost (14)
    available: np.ndarray  # (B,) bool: a candidate (YIELD needs a dynamic obstacle; REVERSE never is one)
    accepted: np.ndarray   # (B,) bool: available and passes the barrier test of eq:behavior_acceptance (22)
    deficit: np.ndarray | None = None    # (B,) sum over k = 1..N of max(0, -min_i h^img) [m^2] (the fallback's choice)
    margin: np.ndarray | None = None     # (B, N+1, M) the imagination's margin D_i - (r_R + r_i + d0) [m]: kappa_img
                                         # m_i (eq:shared_barrier (20)), or BIG-CBF-NoShared's fixed margin
    #: (v_freeze N dt [m], (B,) bool: the rollout ends in the goal region), for :attr:`viable`
    params_stall: tuple | None = None
    #: (B,) progress along the maneuver [m]: sum_k dt e_k^T w_k, e_k the direction of the behavior's command
    #: (eq:behavior_feedback (11)) at step k, w_k the imagined velocity (the filter model's with the governor); None:
    #: use P only
    along: np.ndarray | None = None

    def index(self, mode: str) -> int:
        return self.modes.index(mode)

    @property
    def viable(self) -> np.ndarray:
        """(B,) bool: the candidates the selection may retain (:class:`bigcbf.control.selection.BehaviorSelector`):
        accepted (eq:behavior_acceptance (22)) and, for a moving behavior, *making progress*: the larger of its
        imagined progress P_b (eq:behavior_terms (13), goal distance) and its progress along its own maneuver
        (:attr:`along`) is at least what the freeze speed would give over the horizon, v_freeze N dt, unless it reaches
        the goal region. Progress along the maneuver keeps a sidestep in front of a wide obstacle viable: sliding along
        it barely shortens the goal distance within the horizon (docs/fidelity.md, "Liveness"). YIELD stands still by
        design. Only with the rule ``speed_governor`` (:class:`~bigcbf.params.stack.PlusRules`); without it:
        accepted."""
        if self.params_stall is None:
            return np.asarray(self.accepted)
        p_stall, goal_reached = self.params_stall
        prog = np.asarray(self.P) if self.along is None else np.maximum(self.P, self.along)
        stalled = (prog < p_stall) & ~goal_reached & np.array([m != "YIELD" for m in self.modes])
        return np.asarray(self.accepted) & ~stalled


class _Constants:
    """Per (modes, params) constants of the rollout (the policy rows of eq:behavior_subgoals (10) and
    eq:behavior_feedback (11), :func:`behaviors.mode_rows`; eq:execution (1)), cached."""

    def __init__(self, modes: tuple[str, ...], params: StackParams):
        ex = params.uncertainty.execution
        midx = mode_indices(modes)
        self.B = len(midx)
        self.rows = mode_rows(midx, params)
        self.midx = midx
        self.governed = np.array([m in GOVERNED_MODES for m in modes], bool)   # rows the speed governor applies to
        # execution model, eq:execution: body realized = a u + b conj(u) + d (translation), wz = A[2,:2] u + d_w
        A = np.asarray(ex.A, float)
        self.A = A
        self.a_c, self.b_c, self.d_c = kernels.execution_complex(ex)
        self.ideal_xy = self.a_c == 1 and self.b_c == 0 and self.d_c == 0
        self.a20, self.a21, self.dw = float(A[2, 0]), float(A[2, 1]), float(ex.d[2])
        self.turning = not (self.a20 == 0 and self.a21 == 0 and self.dw == 0)
        self.unit_gradient = bool(np.allclose(A[:2] @ A[:2].T, np.eye(2)))   # ||A_xy^T R^T q|| = ||q||


_CONSTANTS: dict[tuple, tuple[StackParams, _Constants]] = {}


def _constants(modes: tuple[str, ...], params: StackParams) -> _Constants:
    key = (tuple(modes), id(params))     # (the rules do not enter the constants)
    hit = _CONSTANTS.get(key)
    if hit is None or hit[0] is not params:
        if len(_CONSTANTS) > 64:
            _CONSTANTS.clear()
        hit = (params, _Constants(tuple(modes), params))
        _CONSTANTS[key] = hit
    return hit[1]


@dataclass
class _Rollout:
    K: "_Constants"
    P: np.ndarray               # (B, N+1) complex positions
    V: np.ndarray               # (B, N+1) complex nominal realized velocities (column N repeats N-1)
    U: np.ndarray               # (B, N+1) complex body commands (column N repeats N-1)
    TH: np.ndarray              # (B, N+1) yaw
    Oc: np.ndarray | None       # (N+1, M) complex predicted obstacle positions
    cov: np.ndarray | None      # (N+1, M, 2, 2) predicted covariances
    along: np.ndarray | None = None   # (B,) progress along the maneuver [m] (Imagination.along)


class _Governed:
    """The speed governor (governor.py) over a rollout: the rows it applies to and the obstacles' terms."""

    def __init__(self, K: _Constants, obstacles: Obstacles, cov: np.ndarray, params: StackParams):
        self.rows = np.flatnonzero(K.governed)
        self.sig_k = obstacle_sigma_term(cov, params)                  # (N+1, M)
        self.obs_vz = obstacles.v[:, 0] + 1j * obstacles.v[:, 1]
        self.r = np.asarray(obstacles.r, float)
        self.params = params

    def __call__(self, k: int, p, rot, conj_rot, v, Ok) -> np.ndarray:
        """Scales the governed rows of v in place; returns the filter model's velocities w* of those rows."""
        gr = self.rows
        s_gov, w_gov = govern_c(p[gr], rot[gr], v[gr] * conj_rot[gr], Ok, self.obs_vz, self.sig_k[k], self.r,
                                self.params)
        v[gr] = v[gr] * s_gov
        return w_gov


_PREDICTED: list = [None, None]  # the last (key, (Oc, cov)) of _predicted


def _predicted(obstacles: Obstacles, N: int, dt: float, params: StackParams,
               k_cap: int | None = None, v_hold: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """The predicted obstacle positions (N+1, M) complex and covariances (N+1, M, 2, 2) (eq:obs_prop (2),
    eq:cov_prop (3), eq:predicted_obstacles (4); ``prediction.predict_obstacles``), kept for the next rollout of
    the same obstacles (the fallback's, in the same selection). Read-only for their users. ``k_cap`` (the rule
    prediction_cap, :class:`~bigcbf.params.stack.PlusRules`): the covariances held at step k_cap from there on,
    for the obstacles slower than ``v_hold`` [m/s] (inf: all; v_max for ``PlusRules.prediction_cap_scope``
    "escapable")."""
    q = q_sigma_for(obstacles, params.uncertainty)
    key = (np.asarray(obstacles.p, float).tobytes(), np.asarray(obstacles.v, float).tobytes(),
           np.asarray(obstacles.cov, float).tobytes(), np.asarray(q, float).tobytes(), int(N), float(dt), k_cap,
           float(v_hold))
    if _PREDICTED[0] != key:
        P_obs, cov = predict_obstacles(obstacles, N, dt, q)
        if k_cap is not None and k_cap < N:
            held = cov[np.minimum(np.arange(N + 1), k_cap)]
            slow = np.hypot(obstacles.v[:, 0], obstacles.v[:, 1]) < v_hold        # (M,): all when v_hold is inf
            cov = np.where(slow[:, None, None], held, cov)
        Oc = P_obs[..., 0] + 1j * P_obs[..., 1]
        Oc.flags.writeable = cov.flags.writeable = False          # shared by the rollouts that reuse them
        _PREDICTED[:] = [key, (Oc, cov)]
    return _PREDICTED[1]


_PRED_TERM: list = [None, None, None]   # the last (cov, beta, term) of _prediction_term


def _prediction_term(cov: np.ndarray, unc) -> np.ndarray:
    """``kernels.prediction_term`` (eq:uncertainty_margin (21)) of the predicted covariances, kept with the cached
    predictions of :func:`_predicted` (the same read-only array object, the same beta)."""
    if _PRED_TERM[0] is cov and _PRED_TERM[1] == unc.beta and not cov.flags.writeable:
        return _PRED_TERM[2]
    term = kernels.prediction_term(cov, unc)
    term.flags.writeable = False
    _PRED_TERM[:] = [cov, unc.beta, term]
    return term


_GROUPS: list = [None, None]     # the last (key, groups) of _groups


def _groups(K: _Constants, obstacles: Obstacles, params: StackParams, rules: PlusRules) -> np.ndarray | None:
    """The obstacle groups ``PolicyData.build`` would compute for this rollout (``behaviors.obstacle_groups``, when
    a PASS row reads them), kept for the next rollout on the same obstacles (a selection imagines the same scene
    several times: the behaviors, the release fan, the executed-speed judgement); None where build computes none."""
    if not ((rules.pass_group_reach or rules.pass_forward_beside) and len(obstacles) and np.any(K.rows[0] == PASS_KIND)):
        return None
    p = np.ascontiguousarray(obstacles.p, dtype=float)
    r = np.ascontiguousarray(obstacles.r, dtype=float).reshape(-1)
    key = (p.tobytes(), r.tobytes(), float(params.uncertainty.r_robot_m), float(params.uncertainty.d0_m))
    if _GROUPS[0] != key:
        _GROUPS[:] = [key, obstacle_groups(p, r, params)]
    return _GROUPS[1]


def _rollout(state: RobotState, obstacles: Obstacles, goal, params: StackParams, modes: tuple[str, ...],
             release_v: np.ndarray | None = None, start: tuple[np.ndarray, np.ndarray] | None = None,
             rules: PlusRules = PAPER_RULES, score_steps: int | None = None) -> _Rollout:
    """eq:behavior_rollout (12): the closed-loop rollouts of ``modes``: the policy pi_b regenerated at every step
    from the imagined state and the predicted obstacles O^k (:meth:`behaviors.PolicyData.velocity`, the same
    compiled policy the execution loop calls), the robot propagated with the nominal eq:execution (1), the obstacles
    with eq:obs_prop (2) and eq:cov_prop (3). Planar vectors are complex numbers (x + i y; R(theta) is
    multiplication by e^{i theta}); all behaviors advance together. ``release_v`` (B,) complex: the constant world
    velocity of each REVERSE row (default: the push). ``rules``: our rules beyond the paper (the policy's PASS rules,
    ``speed_governor``). ``score_steps``: ``along`` sums the first that many steps (default N)."""
    N, dt = params.N, params.dt_s
    K = _constants(modes, params)
    B, M = K.B, len(obstacles)
    a_c, b_c, d_c, ideal_xy, a20, a21, dw, turning = K.a_c, K.b_c, K.d_c, K.ideal_xy, K.a20, K.a21, K.dw, K.turning
    Oc = cov = governed = None
    Ok = np.zeros((N + 1, 0), complex)
    if M:       # predictions (eq:obs_prop (2), eq:cov_prop (3), eq:predicted_obstacles (4))
        k_cap = int(round(rules.prediction_cap_s / dt)) if rules.prediction_cap else None
        v_hold = params.v_max_mps if rules.prediction_cap_scope == "escapable" else math.inf   # what it can outrun
        Oc, cov = _predicted(obstacles, N, dt, params, k_cap, v_hold)
        Ok = Oc                                                       # (N+1, M)
        if rules.speed_governor and K.governed.any():
            governed = _Governed(K, obstacles, cov, params)
    policy = PolicyData.build(K.midx, goal, obstacles.p, obstacles.r, params, obs_v=obstacles.v, release=release_v,
                              rows=K.rows, rules=rules, groups=_groups(K, obstacles, params, rules))      # the groups of eq:behavior_subgoals (10) from the obstacles at k = 0
    p, th = ((np.full(B, complex(state.px, state.py)), np.full(B, float(state.theta))) if start is None
             else (np.array(start[0], complex), np.array(start[1], float)))   # one start state per row
    # (N+1, B) layouts: one contiguous row per step; row N of V and U repeats row N-1
    Pk, Vk, Uk, THk = (np.empty((N + 1, B), complex), np.empty((N + 1, B), complex), np.empty((N + 1, B), complex),
                       np.empty((N + 1, B)))
    if governed is None and not rules.speed_governor and not policy.push and ideal_xy and not turning:
        # the usual case (nominal execution model, no governor): the loop compiled, the products after it
        _rollout_loop(policy.kind, policy.coef, policy.goal, np.ascontiguousarray(Ok), policy.obs_r, policy.groups,
                      policy.alone, policy.release, policy.geometry, np.array(p, complex), N, dt, Pk, Vk)
        THk[:] = th
        rot = np.exp(1j * th)
        Uk[:N] = Vk[:N] * np.conj(rot)                    # u_k = R(theta)^T v_k, the yaw constant
        Uk[N] = u = Uk[N - 1]
        Vk[N] = kernels.execution_velocity_c(rot, u, a_c, b_c, d_c)
        return _Rollout(K, Pk.T, Vk.T, Uk.T, THk.T, Oc, cov, None)
    along = _rollout_steps(policy, governed, Ok, Oc, p, th, N, dt, K, rules, Pk, Vk, Uk, THk, score_steps)
    return _Rollout(K, Pk.T, Vk.T, Uk.T, THk.T, Oc, cov, along)


def _rollout_steps(policy: PolicyData, governed, Ok, Oc, p, th, N: int, dt: float, K: _Constants,
                   rules: PlusRules, Pk, Vk, Uk, THk, along_steps: int | None = None):
    """The loop of :func:`_rollout` step by step in numpy (the speed governor, the push, or progress along the
    maneuver): fills Pk, Vk, Uk, THk (N+1, B); returns ``along`` over the first ``along_steps`` steps (None without
    the rule ``speed_governor``)."""
    a_c, b_c, d_c, ideal_xy, a20, a21, dw, turning = K.a_c, K.b_c, K.d_c, K.ideal_xy, K.a20, K.a21, K.dw, K.turning
    B = K.B
    rot = np.exp(1j * th)
    conj_rot = np.conj(rot)
    THk[:] = th
    # progress along the maneuver: only the liveness option's viability test reads it (Imagination.along)
    along = np.zeros(B) if rules.speed_governor else None
    for k in range(N):
        Pk[k] = p
        v = policy.velocity(p, Ok[k])
        if along is not None:
            nv = np.abs(v)
            vdir = np.where(nv > _TINY, v / np.maximum(nv, _TINY), 0j)   # the maneuver's direction at step k
        w_gov = None if governed is None else governed(k, p, rot, conj_rot, v, Oc[k])
        Uk[k] = u = v * conj_rot
        # nominal execution (eq:execution) and propagation over dt
        Vk[k] = vreal = v if ideal_xy else kernels.execution_velocity_c(rot, u, a_c, b_c, d_c)
        if w_gov is not None:      # governed rows move as the filter model predicts the common CBF lets them
            vreal = vreal.copy()
            vreal[governed.rows] = w_gov
        if along is not None and (along_steps is None or k < along_steps):
            along += dt * (vdir.real * vreal.real + vdir.imag * vreal.imag)
        p = kernels.euler_step(p, vreal, dt)
        if turning:
            th = kernels.euler_step(th, kernels.execution_yaw_rate_c(u, a20, a21, dw), dt)
            THk[k + 1] = th
            rot = np.exp(1j * th)
            conj_rot = np.conj(rot)
    Pk[N] = p
    Uk[N] = u = Uk[N - 1]
    Vk[N] = kernels.execution_velocity_c(rot, u, a_c, b_c, d_c)       # u_{N-1} realized at the terminal yaw
    return along


@kernel
def _rollout_loop(kind, coef, goal, Ok, obs_r, groups, alone, release, geo, p, N, dt, Pk, Vk):
    """The loop of :func:`_rollout` compiled for the nominal execution model A = I, d = 0 (eq:behavior_rollout
    (12), eq:execution (1)): at each step k the policy of every row (``behaviors._policy_rows``, the kernel
    :meth:`PolicyData.velocity` runs) from the imagined positions ``p`` (B,) and the predicted obstacles Ok[k],
    then the Euler step p + dt v; fills Pk[0..N] and Vk[0..N-1] (N+1, B). The complex products that do not feed
    back (u = R^T v) are left to numpy, whose complex multiply (fused on CPUs with FMA) is not the plain formula
    compiled code would use: so the rollout is the numpy step loop's bits (tests/control/test_imagination_compiled.py)."""
    B = p.shape[0]
    v = np.empty(B, np.complex128)
    for k in range(N):
        _policy_rows(kind, coef, p, goal, Ok[k], obs_r, groups, alone, release, geo, v)
        for b in range(B):
            Pk[k, b] = p[b]
            Vk[k, b] = v[b]
            p[b] = p[b] + dt * v[b]
    for b in range(B):
        Pk[N, b] = p[b]


def rollout_paths(state: RobotState, obstacles: Obstacles, goal, params: StackParams,
                  modes: tuple[str, ...]) -> np.ndarray:
    """The imagined positions (B, N+1, 2) of ``modes`` (eq:behavior_rollout (12)), without scoring."""
    ro = _rollout(state, obstacles, np.asarray(goal, float), params, tuple(modes))
    return np.stack([ro.P.real, ro.P.imag], -1)


#: headings of the release fan, relative to straight back from the goal [rad]
RELEASE_HEADINGS = np.deg2rad([0.0, 45.0, -45.0, 90.0, -90.0, 135.0, -135.0, 180.0])


def release_candidates(state: RobotState, obstacles: Obstacles, goal, params: StackParams,
                       rules: PlusRules = PAPER_RULES) -> np.ndarray:
    """The fallback's candidates (B,) of world velocities as complex numbers: the push
    (:func:`behaviors.release_velocity`; from moving obstacles sideways with the rule ``release_sideways``) alone
    (the paper's "predefined reverse-release fallback", one choice; with the rule ``release_ahead`` from where the
    movers come within the imagination's horizon, long_horizon_s or N dt); with the rule ``release_fan`` also the eight
    ``RELEASE_HEADINGS`` around straight back from the goal at ``v_release_mps``, and 0 (standing still)."""
    ahead_s = rules.rollout_steps(params) * params.dt_s if rules.release_ahead else 0.0
    push = release_velocity(state.p[None], goal, obstacles.p, obstacles.r, params,
                            obstacles.v if rules.release_sideways else None,
                            obstacles.v if rules.release_ahead else None, ahead_s)[0]
    if not rules.release_fan:
        return np.array([complex(push[0], push[1])])
    d_g, _, _ = goal_basis(state.p, goal)
    back = -complex(d_g[0], d_g[1]) if np.any(d_g) else complex(-math.cos(state.theta), -math.sin(state.theta))
    fan = params.v_release_mps * back * np.exp(1j * RELEASE_HEADINGS)
    return np.concatenate([[complex(push[0], push[1])], fan, [0j]])


def choose_release(state: RobotState, obstacles: Obstacles, goal, params: StackParams, *,
                   shared: bool = True, rules: PlusRules = PAPER_RULES) -> tuple[np.ndarray, Imagination, int]:
    """The reverse-release fallback's velocity (2,) [m/s, odom], chosen from :func:`release_candidates` by what it
    makes possible: each candidate's rollout (eq:behavior_rollout (12), the same prediction and shared barrier as
    the behaviors, eq:shared_barrier (20), eq:uncertainty_margin (21), eq:behavior_acceptance (22)) is followed for
    one selection period T_B (the time it will be executed before the next selection), and from where it leaves the
    robot the six behaviors are imagined again (the obstacles predicted T_B ahead, eq:obs_prop (2) and eq:cov_prop
    (3)). The candidate after which the best *viable* behavior (accepted by eq:behavior_acceptance (22) and not
    frozen; see :class:`bigcbf.control.selection.BehaviorSelector`) has the lowest J of eq:behavior_cost (14) is
    chosen: the release aims at
    making a maneuver possible again rather than merely backing off. When no candidate leads to a viable behavior,
    the one with the least accumulated barrier deficit sum_{k=1..N} max(0, -min_i h_{i,k}^img) (it leaves the
    inflated radii soonest and enters none on the way); ties go to the first in the fan's order, the push. The
    outlook is part of the liveness option (the rule ``speed_governor``); without it, the least deficit alone.
    Without the rule ``release_fan`` (the paper's reading) there is one candidate, the push. Also returns the
    candidates' imagination; the chosen row is ``index``."""
    cand = release_candidates(state, obstacles, goal, params, rules)
    img = imagine(state, obstacles, goal, params, modes=(REVERSE,) * len(cand), shared=shared, release_v=cand,
                  rules=rules)
    j_after = (release_outlook(img, obstacles, goal, params, shared=shared, rules=rules) if rules.speed_governor
               else None)
    if j_after is not None and np.isfinite(j_after).any():
        best = int(np.argmin(j_after))
    else:
        best = int(np.argmin(img.deficit))
    return np.array([cand[best].real, cand[best].imag]), img, best


def release_outlook(rel: Imagination, obstacles: Obstacles, goal, params: StackParams, *,
                    shared: bool = True, rules: PlusRules = PAPER_RULES) -> np.ndarray:
    """For each release rollout of ``rel``: the lowest J (eq:behavior_cost (14)) of a viable behavior imagined from the
    state the release reaches after T_B (+inf when none is viable), see :func:`choose_release`."""
    R = len(rel.modes)
    kB = min(int(round(params.T_B_s / params.dt_s)), params.N)
    tB = kB * params.dt_s
    ahead = obstacles
    if len(obstacles):
        q = q_sigma_for(obstacles, params.uncertainty)
        p_ahead, cov_ahead = kernels.advance_obstacles(obstacles.p, obstacles.v, obstacles.cov, q, tB)
        ahead = Obstacles(p_ahead, obstacles.v, cov_ahead, obstacles.r, obstacles.static, obstacles.ids)
    nb = len(BEHAVIORS)
    p0 = np.repeat(rel.p[:, kB, 0] + 1j * rel.p[:, kB, 1], nb)
    th0 = np.repeat(rel.theta[:, kB], nb)
    img = imagine(RobotState(0.0, 0.0, 0.0), ahead, goal, params, modes=BEHAVIORS * R, shared=shared,
                  start=(p0, th0), rules=rules)
    J = np.where(img.viable, img.J, np.inf).reshape(R, nb)
    return J.min(axis=1)


def _barrier_terms(ro: _Rollout, speed: np.ndarray, obstacles: Obstacles, params: StackParams,
                   shared: bool, score_steps: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                                          np.ndarray]:
    """The shared barrier (eq:shared_barrier (20), eq:uncertainty_margin (21), eq:behavior_acceptance (22)) and the
    analytic compatibility W~ (eq:analytic_workload (24)) of rollouts ``ro``, all (b, k, i) at once; ``speed``
    ||u_xy|| (B, N+1). Returns h_min, W, deficit (B,) and the margin (B, N+1, M) (see :class:`Imagination`).
    ``score_steps`` Ns < N (the rule long_horizon): W, the deficit and h_min are those of the first Ns steps (the
    paper's imagination over Ns steps, to the bit), and h_min also takes the moving obstacles
    (:func:`moving_obstacles`) over every state k = 0..N."""
    unc, ex = params.uncertainty, params.uncertainty.execution
    N, K, M = params.N, ro.K, len(obstacles)
    B = K.B
    if not M:
        return np.full(B, np.inf), np.zeros(B), np.zeros(B), np.zeros((B, N + 1, 0))
    Pc, Vc, TH, Oc, cov = ro.P, ro.V, ro.TH, ro.Oc, ro.cov
    Ov = obstacles.v[:, 0] + 1j * obstacles.v[:, 1]                   # (M,)
    if shared:
        kap = kappa_img(obstacles, unc)
        rel_speed = np.abs(np.subtract(Vc[:, :, None], Ov, order="C"))  # ||R(A u + d) - v_i|| (numpy's complex abs)
        pred = _prediction_term(cov, unc)                              # (N+1, M)
        e_exec = kernels.e_exec_speed(speed, ex)                       # (B, N+1)
    else:
        kap, rel_speed, pred, e_exec = 0.0, np.zeros((0, 0, 0)), np.zeros((N + 1, M)), np.zeros((B, N + 1))
    # |grad_u gamma|^2 = 4 ||A_xy^T R^T q||^2 (A_xy = translational rows of A, all three u channels)
    if K.unit_gradient:
        grad2 = np.zeros((0, 0, 0))                                    # 4 ||q||^2, in the kernel
    else:
        A = K.A
        qb = np.multiply(np.subtract(Pc[:, :N, None], Oc[None, :N], order="C"), np.exp(-1j * TH[:, :N])[:, :, None],
                         order="C")                                    # R^T q
        G = A[:2] @ A[:2].T
        grad2 = 4.0 * (G[0, 0] * qb.real ** 2 + 2 * G[0, 1] * qb.real * qb.imag + G[1, 1] * qb.imag ** 2)
    h, margin, wterm = (np.empty((B, N + 1, M)), np.empty((B, N + 1, M)), np.empty((B, N, M)))
    # every array C-ordered (rel_speed and qb made so above; ascontiguousarray then copies nothing): numba compiles
    # one machine code per layout, and these broadcasts came out C, F or A with the number of obstacles (three
    # compiles of this kernel met one by one in the first episodes; copying them read an episode ratio of 0.358 for
    # 0.372 in three paired runs, made in C order 0.361 for 0.362 in four)
    _barrier_kernel(np.ascontiguousarray(Pc), np.ascontiguousarray(Vc), np.ascontiguousarray(Oc), Ov,
                    np.asarray(obstacles.r, float), np.ascontiguousarray(rel_speed), pred, e_exec, float(kap), shared,
                    float(params.noshared_margin_m), float(unc.r_robot_m), float(unc.d0_m), float(unc.tau95_s),
                    float(unc.e_zoh_m), float(params.alpha_per_s), float(params.w_eps), np.ascontiguousarray(grad2),
                    h, margin, wterm)
    Ns = N if score_steps is None else min(score_steps, N)      # Ns = N: the full arrays, the same sums
    h_min = h[:, :Ns + 1].reshape(B, -1).min(axis=1)
    if Ns < N:
        moving = moving_obstacles(obstacles, params)
        if moving.any():
            h_min = np.minimum(h_min, h[:, :, moving].reshape(B, -1).min(axis=1))
    deficit = np.maximum(-h[:, 1:Ns + 1].min(axis=2), 0.0).sum(axis=1)
    W = np.ascontiguousarray(wterm[:, :Ns]).reshape(B, -1).sum(axis=1)
    return h_min, W, deficit, margin


def moving_obstacles(obstacles: Obstacles, params: StackParams) -> np.ndarray:
    """(M,) the tracked obstacles classified dynamic that move at least ``cbf_velocity_min_speed_mps`` (the common
    filter's notion of a moving obstacle, the one its velocity-aware rows use)."""
    speed = np.hypot(obstacles.v[:, 0], obstacles.v[:, 1])
    return (~np.asarray(obstacles.static, bool) & (np.asarray(obstacles.ids) >= 0)
            & (speed >= params.cbf_velocity_min_speed_mps))


@kernel
def _barrier_kernel(Pc, Vc, Oc, Ov, r, rel_speed, pred, e_exec, kap, shared, noshared_margin, r_robot, d0, tau95, e_zoh, alpha,
                    w_eps, grad2, h, margin, wterm):
    """The per-(b, k, i) terms of :func:`_barrier_terms` into h, margin (B, N+1, M) and wterm (B, N, M), in the
    order of the numpy formulas they replace (``kernels.uncertainty_radius``, ``inflated_radius``, ``barrier``,
    eq:uncertainty_margin (21), eq:shared_barrier (20); the summand of eq:analytic_workload (24)): real arithmetic
    only; the relative speeds (numpy's complex abs, vectorized, is not hypot to the bit) and the sums over the
    terms are left to numpy. grad2 (B, N, M), or empty for 4 ||q||^2."""
    B, N1 = Pc.shape
    M = Oc.shape[1]
    unit = grad2.shape[0] == 0
    for b in range(B):
        for k in range(N1):
            for i in range(M):
                q = Pc[b, k] - Oc[k, i]
                q2 = q.real ** 2 + q.imag ** 2
                rv = Vc[b, k] - Ov[i]
                if shared:
                    m = kap * (tau95 * rel_speed[b, k, i] + pred[k, i] + (e_exec[b, k] + e_zoh))
                else:
                    m = noshared_margin
                D = r_robot + r[i] + d0 + m
                hk = q2 - D * D
                h[b, k, i] = hk
                margin[b, k, i] = m
                if k < N1 - 1:
                    gamma = 2.0 * (q.real * rv.real + q.imag * rv.imag) + alpha * hk
                    g2 = 4.0 * q2 if unit else grad2[b, k, i]
                    viol = -gamma
                    if not (viol >= 0.0 or viol != viol):
                        viol = 0.0
                    wterm[b, k, i] = viol * viol / (g2 + w_eps)


def imagine(state: RobotState, obstacles: Obstacles, goal, params: StackParams, *,
            modes: tuple[str, ...] = BEHAVIORS, shared: bool = True, current: str | None = None,
            release_v: np.ndarray | None = None, start: tuple[np.ndarray, np.ndarray] | None = None,
            rules: PlusRules = PAPER_RULES, score_steps: int | None = None) -> Imagination:
    """eq:behavior_rollout (12) rollouts of ``modes`` from ``state`` and their scores (eq:behavior_terms (13),
    eq:behavior_cost (14), eq:behavior_acceptance (22), eq:analytic_workload (24)).

    ``shared`` False is BIG-CBF-NoShared: D_i = r_R + r_i + d0 + noshared_margin_m instead of kappa_img m_i.
    ``current`` is b_cur for C_sw (None: no mode retained yet, C_sw = 0). ``release_v``: see :func:`_rollout`.
    ``rules``: our rules beyond the paper (:class:`~bigcbf.params.stack.PlusRules`; default every one off).
    ``score_steps`` Ns (big-cbf-plus's rule long_horizon; None: N): the rollouts run N steps, every score
    (eq:behavior_terms (13), eq:behavior_cost (14), eq:analytic_workload (24)) and the barrier acceptance
    (eq:behavior_acceptance (22)) are those of the first Ns steps, as the paper's imagination over Ns steps would
    give them, and the acceptance also asks h >= -eps_h of the moving obstacles over all N steps: the longer
    look-ahead only rejects a candidate that walks into a person's path.

    The barrier and compatibility terms do not feed back into the rollout, so they are evaluated after it in one
    shot over (behaviors, steps, obstacles).

    Inputs with a perception fault (``bigcbf.control.faults``) raise ValueError: a NaN would make every comparison
    false and rollouts NaN; the planner brakes before it gets here (``planner.fail_safe``).
    """
    why = perception_fault(state, obstacles, goal)
    if why is not None:
        raise ValueError(f"imagine: perception fault ({why}); the planner brakes instead (control/faults.py)")
    N = params.N
    goal = np.asarray(goal, float)
    pg = complex(goal[0], goal[1])
    ro = _rollout(state, obstacles, goal, params, tuple(modes),
                  None if release_v is None else np.asarray(release_v, complex), start, rules, score_steps)
    Pc, Uc, TH = ro.P, ro.U, ro.TH
    U = np.zeros((ro.K.B, N, 3))
    U[..., 0], U[..., 1] = Uc[:, :N].real, Uc[:, :N].imag
    speed = np.abs(Uc)                                                 # ||u_xy|| (B, N+1)
    Ns = N if score_steps is None else min(int(score_steps), N)
    h_min, W, deficit, margin = _barrier_terms(ro, speed, obstacles, params, shared, Ns)

    # ---- scores (eq:behavior_terms (13), eq:behavior_cost (14)), over the first Ns steps
    P_hist = np.stack([Pc.real, Pc.imag], -1)
    Pr = np.abs(pg - Pc[:, 0]) - np.abs(pg - Pc[:, Ns])
    outside = kernels.outside_goal_region(np.abs(pg - Pc[:, :Ns]), params.eps_g_m)  # standing still there is arrival
    F = np.mean((speed[:, :Ns] < params.v_freeze_mps) & outside, axis=1)
    dU = np.diff(Uc[:, :Ns], axis=1)
    S = np.sum(dU.real ** 2 + dU.imag ** 2, axis=1) + speed[:, 0] ** 2   # u_w = 0 in every behavior
    C = np.array([current is not None and m != current for m in modes], float)
    J = params.w_W * W - params.w_P * Pr + params.w_F * F + params.w_sw * C + params.w_S * S
    dyn = has_dynamic(obstacles)
    available = np.array([m != REVERSE and (dyn or m != "YIELD") for m in modes])
    accepted = available & (h_min >= -params.eps_h_m2)
    stall = ((params.v_freeze_mps * Ns * params.dt_s, kernels.in_goal_region(np.abs(pg - Pc[:, Ns]), params.eps_g_m))
             if rules.speed_governor else None)
    return Imagination(tuple(modes), P_hist, TH, U, h_min, W, Pr, F, S, C, J, available, accepted, deficit, margin,
                       stall, ro.along)
