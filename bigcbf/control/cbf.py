"""The hard CBF execution filter, Eqs. (18)-(19): minimum-intervention QP with proxsuite.

For each obstacle i selected for the filter, D_i^exec = r_R + r_i + d0 + kappa_exec m_i(u_in) (Eqs. 14-15) is
evaluated from the incoming command and held fixed during the solve, which makes the CBF condition of Eq. (18)

    2 q_i^T [R(theta)(A u + d) - v_i] + alpha h_i^exec >= 0

affine in u: a_i^T u >= b_i with a_i = 2 A_xy^T R(theta)^T q_i and b_i = -2 q_i^T (R(theta) d_xy - v_i) - alpha h_i.
Rows are normalized by ||a_i|| (the violation is then in m/s). The QP (Eq. 19) is

    u_safe = argmin (u - u_in)^T H (u - u_in)   s.t.  a_i^T u >= b_i for all i,  u_min <= u <= u_max.

Which obstacles become rows: every tracked obstacle (ids >= 0; if more than ``max_obstacle_constraints``, those
with the smallest h), and of the wall points (ids < 0, e.g. LiDAR scan points), the nearest one in each of
``wall_sectors`` equal bearing sectors around the robot (so a corridor's two walls, or a wall ahead and one
beside, are always both represented). If the box-clipped u_in satisfies every row it is the solution (H is
diagonal, so clipping is the minimum-intervention projection onto the box) and no QP is solved; otherwise rows
that hold for every u in the box are dropped (exactly redundant) and the QP is solved.

QP objects are cached per row count and warm-started from their previous result (proxsuite's
WARM_START_WITH_PREVIOUS_RESULT), so a changing number of constraints between calls is handled by switching
objects, never by padding.

Infeasibility (or a solver failure): the same QP with one slack t >= 0 shared by every row and an exact penalty,

    min_(u, t) (u - u_in)^T H (u - u_in) + SLACK_PENALTY t   s.t.  C_i u + t >= l_i,  u_min <= u <= u_max,

finds the least worst-case violation t* = min_u max_i (l_i - C_i u)^+ over the box and, among the commands
attaining it, the minimum-intervention one (the penalty exceeds any multiplier of the normalized rows, so t is
minimized first; a row with a component below ~1e-5 is the exception: the penalty then stops short of that
component's last ~1e-6 m/s of violation, measured 1.5e-6 m/s, rather than swing u by the whole box for it). This
problem is always feasible and well conditioned; a least-violation LP followed by a QP
on the rows relaxed by t* is not: its feasible set shrinks to a point or a segment and the QP solver failed on
such problems, leaving the LP's vertex, with an arbitrary yaw rate, as the command. If t* > ``FEAS_TOL`` the QP
was infeasible (fallback "least-violation"); otherwise the solver had failed on a feasible problem and the slack
QP's solution is the answer (fallback "qp-retry", not infeasible). If the slack QP fails too, the filter brakes
(u = 0, inside the box; fallback "brake"). A non-finite u_in is treated as 0 (fallback "invalid-input"). The
output is always finite and inside the box.

Perception faults (``bigcbf.control.faults``): when an obstacle estimate has a NaN or an infinity anywhere (p, v,
cov, r), or is implausible (a negative or absurd radius, a covariance that is not symmetric positive semi-definite
or absurdly large, an absurd position or speed), or the robot state is, the filter does not use any of the
estimates: it brakes, u_safe = 0 (inside the actuator box, which the parameters require to contain 0), with
fallback "perception-fault" and the reason in ``FilterInfo.fault``; ``active`` says whether that changed the
command. Why brake rather than drop the faulty obstacle and filter with the others: the faulty numbers may belong
to the obstacle the robot is about to hit, and nothing tells where it is; braking is the one command that does
not rely on them. (Before this check, a NaN made every comparison with it false: one NaN obstacle among valid ones
let 0.8 m/s through unfiltered in 16 of 24 variants, with the filter reporting itself inactive.)
"""
from __future__ import annotations

import math
import time
from bisect import bisect_right
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import proxsuite

from ..params.stack import ExecutionModel, StackParams
from ..types import Obstacles, RobotState
from .faults import perception_fault

