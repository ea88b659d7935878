"""The exact small-QP solver of the CBF filter (bigcbf.control.smallqp) against proxsuite, the reference.

Thousands of seeded random problems of eq:hard_cbf_qp (3 variables, a diagonal H, normalized rows plus the box)
in six families: random rows, parallel and opposite copies of rows, near-parallel rows (1e-9..1e-5 apart), rows
through box corners and edges, zero and tiny rows, rows without a yaw part. Each answer is checked three ways:
- against proxsuite (tight tolerances) wherever proxsuite reports a solution: the same u to 1e-9;
- by its own KKT certificate (primal feasibility, and multipliers >= 0 from a non-negative least-squares fit on
  the active constraints that satisfy stationarity), independent of any solver;
- infeasibility: a problem the solver calls infeasible has a positive least worst-case violation (proxsuite's slack
  QP), and one it solves is feasible (its own answer satisfies every row).
The slack QP (the filter's least-violation fallback) is compared the same way.
"""
import numpy as np
import proxsuite
import pytest
from scipy.optimize import nnls

from bigcbf.control import smallqp

PENALTY = 1e4
KINDS = ("random", "parallel", "near", "corner", "zero", "axis")
N_PER_KIND = 400          # 2,400 problems
_SOLVED = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED


def proxsuite_qp(C, l, u_in, Hd, lo, hi, slack=False, soft=None):
    """The same problem solved by proxsuite's dense solver with tight tolerances: (solved, x). ``soft``: the slack
    QP's t-column (default: every row softened)."""
    n, nv = len(l), (4 if slack else 3)
    soft = np.ones(n) if soft is None else np.asarray(soft, float)
    qp = proxsuite.proxqp.dense.QP(nv, 0, n, True)
    st = qp.settings
    st.eps_abs, st.eps_rel, st.max_iter, st.max_iter_in = 1e-12, 0.0, 200, 50
    st.eps_primal_inf, st.eps_dual_inf, st.verbose = 1e-14, 1e-14, False
    st.check_duality_gap, st.eps_duality_gap_abs, st.eps_duality_gap_rel = True, 1e-12, 0.0
    if slack:
        qp.init(np.diag(np.r_[2 * Hd, 0.0]), np.r_[-2 * Hd * u_in, PENALTY], None, None,
                np.hstack([C, soft[:, None]]), l, np.full(n, 1e20), np.r_[lo, 0.0], np.r_[hi, 1e20])
    else:
        qp.init(np.diag(2 * Hd), -2 * Hd * u_in, None, None, C, l, np.full(n, 1e20), lo, hi)
    qp.solve()
    return qp.results.info.status == _SOLVED, np.array(qp.results.x)


def kkt_residual(C, l, u_in, Hd, lo, hi, x, slack=False) -> tuple[float, float]:
    """(largest constraint violation, stationarity residual with the best multipliers >= 0 on the constraints
    active within 1e-9): both ~0 certify x as the optimum of the convex QP."""
    n = len(l)
    if slack:
        N = np.vstack([np.hstack([C, np.ones((n, 1))]), np.c_[np.eye(3), np.zeros(3)], np.c_[-np.eye(3), np.zeros(3)],
                       [[0, 0, 0, 1.0]]])
        b = np.r_[l, lo, -hi, 0.0]
        grad = np.r_[2 * Hd * (x[:3] - u_in), PENALTY]
    else:
        N = np.vstack([C, np.eye(3), -np.eye(3)])
        b = np.r_[l, lo, -hi]
        grad = 2 * Hd * (x - u_in)
    s = N @ x - b
    act = np.abs(s) <= 1e-9 * (1 + np.abs(b))
    if not act.any():
        return float(max(-s.min(), 0.0)), float(np.abs(grad).max())
    _, res = nnls(N[act].T, grad)
    return float(max(-s.min(), 0.0)), float(res)


