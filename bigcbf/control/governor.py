"""Speed along a candidate: the CBF speed governor of BIG-CBF's behavior policies.

**What the paper leaves open.** ``eq:behavior_feedback`` (11) drives each behavior towards its subgoal at up to a
"behavior-dependent speed limit" v_b^max, and ``eq:behavior_rollout`` (12) imagines every candidate with that
command; the paper does not say how fast a behavior should move near obstacles, nor what the imagination assumes
the hard CBF will do there. Taken literally (v_b^max = 0.8 m/s for GOAL and PASS, 0.55 m/s for SIDE, everywhere),
every candidate is imagined at full speed. The shared radius m_i of eq:uncertainty_margin (21) grows with the command
through tau95 ||R(A u + d) - v_i|| and e_exec(u): with the calibrated tau95 = 0.21 s it is about 0.17 m larger at
0.8 m/s than at rest. In a 0.9 m gap between two posts the robot's centre is 0.45 m from each surface, while
r_R + d0 + m_i is about 0.47 m at full speed and 0.30 m at rest: every full-speed candidate is rejected by
``eq:behavior_acceptance`` (22) ~0.1 m before the narrowest point, the reverse-release fallback fires, and the robot
repeats this. The execution filter has the same blind spot: it evaluates D_i^exec at u_in (Sec. III-C) and holds
it fixed, so a full-speed u_in makes the gap infeasible for the filter too, while the same gap at 0.3 m/s is wide.

**Our choice: the speed along a candidate is the one that makes the most progress once the common CBF has acted
on it.** For the policy's world velocity v_b (eq:behavior_feedback (11), direction kept) and a scale s on
``GOVERNOR_GRID`` (1, 0.9, ..., 0.1, 0), the command s u_b (u_b = R^T v_b) is checked against the CBF condition
``eq:cbf_condition`` (25) of every obstacle, with D_i^exec (eq:shared_barrier (20), eq:uncertainty_margin (21),
kappa_exec) evaluated at that command, exactly as the execution filter evaluates it. In the realized velocity w
(eq:execution (1): w(s) = R(theta)(A s u_b + d)) each row is a half-plane,

    gamma_i = 2 q_i^T (w - v_i) + alpha (||q_i||^2 - D_i(s u_b)^2) >= 0
            <=>  n_i^T w >= n_i^T v_i - alpha h_i(s) / (2 ||q_i||),     n_i = q_i / ||q_i||,

and the filter model (:func:`filter_model`) is the filter's QP in 2-D: the Euclidean projection of w(s) onto the
``MODEL_ROWS`` most violated half-planes, within the speed disk v_max. Its output w*(s) is what the filter would let
the robot do. The governed scale is

    s* = argmax_s  e_b^T w*(s)       (e_b = v_b / ||v_b||; near-ties to the smaller s),

the progress along the behavior's direction after the filter: a command the filter only slows is worth its
admissible part; one it bends sideways is worth the progress the sliding keeps. With one row dead ahead this is the
smallest grid scale that reaches the admissible speed (the robot slows down before the obstacle instead of running
into its inflated radius); with a row at an angle it can be full speed, sliding along the row
(tests/control/test_control_governor.py works both out by hand).

An earlier version subtracted the filter's correction ||w*(s) - w(s)|| from the progress. It slowed every
maneuver whose direction has a component into an obstacle to a crawl: a PASS or SIDE in front of a wide obstacle
(forward part blocked, lateral part free) scored its full-speed slide and a slow slide alike, so the near-tie rule
took the slow one, and the sidestep the scene needs moved at ~0.1 m/s (required_sidestepping, seeds 0-2: 0/3 with
the correction, 3/3 without it; docs/fidelity.md, "Liveness"). The governed command is s* u_b; in the rollout
(eq:behavior_rollout (12)) the robot moves with w*(s*), the filter model's velocity, while the scores (W of
eq:analytic_workload (24); F, S of eq:behavior_terms (13)) and the acceptance (eq:behavior_acceptance (22)) use the
governed command.

Why this is principled (it holds in scenes nobody has drawn): it is the speed the filter itself would let this
direction have, computed with the same formulas (eq:shared_barrier (20), eq:uncertainty_margin (21),
eq:cbf_condition (25)), the same kappa_exec and the same obstacles, so (i) the imagination (eq:behavior_rollout
(12)) rolls out the command that will actually be executed, and m_i in eq:behavior_acceptance (22) is evaluated at
that speed: a gap is judged by whether the robot can pass it at the speed it will pass it; (ii) where
the filter would only slow the command down, the executed u_in is already CBF-admissible, so the filter leaves it
alone and D_i^exec is evaluated at the speed actually driven. A candidate that must slow down
earns less progress P and, if it must stop, the freezing penalty F (eq:behavior_terms (13)): the speed cost is scored,
not hidden.

Scope: the governor is part of BIG-CBF's policies pi_b (GOAL, PASS, SIDE; YIELD commands zero, the REVERSE
fallback keeps its chosen release velocity), applied identically in the rollout (eq:behavior_rollout (12), with
the predicted obstacles O^k of eq:obs_prop (2) and eq:cov_prop (3)) and at every control tick
(eq:online_behavior_command (8)). BIG-CBF-NoShared shares the policies, so it shares the governor (its ablation stays in
the imagination's margin). CBF-only and the baselines are untouched: their commands are their own. It uses every
obstacle the policy sees (all tracks and wall points), a superset of the filter's rows (``cbf.select_constraints``), so
it is never less conservative than the filter. It is a rule of ours, off by default: ``speed_governor = true`` in
``[methods.big-cbf-plus]`` of a run configuration (``PlusRules``; ``big-cbf``, the paper's, never governs) switches it on together with the selection's viability test and the release outlook
(docs/fidelity.md, "Liveness"), which it needs; on the nine paper scenes it is worse than the paper's reading (measured
there). No QP solver is called: 11 scales, each with a closed-form 2-D projection, for all candidates and steps at once.
"""
from __future__ import annotations