FEAS_TOL = 1e-7        # a normalized row may be violated by this much [m/s] and still count as satisfied
_QP_EPS = 1e-9
_QP_MAX_ITER = 100       # outer iterations (warm-started solves here take ~5-15)
_QP_MAX_ITER_IN = 30     # inner iterations per outer one (the default 1500 let infeasible problems run ~1 s)
_INF = 1e20
#: exact-penalty weight of the slack in the least-violation QP (module docstring): the rows are normalized, so
#: their multipliers stay below 2 max(H) (|u_max - u_min| + ...) ~ 10; 1e4 leaves a wide margin
SLACK_PENALTY = 1e4
_T_MAX = _INF         # no upper bound on the slack (a row of a near-degenerate obstacle can need a huge one)
_SOLVED = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
#: FilterInfo.fallback of a step braked for a perception fault (module docstring)
PERCEPTION_FAULT = "perception-fault"


@dataclass
class FilterInfo:
    """What the filter did at one control step."""

    active: bool                 # the filter changed the (box-clipped) command: some CBF row was violated
    infeasible: bool             # the QP had no solution (least-violation or brake fallback used)
    fallback: str | None         # None, "least-violation", "brake", "qp-retry", "invalid-input", "perception-fault"
    solve_ms: float              # time of the whole filter call [ms]
    n_constraints: int           # CBF rows considered (when a QP ran: those left after dropping box-redundant rows)
    h_min: float                 # min_i h_i^exec over all obstacles [m^2] (+inf without obstacles)
    D: np.ndarray                # D_i^exec for every obstacle (M,) [m]
    max_violation: float = 0.0   # largest normalized CBF-row violation of u_safe [m/s]
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # obstacle index of each counted row
    #: kappa_exec m_i (Eq. 14: D_i - r_R - r_i - d0) [m] of the obstacles selected as CBF rows (before rows that
    #: hold over the whole actuator box are dropped)
    margins: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fault: str | None = None     # why the step was a perception fault (fallback "perception-fault"), else None


@dataclass
class CbfRows:
    """Eq. (18) for every obstacle, normalized: C_i u >= l_i with C_i = a_i / ||a_i||, l_i = b_i / ||a_i||, where
    a_i = 2 A_xy^T R(theta)^T q_i and b_i = -2 q_i^T (R(theta) d_xy - v_i) - alpha h_i; plus D^exec, h^exec and
    q (Eqs. 11-15). ``norm`` = ||a_i||; a row with norm 0 (robot center on the obstacle center) has C_i = 0 and
    l_i = b_i (it reads 0 >= b_i)."""

    C: np.ndarray      # (M, 3)
    l: np.ndarray      # (M,)
    norm: np.ndarray   # (M,)
    D: np.ndarray      # (M,) [m]
    h: np.ndarray      # (M,) [m^2]
    q: np.ndarray      # (M, 2) [m]

    @property
    def a(self) -> np.ndarray:
        return self.C * self.norm[:, None]

    @property
    def b(self) -> np.ndarray:
        return np.where(self.norm > 0, self.l * self.norm, self.l)


@lru_cache(maxsize=64)
def _exec_consts(ex: ExecutionModel) -> tuple:
    A = np.asarray(ex.A, float)
    ident = bool(np.array_equal(A[:2], np.eye(3)[:2]))
    return (ident, A[:2].copy(), complex(A[0, 0], A[1, 0]), complex(A[0, 1], A[1, 1]), complex(A[0, 2], A[1, 2]),
            complex(ex.d[0], ex.d[1]), ex.residual_horizon_s, list(ex.residual_speed_mps),
            list(ex.residual_bound_mps))


def _interp(x: float, xs: list, ys: list) -> float:
    """np.interp for one scalar (clamped), without the array overhead."""
    if x <= xs[0]:
        return ys[0]
    j = bisect_right(xs, x)
    if j >= len(xs):
        return ys[-1]
    t = (x - xs[j - 1]) / (xs[j] - xs[j - 1])
    return ys[j - 1] + t * (ys[j] - ys[j - 1])


