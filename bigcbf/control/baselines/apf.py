"""APF + CBF: the artificial potential field of Khatib (1986) at the control rate.

Khatib's potential U = U_att + sum_i U_rep,i; the command is the saturated negative gradient, read as a
velocity (first-order, "velocity = force" form used for velocity-controlled mobile bases):

* Attraction (:func:`attractive_velocity`): U_att = 1/2 k_att ||p - p_g||^2 within ``d_conic_m`` of the goal and
  conic (k_att d_conic ||p - p_g||) beyond, so -grad U_att = k_att e inside and k_att d_conic e/||e|| outside
  (e = p_g - p): bounded far away, vanishing at the goal.
* Repulsion (:func:`repulsive_velocity`), Khatib's FIRAS form: U_rep,i = 1/2 k_rep (1/rho_i - 1/rho_0)^2 for
  rho_i <= rho_0, 0 beyond, with rho_i = ||q_i|| - D_i the distance between the robot's and the obstacle's
  surfaces, D_i = r_R + r_i + d0 (the task's clearance of eq:true_safety_requirement (6): Khatib's rho is the
  shortest distance to the region the robot must not enter; the method's standoff beyond it comes from its
  influence distance rho_0, no extra margin: ``margin_m`` 0; the shared uncertainty m_i of
  eq:uncertainty_margin (21) is BIG-CBF's, applied to every method by the common hard CBF downstream), so
  -grad U_rep,i = k_rep (1/rho_i - 1/rho_0) / rho_i^2 q_i/||q_i||. rho_i is floored at ``rho_min_m`` (the
  field stays finite when the estimate is already inside D_i).
* Obstacles are taken where the shared prediction (eq:obs_prop) puts them ``lookahead_s`` ahead (the current estimate
  for static ones); APF itself is reactive and has no horizon.
* The sum is saturated at v_max (translational), wz = 0 (holonomic base, circular footprint), then clipped to the
  actuator box. Zero inside the goal region.
Gains are per-method choices (Khatib gives the form, not values), documented in :class:`ApfParams`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...params.checks import check_ranges, ranged
from ...params.stack import StackParams
from ...types import Obstacles, RobotState
from ..planner import PlanInfo, fail_safe
from .common import Geometry, at_goal, body_from_world, clip_command

_TINY = 1e-12


@dataclass(frozen=True)
class ApfParams:
    """k_att 1 1/s with a 0.8 m conic radius: full speed 0.8 m/s beyond 0.8 m from the goal.
    k_rep 0.01 m^3/s and rho_0 0.6 m: 0.19 m/s push at 0.3 m from the obstacle's surface, 0.83 m/s at 0.2 m."""

    k_att_per_s: float = ranged(1.0, 0, 100)  # attractive gain [1/s]
    d_conic_m: float = ranged(0.8, 0, 100, lo_open=True)  # quadratic -> conic switch distance [m]
    k_rep_m3_per_s: float = ranged(0.01, 0, 100)  # repulsive gain [m^3/s]
    rho0_m: float = ranged(0.6, 0, 100, lo_open=True)  # influence distance beyond the inflated radius [m]
    rho_min_m: float = ranged(0.02, 0, 10, lo_open=True)  # floor of rho in the gradient [m]
    lookahead_s: float = ranged(0.0, 0, 10)  # where the prediction places dynamic obstacles [s]
    margin_m: float = ranged(0.0, 0, 2)  # safety margin beyond r_R + r_i + d0 (module docstring) [m]

    def __post_init__(self):
        check_ranges(self, positive=("d_conic_m", "rho0_m", "rho_min_m"),
                     nonneg=("k_att_per_s", "k_rep_m3_per_s", "lookahead_s"))
        if self.rho_min_m >= self.rho0_m:
            raise ValueError("rho_min_m must be < rho0_m")


def attractive_velocity(p, goal, ap: ApfParams) -> np.ndarray:
    """-grad U_att (2,) [m/s]: k_att e within d_conic, k_att d_conic e/||e|| beyond (e = p_g - p)."""
    e = np.asarray(goal, float) - np.asarray(p, float)
    n = float(np.hypot(*e))
    return ap.k_att_per_s * (e if n <= ap.d_conic_m else e * (ap.d_conic_m / n))


def repulsive_velocity(p, obs_p, D, ap: ApfParams) -> np.ndarray:
    """sum_i -grad U_rep,i (2,) [m/s] (Khatib's FIRAS): k_rep (1/rho - 1/rho_0)/rho^2 q/||q|| for rho <= rho_0,
    rho = max(||q|| - D, rho_min), q = p - p_i."""
    q = np.asarray(p, float)[None, :] - np.asarray(obs_p, float).reshape(-1, 2)
    if len(q) == 0:
        return np.zeros(2)
    qn = np.hypot(q[:, 0], q[:, 1])
    rho = np.maximum(qn - np.asarray(D, float), ap.rho_min_m)
    mag = np.where(rho <= ap.rho0_m, ap.k_rep_m3_per_s * (1.0 / rho - 1.0 / ap.rho0_m) / rho ** 2, 0.0)
    unit = q / np.maximum(qn, _TINY)[:, None]
    return (mag[:, None] * unit).sum(axis=0)


class ApfPlanner:
    """APF (Khatib 1986) at every control tick; deterministic (``reset`` ignores the seed)."""

    name = "apf"
    params_type = ApfParams

    def __init__(self, params: StackParams, apf: ApfParams = ApfParams()):
        self.params, self.apf = params, apf

    def reset(self, seed: int) -> None:
        """Stateless."""

    @fail_safe
    def plan(self, t: float, state: RobotState, obstacles: Obstacles, goal) -> tuple[np.ndarray, PlanInfo]:
        t0 = time.perf_counter()
        goal = np.asarray(goal, float).reshape(2)
        p = self.params
        if at_goal(state, goal, p):
            u = np.zeros(3)
        else:
            v = attractive_velocity(state.p, goal, self.apf)
            if len(obstacles):
                D = Geometry(self.apf.margin_m).radius(obstacles.r, p)
                obs_p = obstacles.p + self.apf.lookahead_s * obstacles.v
                v = v + repulsive_velocity(state.p, obs_p, D, self.apf)
            u = clip_command(body_from_world(state.theta, v), p)
        return u, PlanInfo(mode="APF", planned=True, planner_ms=(time.perf_counter() - t0) * 1e3, path=None)