import numpy as np

from ..params.stack import StackParams
from ..types import Obstacles, RobotState
from . import kernels
from .behaviors import BEHAVIORS

#: the modes the governor applies to, at every control tick and in every rollout: the moving behaviors (YIELD
#: commands zero; the REVERSE fallback keeps its chosen release velocity)
GOVERNED_MODES: tuple[str, ...] = tuple(m for m in BEHAVIORS if m != "YIELD")
#: the scales s tried, largest first [-]
GOVERNOR_GRID = np.linspace(1.0, 0.0, 11)
#: rows of the filter model: the most violated ones at each scale [-]
MODEL_ROWS = 4
_TINY = 1e-12
_FEAS = 1e-9


def _pair_solve(n1, l1, n2, l2):
    """The point w (complex) with Re(conj(n1) w) = l1 and Re(conj(n2) w) = l2 (nan where the lines are parallel)."""
    det = n1.real * n2.imag - n1.imag * n2.real
    ok = np.abs(det) > 1e-9
    det = np.where(ok, det, 1.0)
    x = (l1 * n2.imag - l2 * n1.imag) / det
    y = (n1.real * l2 - n2.real * l1) / det
    return np.where(ok, x + 1j * y, np.nan + 0j)


def filter_model(w0, n, l, v_max: float) -> np.ndarray:
    """The imagination's model of the common filter (module docstring): the Euclidean projection of realized
    velocities w0 (...) onto the half-planes Re(conj(n_j) w) >= l_j, j = 1..K (n (..., K) unit normals, l (..., K)),
    within the speed disk ||w|| <= v_max (the filter's actuator box, approximated), solved exactly in 2-D: the optimum
    is w0, a projection onto one line, or the intersection of two lines; the closest feasible candidate. If none is
    feasible (the rows contradict each other), the candidate with the least worst violation, scaled into the disk."""
    K = n.shape[-1]
    cands = [w0]
    for j in range(K):
        cands.append(w0 + np.maximum(l[..., j] - (n[..., j].real * w0.real + n[..., j].imag * w0.imag), 0.0) * n[..., j])
    for j in range(K):
        for k in range(j + 1, K):
            cands.append(_pair_solve(n[..., j], l[..., j], n[..., k], l[..., k]))
    C = np.stack(cands, -1)                                                    # (..., Nc)
    finite = np.isfinite(C)
    Cz = np.where(finite, C, 0j)
    viol = (l[..., None, :] - (n[..., None, :].real * Cz[..., :, None].real
                               + n[..., None, :].imag * Cz[..., :, None].imag)).max(-1)   # (..., Nc)
    viol = np.where(finite, viol, np.inf)
    dist = np.abs(Cz - w0[..., None])
    feasible = (viol <= _FEAS) & (np.abs(Cz) <= v_max + 1e-9)
    key = np.where(feasible, dist, np.inf)
    best = np.argmin(key, -1)
    none = ~feasible.any(-1)
    best = np.where(none, np.argmin(viol, -1), best)
    w = np.take_along_axis(Cz, best[..., None], -1)[..., 0]
    return w * np.minimum(1.0, v_max / np.maximum(np.abs(w), _TINY))