def _as_complex(xy: np.ndarray) -> np.ndarray:
    """(M, 2) float -> (M,) complex x + i y (a view when possible)."""
    xy = np.ascontiguousarray(xy, dtype=float)
    return xy.view(np.complex128)[:, 0]


def cbf_rows(state: RobotState, obstacles: Obstacles, u_ref, params: StackParams) -> CbfRows:
    """Eq. (18) as a_i^T u >= b_i for every obstacle, with D_i^exec (Eq. 14) from m_i (Eq. 15) evaluated at u_ref
    and held fixed. Inlines ``uncertainty.uncertainty_radius`` / ``inflated_radius`` / ``barrier`` for speed,
    with planar vectors as complex numbers (the tests check that both agree)."""
    unc = params.uncertainty
    ident, Axy, col0, col1, col2, d_c, horizon, knots, bounds = _exec_consts(unc.execution)
    u0, u1, u2 = np.asarray(u_ref, float).tolist()
    rot = complex(math.cos(state.theta), math.sin(state.theta))
    v_rob = rot * (col0 * u0 + col1 * u1 + col2 * u2 + d_c)      # Eq. (1) nominal: R(theta)(A u + d)
    e_ex = horizon * _interp(math.hypot(u0, u1), knots, bounds)
    q = complex(state.px, state.py) - _as_complex(obstacles.p)      # q_i = p - p_i (Eq. 11)
    V = _as_complex(obstacles.v)
    cov = obstacles.cov
    ca, cc = cov[:, 0, 0], cov[:, 1, 1]
    cb = 0.5 * (cov[:, 0, 1] + cov[:, 1, 0])
    lam = np.maximum(0.5 * (ca + cc) + np.sqrt(0.25 * (ca - cc) ** 2 + cb * cb), 0.0)
    m = unc.tau95_s * np.abs(v_rob - V) + unc.beta * np.sqrt(lam) + (e_ex + unc.e_zoh_m)   # Eq. (15)
    D = (unc.r_robot_m + unc.d0_m) + obstacles.r + unc.kappa_exec * m                     # Eq. (14)
    q_abs = np.abs(q)
    h = q_abs * q_abs - D * D
    qb = (q * rot.conjugate()).view(float).reshape(-1, 2)           # R^T q
    w = rot * d_c - V                                               # R(theta) d - v_i
    b = -2.0 * (q.real * w.real + q.imag * w.imag) - params.alpha_per_s * h
    if ident:                                                       # A_xy = [I 0]: ||a_i|| = 2 ||q_i||
        C = np.zeros((len(q), 3))
        C[:, :2] = qb
        norm = 2.0 * q_abs
    else:
        C = qb @ Axy                                                # a_i / 2 = A_xy^T R^T q_i
        norm = 2.0 * np.sqrt((C * C).sum(axis=1))
    if norm.min(initial=1.0) > 1e-12:
        C /= 0.5 * norm[:, None]
        lv = b / norm
    else:
        pos = norm > 1e-12
        C[pos] /= 0.5 * norm[pos, None]
        C[~pos] = 0.0
        lv = np.where(pos, b / np.where(pos, norm, 1.0), b)
    return CbfRows(C, lv, norm, D, h, q.view(float).reshape(-1, 2))


def select_constraints(obstacles: Obstacles, rows: CbfRows, params: StackParams) -> np.ndarray:
    """Indices of the obstacles that become CBF rows (see the module docstring), in increasing order."""
    ids = np.asarray(obstacles.ids)
    M = len(ids)
    if M <= params.max_obstacle_constraints and (M == 0 or ids.min() >= 0):
        return np.arange(M)
    tracked = np.flatnonzero(ids >= 0)
    if len(tracked) > params.max_obstacle_constraints:
        tracked = tracked[np.argsort(rows.h[tracked], kind="stable")[:params.max_obstacle_constraints]]
    walls = np.flatnonzero(ids < 0)
    if len(walls) and params.wall_sectors > 0:
        K = params.wall_sectors
        bearing = np.arctan2(-rows.q[walls, 1], -rows.q[walls, 0])    # direction robot -> point
        sector = np.floor((bearing + np.pi) * (K / (2 * np.pi))).astype(int) % K
        order = np.lexsort((rows.h[walls], sector))
        first = np.ones(len(order), bool)
        first[1:] = sector[order][1:] != sector[order][:-1]
        walls = walls[order[first]]
    else:
        walls = walls[:0]
    return np.sort(np.concatenate([tracked, walls]))


