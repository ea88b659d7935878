"""The hard CBF execution filter, eq:cbf_condition and eq:hard_cbf_qp: minimum-intervention QP.

For each obstacle i selected for the filter, D_i^exec = r_R + r_i + d0 + kappa_exec m_i(u_in) (eq:shared_barrier,
eq:uncertainty_margin) is evaluated from the incoming command and held fixed
during the solve, which makes the CBF condition of eq:cbf_condition

    2 q_i^T [R(theta)(A u + d) - v_i] + alpha h_i^exec >= 0

affine in u: a_i^T u >= b_i with a_i = 2 A_xy^T R(theta)^T q_i and b_i = -2 q_i^T (R(theta) d_xy - v_i) - alpha h_i.
Rows are normalized by ||a_i|| (the violation is then in m/s). The QP (eq:hard_cbf_qp) is

    u_safe = argmin (u - u_in)^T H (u - u_in)   s.t.  a_i^T u >= b_i for all i,  u_min <= u <= u_max.

Which obstacles become rows: every tracked obstacle (ids >= 0; if more than ``max_obstacle_constraints``, those
with the smallest h), and of the wall points (ids < 0, e.g. LiDAR scan points), the nearest one in each of
``wall_sectors`` equal bearing sectors around the robot (so a corridor's two walls, or a wall ahead and one
beside, are always both represented). If the box-clipped u_in satisfies every row it is the solution (H is
diagonal, so clipping is the minimum-intervention projection onto the box) and no QP is solved; otherwise rows
that hold for every u in the box are dropped (exactly redundant) and the QP is solved.

The solver (``bigcbf.control.smallqp``): with 3 variables, a diagonal H and a few half-spaces, the QP is the
projection of a point onto a polytope in R^3, solved exactly by Goldfarb and Idnani's dual active-set method,
compiled (``bigcbf.control.jit``): a few microseconds, and the same bits in every process (proxsuite, used before,
gave last-bit-different solutions for byte-identical inputs depending on where its buffers fell in memory, and
chose its AVX-512, AVX2 or plain build by the CPU). proxsuite stays the reference in the tests
(tests/control/test_smallqp.py: the same answers to 1e-9). The rows, the selection and the fault pre-check are
compiled kernels too; the filter keeps no state between calls.

Infeasibility (or a solver failure): the same QP with one slack t >= 0 shared by every row and an exact penalty,

    min_(u, t) (u - u_in)^T H (u - u_in) + SLACK_PENALTY t   s.t.  C_i u + t >= l_i,  u_min <= u <= u_max,

finds the least worst-case violation t* = min_u max_i (l_i - C_i u)^+ over the box (the penalty exceeds any
multiplier of the normalized rows, so t is minimized first). This problem is always feasible and solved exactly by
the same method (``smallqp.solve_slack``). When t* > ``FEAS_TOL`` the QP was infeasible (fallback
"least-violation"), and the command is the minimum-intervention one among those within ``SLACK_TOL_MPS`` (5 mm/s)
of the least violation: the hard QP on the rows relaxed by t* + SLACK_TOL_MPS (feasible: the slack solution meets
it; well posed: its feasible set has an interior, where the rows relaxed by t* alone shrink to a point or a
segment). Why the tolerance: the exact penalty makes t the only thing that counts, so a component worth a few mm/s
of violation is driven to its box bound; the calibrated execution model's cross-couplings (A's yaw column, ~0.002)
give every row a yaw-rate component of that size, and the slack command turned the robot at the full 1 rad/s to
gain 2 mm/s, swinging the corner of its rectangular body into a box (big-cbf-plus, mixed dense traffic seed 4,
2026-11-26: an at-fault contact at 0.06 m/s), and jumped between two such near-equal solutions on alternate steps.
Otherwise (t* <= FEAS_TOL) the solver had failed on a feasible problem and the slack QP's solution is the answer
(fallback "qp-retry", not infeasible). If the slack QP fails too, the filter
brakes (u = 0, inside the box; fallback "brake"). A non-finite u_in is treated as 0 (fallback "invalid-input").
The output is always finite and inside the box.

The last resort (``StackParams.cbf_last_resort``) is what an infeasible step commands: "slack" (the default, the
paper's configuration: the least-violation command above), "brake" (u = 0: the robot stops and keeps still, so a
contact that follows is the other's doing; fallback "brake"), or "evade" (the full-speed sidestep, at v_max, across
the path of the obstacle whose row the least-violation command violates most, on the side of that path where the
robot is, projected on the other obstacles' rows by the same slack QP; fallback "evade"; when that obstacle is a wall
point or moves slower than ``cbf_velocity_min_speed_mps``, the least-violation command), or "passive" (the
least-violation command with its approach toward every body whose barrier is already violated, h_i^exec < 0, taken
out: the robot's own velocity toward such a body, q_i^T R(theta)(A u + d) < 0, is projected to zero, a few
alternating projections over those bodies; passive safety, the notion HuNavSim's and the at-fault classification
use: a contact that follows is not the robot's doing; fallback "passive"). Every variant is still clipped to the box
and its row violation measured.

The slowdown (``StackParams.cbf_slowdown``, off by default: the paper's filter). D_i^exec grows with the command
it is evaluated at (tau95 ||R(A u_in + d) - v_i|| and e_exec(u_in) in eq:uncertainty_margin), and the filter holds it
fixed at u_in. A gap the robot is driven into at full speed can then have no feasible command, although the same gap
is wide at a crawl: dev worlds clutter_00006 (0.78 m between a box and a wall; D_i^exec 0.38 m at 0.8 m/s, 0.29 m at
rest) held big-cbf-plus there in the least-violation command until its time ran out. With the switch, a step that is
infeasible at u_in is filtered again from s u_in for s in ``SLOWDOWN_SCALES`` (0.5, 0.25, 0), fastest first: the
rows with D_i^exec evaluated at s u_in, the QP's minimum intervention from s u_in, every other step as above. The
first s whose QP is feasible gives the command (fallback "slowdown", ``FilterInfo.slowdown`` = s; not infeasible:
eq:hard_cbf_qp (26) held, with the margins of the command the filter started from, as without the switch). Only
when no s is feasible does the step stay infeasible, with the least-violation command and the last resort of u_in's
problem, as without the switch. It is the paper's rule (margins at the command the filter starts from, held fixed)
applied to a command the filter has first slowed down: what the hard filter does to an infeasible full-speed
command anyway, but with the margins of the speed it will have. Measured over every method (docs/fidelity.md, "The common
filter's slowdown"), it frees channels like that one but, with walkers near, the slowed command's margins can be the
smaller ones and its command moves towards a person: three at-fault contacts on the test split that the
least-violation command did not have. Hence off by default for every method.

The velocity-aware barrier (``StackParams.cbf_velocity_rows``, off by default): every selected tracked obstacle
that moves adds one collision-cone row (``bigcbf.control.velocity_barrier``) after the distance rows, with the same
D_i^exec; the rows go through the same pre-check and QP. When that QP has no solution, the distance rows come
first (lexicographically): the slack QP with only the velocity rows softened (``smallqp.solve_soft``) keeps every
distance row exact and relaxes the cone rows by the least worst-case violation (then, as above, the
minimum-intervention command within ``SLACK_TOL_MPS`` of it; fallback "velocity-relaxed",
``FilterInfo.velocity_relaxed``; the step is not infeasible: the paper's QP, eq:hard_cbf_qp (26), held). Only when
the distance rows and the box admit no command is the step infeasible, and then the slack QP over every row and
the last resort decide as above. Without this order the switch could trade a distance row's violation for a cone
row's (one shared slack): the paper's barrier would then hold less often with the switch on than off. ``FilterInfo
.rows`` names each counted row's obstacle, ``FilterInfo.n_velocity_rows`` how many of them are cone rows. With the
switch off nothing of this runs.

Perception faults (``bigcbf.control.faults``): when an obstacle estimate has a NaN or an infinity anywhere (p, v,
cov, r), or is implausible (a negative or absurd radius, a covariance that is not symmetric positive semi-definite
or absurdly large, an absurd position or speed), or the robot state is, the filter does not use any of the
estimates: it brakes, u_safe = 0 (inside the actuator box, which the parameters require to contain 0), with
fallback "perception-fault" and the reason in ``FilterInfo.fault``; ``active`` says whether that changed the
command. Why brake rather than drop the faulty obstacle and filter with the others: the faulty numbers may belong
to the obstacle the robot is about to hit, and nothing tells where it is; braking is the one command that does
not rely on them. (Before this check, a NaN made every comparison with it false: one NaN obstacle among valid ones
let 0.8 m/s through unfiltered in 16 of 24 variants, with the filter reporting itself inactive.) The row kernel
checks the plainly-usable case (every number finite and well inside the bounds) on the way; only when that fails
does ``faults.perception_fault`` look closer.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from ..params.stack import StackParams
from ..types import Obstacles, RobotState
from . import smallqp
from .faults import MAX_COVARIANCE_M2, MAX_POSITION_M, MAX_RADIUS_M, MAX_SPEED_MPS, perception_fault
from .jit import kernel
from .velocity_barrier import sidestep_target, velocity_rows

FEAS_TOL = 1e-7        # a normalized row may be violated by this much [m/s] and still count as satisfied
#: exact-penalty weight of the slack in the least-violation QP (module docstring): the rows are normalized, so
#: their multipliers stay below 2 max(H) (|u_max - u_min| + ...) ~ 10; 1e4 leaves a wide margin
SLACK_PENALTY = 1e4
#: the least-violation command's tolerance (module docstring) [m/s]: among the commands whose worst row violation is
#: within this of the least, the minimum-intervention one. A tenth of v_freeze and a sixth of the calibrated execution
#: residual bound (0.032 m/s): a violation difference the robot cannot execute, let alone measure
SLACK_TOL_MPS = 5e-3
#: StackParams.cbf_slowdown: the fractions s of an infeasible step's u_in whose margins are tried, fastest first
#: (module docstring, "The slowdown") [-]
SLOWDOWN_SCALES = (0.5, 0.25, 0.0)
#: FilterInfo.fallback of a step braked for a perception fault (module docstring)
PERCEPTION_FAULT = "perception-fault"


@dataclass
class FilterInfo:
    """What the filter did at one control step."""

    active: bool                 # the filter changed the (box-clipped) command: some CBF row was violated
    infeasible: bool             # the QP had no solution (least-violation or brake fallback used)
    fallback: str | None         # None, "least-violation", "brake", "evade", "passive", "velocity-relaxed",
    #                              "qp-retry", "invalid-input", "perception-fault", "slowdown" (", " and the
    #                              slowed step's own, if any)
    solve_ms: float              # time of the whole filter call [ms]
    n_constraints: int           # CBF rows considered (when a QP ran: those left after dropping box-redundant rows)
    h_min: float                 # min_i h_i^exec over all obstacles [m^2] (+inf without obstacles)
    D: np.ndarray                # D_i^exec for every obstacle (M,) [m]
    max_violation: float = 0.0   # largest normalized CBF-row violation of u_safe [m/s]
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # obstacle index of each counted row
    #: of the counted rows, those of the velocity-aware barrier (StackParams.cbf_velocity_rows; its rows follow the
    #: distance rows in ``rows``)
    n_velocity_rows: int = 0
    #: the distance rows held but not every velocity-aware row could (the lexicographic fallback; not infeasible)
    velocity_relaxed: bool = False
    #: kappa_exec m_i (eq:shared_barrier: D_i - r_R - r_i - d0) [m] of the obstacles selected as CBF rows (before rows
    #: that hold over the whole actuator box are dropped)
    margins: np.ndarray = field(default_factory=lambda: np.zeros(0))
    fault: str | None = None     # why the step was a perception fault (fallback "perception-fault"), else None
    #: StackParams.cbf_slowdown: the fraction s of u_in whose margins and reference made the step feasible (fallback
    #: "slowdown"), else None
    slowdown: float | None = None


@dataclass
class CbfRows:
    """eq:cbf_condition for every obstacle, normalized: C_i u >= l_i with C_i = a_i / ||a_i||, l_i = b_i / ||a_i||,
    where a_i = 2 A_xy^T R(theta)^T q_i and b_i = -2 q_i^T (R(theta) d_xy - v_i) - alpha h_i; plus D^exec, h^exec and q
    (eq:relative_position_error, eq:shared_barrier, eq:uncertainty_margin). ``norm`` =
    ||a_i||; a row with norm 0 (robot center on the obstacle center) has C_i = 0 and l_i = b_i (it reads 0 >= b_i).
    ``margin`` = D_i - (r_R + d0) - r_i = kappa_exec m_i [m]; ``plain``: every input number finite and plainly within
    the fault bounds (``faults._plainly_usable`` and the state's bounds)."""

    C: np.ndarray      # (M, 3)
    l: np.ndarray      # (M,)
    norm: np.ndarray   # (M,)
    D: np.ndarray      # (M,) [m]
    h: np.ndarray      # (M,) [m^2]
    q: np.ndarray      # (M, 2) [m]
    margin: np.ndarray = field(default_factory=lambda: np.zeros(0))   # (M,) [m]
    plain: bool = True

    @property
    def a(self) -> np.ndarray:
        return self.C * self.norm[:, None]

    @property
    def b(self) -> np.ndarray:
        return np.where(self.norm > 0, self.l * self.norm, self.l)


@lru_cache(maxsize=64)
def _consts(params: StackParams) -> tuple:
    """The constants of the row kernel, per parameter set: (floats, A_xy, knots, bounds, A_xy == [I 0])."""
    unc = params.uncertainty
    ex = unc.execution
    A = np.asarray(ex.A, float)
    ident = bool(np.array_equal(A[:2], np.eye(3)[:2]))
    k = np.array([unc.tau95_s, unc.beta, unc.e_zoh_m, unc.r_robot_m, unc.d0_m, unc.kappa_exec, params.alpha_per_s,
                  ex.residual_horizon_s, ex.d[0], ex.d[1], MAX_POSITION_M, MAX_SPEED_MPS, MAX_RADIUS_M,
                  MAX_COVARIANCE_M2])
    return (k, np.ascontiguousarray(A[:2]), np.asarray(ex.residual_speed_mps, float),
            np.asarray(ex.residual_bound_mps, float), ident)


@kernel
def _interp(x, xs, ys):
    """np.interp for one scalar (clamped at both ends)."""
    if x <= xs[0]:
        return ys[0]
    n = xs.shape[0]
    if x >= xs[n - 1]:
        return ys[n - 1]
    j = np.searchsorted(xs, x, side="right")
    t = (x - xs[j - 1]) / (xs[j] - xs[j - 1])
    return ys[j - 1] + t * (ys[j] - ys[j - 1])


@kernel
def _rows_kernel(px, py, theta, vx, vy, wz, u0, u1, u2, P, V, cov, r, k, Axy, knots, bounds, ident):
    """The rows of cbf_rows (eq:cbf_condition with eq:shared_barrier and eq:uncertainty_margin), and the plain
    fault pre-check; see ``cbf_rows``.

    Length: a numba kernel: one pass over the obstacles computing each one's margin, barrier, row and plain fault check
    from the same intermediate values; the unpacking of k and the robot's terms sit above the loop."""
    tau, beta, e_zoh, r_robot, d0, kappa, alpha = k[0], k[1], k[2], k[3], k[4], k[5], k[6]
    horizon, d_c = k[7], complex(k[8], k[9])
    max_pos, max_speed, max_radius, max_cov = k[10], k[11], k[12], k[13]
    M = r.shape[0]
    C = np.zeros((M, 3))
    lv = np.empty(M)
    norm = np.empty(M)
    D = np.empty(M)
    h = np.empty(M)
    q = np.empty((M, 2))
    margin = np.empty(M)
    rot = complex(math.cos(theta), math.sin(theta))
    cols = (complex(Axy[0, 0], Axy[1, 0]) * u0 + complex(Axy[0, 1], Axy[1, 1]) * u1
            + complex(Axy[0, 2], Axy[1, 2]) * u2 + d_c)
    v_rob = rot * cols                                         # eq:execution nominal: R(theta)(A u + d)
    e_ex = horizon * _interp(math.hypot(u0, u1), knots, bounds)
    rd = rot * d_c
    base = r_robot + d0
    # the state's plain check (faults.state_fault without a goal)
    plain = (math.isfinite(px) and math.isfinite(py) and math.isfinite(theta) and math.isfinite(vx)
             and math.isfinite(vy) and math.isfinite(wz) and max(abs(px), abs(py)) <= max_pos
             and math.hypot(vx, vy) <= max_speed)
    vlim = max_speed / math.sqrt(2.0)
    for i in range(M):
        qx, qy = px - P[i, 0], py - P[i, 1]                    # q_i = p - p_i (eq:relative_position_error)
        Vi = complex(V[i, 0], V[i, 1])
        ca, cc, c01, c10 = cov[i, 0, 0], cov[i, 1, 1], cov[i, 0, 1], cov[i, 1, 0]
        cb = 0.5 * (c01 + c10)
        lam = max(0.5 * (ca + cc) + math.sqrt(0.25 * (ca - cc) ** 2 + cb * cb), 0.0)
        m = tau * abs(v_rob - Vi) + beta * math.sqrt(lam) + (e_ex + e_zoh)    # eq:uncertainty_margin
        Di = base + r[i] + kappa * m                                          # eq:shared_barrier
        q_abs = math.hypot(qx, qy)
        hi = q_abs * q_abs - Di * Di
        c, s = rot.real, rot.imag
        qb0, qb1 = qx * c + qy * s, qy * c - qx * s                           # R^T q
        w = rd - Vi                                                           # R(theta) d - v_i
        b = -2.0 * (qx * w.real + qy * w.imag) - alpha * hi
        if ident:                                                             # A_xy = [I 0]: ||a_i|| = 2 ||q_i||
            a0, a1, a2 = qb0, qb1, 0.0
            nrm = 2.0 * q_abs
        else:                                                                 # a_i / 2 = A_xy^T R^T q_i
            a0 = qb0 * Axy[0, 0] + qb1 * Axy[1, 0]
            a1 = qb0 * Axy[0, 1] + qb1 * Axy[1, 1]
            a2 = qb0 * Axy[0, 2] + qb1 * Axy[1, 2]
            nrm = 2.0 * math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        if nrm > 1e-12:
            half = 0.5 * nrm
            C[i, 0], C[i, 1], C[i, 2] = a0 / half, a1 / half, a2 / half
            lv[i] = b / nrm
        else:
            lv[i] = b
        norm[i], D[i], h[i], q[i, 0], q[i, 1] = nrm, Di, hi, qx, qy
        margin[i] = Di - base - r[i]
        if plain:   # faults._plainly_usable, obstacle by obstacle
            plain = (math.isfinite(P[i, 0]) and math.isfinite(P[i, 1]) and math.isfinite(V[i, 0])
                     and math.isfinite(V[i, 1]) and math.isfinite(ca) and math.isfinite(cc)
                     and math.isfinite(c01) and math.isfinite(c10) and math.isfinite(r[i])
                     and abs(P[i, 0]) <= max_pos and abs(P[i, 1]) <= max_pos and abs(V[i, 0]) <= vlim
                     and abs(V[i, 1]) <= vlim and 0.0 <= r[i] <= max_radius and c01 == c10 and ca >= 0.0
                     and cc >= 0.0 and ca * cc >= c01 * c01 and ca + cc <= max_cov)
    return C, lv, norm, D, h, q, margin, plain


def _f64(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def cbf_rows(state: RobotState, obstacles: Obstacles, u_ref, params: StackParams) -> CbfRows:
    """eq:cbf_condition as a_i^T u >= b_i for every obstacle, with D_i^exec (eq:shared_barrier)
    from m_i (eq:uncertainty_margin) evaluated at u_ref and held fixed. A compiled kernel that inlines
    ``kernels.uncertainty_radius`` / ``inflated_radius`` / ``barrier`` (it sums D_i as (r_R + d0) + r_i + kappa m,
    the kernel as (r_R + r_i) + d0 + kappa m; tests/control/test_control_kernels.py checks that both agree)."""
    k, Axy, knots, bounds, ident = _consts(params)
    u0, u1, u2 = np.asarray(u_ref, float).reshape(3).tolist()
    C, lv, norm, D, h, q, margin, plain = _rows_kernel(
        float(state.px), float(state.py), float(state.theta), float(state.vx), float(state.vy), float(state.wz),
        u0, u1, u2, _f64(obstacles.p), _f64(obstacles.v), _f64(obstacles.cov), _f64(obstacles.r), k, Axy, knots,
        bounds, ident)
    return CbfRows(C, lv, norm, D, h, q, margin, bool(plain))


@kernel
def _select_kernel(ids, h, q, max_rows, K):
    """select_constraints on arrays: the indices in increasing order."""
    M = ids.shape[0]
    all_tracked = True
    for i in range(M):
        if ids[i] < 0:
            all_tracked = False
            break
    if M <= max_rows and all_tracked:
        return np.arange(M)
    keep = np.zeros(M, np.bool_)
    nt = 0
    for i in range(M):
        if ids[i] >= 0:
            nt += 1
    tracked = np.empty(nt, np.int64)
    j = 0
    for i in range(M):
        if ids[i] >= 0:
            tracked[j] = i
            j += 1
    if nt > max_rows:
        order = np.argsort(h[tracked], kind="mergesort")      # stable: equal h keep their order
        for j in range(max_rows):
            keep[tracked[order[j]]] = True
    else:
        for j in range(nt):
            keep[tracked[j]] = True
    if K > 0:
        best = np.full(K, -1, np.int64)
        scale = K / (2 * np.pi)
        for i in range(M):
            if ids[i] >= 0:
                continue
            bearing = math.atan2(-q[i, 1], -q[i, 0])                  # direction robot -> point
            s = int(math.floor((bearing + np.pi) * scale)) % K
            if best[s] < 0 or h[i] < h[best[s]]:                   # nearest in its sector, first among equals
                best[s] = i
        for s in range(K):
            if best[s] >= 0:
                keep[best[s]] = True
    return np.flatnonzero(keep)


def select_constraints(obstacles: Obstacles, rows: CbfRows, params: StackParams) -> np.ndarray:
    """Indices of the obstacles that become CBF rows (see the module docstring), in increasing order."""
    ids = np.ascontiguousarray(obstacles.ids, dtype=np.int64)
    return _select_kernel(ids, _f64(rows.h), _f64(rows.q), int(params.max_obstacle_constraints),
                          int(params.wall_sectors))


@kernel
def _prepare(C, lv, idx, u_in, lo, hi, feas_tol):
    """The selected rows (C_k, l_k), u_in clipped to the box and its largest row violation; when a row is violated
    by more than feas_tol, only the rows that can be violated inside the box (the others hold over the whole box:
    dropped), and whether one of those holds nowhere in the box (the QP is infeasible: no solve)."""
    n = idx.shape[0]
    u = np.empty(3)
    for j in range(3):
        u[j] = min(max(u_in[j], lo[j]), hi[j])
    viol = 0.0
    for k in range(n):
        i = idx[k]
        v = lv[i] - (C[i, 0] * u[0] + C[i, 1] * u[1] + C[i, 2] * u[2])
        if k == 0 or v > viol:
            viol = v
    active = n > 0 and viol > feas_tol
    live = np.ones(n, np.bool_)
    hopeless = False
    if active:
        # over the box, C_i u ranges over C_i c -+ |C_i| w (c centre, w half-width)
        for k in range(n):
            i = idx[k]
            centre = 0.0
            spread = 0.0
            for j in range(3):
                centre += C[i, j] * (0.5 * (lo[j] + hi[j]))
                spread += abs(C[i, j]) * (0.5 * (hi[j] - lo[j]))
            live[k] = centre - spread < lv[i]
            if live[k] and centre + spread < lv[i] - feas_tol:
                hopeless = True
    sel = idx[live]
    Ck = np.empty((sel.shape[0], 3))
    lk = np.empty(sel.shape[0])
    for k in range(sel.shape[0]):
        for j in range(3):
            Ck[k, j] = C[sel[k], j]
        lk[k] = lv[sel[k]]
    return u, viol, active, Ck, lk, sel, hopeless


@kernel
def _clip_violation(C, lv, x, lo, hi):
    """x clipped to the box and the largest row violation there (-inf without rows)."""
    u = np.empty(3)
    for j in range(3):
        u[j] = min(max(x[j], lo[j]), hi[j])
    viol = -np.inf
    for k in range(lv.shape[0]):
        v = lv[k] - (C[k, 0] * u[0] + C[k, 1] * u[1] + C[k, 2] * u[2])
        if v > viol:
            viol = v
    return u, viol


class CbfFilter:
    """The common hard CBF filter (eq:cbf_condition, eq:hard_cbf_qp); every method feeds its u_in through the same
    instance type."""

    def __init__(self, params: StackParams):
        self.params = params
        self.lo = np.asarray(params.u_min, float)
        self.hi = np.asarray(params.u_max, float)
        self.Hd = np.asarray(params.H_diag, float)
        unc = params.uncertainty
        self._base = unc.r_robot_m + unc.d0_m

    def reset(self) -> None:
        """A new episode. The filter keeps no state between calls (the exact solver needs no warm start)."""

    def _solve_qp(self, C, lvec, u_target, cache: bool = True) -> np.ndarray | None:
        """eq:hard_cbf_qp, exactly (``smallqp.solve_hard``); None when the solver reports no solution (infeasible, or
        its iteration limit). ``cache`` is accepted for the callers of the earlier warm-started solver."""
        status, x = smallqp.solve_hard(C, lvec, u_target, self.Hd, self.lo, self.hi)
        if status != smallqp.OK or not np.isfinite(x).all():
            return None
        return x

    def _least_violation(self, C, lvec, u_in) -> tuple[float, np.ndarray] | None:
        """The slack QP of the module docstring (``smallqp.solve_slack``). Returns (t*, u) or None when the solver
        gives no finite command."""
        status, x, _ = smallqp.solve_slack(C, lvec, u_in, self.Hd, self.lo, self.hi, SLACK_PENALTY)
        # an unfinished solve (the iteration limit) still gives a command; its violation is measured
        if not np.isfinite(x).all():
            return None
        u, viol = _clip_violation(C, lvec, x, self.lo, self.hi)
        t_star = max(float(viol), 0.0)
        if t_star > FEAS_TOL:
            u, t_star = self._within_tolerance(C, lvec, np.ones(len(lvec), bool), u_in, u, t_star)
        return t_star, u

    def _within_tolerance(self, C, lvec, soft, u_in, u, t_star) -> tuple[np.ndarray, float]:
        """The second stage of the least-violation command (module docstring): the minimum-intervention command with
        the ``soft`` rows relaxed by t* + SLACK_TOL_MPS and the others exact (``smallqp.solve_hard``). ``u`` (whose
        soft rows are violated by at most t*) is feasible there, so only a solver failure keeps it. Returns
        (u, the soft rows' largest violation)."""
        status, x = smallqp.solve_hard(C, lvec - np.where(soft, t_star + SLACK_TOL_MPS, 0.0), u_in, self.Hd,
                                       self.lo, self.hi)
        if status != smallqp.OK or not np.isfinite(x).all():
            return u, t_star
        x, viol = _clip_violation(C[~soft], lvec[~soft], x, self.lo, self.hi)    # (-inf without hard rows)
        if viol > 1e-6:
            return u, t_star
        return x, max(float(_clip_violation(C[soft], lvec[soft], x, self.lo, self.hi)[1]), 0.0)

    def filter(self, state: RobotState, obstacles: Obstacles, u_in) -> tuple[np.ndarray, FilterInfo]:
        """eq:cbf_condition, eq:hard_cbf_qp: the minimum-intervention safe command u_safe (3,) and what the filter
        did. With ``cbf_slowdown``, a step infeasible at u_in is filtered again from the slower commands s u_in
        (module docstring, "The slowdown")."""
        t0 = time.perf_counter()
        u, info = self._filter(state, obstacles, u_in, t0)
        if info.infeasible and self.params.cbf_slowdown:
            u_in = np.asarray(u_in, float).reshape(3)
            for s in SLOWDOWN_SCALES:
                u_s, info_s = self._filter(state, obstacles, s * u_in, t0)
                if not info_s.infeasible:
                    info_s.active = True
                    info_s.fallback = "slowdown" if info_s.fallback is None else f"slowdown, {info_s.fallback}"
                    info_s.slowdown = s
                    return u_s, info_s
        return u, info

    def _filter(self, state: RobotState, obstacles: Obstacles, u_in, t0: float) -> tuple[np.ndarray, FilterInfo]:
        """The filter of one reference command u_in (:meth:`filter`); ``t0``: when the call began."""
        u_in = np.asarray(u_in, float).reshape(3)
        fallback = None
        if not np.isfinite(u_in).all():
            u_in, fallback = np.zeros(3), "invalid-input"
        rows = cbf_rows(state, obstacles, u_in, self.params)
        if not rows.plain:
            fault = perception_fault(state, obstacles)
            if fault is not None:
                return self._brake_for_fault(u_in, obstacles, fault, t0)
        idx = select_constraints(obstacles, rows, self.params)
        margins = rows.margin[idx]
        C_all, l_all, idx = rows.C, rows.l, np.asarray(idx, np.int64)
        owner = None
        if self.params.cbf_velocity_rows:
            # the velocity-aware barrier (velocity_barrier.py): cone rows after the distance rows, numbered M + k
            Cv, lv_, own = self._velocity_rows(state, obstacles, rows, idx, u_in)
            if len(lv_):
                M = len(rows.l)
                C_all, l_all = np.vstack((rows.C, Cv)), np.concatenate((rows.l, lv_))
                owner = np.concatenate((np.arange(M), own))
                idx = np.concatenate((idx, M + np.arange(len(lv_), dtype=np.int64)))
        u, viol, active, C, lvec, idx, hopeless = _prepare(C_all, l_all, idx, u_in, self.lo, self.hi, FEAS_TOL)
        infeasible = velocity_relaxed = False
        if active:
            x = None if hopeless else self._solve_qp(C, lvec, u_in, cache=True)
            if x is not None:
                x, viol = _clip_violation(C, lvec, x, self.lo, self.hi)
            if x is not None and viol <= 1e-6:
                u = x
            else:
                vel = idx >= len(rows.l)
                relaxed = self._relax_velocity_rows(C, lvec, vel, u_in) if owner is not None and vel.any() else None
                if relaxed is not None:        # t* <= FEAS_TOL: the solver had failed on a feasible problem
                    u, t_star = relaxed
                    velocity_relaxed = t_star > FEAS_TOL
                    fallback = "velocity-relaxed" if velocity_relaxed else (fallback or "qp-retry")
                else:
                    u, fallback, infeasible = self._infeasible(C, lvec, u_in, fallback)
                    if infeasible and self.params.cbf_last_resort != "slack":
                        u, fallback = self._last_resort(state, obstacles, rows, C, lvec, idx, owner, u)
                    if not np.isfinite(u).all():
                        u, fallback = np.zeros(3), "brake"
                u, viol = _clip_violation(C, lvec, u, self.lo, self.hi)
        h = rows.h
        n_vel = 0
        if owner is not None:
            n_vel = int(np.count_nonzero(idx >= len(rows.l)))
            idx = owner[idx]
        info = FilterInfo(active=bool(active), infeasible=infeasible, fallback=fallback,
                          solve_ms=(time.perf_counter() - t0) * 1e3, n_constraints=len(lvec),
                          h_min=float(h.min()) if len(h) else math.inf, D=rows.D, max_violation=max(float(viol), 0.0),
                          rows=idx, margins=margins, n_velocity_rows=n_vel, velocity_relaxed=velocity_relaxed)
        return u, info

    def _relax_velocity_rows(self, C, lvec, soft, u_in) -> tuple[np.ndarray, float] | None:
        """The lexicographic fallback of the velocity-aware barrier (module docstring): the distance rows hard, the
        velocity rows (``soft``) relaxed by one shared slack (``smallqp.solve_soft``). (u, the velocity rows' largest
        violation t*), or None when the distance rows and the box admit no command (then the step is infeasible and
        the slack QP over every row decides)."""
        status, x, _ = smallqp.solve_soft(C, lvec, soft.astype(np.float64), u_in, self.Hd, self.lo, self.hi,
                                          SLACK_PENALTY)
        if status != smallqp.OK or not np.isfinite(x).all():
            return None
        u, viol = _clip_violation(C[~soft], lvec[~soft], x, self.lo, self.hi)     # (boolean indexing copies)
        if viol > 1e-6:
            return None
        t_star = max(float(_clip_violation(C[soft], lvec[soft], u, self.lo, self.hi)[1]), 0.0)
        if t_star > FEAS_TOL:
            u, t_star = self._within_tolerance(C, lvec, soft, u_in, u, t_star)
        return u, t_star

    def _velocity_rows(self, state: RobotState, obstacles: Obstacles, rows: CbfRows, idx: np.ndarray, u_in):
        """The collision-cone rows of the selected obstacles (``velocity_barrier.velocity_rows``), D_i^exec from
        ``rows``: (C, l, owner)."""
        p = self.params
        _, Axy, _, _, ident = _consts(p)
        d = p.uncertainty.execution.d
        return velocity_rows(float(state.px), float(state.py), float(state.theta), float(u_in[0]), float(u_in[1]),
                             float(u_in[2]), _f64(obstacles.p), _f64(obstacles.v), _f64(rows.D),
                             np.ascontiguousarray(obstacles.ids, dtype=np.int64), idx, Axy, float(d[0]), float(d[1]),
                             float(p.cbf_velocity_horizon_s), float(p.cbf_velocity_min_speed_mps), ident, self.lo,
                             self.hi)

    def _last_resort(self, state, obstacles, rows, C, lvec, sel, owner, u_slack):
        """StackParams.cbf_last_resort other than "slack" (module docstring), when the QP is infeasible: "brake"
        gives u = 0; "evade" the full-speed sidestep across the path of the obstacle of the worst row of the slack
        solution, projected on the other obstacles' rows by the least-violation QP (the slack solution when that
        obstacle is a wall point or slower than ``cbf_velocity_min_speed_mps``). Returns (u, fallback)."""
        p = self.params
        if p.cbf_last_resort == "brake":
            return np.zeros(3), "brake"
        if p.cbf_last_resort == "passive":
            return self._passive(state, rows, u_slack), "passive"
        obst = sel if owner is None else owner[sel]
        k = int(np.argmax(lvec - C @ u_slack))
        j = int(obst[k])
        v_j = np.asarray(obstacles.v[j], float)
        if int(obstacles.ids[j]) < 0 or float(np.hypot(v_j[0], v_j[1])) < p.cbf_velocity_min_speed_mps:
            return u_slack, "least-violation"
        _, Axy, _, _, _ = _consts(p)
        target = sidestep_target(float(state.theta), rows.q[j], v_j, p.v_max_mps, Axy,
                                 np.asarray(p.uncertainty.execution.d[:2], float))
        others = obst != j
        if not others.any():
            return np.minimum(np.maximum(target, self.lo), self.hi), "evade"
        lv = self._least_violation(np.ascontiguousarray(C[others]), np.ascontiguousarray(lvec[others]), target)
        if lv is None:
            return u_slack, "least-violation"
        return lv[1], "evade"

    def _passive(self, state: RobotState, rows: CbfRows, u: np.ndarray, sweeps: int = 20) -> np.ndarray:
        """The "passive" last resort (module docstring): u with its approach toward every body inside its D_i^exec
        (h_i < 0) removed. In the normalized rows, the robot's velocity R(theta)(A u + d) does not approach body i iff
        C_i u >= f_i = -2 q_i^T R(theta) d_xy / ||a_i|| (C_i u = 2 q_i^T R(theta) A_xy u / ||a_i||,
        eq:cbf_condition (25)). Alternating projections onto those half-planes and the actuator box (``sweeps``
        passes); what is still short of a half-plane then is closed by scaling u toward 0 (the largest factor in
        [0, 1] that meets every f_i that u = 0 meets)."""
        inside = np.flatnonzero((rows.h < 0) & (rows.norm > 0))
        if not len(inside):
            return u
        c, s = math.cos(state.theta), math.sin(state.theta)
        dxy = np.asarray(self.params.uncertainty.execution.d[:2], float)
        drift = np.array([c * dxy[0] - s * dxy[1], s * dxy[0] + c * dxy[1]])        # R(theta) d_xy
        floor = -2.0 * (rows.q[inside] @ drift) / rows.norm[inside]
        Ci = rows.C[inside]
        n2 = np.einsum("ij,ij->i", Ci, Ci)
        u = np.minimum(np.maximum(np.asarray(u, float), self.lo), self.hi)
        for _ in range(sweeps):
            for k in range(len(inside)):
                gap = floor[k] - float(Ci[k] @ u)
                if gap > 0 and n2[k] > 0:
                    u = u + gap * Ci[k] / n2[k]
            u = np.minimum(np.maximum(u, self.lo), self.hi)
        cu = Ci @ u
        short = (cu < floor - 1e-12) & (floor <= 0)          # f_i that u = 0 meets (C_i 0 = 0 >= f_i)
        if short.any():     # C_i (t u) >= f_i for t <= f_i / C_i u (C_i u < f_i <= 0)
            u = u * float(np.clip(np.min(floor[short] / cu[short]), 0.0, 1.0))
        return u

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
