"""Backup-CBF + CBF: backup control barrier functions after Chen, Jankovic, Santillo and Ames (2021), "Backup control
barrier functions: formulation and comparative study"; reference implementation: tkkim-robot/safe_control,
``position_control/backup_cbf_qp.py`` (class ``BackupCBF``) with its ``StoppingController``.

Backup CBFs certify a state when the closed-loop trajectory phi_b(tau, x) of a backup policy pi_b stays in the safe
set over a horizon T and ends in a backup set S_B (a controlled-invariant set of pi_b): the implicit safe set
S_I = {x : h(phi_b(tau, x)) >= 0 for tau in [0, T], h_B(phi_b(T, x)) >= 0}. They enforce it with a QP that keeps
the input closest to the nominal one subject to a CBF condition on every discretized state of the backup trajectory,
d/dt h(phi_b(tau_i, x)) >= -alpha h(phi_b(tau_i, x)), and on the terminal backup set with alpha_B. Because these
are CBF conditions, not a yes/no certificate, they act before the backup trajectory becomes unsafe (they bound how
fast it may approach an obstacle), and where it is already unsafe (the robot inside the task's clearance, where
braking alone does not certify) they demand that it recover at rate alpha. Here, at every control tick:

* Nominal: the GOAL feedback law (eq:behavior_feedback (11) with b = GOAL), as for CBF-only.
* Backup policy pi_b: braking to rest (safe_control's ``StoppingController``: world velocity command 0 tracked with
  the deceleration limit ``a_brake_mps2``), flowed forward by :func:`.shield.rollout` over ``horizon_s`` = 2.0 s
  (``backup_horizon`` of ``BackupCBF``) in steps of dt_s against the shared prediction (eq:obs_prop, eq:cov_prop).
* Safety h = min_i ||q_i|| - D_i with D_i = r_R + r_i + d0 + ``margin_m``: the task's clearance of
  eq:true_safety_requirement (6) plus safe_control's ``safety_margin`` (default 0.0).
* Backup set S_B: at rest and safe (safe_control's ``_h_terminal`` for a double integrator: v_max - ||v|| >= 0
  and h >= 0 at tau = T). Braking from the speed limit ends at rest within 0.8 / a_brake = 0.4 s, so the velocity
  part holds on every rollout and the terminal row is the h row at tau = T with ``alpha_terminal``.
* QP (:func:`.shield.solve_sqp`): min ||u - u_nom||^2 subject to
  h(phi_b(tau_i, x_1(u))) >= (1 - alpha T_C) h(phi_b(tau_i, x_0)) for i = 0..K (alpha = ``alpha_per_s``, 1.0 1/s,
  and ``alpha_terminal_per_s``, 2.0 1/s, at i = K: safe_control's ``alpha`` and ``alpha_terminal``) and the
  actuator box; the sensitivities by finite differences (:mod:`.shield`). If the QP is infeasible, the backup
  policy's command (zero velocity) is executed (mode BACKUP), as safe_control falls back to the backup control.

Modes: NOMINAL (the QP kept u_nom), BACKUP-CBF (it changed u_nom), BACKUP (infeasible). Deterministic.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...params.checks import check_ranges, ranged
from ...params.stack import StackParams
from ...types import Obstacles, RobotState
from ..kernels import execution_velocity
from .common import Geometry, clip_command, predict, world_velocity
from .shield import ShieldPlanner, min_distance, one_step, rollout, solve_sqp


@dataclass(frozen=True)
class BackupCbfParams:
    """The authors' defaults (tkkim-robot/safe_control ``BackupCBF``): 2.0 s backup horizon, alpha 1.0, alpha_terminal
    2.0, safety margin 0; the braking deceleration is this robot's (the acceleration limit of every rollout here)."""

    a_brake_mps2: float = ranged(2.0, 0, 50, lo_open=True)  # braking deceleration of the backup [m/s^2]
    horizon_s: float = ranged(2.0, 0, 20, lo_open=True)  # backup horizon T [s]
    alpha_per_s: float = ranged(1.0, 0, 1000, lo_open=True)  # class-K gain along the backup trajectory [1/s]
    alpha_terminal_per_s: float = ranged(2.0, 0, 1000, lo_open=True)  # class-K gain of the backup-set row [1/s]
    margin_m: float = ranged(0.0, 0, 2)  # safety margin beyond r_R + r_i + d0 [m]

    def __post_init__(self):
        check_ranges(self, positive=("a_brake_mps2", "horizon_s", "alpha_per_s", "alpha_terminal_per_s"))


def brake_policy(k: int, p: np.ndarray, obs_p: np.ndarray) -> np.ndarray:
    """pi_b: command zero velocity (B, 2)."""
    return np.zeros_like(p)


class BackupCbfPlanner(ShieldPlanner):
    """Backup-CBF QP at every control tick (deterministic; ``reset`` ignores the seed)."""

    name = "backup-cbf"
    params_type = BackupCbfParams

    def __init__(self, params: StackParams, backup: BackupCbfParams = BackupCbfParams()):
        super().__init__(params)
        self.backup = backup

    def shield(self, state: RobotState, obstacles: Obstacles, goal: np.ndarray, u_nom: np.ndarray):
        p, bp = self.params, self.backup
        K = max(1, int(round(bp.horizon_s / p.dt_s)))
        geo = Geometry(bp.margin_m)
        # the backup trajectory from the current state (measured velocity) ...
        pred0 = predict(obstacles, p, K)
        ro0 = rollout(state.p[None], world_velocity(state)[None], state.theta, brake_policy, pred0, p,
                      bp.a_brake_mps2, geo)
        h0 = min_distance(ro0.p, pred0, p, geo)[0]
        # ... and from the state after one control period under u and its two perturbations
        pred1 = predict(obstacles, p, K, t0_s=p.T_C_s)

        def values_at(U):
            ro1 = rollout(one_step(state.p[None], state.theta, U, p),
                          execution_velocity(state.theta, U, p.uncertainty.execution), state.theta, brake_policy,
                          pred1, p, bp.a_brake_mps2, geo)
            self._path = ro1.p[0]
            return min_distance(ro1.p, pred1, p, geo)

        self.last_h_min = h0
        decay = np.full(K + 1, 1.0 - bp.alpha_per_s * p.T_C_s)
        decay[-1] = 1.0 - bp.alpha_terminal_per_s * p.T_C_s
        u = solve_sqp(values_at, h0, decay, u_nom, p)
        if u is None:
            return np.zeros(3), "BACKUP", ro0.p[0]
        u = clip_command(u, p)
        mode = "NOMINAL" if np.allclose(u, u_nom, rtol=0, atol=1e-9) else "BACKUP-CBF"
        return u, mode, self._path
