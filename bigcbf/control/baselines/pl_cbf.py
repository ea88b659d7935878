"""PL-CBF + CBF: Policy-Library CBF (Kim, Okamoto, Hoxha, Fainekos and Panagou 2026, "Policy Library CBF:
finite-horizon safety at runtime via parallel rollouts"); reference implementation: tkkim-robot/plcbf,
``examples/warehouse/algorithms/plcbf_di.py`` (class ``PLCBF_DI``, the planar holonomic example) on ``plcbf/pcbf.py``.

PL-CBF generalizes the single backup policy of backup CBFs to a library of closed-loop policies rolled out in
parallel. Each policy pi_l has a value V_l(x) = min over the horizon of h(phi_l(tau, x)) (positive: pi_l keeps the
robot safe from x); the controller selects one policy and solves min ||u - u_nom||^2 subject to the CBF condition
on its value, dV_l/dt >= -alpha V_l, and the input box. As in ``PLCBF_DI``, at every control tick:

* Nominal: the GOAL feedback law (eq:behavior_feedback (11) with b = GOAL), as for CBF-only.
* Library (``_setup_policies``): ``n_angle`` = 10 "angle" policies, each driving at the speed limit v_max (the
  authors' v_ref, capped by the robot) along the fixed world direction 2 pi j / n_angle for the whole horizon; the
  "stop" policy (zero velocity); and the "nominal" waypoint policy (towards the goal at v_max, slowing within
  ``slow_radius_m`` of it). Rolled out by :func:`.shield.rollout` (velocity tracked with the acceleration limit
  ``a_max_mps2``, the robot's) over ``horizon_s`` = 2.0 s (``eval_horizon_steps`` of ``PLCBF_DI``) against the
  shared prediction (eq:obs_prop, eq:cov_prop). All obstacles count (the authors' warehouse example evaluates V on
  the moving ones and leaves static ones to a separate HO-CBF; here the common hard CBF downstream is that
  separate filter for every method, and the paper's PL-CBF acts in the static scenes too).
* Value V_l = min over the horizon and the obstacles of ||q_i|| - D_i (plcbf's ``dist - (r_o + r_R + margin)``;
  the authors' smooth minimum is replaced by the exact one), D_i = r_R + r_i + d0 + ``margin_m``: the task's
  clearance of eq:true_safety_requirement (6) plus the authors' ``safety_margin`` (default 0.0).
* Selection (``max_operator = 'input_space'``, the authors' default): each policy's score is the area of the inputs
  in the actuator box that satisfy its linearized CBF condition (``_compute_feasible_area_jit``; V itself when the
  condition does not depend on the input); among policies with V > 0 the largest score wins (ties within 1e-3: the
  larger V, then the angle policy best aligned with u_nom); if none has V > 0, the largest score.
* QP: min ||u - u_nom||^2 subject to V_sel(x_1(u)) >= (1 - alpha T_C) V_sel(x_0) (alpha = ``alpha_per_s`` = 5.0,
  ``cbf_alpha`` of ``PLCBF_DI``; discrete form, sensitivities and relinearization in :mod:`.shield`) and the actuator box. If it is
  infeasible, the selected policy's first command is executed (the authors' fallback to the backup input).

Modes: NOMINAL (u_nom kept), PL-<policy> (the QP changed u_nom under that policy's value), <policy> (infeasible:
the policy's command). Deterministic.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...params.checks import check_ranges, ranged
from ...params.stack import StackParams
from ...types import Obstacles, RobotState
from ..kernels import execution_velocity
from .common import Geometry, body_from_world, clip_command, predict, world_velocity
from .shield import ShieldPlanner, min_distance, one_step, rollout, sensitivity_commands, solve_sqp

#: score and value ties of the selection rule (``PLCBF_DI.solve_control_problem``)
_TIE = 1e-3
#: below this |grad V . g| the score is V itself (``min_lg_norm`` of ``PLCBF_DI``)
_MIN_LG = 1e-3


@dataclass(frozen=True)
class PlCbfParams:
    """The authors' defaults (tkkim-robot/plcbf ``PLCBF_DI``): 10 angle policies, 2.0 s evaluation horizon,
    cbf_alpha 5.0, safety margin 0; speeds and accelerations are this robot's."""

    n_angle: int = ranged(10, 1, 360)  # angle policies [-]
    horizon_s: float = ranged(2.0, 0, 20, lo_open=True)  # evaluation horizon [s]
    alpha_per_s: float = ranged(5.0, 0, 1000, lo_open=True)  # class-K gain of the selected value's condition [1/s]
    a_max_mps2: float = ranged(2.0, 0, 50, lo_open=True)  # acceleration limit of the rollouts [m/s^2]
    slow_radius_m: float = ranged(1.0, 0, 100, lo_open=True)  # the nominal policy slows within this of the goal [m]
    margin_m: float = ranged(0.0, 0, 2)  # safety margin beyond r_R + r_i + d0 [m]

    def __post_init__(self):
        check_ranges(self, positive=("horizon_s", "alpha_per_s", "a_max_mps2", "slow_radius_m"),
                     min_int={"n_angle": 1})