def govern_c(p, rot, u, obs_p, obs_v, obs_sig, obs_r, params: StackParams) -> tuple[np.ndarray, np.ndarray]:
    """The governor (module docstring; ``eq:cbf_condition`` (25) with D_i of ``eq:shared_barrier`` (20) and
    ``eq:uncertainty_margin`` (21)) on complex planar vectors, for B robot states at once.

    p (B,) positions, rot (B,) e^{i theta}, u (B,) body commands u_x + i u_y of eq:behavior_feedback (11) (u_w = 0),
    obs_p (M,) obstacle positions, obs_v (M,) velocities, obs_sig (M,) beta sqrt(lambda_max(Sigma_i)) [m], obs_r (M,)
    radii. Returns the scale s* (B,) and the filter model's realized velocity w* (B,) of the governed command s* u.
    """
    p, rot, u = np.asarray(p, complex), np.asarray(rot, complex), np.asarray(u, complex)
    B = p.shape[0]
    unc, ex = params.uncertainty, params.uncertainty.execution
    a_c, b_c, d_c = kernels.execution_complex(ex)                             # eq:execution
    Rd = rot * d_c                                                             # R d (B,)
    L = rot * (a_c * u + b_c * np.conj(u))                                     # R A u (B,): w(s) = s L + R d
    M = np.shape(obs_r)[0]
    if M == 0:
        return np.ones(B), L + Rd
    S = GOVERNOR_GRID
    W0 = S[None, :] * L[:, None] + Rd[:, None]                                 # (B, S)
    q = (p[:, None] - obs_p)[:, None, :]                                       # (B, 1, M)
    qn = np.maximum(np.abs(q), _TINY)
    nrm = q / qn
    relv = W0[:, :, None] - obs_v                                              # (B, S, M)
    speed = S[None, :] * np.abs(u)[:, None]                                    # ||s u_xy|| (B, S)
    m = kernels.uncertainty_radius(np.abs(relv), obs_sig, kernels.e_exec_speed(speed, ex)[:, :, None],
                                   unc)                                        # eq:uncertainty_margin
    # eq:shared_barrier, summed as the compiled CBF rows sum it ((r_R + d0) + r_i, cbf._rows_kernel), not as
    # kernels.inflated_radius ((r_R + r_i) + d0): the governor models the filter (equal to rounding)
    D = (unc.r_robot_m + unc.d0_m) + np.asarray(obs_r, float) + unc.kappa_exec * m
    h = kernels.barrier(qn * qn, D)
    # eq:cbf_condition (25) in the realized velocity w: Re(conj(n_i) w) >= Re(conj(n_i) v_i) - alpha h_i / (2 ||q_i||)
    lim = (nrm.real * obs_v.real + nrm.imag * obs_v.imag) - params.alpha_per_s * h / (2.0 * qn)
    viol = lim - (nrm.real * W0[:, :, None].real + nrm.imag * W0[:, :, None].imag)
    Kr = min(MODEL_ROWS, M)
    top = np.argpartition(-viol, Kr - 1, axis=-1)[..., :Kr] if M > Kr else np.broadcast_to(np.arange(M), viol.shape)
    n_top = np.take_along_axis(np.broadcast_to(nrm, viol.shape), top, -1)
    l_top = np.take_along_axis(lim, top, -1)
    w = filter_model(W0, n_top, l_top, params.v_max_mps)                       # (B, S)
    dirn = L / np.maximum(np.abs(L), _TINY)
    prog = dirn.real[:, None] * w.real + dirn.imag[:, None] * w.imag          # progress along the behavior (B, S)
    rows = np.arange(B)
    best = np.argmax(prog - 1e-9 * S[None, :], axis=1)   # progress after the filter; near-ties to the smaller scale
    s = np.where(np.abs(u) > _TINY, S[best], 1.0)
    return s, np.where(np.abs(u) > _TINY, w[rows, best], Rd)


def obstacle_sigma_term(cov, params: StackParams) -> np.ndarray:
    """beta sqrt(lambda_max(Sigma_i)) [m] (the obstacle-prediction term of ``eq:uncertainty_margin``), for
    covariances (..., 2, 2): ``kernels.prediction_term``."""
    return kernels.prediction_term(cov, params.uncertainty)


def govern_command(state: RobotState, obstacles: Obstacles, u, params: StackParams) -> tuple[np.ndarray, float]:
    """The governed body command s* u (3,) and s* for one robot state (module docstring). ``u`` (3,) is a behavior's
    body twist from eq:behavior_feedback (11); its yaw rate is scaled with it (the behaviors command none). The
    caller applies it only with the rule ``speed_governor`` (``big-cbf-plus``)."""
    u = np.asarray(u, float).reshape(3)
    if len(obstacles) == 0:
        return u, 1.0
    op = obstacles.p[:, 0] + 1j * obstacles.p[:, 1]
    ov = obstacles.v[:, 0] + 1j * obstacles.v[:, 1]
    s, _ = govern_c(np.array([complex(state.px, state.py)]), np.array([np.exp(1j * state.theta)]),
                    np.array([complex(u[0], u[1])]), op, ov, obstacle_sigma_term(obstacles.cov, params),
                    obstacles.r, params)
    return u * float(s[0]), float(s[0])
