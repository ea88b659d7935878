"""PL-CBF + CBF: Policy-Library CBF (Kim, Okamoto, Hoxha, Fainekos and Panagou 2026, "Policy Library CBF:
finite-horizon safety at runtime via parallel rollouts"; code: github.com/tkkim-robot/plcbf).

PL-CBF generalizes the single backup policy of backup CBFs to a finite library of closed-loop fallback policies
rolled out in parallel: a state is certified when at least one library policy keeps the trajectory safe over the
horizon, and the nominal input is kept whenever it leads to a certified state. The authors' navigation examples
use a set of directional ("angle") fallback policies plus stopping; we use, as world-velocity policies
(:mod:`.shield`, acceleration limit ``a_max_mps2``, horizon N dt = 1.5 s, the shared prediction, the method's
own geometry below):

* STOP: command zero velocity;
* DIR-j, j = 0..n_dir-1: move at ``v_dir_mps`` along the goal direction rotated by 2 pi j / n_dir for
  ``t_move_s``, then stop (ending at rest, the terminal set of a backup policy);
* RELEASE: the reverse-release law of BIG-CBF's fallback (:func:`release_velocity`, closed loop: regenerated
  from the rollout's position and the predicted obstacles at every step).

At every control tick: u_nom = the GOAL feedback law (eq:behavior_feedback). The library is rolled out from the
state after one control step of u_nom (velocity that of u_nom, obstacles predicted from T_C). If at least one policy is
safe there (min h >= 0), u_nom is executed (mode NOMINAL). Otherwise the library is rolled out from the current
state (current measured velocity) and the certified policy with the best value is executed (its first command;
mode = its name). Value = goal progress of the rollout, ||p_0 - p_g|| - ||p_K - p_g|| [m], ties to the larger
min h. If nothing is certified, the policy with the largest min h (the least violating) is executed.
The authors select by a minimum-intervention QP; with a holonomic first-order base the library's first commands
are the candidate inputs, so the selection above is the discrete counterpart (documented choice).
Geometry (the method's own, not BIG-CBF's shared uncertainty): the authors' library (github.com/tkkim-robot/
safe_control, whose CBFs PL-CBF builds on) uses h = ||p - p_o||^2 - beta (r_o + r_R)^2 with beta = 1.01, i.e.
D_i = sqrt(1.01) (r_R + r_i) (``radius_scale``), a 0.5 % inflation of the footprint-plus-obstacle distance and no
additive margin. The common hard CBF downstream enforces r_R + r_i + d0 + kappa_exec m_i for every method.
Deterministic.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...params.checks import check_ranges, ranged
from ...params.stack import StackParams
from ...types import Obstacles, RobotState
from ..behaviors import goal_basis, release_velocity
from ..kernels import execution_velocity
from .common import Geometry, body_from_world, clip_command, predict, world_velocity
from .shield import ShieldPlanner, one_step, rollout


@dataclass(frozen=True)
class PlCbfParams:
    n_dir: int = ranged(8, 1, 360)  # directional policies [-]
    v_dir_mps: float = ranged(0.5, 0, 5, lo_open=True)  # speed of a directional policy [m/s]
    t_move_s: float = ranged(1.0, 0, 60, lo_open=True)  # how long a directional policy moves before stopping [s]
    a_max_mps2: float = ranged(2.0, 0, 50, lo_open=True)  # acceleration limit of the rollouts [m/s^2]
    radius_scale: float = ranged(1.01 ** 0.5, 1, 10)  # D_i = radius_scale (r_R + r_i): safe_control's beta = 1.01 on D^2 [-]
    margin_m: float = ranged(0.0, 0, 2)  # additive safety margin [m]

    def __post_init__(self):
        check_ranges(self, positive=("v_dir_mps", "t_move_s", "a_max_mps2"), min_int={"n_dir": 1})


class PolicyLibrary:
    """The fallback library as one batched policy: rows = (STOP, DIR-0..DIR-n-1, RELEASE) x candidates."""

    def __init__(self, params: StackParams, pl: PlCbfParams, goal: np.ndarray, obstacles: Obstacles):
        self.params, self.pl, self.goal, self.obstacles = params, pl, goal, obstacles
        self.names = ("STOP",) + tuple(f"DIR-{j}" for j in range(pl.n_dir)) + ("RELEASE",)

    def __len__(self) -> int:
        return len(self.names)

    def directions(self, p0: np.ndarray) -> np.ndarray:
        """Unit world directions (n_dir, 2): the goal direction from p0 rotated by 2 pi j / n_dir."""
        d_g, _, dist = goal_basis(p0, self.goal)
        base = np.arctan2(d_g[1], d_g[0]) if dist > 1e-9 else 0.0
        a = base + 2 * np.pi * np.arange(self.pl.n_dir) / self.pl.n_dir
        return np.stack([np.cos(a), np.sin(a)], -1)

    def policy(self, p0: np.ndarray):
        """The library as a Policy over rows grouped by candidate: row c * L + l is policy l from candidate c."""
        L, dt = len(self), self.params.dt_s
        dirs = self.directions(p0)
        obs = self.obstacles

        def pi(k: int, p: np.ndarray, obs_p: np.ndarray) -> np.ndarray:
            out = np.zeros_like(p).reshape(-1, L, 2)
            if k * dt < self.pl.t_move_s - 1e-9:
                out[:, 1:1 + self.pl.n_dir] = self.pl.v_dir_mps * dirs[None]
            prow = p.reshape(-1, L, 2)[:, -1]
            out[:, -1] = release_velocity(prow, self.goal, obs_p, obs.r, self.params, obs.v)
            return out.reshape(-1, 2)
        return pi


class PlCbfPlanner(ShieldPlanner):
    """PL-CBF shield at every control tick (deterministic; ``reset`` ignores the seed)."""

    name = "pl-cbf"
    params_type = PlCbfParams

    def __init__(self, params: StackParams, pl: PlCbfParams = PlCbfParams()):
        super().__init__(params)
        self.pl = pl

    def shield(self, state: RobotState, obstacles: Obstacles, goal: np.ndarray, u_nom: np.ndarray):
        p = self.params
        lib = PolicyLibrary(p, self.pl, goal, obstacles)
        L = len(lib)
        # 1) is the state after one step of the nominal certified by some library policy?
        p1 = one_step(state.p, state.theta, u_nom, p)
        v1 = execution_velocity(state.theta, u_nom, p.uncertainty.execution)
        geo = Geometry(self.pl.margin_m, self.pl.radius_scale)
        ro = rollout(np.tile(p1, (L, 1)), np.tile(v1, (L, 1)), state.theta, lib.policy(p1),
                     predict(obstacles, p, t0_s=p.T_C_s), p, self.pl.a_max_mps2, geo)
        if np.any(ro.h_min >= 0.0):
            self.last_h_min = ro.h_min
            return clip_command(u_nom, p), "NOMINAL", ro.p[int(np.argmax(ro.h_min))]
        # 2) otherwise execute the best certified library policy from the current state
        ro = rollout(np.tile(state.p, (L, 1)), np.tile(world_velocity(state), (L, 1)), state.theta,
                     lib.policy(state.p), predict(obstacles, p), p, self.pl.a_max_mps2, geo)
        self.last_h_min = ro.h_min
        ok = ro.h_min >= 0.0
        if ok.any():
            value = np.hypot(*(state.p - goal)) - np.hypot(*(ro.p[:, -1] - goal).T)
            order = np.lexsort((-ro.h_min, -value))              # best value first, ties: larger h_min
            j = int(order[ok[order]][0])
            mode = lib.names[j]
        else:
            j = int(np.argmax(ro.h_min))
            mode = lib.names[j] + "-UNCERTIFIED"
        return clip_command(body_from_world(state.theta, ro.v_cmd[j, 0]), p), mode, ro.p[j]
