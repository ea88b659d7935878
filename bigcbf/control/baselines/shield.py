"""Closed-loop fallback-policy rollouts shared by the two policy shields (backup-CBF and PL-CBF).

A fallback policy maps (step k, robot positions (B, 2), predicted obstacles O^k) to commanded world
velocities (B, 2). The rollout's state is the robot's realized world velocity v (what odometry measures); a
command asks, through the nominal execution model ``eq:execution`` (A, d; the yaw is held, wz = 0), for the realized
velocity E(c) = R(theta)(A_xy R(theta)^T c + d_xy), which the robot reaches with an acceleration limit ``a_max``
(it cannot stop instantly: :func:`~bigcbf.control.baselines.common.accel_limited`); semi-implicit Euler:

    v_{k+1} = accel_limited(v_k, E(pi(k, p_k, O^k))),   p_{k+1} = p_k + dt v_{k+1}.

The initial v0 is a realized velocity too (measured, or E of the command about to be sent).

Safety of a rollout is the method's own barrier h_i^k = ||q_i^k||^2 - D_i^2 >= 0 (D_i of the shield's
:class:`~bigcbf.control.baselines.common.Geometry`: footprint, obstacle radius, d0 and the method's margin) for
every obstacle i and every state k = 0..K against the shared prediction (``eq:obs_prop``, ``eq:cov_prop``).

Both shields then impose, as their sources do, a CBF condition on the value of a policy's rollout as a function of
the current state, dV/dt >= -alpha V (Chen et al. 2021, the backup-CBF QP: one constraint per discretized state of the backup
trajectory; Kim et al. 2026: one on the selected policy's V = min_k h). The robot's input is a velocity command, so
the discrete form over one control period T_C is used, V(x_1(u)) >= (1 - alpha T_C) V(x_0), with x_1(u) the state
after T_C under u (:func:`one_step`, velocity E(u)) and x_0 the current one (measured velocity). V(x_1(u)) is
linearized (at u_nom, then again at each answer: :func:`solve_sqp`) by finite differences of ``FD_STEP`` in the body command's vx and vy (the sensitivity matrices
of Chen et al. and the JAX gradients of tkkim-robot/plcbf, computed numerically): :func:`value_rows` gives the
rows C u >= l of the QP min ||u - u_nom||^2 (the authors' QP), solved exactly by ``bigcbf.control.smallqp``. The
barrier there is the signed distance h = ||q_i|| - D_i (safe_control's ``_h_safety`` and plcbf's value function,
both dist - radii - margin), the minimum over obstacles at each state.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ...params.stack import StackParams
from ...types import Obstacles, RobotState
from ..behaviors import behavior_command
from ..planner import PlanInfo, clip_command, fail_safe
from .. import kernels
from ..kernels import execution_velocity
from .. import smallqp
from .common import (Geometry, Prediction, accel_limited, at_goal, barrier_along, body_from_world,
                     surface_distance)

Policy = Callable[[int, np.ndarray, np.ndarray], np.ndarray]


@dataclass
class Rollout:
    p: np.ndarray        # (B, K+1, 2) positions [m]
    v_cmd: np.ndarray    # (B, K, 2) commanded world velocities [m/s]
    u: np.ndarray        # (B, K, 3) body commands realizing v_cmd
    h_min: np.ndarray    # (B,) min over k = 0..K and i of h_i^k [m^2] (+inf without obstacles)


def rollout(p0: np.ndarray, v0: np.ndarray, theta: float, policy: Policy, pred: Prediction,
            params: StackParams, a_max: float, geometry: Geometry = Geometry()) -> Rollout:
    """Roll B closed-loop policies out from positions p0 (B, 2) and world velocities v0 (B, 2) over the
    prediction's horizon (see the module docstring); ``policy`` returns (B, 2) commands for all rows."""
    K, dt = pred.p.shape[0] - 1, params.dt_s
    ex = params.uncertainty.execution
    p = np.array(np.broadcast_to(p0, np.shape(v0)), float)
    v = np.array(v0, float)
    B = len(p)
    P = np.empty((B, K + 1, 2))
    Vc = np.empty((B, K, 2))
    P[:, 0] = p
    # the yaw is held, so eq:execution on a world command is affine: E(cmd) = R (A_xy R^T cmd + d_xy) = cmd M^T + c
    c = execution_velocity(theta, np.zeros(3), ex)
    M = np.stack([execution_velocity(theta, body_from_world(theta, e), ex) - c for e in np.eye(2)], -1)
    ideal = bool(np.allclose(M, np.eye(2), rtol=0, atol=1e-15) and not c.any())
    for k in range(K):
        cmd = policy(k, p, pred.p[k])
        Vc[:, k] = cmd
        v = accel_limited(v, cmd if ideal else cmd @ M.T + c, a_max, dt)
        p = kernels.euler_step(p, v, dt)
        P[:, k + 1] = p
    U = body_from_world(theta, Vc)
    h = barrier_along(P, pred, params, geometry)
    h_min = h.min(axis=(1, 2)) if pred.M else np.full(B, np.inf)
    return Rollout(P, Vc, U, h_min)


#: finite-difference step of the value sensitivities [m/s]
FD_STEP = 1e-3


def sensitivity_commands(u_nom: np.ndarray) -> np.ndarray:
    """u_nom, u_nom + FD_STEP e_vx and u_nom + FD_STEP e_vy (3, 3) (body twists)."""
    return np.asarray(u_nom, float)[None] + FD_STEP * np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])


