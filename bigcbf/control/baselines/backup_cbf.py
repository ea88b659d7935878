"""Backup-CBF + CBF: a backup-policy shield after Chen, Jankovic, Santillo and Ames (2021), "Backup control
barrier functions: formulation and comparative study".

Backup CBFs certify a state as safe when the closed-loop trajectory of a backup policy pi_b started there stays
in the safe set over a finite horizon (the implicit safe set S_I = {x : h(phi_b(tau, x)) >= 0, tau in [0, T]}).
Chen et al. enforce membership of S_I with a QP whose constraints differentiate h(phi_b(tau, x)) along the flow
(sensitivity matrices). The BIG-CBF paper uses Backup-CBF as a *policy shield* in front of the common hard CBF
(Sec. IV-A), and this project's issue specifies that shield: keep u_nom while the backup rollout from the state
it leads to stays safe, otherwise intervene. The intervention here is the interpolation between the nominal and
the backup input (the form whose optimal blend van Wijk, Das, Molnar, Ames and Burdick 2025, "Safety-critical
control with bounded inputs: a closed-form solution for backup control barrier functions", derive in closed
form), searched on a grid rather than in closed form. Here, at every control tick:

* Nominal: the GOAL feedback law (eq:behavior_feedback with b = GOAL), as for CBF-only.
* Backup policy pi_b: braking to a stop (world velocity command 0) tracked with the deceleration limit
  ``a_brake_mps2`` (:mod:`.shield`); horizon N dt = 1.5 s; safety h_i^k = ||q_i^k||^2 - D_i^2 >= 0 against the
  shared prediction (eq:obs_prop, eq:cov_prop) for every obstacle and step.
* Geometry (the method's own, not BIG-CBF's shared uncertainty): D_i = r_R + r_i, the footprint against the
  obstacle with no extra margin (``margin_m`` 0). Backup CBFs certify the implicit safe set of a collision-free
  constraint set; the robustness they add comes from the backup horizon, not from an inflated radius, and Chen et
  al. state no margin. The common hard CBF downstream enforces r_R + r_i + d0 + kappa_exec m_i for every method.
* Shield (interpolation): candidates u_lambda = (1 - lambda) u_nom + lambda u_b for
  lambda on the grid ``blends`` (0 = nominal, 1 = backup). For each, the state after one control step T_C
  under u_lambda (eq:execution, nominal) is computed and the backup rollout from there (initial velocity that of
  u_lambda, obstacles predicted from T_C on) is checked. The smallest certified lambda is executed; if none is
  certified the backup command itself is executed (the shield's last resort; the hard CBF downstream handles
  what braking cannot).
The rollouts are one batch over the blend grid (one loop over the 15 steps). Deterministic.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...params.checks import check_ranges, ranged
from ...params.stack import StackParams
from ...types import Obstacles, RobotState
from ..kernels import execution_velocity
from .common import Geometry, clip_command, predict
from .shield import ShieldPlanner, one_step, rollout


@dataclass(frozen=True)
class BackupCbfParams:
    a_brake_mps2: float = ranged(2.0, 0, 50, lo_open=True)  # braking deceleration of the backup [m/s^2]
    margin_m: float = ranged(0.0, 0, 2)  # the method's own safety margin (docstring) [m]
    blends: tuple[float, ...] = ranged((0.0, 0.25, 0.5, 0.75, 1.0), 0, 1)  # lambda grid, increasing, from 0 to 1 [-]

    def __post_init__(self):
        check_ranges(self, positive=("a_brake_mps2",))
        b = self.blends
        if not b or b[0] != 0.0 or b[-1] != 1.0 or any(y <= x for x, y in zip(b, b[1:])):
            raise ValueError("blends must increase from 0.0 to 1.0")


def brake_policy(k: int, p: np.ndarray, obs_p: np.ndarray) -> np.ndarray:
    """pi_b: command zero velocity (B, 2)."""
    return np.zeros_like(p)


class BackupCbfPlanner(ShieldPlanner):
    """Backup-CBF shield at every control tick (deterministic; ``reset`` ignores the seed)."""

    name = "backup-cbf"
    params_type = BackupCbfParams

    def __init__(self, params: StackParams, backup: BackupCbfParams = BackupCbfParams()):
        super().__init__(params)
        self.backup = backup

    def shield(self, state: RobotState, obstacles: Obstacles, goal: np.ndarray, u_nom: np.ndarray):
        p = self.params
        lam = np.asarray(self.backup.blends, float)
        U = (1.0 - lam)[:, None] * u_nom[None, :]                  # u_b = 0
        v0 = execution_velocity(state.theta, U, p.uncertainty.execution)
        p1 = one_step(state.p[None], state.theta, U, p)
        pred = predict(obstacles, p, t0_s=p.T_C_s)
        ro = rollout(p1, v0, state.theta, brake_policy, pred, p, self.backup.a_brake_mps2,
                     Geometry(self.backup.margin_m))
        self.last_h_min = ro.h_min
        ok = np.flatnonzero(ro.h_min >= 0.0)
        if len(ok):
            j = int(ok[0])
            mode = "NOMINAL" if lam[j] == 0.0 else ("BACKUP" if lam[j] == 1.0 else "BLEND")
        else:
            j, mode = len(lam) - 1, "BACKUP"
        return clip_command(U[j], p), mode, ro.p[j]