def problem(rng, kind):
    """One random problem of a family (module docstring): C (n, 3), l, u_in, Hd, lo, hi."""
    lo, hi = -rng.uniform(0.3, 1.5, 3), rng.uniform(0.3, 1.5, 3)
    Hd = rng.uniform(0.1, 3.0, 3) if rng.random() < 0.5 else np.ones(3)
    n = int(rng.integers(1, 13))
    C = rng.normal(size=(n, 3))
    C /= np.linalg.norm(C, axis=1)[:, None]
    l = rng.uniform(-0.6, 0.8, n)
    if kind == "parallel":
        k = int(rng.integers(1, n + 1))
        for j in range(k, n):
            s = int(rng.integers(0, k))
            sign = 1.0 if rng.random() < 0.5 else -1.0
            C[j] = sign * C[s]
            l[j] = rng.uniform(-0.6, 0.8) if rng.random() < 0.7 else sign * l[s]
    elif kind == "near":
        for j in range(1, n):
            if rng.random() < 0.6:
                s = int(rng.integers(0, j))
                C[j] = C[s] + 10 ** rng.uniform(-9, -5) * rng.normal(size=3)
                C[j] /= np.linalg.norm(C[j])
                l[j] = l[s] + 10 ** rng.uniform(-10, -3) * rng.normal()
    elif kind == "corner":
        for j in range(n):
            corner = np.where(rng.random(3) < 0.5, lo, hi)
            if rng.random() < 0.3:
                corner[int(rng.integers(3))] = 0.0
            if rng.random() < 0.3:
                C[j, int(rng.integers(3))] = 0.0
                C[j] /= np.linalg.norm(C[j])
            l[j] = C[j] @ corner
    elif kind == "zero":
        for j in range(n):
            if rng.random() < 0.3:
                C[j] = 0.0 if rng.random() < 0.5 else C[j] * 10 ** rng.uniform(-9, -5)
                l[j] = rng.uniform(-0.5, 0.5) if rng.random() < 0.5 else -abs(l[j])
    elif kind == "axis":
        C[:, 2] = 0.0
        C /= np.linalg.norm(C, axis=1)[:, None]
    u_in = rng.uniform(-1.3, 1.3, 3) * (hi - lo) / 2 + (hi + lo) / 2
    return C, l, u_in, Hd, lo, hi


@pytest.mark.parametrize("kind", KINDS)
def test_against_proxsuite_and_kkt(kind):
    rng = np.random.default_rng(KINDS.index(kind) + 100)
    worst = {"hard": 0.0, "slack": 0.0}
    counts = {"hard": 0, "slack": 0, "compared": 0}
    for _ in range(N_PER_KIND):
        C, l, u_in, Hd, lo, hi = problem(rng, kind)
        status, x = smallqp.solve_hard(C, l, u_in, Hd, lo, hi)
        assert status in (smallqp.OK, smallqp.INFEASIBLE)          # never the iteration limit
        if status == smallqp.OK:
            counts["hard"] += 1
            viol, res = kkt_residual(C, l, u_in, Hd, lo, hi, x)
            assert viol <= 1e-10 and res <= 1e-10, (viol, res)
            ok, ref = proxsuite_qp(C, l, u_in, Hd, lo, hi)
            if ok:
                counts["compared"] += 1
                worst["hard"] = max(worst["hard"], float(np.abs(x - ref).max()))
            continue
        counts["slack"] += 1
        status, u, t = smallqp.solve_slack(C, l, u_in, Hd, lo, hi, PENALTY)
        assert status == smallqp.OK
        viol, res = kkt_residual(C, l, u_in, Hd, lo, hi, np.r_[u, t], slack=True)
        assert viol <= 1e-10 and res <= 1e-9, (viol, res)    # (the gradient's t-part is 1e4)
        assert t > 0.0                                              # infeasible indeed: no u without violation
        ok, ref = proxsuite_qp(C, l, u_in, Hd, lo, hi, slack=True)
        if ok:
            counts["compared"] += 1
            assert ref[3] > 1e-9                                    # proxsuite finds a violation too
            worst["slack"] = max(worst["slack"], float(np.abs(u - ref[:3]).max()))
    assert counts["hard"] > 40 and counts["slack"] > 40, counts      # both kinds of problem occur
    assert counts["compared"] > 0.7 * N_PER_KIND, counts
    assert worst["hard"] <= 1e-9 and worst["slack"] <= 1e-9, worst


def test_hand_values():
    """By hand. H = I, box [-1, 1]^3. One row u_x <= 0.3 (-u_x >= -0.3) from u_in = (0.6, 0.1, 0.2):
    u = (0.3, 0.1, 0.2). Two opposite rows u_x >= 0.5 and u_x <= 0.3 (infeasible): the slack QP balances them,
    u_x = 0.4 with t = 0.1, and keeps u_y and the yaw rate."""
    lo, hi, Hd = -np.ones(3), np.ones(3), np.ones(3)
    status, u = smallqp.solve_hard(np.array([[-1.0, 0, 0]]), np.array([-0.3]), np.array([0.6, 0.1, 0.2]), Hd, lo, hi)
    assert status == smallqp.OK
    np.testing.assert_allclose(u, [0.3, 0.1, 0.2], atol=1e-15)
    C, l = np.array([[1.0, 0, 0], [-1.0, 0, 0]]), np.array([0.5, -0.3])
    status, u = smallqp.solve_hard(C, l, np.array([0.6, 0.1, 0.2]), Hd, lo, hi)
    assert status == smallqp.INFEASIBLE
    status, u, t = smallqp.solve_slack(C, l, np.array([0.6, 0.1, 0.2]), Hd, lo, hi, PENALTY)
    assert status == smallqp.OK
    np.testing.assert_allclose(np.r_[u, t], [0.4, 0.1, 0.2, 0.1], atol=1e-15)
    # a zero row that cannot hold (0 >= 0.2) is infeasible; one that holds (0 >= -0.2) changes nothing
    status, _ = smallqp.solve_hard(np.zeros((1, 3)), np.array([0.2]), np.zeros(3), Hd, lo, hi)
    assert status == smallqp.INFEASIBLE
    status, u = smallqp.solve_hard(np.zeros((1, 3)), np.array([-0.2]), np.array([0.5, 0, 0]), Hd, lo, hi)
    assert status == smallqp.OK and np.array_equal(u, [0.5, 0.0, 0.0])


