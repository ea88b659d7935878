"""MPPI + CBF: model predictive path integral control (Williams et al. 2017) at the BIG-CBF outer-loop rate.

As configured in the paper (Sec. IV-A): a planning cycle every T_B = 0.5 s (2 Hz), the same 1.5 s horizon as
BIG-CBF (N = 15 steps of dt = 0.1 s), 512 sampled control sequences, two sampling updates per cycle. Sampling
and the weights in numpy; the rollouts and their costs in one compiled pass per sample (``_rollout_costs``,
numba: the array version made (512, 15, 24) temporaries and took ~80 % of a cycle).

* Decision variable: a sequence of world-frame translational velocities V (N, 2); the body command is
  [R(theta)^T V_k, 0] (holonomic base, circular footprint: yaw is not used, wz = 0). World frame, so the
  sequence keeps its meaning if the odometry yaw drifts between updates.
* Sampling (Williams et al., Alg. 2): V^s = V + eps^s, eps ~ N(0, sigma^2 I), each sample clipped to
  |v| <= v_max; sample 0 is the unperturbed mean, sample 1 the stop sequence. The RNG is
  np.random.default_rng(seed) created in ``reset(seed)``: an episode is deterministic per seed.
* Rollout: eq:execution (nominal execution model) from the current state, obstacles by the shared prediction
  (eq:obs_prop, eq:cov_prop); the collision radius D_i = r_R + r_i + d0 + ``margin_m``: the task's clearance of
  eq:true_safety_requirement (6) plus margin_m = 0.10 m,
  the default ``collision_margin_distance`` of Nav2's MPPI controller ("margin distance from collision to apply severe
  penalty, similar to footprint inflation; between 0.05-0.2 is reasonable"; Williams et al. penalize track boundaries
  and state no obstacle margin). The shared uncertainty m_i of eq:uncertainty_margin is BIG-CBF's; the common hard CBF
  downstream applies it to every method.
* Cost S(V^s) = sum_k dt [w_goal ||p_k - p_g|| + w_coll 1(d_k < 0) + w_clear exp(-max(d_k, 0) / l_clear)]
  + w_term ||p_N - p_g|| + w_smooth sum_k ||V_k - V_{k-1}||^2 (V_{-1} = the measured velocity)
  + gamma sum_k V_k^T Sigma^{-1} eps_k (the control-cost term of the information-theoretic update, Williams'
  gamma = lambda (1 - alpha) with alpha = 0), with d_k = min_i ||q_i|| - D_i at step k.
* Update: w_s = exp(-(S_s - min S)/lambda) / sum; V <- V + sum_s w_s eps_s (then clipped); twice per cycle.
  The temperature lambda is set at each update so that the weights' effective sample size 1 / sum_s w_s^2 is
  ``ess_fraction`` of the samples (bisection on log lambda; the adaptive-temperature practice of MPPI
  implementations): a fixed lambda is meaningless against costs whose spread changes by orders of magnitude
  between an open floor and a crowd, and the fixed 0.1 used before let one sample take 97 % of the weight, so
  MPPI executed that sample's white noise (0.2 m/s lateral jitter on an empty floor).
* Warm start: the previous sequence shifted by the elapsed steps (0.5 s = 5 steps), padded with its last value.
* Between updates the optimized sequence is followed, time-indexed: at time t the command is V_k with
  k = floor((t - t_plan) / dt) (the last element beyond the horizon). Zero inside the goal region.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ...params.checks import check_ranges, ranged
from ...params.stack import StackParams
from ...types import Obstacles, RobotState
from ..jit import kernel
from ..planner import PlanInfo, fail_safe
from .common import Geometry, at_goal, body_from_world, clip_command, integrate, predict, world_velocity

_T_EPS = 1e-6
_TINY = 1e-12


@dataclass(frozen=True)
class MppiParams:
    """MPPI sampling and cost (Williams et al. give the algorithm; the paper the rate, horizon and counts)."""

    samples: int = ranged(512, 2, 20000)  # sampled sequences per update [-]
    iterations: int = ranged(2, 1, 100)  # sampling updates per planning cycle [-]
    sigma_mps: float = ranged(0.35, 0, 5, lo_open=True)  # exploration noise std per axis [m/s]
    gamma: float = ranged(0.1, 0, 1000000.0, lo_open=True)  # control-cost weight gamma [cost units]
    ess_fraction: float = ranged(0.1, 0, 1, lo_open=True)  # target effective sample size of the weights, fraction of samples [-]
    w_goal: float = ranged(2.0, 0, 1000000.0)  # running goal-distance cost [1/s]
    w_term: float = ranged(10.0, 0, 1000000.0)  # terminal goal-distance cost [1/m]
    w_coll: float = ranged(200.0, 0, 1000000.0)  # running penalty while inside an inflated radius [1/s]
    w_clear: float = ranged(2.0, 0, 1000000.0)  # running clearance cost [1/s]
    l_clear_m: float = ranged(0.15, 0, 10, lo_open=True)  # clearance cost length scale [m]
    w_smooth: float = ranged(0.05, 0, 1000000.0)  # smoothness weight [s^2/m^2]
    margin_m: float = ranged(0.10, 0, 2)  # collision margin beyond r_R + r_i + d0 (Nav2 MPPI's default; module docstring) [m]

    def __post_init__(self):
        check_ranges(self, positive=("sigma_mps", "gamma", "ess_fraction", "l_clear_m"),
                     nonneg=("w_goal", "w_term", "w_coll", "w_clear", "w_smooth"),
                     min_int={"samples": 2, "iterations": 1})
        if self.ess_fraction > 1:
            raise ValueError(f"ess_fraction must be in (0, 1], got {self.ess_fraction}")


def sample_sequences(V: np.ndarray, rng: np.random.Generator, v_max: float, mp: MppiParams
                     ) -> tuple[np.ndarray, np.ndarray]:
    """V^s = clip(V + eps^s) (S, N, 2) and the effective noises eps^s = V^s - V; sample 0 is V itself and
    sample 1 the stop sequence."""
    S, N = mp.samples, len(V)
    eps = rng.normal(0.0, mp.sigma_mps, (S, N, 2))
    Vs = V[None] + eps
    Vs[0] = V
    Vs[1] = 0.0
    n = np.hypot(Vs[..., 0], Vs[..., 1])
    Vs *= np.minimum(1.0, v_max / np.maximum(n, _TINY))[..., None]
    return Vs, Vs - V[None]


def mppi_weights(S: np.ndarray, lam: float) -> np.ndarray:
    """w_s = exp(-(S_s - min S)/lambda) / sum_s exp(-(S_s - min S)/lambda) (Williams et al. 2017, Alg. 2)."""
    z = np.exp(-(S - np.min(S)) / lam)
    return z / z.sum()


def effective_sample_size(w: np.ndarray) -> float:
    """1 / sum w_s^2 (1 when one sample has all the weight, S for uniform weights)."""
    return float(1.0 / np.dot(w, w))


def temperature(S: np.ndarray, ess_target: float, iterations: int = 40) -> float:
    """The lambda at which mppi_weights(S, lambda) has effective sample size ess_target (it grows monotonically
    with lambda, from 1 to len(S)), by bisection on log lambda between 1e-6 and 1e6 times the cost spread."""
    spread = float(np.ptp(S))
    if not spread > 0:
        return 1.0                                  # all costs equal: any lambda gives uniform weights
    d = S - np.min(S)
    lo, hi = np.log(1e-6 * spread), np.log(1e6 * spread)
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        z = np.exp(-d / np.exp(mid))
        ess = z.sum() ** 2 / np.dot(z, z)
        lo, hi = (mid, hi) if ess < ess_target else (lo, mid)
    return float(np.exp(0.5 * (lo + hi)))


@kernel
def _rollout_costs(Vs, eps, V, px, py, theta0, v0, goal, P, D, A, d, w):
    """S(V^s) and the rollout positions of ``MppiPlanner.costs``, one sample at a time: the body command u_k =
    [R(theta)^T V_k, 0] with the yaw at planning time; eq:execution nominal (no residual) integrated with forward Euler
    as ``kernels.euler_paths`` (``common.integrate``) (yaw first, then p_{k+1} = p_k + dt R(theta_k)(A u_k + d)_xy);
    d_k = min_i ||q_i|| - D_i against the shared prediction P (N, M, 2) (eq:obs_prop), with the method's own D_i
    (``Geometry``). A non-finite distance makes the cost non-finite, so ``optimize`` gives that sample no weight."""
    S, N = Vs.shape[0], Vs.shape[1]
    M = D.shape[0]
    dt, w_goal, w_term, w_coll, w_clear, l_clear, w_smooth, g_ctrl = w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]
    c0, s0 = math.cos(theta0), math.sin(theta0)
    cost = np.empty(S)
    paths = np.empty((S, N + 1, 2))
    for b in range(S):
        x, y, th, wacc = px, py, theta0, 0.0
        paths[b, 0, 0], paths[b, 0, 1] = x, y
        run_goal = 0.0
        run_obs = 0.0
        dg = 0.0
        smooth = 0.0
        ctrl = 0.0
        vpx, vpy = v0[0], v0[1]
        for k in range(N):
            Vx, Vy = Vs[b, k, 0], Vs[b, k, 1]
            ux, uy = c0 * Vx + s0 * Vy, -s0 * Vx + c0 * Vy            # body_from_world (wz = 0)
            bx = A[0, 0] * ux + A[0, 1] * uy + d[0]
            by = A[1, 0] * ux + A[1, 1] * uy + d[1]
            c, s = math.cos(th), math.sin(th)
            x += dt * (c * bx - s * by)
            y += dt * (s * bx + c * by)
            wacc += A[2, 0] * ux + A[2, 1] * uy + d[2]
            th = theta0 + dt * wacc
            paths[b, k + 1, 0], paths[b, k + 1, 1] = x, y
            dg = math.hypot(x - goal[0], y - goal[1])
            run_goal += dg
            if M > 0:
                dmin = np.inf
                bad = False
                for i in range(M):
                    qx, qy = x - P[k, i, 0], y - P[k, i, 1]
                    di = math.sqrt(qx * qx + qy * qy) - D[i]               # ||q_i|| - D_i
                    if not math.isfinite(di):
                        bad = True
                    elif di < dmin:
                        dmin = di
                if bad:
                    dmin = np.nan
                if dmin < 0.0:
                    run_obs += w_coll
                run_obs += w_clear * math.exp(-(0.0 if dmin <= 0.0 else dmin) / l_clear)
            ex_, ey_ = Vx - vpx, Vy - vpy
            smooth += ex_ * ex_ + ey_ * ey_
            vpx, vpy = Vx, Vy
            ctrl += V[k, 0] * eps[b, k, 0] + V[k, 1] * eps[b, k, 1]
        cost[b] = w_goal * dt * run_goal + w_term * dg + dt * run_obs + w_smooth * smooth + g_ctrl * ctrl
    return cost, paths


class MppiPlanner:
    """MPPI (Williams et al. 2017) at 2 Hz; follows its sequence between updates; deterministic per seed."""

    name = "mppi"
    params_type = MppiParams

    def __init__(self, params: StackParams, mppi: MppiParams = MppiParams()):
        self.params, self.mppi = params, mppi
        self.reset(0)

    def reset(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.V = np.zeros((self.params.N, 2))
        self._t_plan: float | None = None
        self._next_t: float | None = None
        self._path: np.ndarray | None = None

    def costs(self, Vs: np.ndarray, eps: np.ndarray, state: RobotState, pred, goal) -> tuple[np.ndarray, np.ndarray]:
        """S(V^s) (S,) of the module docstring and the rollout positions (S, N+1, 2): the compiled
        ``_rollout_costs`` (one pass per sample; tests/control/test_baselines.py checks it against the same
        formulas written with numpy arrays)."""
        p, mp = self.params, self.mppi
        ex = p.uncertainty.execution
        D = Geometry(mp.margin_m).radius(pred.r, p)
        P = np.ascontiguousarray(np.asarray(pred.p, float)[1:]).reshape(len(self.V), pred.M, 2)
        w = np.array([p.dt_s, mp.w_goal, mp.w_term, mp.w_coll, mp.w_clear, mp.l_clear_m, mp.w_smooth,
                      mp.gamma / mp.sigma_mps ** 2])
        return _rollout_costs(np.ascontiguousarray(Vs, dtype=float), np.ascontiguousarray(eps, dtype=float),
                              np.ascontiguousarray(self.V, dtype=float), float(state.px), float(state.py),
                              float(state.theta), world_velocity(state), np.asarray(goal, float), P,
                              np.asarray(D, float), np.asarray(ex.A, float), np.asarray(ex.d, float), w)

    def optimize(self, state: RobotState, obstacles: Obstacles, goal) -> None:
        """One planning cycle: ``iterations`` MPPI updates of the warm-started sequence."""
        p, mp = self.params, self.mppi
        pred = predict(obstacles, p)
        for _ in range(mp.iterations):
            Vs, eps = sample_sequences(self.V, self.rng, p.v_max_mps, mp)
            S, paths = self.costs(Vs, eps, state, pred, goal)
            finite = np.isfinite(S)
            if not finite.any():                              # (non-finite estimates) nothing to learn from:
                self.V = np.zeros_like(self.V)               # start over from rest rather than latch a NaN
                continue
            S = np.where(finite, S, S[finite].max() + 1e6)   # a non-finite cost gets no weight
            w = mppi_weights(S, temperature(S, mp.ess_fraction * mp.samples))
            V = self.V + np.tensordot(w, eps, axes=1)
            n = np.hypot(V[:, 0], V[:, 1])
            self.V = V * np.minimum(1.0, p.v_max_mps / np.maximum(n, _TINY))[:, None]
        U = body_from_world(state.theta, self.V[None])
        self._path = integrate(state, U, p.dt_s, p)[0][0]

    @fail_safe
    def plan(self, t: float, state: RobotState, obstacles: Obstacles, goal) -> tuple[np.ndarray, PlanInfo]:
        t0 = time.perf_counter()
        p = self.params
        goal = np.asarray(goal, float).reshape(2)
        planned = self._next_t is None or t >= self._next_t - _T_EPS
        if planned:
            if self._t_plan is not None:                        # warm start: shift by the elapsed steps
                shift = min(int(round((t - self._t_plan) / p.dt_s)), p.N)
                if shift > 0:
                    self.V = np.concatenate([self.V[shift:], np.repeat(self.V[-1:], shift, axis=0)])
            self.optimize(state, obstacles, goal)
            self._t_plan = t
            nxt = t if self._next_t is None else self._next_t
            while nxt <= t + _T_EPS:
                nxt += p.T_B_s
            self._next_t = nxt
        if at_goal(state, goal, p):
            u = np.zeros(3)
        else:
            k = min(int(np.floor((t - self._t_plan) / p.dt_s + _T_EPS)), p.N - 1)
            u = clip_command(body_from_world(state.theta, self.V[k]), p)
        return u, PlanInfo("MPPI", planned, (time.perf_counter() - t0) * 1e3, self._path)
