"""Issue 26: the tracker's compiled measurement update (tracker._measurement_update) against its numpy references,
kalman.kf_update (the CV filter, Joseph form), kalman.static_update (the constant-position filter and its
consistency check) and classify.speed_sigma, on random filters: equal to rounding."""
import numpy as np

from bigcbf.perception.classify import speed_sigma
from bigcbf.perception.kalman import kf_update, static_update
from bigcbf.perception.tracker import _measurement_update


def _spd(rng, n, d, scale):
    a = rng.normal(size=(n, d, d)) * scale
    return a @ a.transpose(0, 2, 1) + np.eye(d) * scale ** 2 * 0.1


def test_compiled_update_matches_the_numpy_references():
    rng = np.random.default_rng(7)
    n = 9
    x = rng.normal(size=(n, 4))
    x[3, 2:] = 0.0                                          # a track at rest: the speed's std is lambda_max's
    P = _spd(rng, n, 4, 0.3)
    xs = x[:, :2] + rng.normal(size=(n, 2)) * 0.05
    xs[5] += 3.0                                            # far from the CV filter: the check restarts it there
    Ps = _spd(rng, n, 2, 0.1)
    rows = np.array([0, 3, 5, 8], np.int64)
    cols = np.array([2, 0, 1, 3], np.int64)
    z = x[rows[np.argsort(cols)], :2] + rng.normal(size=(4, 2)) * 0.1
    R = _spd(rng, 4, 2, 0.1)
    gate = 9.21
    # the references
    xr, Pr = kf_update(x[rows], P[rows], z[cols], R[cols])
    xsr, Psr = static_update(xs[rows], Ps[rows], xr[:, :2], Pr[:, :2, :2], z[cols], R[cols], gate)
    sig_r = speed_sigma(xr[:, 2:], Pr[:, 2:, 2:])
    sv_r = np.sqrt(np.linalg.eigvalsh(Pr[:, 2:, 2:])[:, -1])
    # compiled, in place
    xc, Pc, xsc, Psc, sv = x.copy(), P.copy(), xs.copy(), Ps.copy(), np.zeros(n)
    sig = np.empty(len(rows))
    _measurement_update(rows, cols, xc, Pc, xsc, Psc, z, R, gate, sig, sv)
    np.testing.assert_allclose(xc[rows], xr, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Pc[rows], Pr, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(xsc[rows], xsr, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Psc[rows], Psr, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(sig, sig_r, rtol=1e-10)
    np.testing.assert_allclose(sv[rows], sv_r, rtol=1e-10)
    assert np.array_equal(xsc[5], xc[5, :2])                # restarted from the CV filter
    others = np.setdiff1d(np.arange(n), rows)               # tracks without a measurement are left alone
    assert np.array_equal(xc[others], x[others]) and np.array_equal(Pc[others], P[others])


def test_compiled_report_matches_the_numpy_reference():
    """Tracker.reported (compiled: tracker._reported) against its numpy form (as of 417ecbb): static tracks report
    the constant-position filter, dynamic ones the CV filter; coasting covariances capped at the last update's
    largest std plus coast_bound (cap_covariance)."""
    from bigcbf.perception.tracker import Tracker, cap_covariance, coast_bound
    rng = np.random.default_rng(5)
    T = Tracker()
    n = 12
    T.x, T.P = rng.normal(size=(n, 4)), _spd(rng, n, 4, 0.4)
    T.xs, T.Ps, T.P_hit = rng.normal(size=(n, 2)), _spd(rng, n, 2, 0.2), _spd(rng, n, 2, 0.05)
    T.static = rng.random(n) < 0.4
    T.sv_hit = rng.uniform(0.01, 0.3, n)
    T.t = 3.0
    T.last_hit = np.where(rng.random(n) < 0.5, 3.0, 3.0 - rng.uniform(0.05, 1.5, n))
    idx = np.array([0, 2, 3, 5, 7, 8, 11])
    p, cov = T.reported(idx)
    st = T.static[idx]
    p0 = np.where(st[:, None], T.xs[idx], T.x[idx, :2])
    c0 = np.where(st[:, None, None], T.Ps[idx], T.P[idx, :2, :2])
    tau = T.t - T.last_hit[idx]
    lam0 = np.linalg.eigvalsh(T.P_hit[idx])[:, -1]
    sigma_max = np.sqrt(np.maximum(lam0, 0.0)) + coast_bound(tau, st, np.linalg.norm(T.x[idx, 2:], axis=1),
                                                             T.sv_hit[idx], T.params)
    c0 = np.where((tau > 1e-9)[:, None, None], cap_covariance(c0, sigma_max), c0)
    assert np.array_equal(p, p0)
    np.testing.assert_allclose(cov, c0, rtol=1e-12, atol=1e-15)
    assert not np.allclose(cov, np.where(st[:, None, None], T.Ps[idx], T.P[idx, :2, :2]))     # some were capped


def test_compiled_prediction_matches_kf_predict():
    """Tracker.predict (compiled: tracker._predict_tracks) against kalman.kf_predict (x' = F x, P' = F P F^T + Q)."""
    from bigcbf.perception.kalman import cv_model, kf_predict
    from bigcbf.perception.tracker import _predict_tracks
    rng = np.random.default_rng(9)
    x, P = rng.normal(size=(7, 4)), _spd(rng, 7, 4, 0.3)
    for dt in (0.1, 0.05, 1.3):
        F, Q = cv_model(dt, 0.5)
        xr, Pr = kf_predict(x, P, dt, 0.5)
        xc, Pc = x.copy(), P.copy()
        _predict_tracks(xc, Pc, F, Q)
        np.testing.assert_allclose(xc, xr, rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(Pc, Pr, rtol=1e-12, atol=1e-14)


def test_nearest_first_is_numpys_stable_argsort():
    """tracker._nearest_first (issue 26) orders tracks as idx[argsort(|p - robot| - r, stable)] did, ties in idx's
    order (two tracks at the same surface distance)."""
    from bigcbf.perception.tracker import _nearest_first
    rng = np.random.default_rng(2)
    for _ in range(300):
        n = int(rng.integers(0, 12))
        x = rng.uniform(-5, 5, (n, 4))
        r = rng.uniform(0, 0.5, n)
        if n >= 2:
            x[1, :2], r[1] = x[0, :2], r[0]                # a tie
        idx = np.flatnonzero(rng.random(n) < 0.7)
        robot = rng.uniform(-1, 1, 2)
        ref = idx[np.argsort((np.linalg.norm(x[:, :2] - robot, axis=1) - r)[idx], kind="stable")]
        assert np.array_equal(_nearest_first(idx, x, r, float(robot[0]), float(robot[1])), ref)


def ref_report(self, robot_xy):
    """tracker.Tracker.report as of 96c6b28."""
    from bigcbf.types import Obstacles
    from bigcbf.perception.tracker import _nearest_first
    pr = self.params
    measured = self.last_hit >= (self.t if self.t is not None else 0.0) - 1e-9
    circle = self.confirmed & (~self.static | self.is_round())
    idx = np.flatnonzero(circle)
    order = _nearest_first(idx, self.x, self.r, float(robot_xy[0]), float(robot_xy[1]))
    order, beyond = order[: pr.max_tracks], order[pr.max_tracks:]
    as_points = np.zeros(len(self), bool)
    as_points[beyond] = True
    as_points |= self.confirmed & ~circle
    as_points &= self.static | measured
    as_points |= ~self.confirmed & measured
    surfaces = [self.surface[k] for k in np.flatnonzero(as_points) if len(self.surface[k])]
    if len(order) == 0:
        return Obstacles.empty(), surfaces
    v = np.where(self.static[order, None], 0.0, self.x[order, 2:])
    p, cov = self.reported(order)
    return (Obstacles(p, v, cov, self.r[order].copy(), self.static[order].copy(), self.ids[order].copy()),
            surfaces)


def test_report_and_misses_compiled_match_their_numpy_form():
    """Tracker.report's choice (compiled: tracker._circles, issue 26) against its numpy form (as of 96c6b28) on
    random track sets (confirmed or not, static or not, round or not, measured now or coasting, over the budget,
    surfaces empty or not): the same circles, bit for bit, and the same surfaces; and tracker._missed against the
    numpy form of Tracker.step's misses and deletion test."""
    from bigcbf.params.perception import PerceptionParams
    from bigcbf.perception.tracker import Tracker, _missed
    rng = np.random.default_rng(12)
    for trial in range(300):
        T = Tracker(PerceptionParams(max_tracks=int(rng.integers(0, 6))))
        n = int(rng.integers(0, 12))
        T.x, T.P = rng.normal(size=(n, 4)), _spd(rng, n, 4, 0.4)
        T.xs, T.Ps, T.P_hit = rng.normal(size=(n, 2)), _spd(rng, n, 2, 0.2), _spd(rng, n, 2, 0.05)
        T.sv_hit, T.r = rng.uniform(0.01, 0.3, n), rng.uniform(0.05, 0.5, n)
        T.confirmed, T.static = rng.random(n) < 0.7, rng.random(n) < 0.5
        T.roundness = rng.choice([0.0, 0.4, 0.5, 1.0], n)
        T.ids = rng.permutation(100)[:n]
        T.t = 3.0
        T.last_hit = np.where(rng.random(n) < 0.5, 3.0, 3.0 - rng.uniform(0.05, 1.5, n))
        T.surface = np.empty(n, object)
        for k in range(n):
            T.surface[k] = rng.normal(size=(int(rng.integers(0, 3)), 2))
        robot = rng.uniform(-1, 1, 2)
        (a, sa), (b, sb) = T.report(robot), ref_report(T, robot)
        for f in ("p", "v", "cov", "r", "static", "ids"):
            x, y = getattr(a, f), getattr(b, f)
            assert x.dtype == y.dtype and np.array_equal(x, y), f
        assert len(sa) == len(sb) and all(p is q for p, q in zip(sa, sb))
        # the misses and the deletion test
        T.misses = rng.integers(0, 4, n)
        rows = np.flatnonzero(rng.random(n) < 0.5)
        pr, t = T.params, 3.2
        missed = np.ones(n, bool)
        missed[rows] = False
        want = T.misses.copy()
        want[missed] += 1
        alive = np.where(T.confirmed, t - T.last_hit <= pr.coast_s + 1e-9, want <= pr.tentative_max_misses)
        got, every = _missed(rows, t, float(pr.coast_s + 1e-9), int(pr.tentative_max_misses), T.misses,
                             T.confirmed, T.last_hit)
        assert np.array_equal(T.misses, want) and np.array_equal(got, alive) and every == alive.all()


def test_small_kernels_are_their_numpy_expressions():
    """tracker._plus_eye is numpy's A + c * np.eye(2) bit for bit (signed zeros off the diagonal, c of either
    sign), and tracker._gated keeps the assigned pairs that pass the gate, in order, as rows[ok[rows, cols]]."""
    from bigcbf.perception.tracker import _gated, _plus_eye
    rng = np.random.default_rng(3)
    A = rng.normal(size=(6, 2, 2))
    A[0, 0, 1], A[1, 1, 0], A[2, 0, 0] = -0.0, 0.0, -0.0
    for c in (0.0, 0.0025, -0.5, 3.0):
        got, want = _plus_eye(A, c), A + c * np.eye(2)
        assert np.array_equal(got, want) and np.array_equal(np.signbit(got), np.signbit(want))
    ok = rng.random((5, 4)) < 0.5
    rows, cols = np.array([0, 1, 3, 4]), np.array([2, 0, 3, 1])
    keep = ok[rows, cols]
    r, c = _gated(rows, cols, ok)
    assert np.array_equal(r, rows[keep]) and np.array_equal(c, cols[keep])