def test_soft_rows_hand_values():
    """By hand (H = I, box [-1, 1]^3, u_in = (0.6, 0.1, 0.2)): u_x >= 0.5 hard and u_x <= 0.3 soft gives u_x = 0.5,
    t = 0.2 (the hard row exact, the soft one violated by the rest); the other way round u_x = 0.3, t = 0.2; both
    rows hard is infeasible; both soft is solve_slack's balance (0.4, t = 0.1), bit for bit."""
    lo, hi, Hd, u_in = -np.ones(3), np.ones(3), np.ones(3), np.array([0.6, 0.1, 0.2])
    C, l = np.array([[1.0, 0, 0], [-1.0, 0, 0]]), np.array([0.5, -0.3])
    status, u, t = smallqp.solve_soft(C, l, np.array([0.0, 1.0]), u_in, Hd, lo, hi, PENALTY)
    assert status == smallqp.OK
    np.testing.assert_allclose(np.r_[u, t], [0.5, 0.1, 0.2, 0.2], atol=1e-15)
    status, u, t = smallqp.solve_soft(C, l, np.array([1.0, 0.0]), u_in, Hd, lo, hi, PENALTY)
    assert status == smallqp.OK
    np.testing.assert_allclose(np.r_[u, t], [0.3, 0.1, 0.2, 0.2], atol=1e-15)
    assert smallqp.solve_soft(C, l, np.zeros(2), u_in, Hd, lo, hi, PENALTY)[0] == smallqp.INFEASIBLE
    both = smallqp.solve_soft(C, l, np.ones(2), u_in, Hd, lo, hi, PENALTY)
    ref = smallqp.solve_slack(C, l, u_in, Hd, lo, hi, PENALTY)
    assert both[0] == ref[0] and both[1].tobytes() == ref[1].tobytes() and both[2] == ref[2]


@pytest.mark.parametrize("kind", ("random", "parallel", "corner"))
def test_soft_rows_against_proxsuite(kind):
    """Random problems with a random half of the rows hard: where the hard rows and the box admit a command,
    solve_soft's is proxsuite's to 1e-9 and holds every hard row; where solve_soft says infeasible, the hard rows
    alone are (solve_hard)."""
    rng = np.random.default_rng({"random": 31, "parallel": 32, "corner": 33}[kind])
    counts = {"ok": 0, "infeasible": 0, "compared": 0}
    for _ in range(300):
        C, l, u_in, Hd, lo, hi = problem(rng, kind)
        soft = (rng.random(len(l)) < 0.5).astype(float)
        soft[int(rng.integers(len(l)))] = 1.0                     # at least one softened row
        status, u, t = smallqp.solve_soft(C, l, soft, u_in, Hd, lo, hi, PENALTY)
        hard = soft == 0
        assert status in (smallqp.OK, smallqp.INFEASIBLE)
        if status == smallqp.INFEASIBLE:
            counts["infeasible"] += 1
            assert hard.any() and smallqp.solve_hard(C[hard], l[hard], u_in, Hd, lo, hi)[0] == smallqp.INFEASIBLE
            continue
        counts["ok"] += 1
        assert t >= -1e-12 and np.all(C[hard] @ u >= l[hard] - 1e-10 * (1 + np.abs(l[hard])))
        assert np.all(C[~hard] @ u + t >= l[~hard] - 1e-10 * (1 + np.abs(l[~hard])))
        ok, ref = proxsuite_qp(C, l, u_in, Hd, lo, hi, slack=True, soft=soft)
        if ok:
            counts["compared"] += 1
            assert np.abs(u - ref[:3]).max() <= 1e-9 and abs(t - ref[3]) <= 1e-9
    assert counts["ok"] > 100 and counts["compared"] > 100, counts