class CbfFilter:
    """The common hard CBF filter (Eqs. 18-19); every method feeds its u_in through the same instance type."""

    def __init__(self, params: StackParams):
        self.params = params
        self.lo = np.asarray(params.u_min, float)
        self.hi = np.asarray(params.u_max, float)
        self.Hd = np.asarray(params.H_diag, float)
        self._H = np.diag(2.0 * self.Hd)
        self._minus2Hd = -2.0 * self.Hd
        self._centre = 0.5 * (self.lo + self.hi)
        self._half = 0.5 * (self.hi - self.lo)
        self._qps: dict[int, tuple] = {}
        self._slack_qps: dict[int, tuple] = {}
        self._H_slack = np.diag(np.r_[2.0 * self.Hd, 0.0])
        self._lo_slack, self._hi_slack = np.r_[self.lo, 0.0], np.r_[self.hi, _T_MAX]

    def reset(self) -> None:
        """Forget the warm starts (a new episode)."""
        self._qps.clear()
        self._slack_qps.clear()

    def _new_qp(self, n: int, nvar: int = 3):
        qp = proxsuite.proxqp.dense.QP(nvar, 0, n, True)
        st = qp.settings
        st.eps_abs = _QP_EPS
        st.eps_rel = 0.0
        st.eps_primal_inf = 1e-8
        st.eps_dual_inf = 1e-8
        st.max_iter = _QP_MAX_ITER
        st.max_iter_in = _QP_MAX_ITER_IN
        # without the duality-gap test, degenerate problems (parallel rows) stopped ~1e-5 m/s from the optimum
        st.check_duality_gap = True
        st.eps_duality_gap_abs = _QP_EPS
        st.eps_duality_gap_rel = 0.0
        st.verbose = False
        st.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
        return qp

    def _solve_qp(self, C, lvec, u_target, cache: bool) -> np.ndarray | None:
        """Eq. (19) with proxsuite; None when the solver does not report a solution."""
        n = len(lvec)
        g = self._minus2Hd * u_target
        entry = self._qps.get(n) if cache else None
        if entry is None:
            qp, uvec = self._new_qp(n), np.full(n, _INF)
            qp.init(self._H, g, None, None, C, lvec, uvec, self.lo, self.hi)
            if cache:
                self._qps[n] = (qp, uvec)
        else:
            qp, uvec = entry
            qp.update(g=g, C=C, l=lvec)
        qp.solve()
        res = qp.results
        if res.info.status != _SOLVED:
            if cache:
                self._qps.pop(n, None)       # do not warm-start from a failed solve
            return None
        x = np.array(res.x)
        return x if np.isfinite(x).all() else None

    def _least_violation(self, C, lvec, u_in) -> tuple[float, np.ndarray] | None:
        """The slack QP of the module docstring (proxsuite, warm-started per row count). Returns (t*, u) or
        None when the solver fails."""
        n = len(lvec)
        Ca = np.hstack([C, np.ones((n, 1))])
        g = np.r_[self._minus2Hd * u_in, SLACK_PENALTY]
        entry = self._slack_qps.get(n)
        if entry is None:
            qp = self._new_qp(n, 4)
            qp.init(self._H_slack, g, None, None, Ca, lvec, np.full(n, _INF), self._lo_slack, self._hi_slack)
            self._slack_qps[n] = (qp,)
        else:
            qp = entry[0]
            qp.update(g=g, C=Ca, l=lvec)
        qp.solve()
        res = qp.results
        x = np.array(res.x)
        if res.info.status != _SOLVED:
            self._slack_qps.pop(n, None)      # do not warm-start from an unfinished solve
        # this problem is always feasible: an unfinished solve (the iteration limit, e.g. with a row of a robot
        # sitting on an obstacle's centre, l_i ~ 1e6) still gives a usable command; its violation is measured
        if not np.isfinite(x).all():
            return None
        u = np.minimum(np.maximum(x[:3], self.lo), self.hi)
        return max(float((lvec - C @ u).max()), 0.0), u

    def filter(self, state: RobotState, obstacles: Obstacles, u_in) -> tuple[np.ndarray, FilterInfo]:
        """Eqs. (18)-(19): the minimum-intervention safe command u_safe (3,) and what the filter did."""
        t0 = time.perf_counter()
        u_in = np.asarray(u_in, float).reshape(3)
        fallback = None
        if not np.isfinite(u_in).all():
            u_in, fallback = np.zeros(3), "invalid-input"
        fault = perception_fault(state, obstacles)
        if fault is not None:
            return self._brake_for_fault(u_in, obstacles, fault, t0)
        rows = cbf_rows(state, obstacles, u_in, self.params)
        idx = select_constraints(obstacles, rows, self.params)
        unc = self.params.uncertainty
        margins = rows.D[idx] - (unc.r_robot_m + unc.d0_m) - obstacles.r[idx]
        if len(idx) < len(rows.l):
            C, lvec = rows.C[idx], rows.l[idx]
        else:
            C, lvec = rows.C, rows.l
        u = np.minimum(np.maximum(u_in, self.lo), self.hi)
        viol = float((lvec - C @ u).max()) if len(lvec) else 0.0
        active = viol > FEAS_TOL
        infeasible = False
        if active:
            # over the box, C_i u ranges over C_i c -+ |C_i| w (c centre, w half-width): rows whose minimum is
            # >= l_i hold everywhere (redundant, dropped); rows whose maximum is < l_i hold nowhere (the QP is
            # infeasible: the solver is skipped)
            centre = C @ self._centre
            spread = np.abs(C) @ self._half
            live = centre - spread < lvec
            if not live.all():
                C, lvec, idx, centre, spread = C[live], lvec[live], idx[live], centre[live], spread[live]
            hopeless = centre + spread < lvec - FEAS_TOL
            x = None if hopeless.any() else self._solve_qp(C, lvec, u_in, cache=True)
            if x is not None:
                x = np.minimum(np.maximum(x, self.lo), self.hi)
                viol = float((lvec - C @ x).max())
            if x is not None and viol <= 1e-6:
                u = x
            else:
                u, fallback, infeasible = self._infeasible(C, lvec, u_in, fallback)
                if not np.isfinite(u).all():
                    u, fallback = np.zeros(3), "brake"
                u = np.minimum(np.maximum(u, self.lo), self.hi)
                viol = float((lvec - C @ u).max())
        h = rows.h
        info = FilterInfo(active=active, infeasible=infeasible, fallback=fallback,
                          solve_ms=(time.perf_counter() - t0) * 1e3, n_constraints=len(lvec),
                          h_min=float(h.min()) if len(h) else math.inf, D=rows.D, max_violation=max(viol, 0.0),
                          rows=idx, margins=margins)
        return u, info

    def _brake_for_fault(self, u_in: np.ndarray, obstacles: Obstacles, fault: str, t0: float):
        """A perception fault (module docstring): u_safe = 0, nothing of the estimates used."""
        u = np.zeros(3)
        changed = bool(np.any(np.minimum(np.maximum(u_in, self.lo), self.hi) != 0.0))
        info = FilterInfo(active=changed, infeasible=False, fallback=PERCEPTION_FAULT,
                          solve_ms=(time.perf_counter() - t0) * 1e3, n_constraints=0, h_min=math.nan,
                          D=np.zeros(len(obstacles)), max_violation=0.0, fault=fault)
        return u, info

    def _infeasible(self, C, lvec, u_in, fallback):
        """The QP failed: the slack QP (least worst-case violation, then minimum intervention).
        Returns (u, fallback, infeasible); infeasible only when the least violation exceeds FEAS_TOL, otherwise
        (the solver failed on a feasible problem) the fallback is reported as "qp-retry"."""
        lv = self._least_violation(C, lvec, u_in)
        if lv is None:
            return np.zeros(3), "brake", True
        t_star, u = lv
        infeasible = t_star > FEAS_TOL
        return u, ("least-violation" if infeasible else (fallback or "qp-retry")), infeasible