class PolicyLibrary:
    """The library as one batched policy over rows grouped by start state: row c * L + l is policy l
    (angle-0..angle-(n-1), stop, nominal) from start state c."""

    def __init__(self, params: StackParams, pl: PlCbfParams, goal: np.ndarray):
        self.params, self.pl, self.goal = params, pl, np.asarray(goal, float)
        self.names = tuple(f"angle-{j}" for j in range(pl.n_angle)) + ("stop", "nominal")
        a = 2 * np.pi * np.arange(pl.n_angle) / pl.n_angle
        self.angles = a
        self.v_angle = params.v_max_mps * np.stack([np.cos(a), np.sin(a)], -1)      # (n_angle, 2)

    def __len__(self) -> int:
        return len(self.names)

    def __call__(self, k: int, p: np.ndarray, obs_p: np.ndarray) -> np.ndarray:
        L, n = len(self), self.pl.n_angle
        out = np.zeros((len(p) // L, L, 2))
        out[:, :n] = self.v_angle[None]
        e = self.goal[None] - p.reshape(-1, L, 2)[:, -1]
        dist = np.hypot(e[:, 0], e[:, 1])
        speed = self.params.v_max_mps * np.minimum(1.0, dist / self.pl.slow_radius_m)
        out[:, -1] = e * (speed / np.maximum(dist, 1e-12))[:, None]
        return out.reshape(-1, 2)


def feasible_area(g: np.ndarray, b: float, lo: np.ndarray, hi: np.ndarray) -> float:
    """Area of {u in [lo, hi] (2-D box) : g . u >= b} (plcbf's ``_compute_feasible_area_jit``: the box clipped by
    the half-plane, Sutherland-Hodgman, shoelace)."""
    box = [(lo[0], lo[1]), (hi[0], lo[1]), (hi[0], hi[1]), (lo[0], hi[1])]
    out = []
    for i in range(4):
        a, c = np.array(box[i]), np.array(box[(i + 1) % 4])
        fa, fc = g @ a - b, g @ c - b
        if fa >= 0:
            out.append(a)
        if (fa >= 0) != (fc >= 0):
            out.append(a + (c - a) * (fa / (fa - fc)))
    if len(out) < 3:
        return 0.0
    P = np.array(out)
    return float(0.5 * abs(np.dot(P[:, 0], np.roll(P[:, 1], -1)) - np.dot(P[:, 1], np.roll(P[:, 0], -1))))


def select_policy(V: np.ndarray, score: np.ndarray, alignment: np.ndarray) -> int:
    """The selection rule of ``PLCBF_DI.solve_control_problem``, in its order over the library."""
    best = 0
    for j in range(1, len(V)):
        bV, bS = V[best], score[best]
        if V[j] > 0 and bV > 0:
            if score[j] > bS + _TIE:
                best = j
            elif abs(score[j] - bS) <= _TIE:
                if V[j] > bV + _TIE or (abs(V[j] - bV) <= _TIE and alignment[j] > alignment[best]):
                    best = j
        elif V[j] > 0 and bV <= 0:
            best = j
        elif V[j] <= 0 and bV <= 0 and score[j] > bS + _TIE:
            best = j
    return best


class PlCbfPlanner(ShieldPlanner):
    """PL-CBF at every control tick (deterministic; ``reset`` ignores the seed)."""

    name = "pl-cbf"
    params_type = PlCbfParams

    def __init__(self, params: StackParams, pl: PlCbfParams = PlCbfParams()):
        super().__init__(params)
        self.pl = pl

    def shield(self, state: RobotState, obstacles: Obstacles, goal: np.ndarray, u_nom: np.ndarray):
        p, pl = self.params, self.pl
        K = max(1, int(round(pl.horizon_s / p.dt_s)))
        geo = Geometry(pl.margin_m)
        lib = PolicyLibrary(p, pl, goal)
        L = len(lib)
        # V_l from the current state (measured velocity) ...
        pred0 = predict(obstacles, p, K)
        ro0 = rollout(np.tile(state.p, (L, 1)), np.tile(world_velocity(state), (L, 1)), state.theta, lib, pred0, p,
                      pl.a_max_mps2, geo)
        V0 = min_distance(ro0.p, pred0, p, geo).min(axis=1)                          # (L,)
        # ... and from the state after T_C under u_nom and its perturbations (3 start states x L policies)
        U = sensitivity_commands(u_nom)
        p1 = one_step(state.p[None], state.theta, U, p)
        v1 = execution_velocity(state.theta, U, p.uncertainty.execution)
        pred1 = predict(obstacles, p, K, t0_s=p.T_C_s)
        ro1 = rollout(np.repeat(p1, L, axis=0), np.repeat(v1, L, axis=0), state.theta, lib, pred1, p,
                      pl.a_max_mps2, geo)
        V1 = min_distance(ro1.p, pred1, p, geo).min(axis=1).reshape(3, L)
        self.last_h_min = V0
        decay = np.full(L, 1.0 - pl.alpha_per_s * p.T_C_s)
        G = (V1[1:] - V1[0]) / (U[1, 0] - U[0, 0])                                   # (2, L)
        lo, hi = np.asarray(p.u_min, float)[:2], np.asarray(p.u_max, float)[:2]
        score = np.empty(L)
        for j in range(L):
            if not (np.isfinite(V0[j]) and np.isfinite(V1[:, j]).all()):
                score[j] = np.inf if not np.isfinite(V0[j]) else V0[j]
            elif np.hypot(*G[:, j]) < _MIN_LG:
                score[j] = V0[j]
            else:
                b = decay[j] * V0[j] - V1[0, j] + G[:, j] @ u_nom[:2]
                score[j] = feasible_area(G[:, j], b, lo, hi)
        alignment = np.full(L, -1.0)
        if np.hypot(u_nom[0], u_nom[1]) > 0.1:
            v_nom = world_velocity(RobotState(state.px, state.py, state.theta, u_nom[0], u_nom[1]))
            alignment[:pl.n_angle] = np.cos(lib.angles - np.arctan2(v_nom[1], v_nom[0]))
        j = select_policy(V0, score, alignment)
        def values_at(Uc):
            ro = rollout(np.repeat(one_step(state.p[None], state.theta, Uc, p), L, axis=0),
                         np.repeat(execution_velocity(state.theta, Uc, p.uncertainty.execution), L, axis=0),
                         state.theta, lib, pred1, p, pl.a_max_mps2, geo)
            self._path = ro.p[j]
            return min_distance(ro.p, pred1, p, geo).min(axis=1).reshape(3, L)[:, j:j + 1]

        u = solve_sqp(values_at, V0[j:j + 1], decay[j:j + 1], u_nom, p)
        if u is None:
            return clip_command(body_from_world(state.theta, ro0.v_cmd[j, 0]), p), lib.names[j].upper(), ro0.p[j]
        u = clip_command(u, p)
        mode = "NOMINAL" if np.allclose(u, u_nom, rtol=0, atol=1e-9) else "PL-" + lib.names[j].upper()
        return u, mode, self._path
