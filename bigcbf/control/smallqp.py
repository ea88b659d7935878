"""The CBF filter's small QPs solved exactly: Goldfarb and Idnani's dual active-set method (Math. Prog. 27, 1983).

Two problems, both from ``bigcbf.control.cbf`` (eq:hard_cbf_qp (26), with the rows of eq:cbf_condition (25),
normalized to C_i u >= l_i):

- the hard QP: min_u (u - u_in)^T H (u - u_in) s.t. C u >= l, u_min <= u <= u_max (3 variables, H diagonal > 0);
- its slack form, used when the hard QP is infeasible: min_(u, t) (u - u_in)^T H (u - u_in) + P t s.t.
  C u + t >= l, u_min <= u <= u_max, t >= 0 (4 variables; t has no curvature);
- the slack form with only some rows softened (``solve_soft``): C_i u + s_i t >= l_i with s_i in {0, 1}, the rows
  with s_i = 0 hard (the filter's lexicographic fallback: the distance rows hard, the velocity-aware rows relaxed).

The method keeps a set A of active constraints (linearly independent normals) and multipliers lambda_A >= 0 such
that x minimizes the objective on {x: n_j^T x = b_j, j in A} (dual feasibility); it adds the most violated
constraint p, moving x and the multipliers along the direction that raises n_p^T x at unit rate while the active
ones stay active; a multiplier that would turn negative drops its constraint first (a "partial step"). When n_p is
a combination of the active normals, the step is in the multipliers only; when no active multiplier can shrink,
the constraints are infeasible (Farkas). Every full step raises the dual objective strictly, so the method ends
after finitely many steps, exactly (no tolerance decides where the optimum is, only which constraints are
violated, by more than ``TOL (1 + |b|)``). The answer is then re-solved from the final active set's KKT system, so
it depends only on that set.

Start points: the hard QP starts from x = u_in with A empty (the unconstrained minimum); the slack QP from
(u_in, 0) with A = {t >= 0}, lambda = P (the minimum with t held at 0). With t's zero curvature the KKT systems
stay nonsingular because A always holds a softened row or t >= 0 (the t-component of the stationarity condition,
P = sum of the softened rows' multipliers + that of t >= 0, forbids dropping the last of them).

Deterministic: plain double arithmetic in a fixed order (``bigcbf.control.jit``), Gaussian elimination with
partial pivoting, ties broken by the lowest index; no thread, no alignment-dependent reduction. The tests compare
it with proxsuite on thousands of problems (tests/control/test_smallqp.py).
"""
from __future__ import annotations

import numpy as np

from .jit import kernel

OK, INFEASIBLE, FAILED = 0, 1, 2
#: a constraint n^T x >= b counts as violated below -TOL (1 + |b|)
TOL = 1e-12
#: Gaussian elimination calls a pivot zero below this fraction of the matrix's largest entry
_PIVOT = 1e-13
_MAX_ITER = 200


@kernel
def _solve_dense(M, rhs, m, sol):
    """Solve M[:m, :m] s = rhs[:m] by Gaussian elimination with partial pivoting (M, rhs overwritten); the
    solution in sol[:m]. False when a pivot is below _PIVOT times the largest entry (numerically singular)."""
    scale = 0.0
    for i in range(m):
        for j in range(m):
            a = abs(M[i, j])
            if a > scale:
                scale = a
    if scale == 0.0:
        return False
    for k in range(m):
        piv, best = k, abs(M[k, k])
        for i in range(k + 1, m):
            a = abs(M[i, k])
            if a > best:
                piv, best = i, a
        if best <= _PIVOT * scale:
            return False
        if piv != k:
            for j in range(k, m):
                M[k, j], M[piv, j] = M[piv, j], M[k, j]
            rhs[k], rhs[piv] = rhs[piv], rhs[k]
        for i in range(k + 1, m):
            f = M[i, k] / M[k, k]
            if f != 0.0:
                for j in range(k + 1, m):
                    M[i, j] -= f * M[k, j]
                rhs[i] -= f * rhs[k]
    for k in range(m - 1, -1, -1):
        s = rhs[k]
        for j in range(k + 1, m):
            s -= M[k, j] * sol[j]
        sol[k] = s / M[k, k]
    return True