def test_same_bits_whatever_the_memory_layout():
    """The answer depends on the input values only: inputs copied to buffers at every 8-byte offset of a 64-byte
    line (the alignments that changed proxsuite's AVX-512 results) give byte-identical answers."""
    rng = np.random.default_rng(7)

    def at_offset(a, off):
        buf = np.zeros(a.size + 16)
        start = ((-buf.ctypes.data) % 64 + off) // 8
        view = buf[start:start + a.size].reshape(a.shape)
        view[...] = a
        return view

    for _ in range(200):
        C, l, u_in, Hd, lo, hi = problem(rng, KINDS[int(rng.integers(len(KINDS)))])
        ref = smallqp.solve_hard(C, l, u_in, Hd, lo, hi)[1].tobytes()
        ref_s = smallqp.solve_slack(C, l, u_in, Hd, lo, hi, PENALTY)[1].tobytes()
        for off in range(8, 64, 8):
            args = [at_offset(a, off) for a in (C, l, u_in, Hd, lo, hi)]
            assert smallqp.solve_hard(*args)[1].tobytes() == ref
            assert smallqp.solve_slack(*args, PENALTY)[1].tobytes() == ref_s


# A problem from a bench episode (generated world corridor_01000, CBF-only, seed 0): three rows and box bounds
# active at a vertex, then a fourth row still violated. Before the fix the solver added it to a full active set,
# wrote past its (3,) arrays and corrupted the heap ("double free or corruption", the worker died).
_FULL_C = np.array([[-0.9576237096771075, -0.2880159104008851, 0.00191468540611819],
                    [-0.6749756946719315, -0.7378350269277971, 0.00269900733609825],
                    [0.3333976410694799, 0.9427821676131166, -0.00279237533644822],
                    [0.04683393723138622, 0.9988993612018757, -0.00257847123138193],
                    [-0.5311372385961266, 0.8472845133498044, -0.00147892327947206],
                    [0.9509666114719982, 0.309287345168722, -0.00196009794382181]])
_FULL_L = np.array([0.5795147015633134, -0.5580879191315216, -0.14649760359240285,
                    -0.19529278371065376, -0.4567716632337355, -0.4853596148758686])
_FULL_U = np.array([0.78630117584654, -0.14741255327260505, 0.0])
_BOX = (np.ones(3), np.array([-0.8, -0.8, -1.0]), np.array([0.8, 0.8, 1.0]))


def test_full_active_set_then_another_violated_row():
    """The captured problem is infeasible (rows 0 and 5 ask for opposite x-components beyond the box: 0.9576 u_x
    <= -0.5795 + ... and 0.9510 u_x >= -0.4854 + ...); the hard QP says so and the slack QP's least violation is
    proxsuite's."""
    status, _ = smallqp.solve_hard(_FULL_C, _FULL_L, _FULL_U, *_BOX)
    assert status == smallqp.INFEASIBLE
    status, u, t = smallqp.solve_slack(_FULL_C, _FULL_L, _FULL_U, *_BOX, PENALTY)
    ok, ref = proxsuite_qp(_FULL_C, _FULL_L, _FULL_U, *_BOX, slack=True)
    assert status == smallqp.OK and t > 0
    assert ok and np.allclose(np.r_[u, t], ref, atol=1e-8)


_BOUNDSCHECK_SCRIPT = """
import numpy as np
from bigcbf.control import smallqp
import sys
sys.path.insert(0, {tests!r})
from test_smallqp import problem, KINDS, _FULL_C, _FULL_L, _FULL_U, _BOX, PENALTY
smallqp.solve_hard(_FULL_C, _FULL_L, _FULL_U, *_BOX)
smallqp.solve_slack(_FULL_C, _FULL_L, _FULL_U, *_BOX, PENALTY)
rng = np.random.default_rng(7)
for kind in KINDS:
    for _ in range(100):
        C, l, u_in, Hd, lo, hi = problem(rng, kind)
        smallqp.solve_hard(C, l, u_in, Hd, lo, hi)
        smallqp.solve_slack(C, l, u_in, Hd, lo, hi, PENALTY)
for _ in range(300):             # many rows in every direction: vertices reached, more rows still violated
    n = int(rng.integers(4, 25))
    C = rng.normal(size=(n, 3)); C[:, 2] *= rng.choice([1e-3, 1.0]); C /= np.linalg.norm(C[:, :2], axis=1)[:, None]
    l = rng.uniform(-0.6, 0.6, n); u_in = rng.uniform(-1, 1, 3)
    smallqp.solve_hard(C, l, u_in, *_BOX)
    smallqp.solve_slack(C, l, u_in, *_BOX, PENALTY)
print("ok")
"""


def test_no_out_of_bounds_access(tmp_path):
    """Every kernel access checked (numba's bounds checking, compiled afresh in a subprocess): the captured problem,
    the six families and random problems with up to 24 rows in every direction."""
    import os
    import subprocess
    import sys
    from pathlib import Path
    env = dict(os.environ, NUMBA_BOUNDSCHECK="1", NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    r = subprocess.run([sys.executable, "-c", _BOUNDSCHECK_SCRIPT.format(tests=str(Path(__file__).parent))],
                       env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stderr[-2000:]