def min_distance(paths: np.ndarray, pred: Prediction, params: StackParams, geometry: Geometry) -> np.ndarray:
    """h^k = min_i ||q_i^k|| - D_i along rollouts (B, K+1, 2) -> (B, K+1) [m] (+inf without obstacles)."""
    if pred.M == 0:
        return np.full(paths.shape[:2], np.inf)
    return surface_distance(paths, pred, params, geometry).min(axis=2)


def value_rows(h0: np.ndarray, h1: np.ndarray, u_nom: np.ndarray, decay: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows C u >= l (R, 3), (R,) of the discrete CBF condition h(x_1(u)) >= decay h(x_0) linearized at u_nom:
    h0 (R,) the values from the current state, h1 (3, R) those from x_1 of ``sensitivity_commands(u_nom)``
    (u_nom here is the linearization point),
    decay (R,) = 1 - alpha T_C per row. Rows with a non-finite value (no obstacle) are dropped."""
    G = (h1[1:] - h1[0]) / FD_STEP                                     # (2, R): d h / d (vx, vy)
    ok = np.isfinite(h0) & np.isfinite(h1).all(axis=0)
    C = np.zeros((int(ok.sum()), 3))
    C[:, 0], C[:, 1] = G[0, ok], G[1, ok]
    l = decay[ok] * h0[ok] - h1[0, ok] + C[:, 0] * u_nom[0] + C[:, 1] * u_nom[1]
    return C, l


def solve_rows(C: np.ndarray, l: np.ndarray, u_nom: np.ndarray, params: StackParams) -> np.ndarray | None:
    """min ||u - u_nom||^2 s.t. C u >= l and the actuator box (``smallqp.solve_hard``); None when infeasible."""
    lo, hi = np.asarray(params.u_min, float), np.asarray(params.u_max, float)
    u0 = np.clip(np.asarray(u_nom, float), lo, hi)
    if len(C) == 0:
        return u0
    status, u = smallqp.solve_hard(np.ascontiguousarray(C), np.ascontiguousarray(l, dtype=float), u0,
                                   np.ones(3), lo, hi)
    return u if status == smallqp.OK else None


#: linearizations of the discrete condition per control tick (sequential QP: each relinearizes at the last answer)
SQP_ITERATIONS = 3


def solve_sqp(values_at: Callable[[np.ndarray], np.ndarray], h0: np.ndarray, decay: np.ndarray,
              u_nom: np.ndarray, params: StackParams) -> np.ndarray | None:
    """min ||u - u_nom||^2 s.t. h(x_1(u)) >= decay h(x_0) and the box, by ``SQP_ITERATIONS`` linearizations:
    ``values_at(U (3, 3))`` gives h(x_1) (3, R) at ``sensitivity_commands(u_lin)``; the first u_lin is u_nom, each
    next one the last QP answer. None when a QP is infeasible."""
    u = np.asarray(u_nom, float)
    for _ in range(SQP_ITERATIONS):
        C, l = value_rows(h0, values_at(sensitivity_commands(u)), u, decay)
        nxt = solve_rows(C, l, u_nom, params)
        if nxt is None:
            return None
        if np.allclose(nxt, u, rtol=0, atol=1e-9):
            return nxt
        u = nxt
    return u


def one_step(p: np.ndarray, theta: float, u_body: np.ndarray, params: StackParams) -> np.ndarray:
    """The position after one control period T_C under u (``eq:execution``, nominal): p + T_C R(theta)(A u + d)."""
    return kernels.euler_step(np.asarray(p, float), execution_velocity(theta, np.asarray(u_body, float),
                                                                       params.uncertainty.execution), params.T_C_s)


class ShieldPlanner:
    """What the policy shields share: at every control tick the nominal input is the GOAL feedback law
    (eq:behavior_feedback with b = GOAL, as for CBF-only) and ``shield`` decides what to send instead; zero inside the
    goal region. Deterministic (``reset`` ignores the seed); ``last_h_min`` keeps the latest rollouts' worst barrier
    values."""

    name = ""

    def __init__(self, params: StackParams):
        self.params = params
        self.last_h_min: np.ndarray | None = None

    def reset(self, seed: int) -> None:
        self.last_h_min = None

    def shield(self, state: RobotState, obstacles: Obstacles, goal: np.ndarray,
               u_nom: np.ndarray) -> tuple[np.ndarray, str, np.ndarray | None]:
        """(u_in, mode, rollout path shown in videos) for ``u_nom`` (the GOAL law's command clipped to the actuator
        box) with at least one obstacle (:meth:`plan` sends ``u_nom`` itself when there is none)."""
        raise NotImplementedError

    @fail_safe
    def plan(self, t: float, state: RobotState, obstacles: Obstacles, goal) -> tuple[np.ndarray, PlanInfo]:
        t0 = time.perf_counter()
        goal = np.asarray(goal, float).reshape(2)
        if at_goal(state, goal, self.params):
            return np.zeros(3), PlanInfo("NOMINAL", True, (time.perf_counter() - t0) * 1e3, None)
        u_nom = clip_command(behavior_command("GOAL", state, obstacles, goal, self.params), self.params)
        if len(obstacles) == 0:                       # nothing to avoid: every value is +inf, the nominal input
            self.last_h_min = None
            return u_nom, PlanInfo("NOMINAL", True, (time.perf_counter() - t0) * 1e3, None)
        u, mode, path = self.shield(state, obstacles, goal, u_nom)
        return u, PlanInfo(mode, True, (time.perf_counter() - t0) * 1e3, path)