@kernel
def _kkt(Qd, N, act, nact, p, M, rhs):
    """The KKT matrix of the active set A (plus constraint p if p >= 0) in M: [[Q, -N_A^T], [N_A, 0]]; returns
    its size. rhs zeroed."""
    nv = Qd.shape[0]
    na = nact + (1 if p >= 0 else 0)
    m = nv + na
    for i in range(m):
        rhs[i] = 0.0
        for j in range(m):
            M[i, j] = 0.0
    for i in range(nv):
        M[i, i] = Qd[i]
    for k in range(na):
        c = act[k] if k < nact else p
        for i in range(nv):
            M[i, nv + k] = -N[c, i]
            M[nv + k, i] = N[c, i]
    return m


@kernel
def gi_solve(Qd, g, N, b, x, act, lam, nact, max_iter):
    """min 1/2 x^T diag(Qd) x + g^T x s.t. N x >= b by the dual active-set method (module docstring).

    Qd (nv,) >= 0, g (nv,), N (nc, nv), b (nc,). x (nv,), act (nv,) int, lam (nv,) and nact: a dual-feasible start
    (updated in place: the solution, its active set and multipliers). Returns (status, nact, iterations) with status
    OK, INFEASIBLE (no x satisfies N x >= b) or FAILED (the iteration limit, or a singular KKT system).

    Length: a numba kernel: one dual active-set loop whose state (x, act, lam, nact, the active mask) every step updates
    in place; the primal step and the multiplier-only step end in the same drop of a constraint."""
    nv = Qd.shape[0]
    nc = N.shape[0]
    size = 2 * nv + 1
    M = np.empty((size, size))
    rhs = np.empty(size)
    sol = np.empty(size)
    G = np.empty((nv, nv))
    alpha = np.empty(nv)
    inact = np.zeros(nc, np.bool_)
    for k in range(nact):
        inact[act[k]] = True
    it = 0
    while True:
        # the most violated constraint (the lowest index among equals)
        p = -1
        worst = 0.0
        for c in range(nc):
            if inact[c]:
                continue
            s = -b[c]
            for i in range(nv):
                s += N[c, i] * x[i]
            if s < -TOL * (1.0 + abs(b[c])) and (p < 0 or s < worst):
                p, worst = c, s
        if p < 0:
            break
        lam_p = 0.0
        while True:
            it += 1
            if it > max_iter:
                return FAILED, nact, it
            # with nv independent normals active, n_p is their combination: no primal step exists (the KKT system
            # is singular; rounding can hide that from the pivot test, and p would overrun act and lam)
            full = nact >= nv
            if not full:
                m = _kkt(Qd, N, act, nact, p, M, rhs)
                rhs[m - 1] = 1.0                          # raise n_p^T x at unit rate, the active ones fixed
            if not full and _solve_dense(M, rhs, m, sol):
                s = b[p]
                for i in range(nv):
                    s -= N[p, i] * x[i]                   # the step that makes p active
                t1, jdrop = np.inf, -1
                for k in range(nact):
                    dl = sol[nv + k]
                    if dl < 0.0:
                        r = lam[k] / -dl
                        if r < t1:
                            t1, jdrop = r, k
                step = s if s <= t1 else t1
                for i in range(nv):
                    x[i] += step * sol[i]
                for k in range(nact):
                    lam[k] += step * sol[nv + k]
                lam_p += step * sol[nv + nact]
                if s <= t1:                               # full step: p joins the active set
                    act[nact], lam[nact] = p, lam_p
                    inact[p] = True
                    nact += 1
                    break
            else:
                # n_p = N_A^T alpha: a step in the multipliers only; alpha from (N_A N_A^T) alpha = N_A n_p
                if nact == 0:                             # (the KKT system is singular only for n_p = 0)
                    return INFEASIBLE, nact, it
                for k in range(nact):
                    s = 0.0
                    for i in range(nv):
                        s += N[act[k], i] * N[p, i]
                    rhs[k] = s
                    for j in range(nact):
                        s = 0.0
                        for i in range(nv):
                            s += N[act[k], i] * N[act[j], i]
                        G[k, j] = s
                if not _solve_dense(G, rhs, nact, alpha):
                    return FAILED, nact, it
                t1, jdrop = np.inf, -1
                for k in range(nact):
                    if alpha[k] > 0.0:
                        r = lam[k] / alpha[k]
                        if r < t1:
                            t1, jdrop = r, k
                if jdrop < 0:
                    return INFEASIBLE, nact, it
                for k in range(nact):
                    lam[k] -= t1 * alpha[k]
                lam_p += t1
            # partial step: drop the constraint whose multiplier reached 0, then try p again
            inact[act[jdrop]] = False
            for k in range(jdrop, nact - 1):
                act[k], lam[k] = act[k + 1], lam[k + 1]
            nact -= 1
    # the answer from the final active set's KKT system: Q x - N_A^T lambda = -g, N_A x = b_A
    m = _kkt(Qd, N, act, nact, -1, M, rhs)
    for i in range(nv):
        rhs[i] = -g[i]
    for k in range(nact):
        rhs[nv + k] = b[act[k]]
    if _solve_dense(M, rhs, m, sol):
        for i in range(nv):
            x[i] = sol[i]
        for k in range(nact):
            lam[k] = sol[nv + k]
    return OK, nact, it


@kernel
def _box_rows(C, l, lo, hi, slack, soft):
    """The constraint matrix N x >= b of the hard QP (slack False: x = u) or of the slack QP (x = (u, t)): the
    rows, then u >= lo, -u >= -hi, then (slack) t >= 0. In the slack QP, t enters row i with coefficient soft[i]
    (1: the row may be violated by t; 0: the row is hard)."""
    n = C.shape[0]
    nv = 4 if slack else 3
    nc = n + 6 + (1 if slack else 0)
    N = np.zeros((nc, nv))
    b = np.empty(nc)
    for i in range(n):
        for j in range(3):
            N[i, j] = C[i, j]
        if slack:
            N[i, 3] = soft[i]
        b[i] = l[i]
    for j in range(3):
        N[n + j, j] = 1.0
        b[n + j] = lo[j]
        N[n + 3 + j, j] = -1.0
        b[n + 3 + j] = -hi[j]
    if slack:
        N[n + 6, 3] = 1.0
        b[n + 6] = 0.0
    return N, b


@kernel
def solve_hard(C, l, u_in, Hd, lo, hi):
    """eq:hard_cbf_qp (26): min (u - u_in)^T diag(Hd) (u - u_in) s.t. C u >= l, lo <= u <= hi. Returns (status, u)."""
    N, b = _box_rows(C, l, lo, hi, False, l)
    Qd = 2.0 * Hd
    g = -Qd * u_in
    x = u_in.copy()
    act = np.zeros(3, np.int64)
    lam = np.zeros(3)
    status, _, _ = gi_solve(Qd, g, N, b, x, act, lam, 0, _MAX_ITER)
    return status, x


@kernel
def solve_slack(C, l, u_in, Hd, lo, hi, penalty):
    """min (u - u_in)^T diag(Hd) (u - u_in) + penalty t s.t. C u + t >= l, lo <= u <= hi, t >= 0.
    Returns (status, u, t)."""
    return solve_soft(C, l, np.ones(C.shape[0]), u_in, Hd, lo, hi, penalty)


@kernel
def solve_soft(C, l, soft, u_in, Hd, lo, hi, penalty):
    """The slack QP with only some rows softened: min (u - u_in)^T diag(Hd) (u - u_in) + penalty t s.t.
    C_i u + soft_i t >= l_i (soft_i 1: the row may be violated by t; 0: hard), lo <= u <= hi, t >= 0.
    Status INFEASIBLE when the hard rows and the box admit no u. Returns (status, u, t)."""
    n = C.shape[0]
    N, b = _box_rows(C, l, lo, hi, True, soft)
    Qd = np.zeros(4)
    g = np.zeros(4)
    x = np.zeros(4)
    for j in range(3):
        Qd[j] = 2.0 * Hd[j]
        g[j] = -Qd[j] * u_in[j]
        x[j] = u_in[j]
    g[3] = penalty
    act = np.zeros(4, np.int64)
    lam = np.zeros(4)
    act[0], lam[0] = n + 6, penalty                       # start: t held at 0 (its multiplier balances P)
    status, _, _ = gi_solve(Qd, g, N, b, x, act, lam, 1, _MAX_ITER)
    return status, x[:3].copy(), x[3]
