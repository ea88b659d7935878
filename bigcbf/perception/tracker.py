"""Multi-object tracker: gating, assignment, track birth / confirmation / coasting / deletion, one CV Kalman filter
per track, static/dynamic hysteresis, each track's shape (round or not) and last surface. Tracks are kept as arrays
(a few dozen at most).

Life of a track:
* born TENTATIVE from a cluster no track claimed (unless its centre lies inside an existing track's circle: a
  split cluster of a known object), with velocity 0 and velocity std init_vel_sigma_mps;
* CONFIRMED after confirm_hits measurements; a tentative track is deleted after tentative_max_misses misses;
* classified static/dynamic (``classify``) once its velocity rests on more than classify_after_hits measurements
  (default 1: from its second measurement on). A phantom velocity of a static object is kept out by the
  measurement covariances and the significance test, not by waiting: each measurement comes with the covariance
  of its own fit (``geometry.circle_fit_covariance``), so a 0.15 m bin 4.5 m away seen by four beams (its first
  fits jumped 11 cm) has a centre std of ~8 cm along the line of sight and its velocity estimate a large std,
  and dynamic_sigma = 2 asks for a speed twice that std. With the former fixed 5 cm std and a 1-sigma test, far
  posts of the dev split's post fields were dynamic in up to 9 % of the scans of an episode (posts_00001); a
  walker near the robot, measured to 1-2 cm, still turns dynamic at its fourth measurement;
* a confirmed track with no measurement coasts at constant velocity with growing covariance for coast_s (a
  pedestrian hidden behind a wall or another pedestrian keeps its identity), then is deleted; while it coasts,
  its reported covariance is bounded by physics (:func:`coast_bound`);
* at most max_candidates tracks are kept (the farthest are dropped); :meth:`Tracker.report` gives the circles
  (confirmed, dynamic or round, the max_tracks nearest by distance to their surface, |p - p_robot| - r) and the
  surfaces of the others (static and not round, beyond the budget, tentative ones measured now).
Shape: a track is round while the smoothed share (factor shape_smoothing) of its measurements that the circle
model explained outright (``geometry.Measurement.round``) is at least 1/2; it starts with its first measurement's.
Association: cost = Euclidean distance between the predicted centre and a cluster centre; a pair is allowed when
its Mahalanobis distance squared (innovation covariance S = P_pos + R, R the measurement's fit covariance plus
fit_model_sigma_m^2 I) is below gate_chi2 or its distance is below gate_min_m, never beyond gate_max_m, and only
when the cluster's radius is within gate_radius_m of the track's (two objects merged into one cluster, e.g. a
pedestrian passing a post, must not drag the post's track); the assignment minimising the total cost is scipy's
linear_sum_assignment. Before that, the pipeline splits clusters that hold two known objects along the tracks'
predicted circles (:meth:`Tracker.surface_owner`, ``pipeline.Perception._segment``).

Two filters per track. The constant-velocity Kalman filter (``kalman``) estimates every track's velocity and drives
the static/dynamic classification; dynamic tracks report its position and covariance. Static tracks report a
constant-position Kalman filter run beside it (state = position, a random walk of PSD ``static_pos_psd_m2ps``): a
post does not move, and the CV model's acceleration noise (tuned for walkers) would inflate a post's covariance
for nothing. When the two filters' positions disagree beyond gate_chi2 (Mahalanobis over the sum of their
covariances: the object moves), the constant-position filter restarts from the CV filter's position and covariance.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..control.jit import kernel
from ..params.perception import PerceptionParams
from ..types import Obstacles
from .classify import _hysteresis
from .kalman import cv_model

_INFEASIBLE = 1e9

_FIELDS = ("x", "P", "xs", "Ps", "ids", "r", "hits", "misses", "confirmed", "static", "n_dyn", "n_stat", "last_hit",
           "P_hit", "sv_hit", "roundness", "surface")


def coast_bound(tau, static, speed, sigma_v0, params: PerceptionParams) -> np.ndarray:
    """How far [m] a track's object can have moved from where the prediction puts it after coasting tau seconds
    without a measurement (physics, not statistics):

    * static: 0 (a static object does not move);
    * dynamic (a walking person): min((v_max + |v|) tau, a_max tau^2 / 2 + sigma_v0 tau). The person is within
      v_max tau of where it was at the last update and the constant-velocity prediction within |v| tau of it;
      with bounded acceleration its velocity stays within a_max tau of its value then, known to sigma_v0.

    v_max = walk_speed_max_mps, a_max = walk_accel_max_mps2; all arguments broadcast."""
    tau = np.maximum(np.asarray(tau, float), 0.0)
    dyn = np.minimum((params.walk_speed_max_mps + np.asarray(speed, float)) * tau,
                     0.5 * params.walk_accel_max_mps2 * tau * tau + np.asarray(sigma_v0, float) * tau)
    return np.where(np.asarray(static, bool), 0.0, dyn)


def cap_covariance(cov: np.ndarray, sigma_max) -> np.ndarray:
    """Scale 2x2 covariances (N, 2, 2) down so that their largest standard deviation is at most sigma_max (N,)
    (unchanged where it already is)."""
    cov = np.asarray(cov, float)
    a, b, c = cov[:, 0, 0], 0.5 * (cov[:, 0, 1] + cov[:, 1, 0]), cov[:, 1, 1]
    lam = 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b)
    cap = np.asarray(sigma_max, float) ** 2
    k = np.where(lam > cap, cap / np.maximum(lam, 1e-300), 1.0)
    return cov * k[:, None, None]


@kernel
def _nearest_circle(points, c, r, tol, conf, out):
    """:meth:`Tracker.surface_owner`'s assignment, compiled: for each point the circle (c, r) nearest in
    | |p - c| - r | (the first of equal ones, as np.argmin), taken when within its ``tol``: out[i] = conf[best]."""
    for i in range(points.shape[0]):
        best, dbest = 0, np.inf
        for j in range(c.shape[0]):
            d = abs(math.sqrt((points[i, 0] - c[j, 0]) ** 2 + (points[i, 1] - c[j, 1]) ** 2) - r[j])
            if d != d:                 # np.argmin: the first NaN
                best, dbest = j, d
                break
            if d < dbest:
                best, dbest = j, d
        if dbest <= tol[best]:
            out[i] = conf[best]


@kernel
def _surface_owner(points, confirmed, x, P, r, merge_tol):
    """:meth:`Tracker.surface_owner` compiled: the confirmed tracks' circles and tolerances
    (:func:`_surface_tolerance`), each point's owner (:func:`_nearest_circle`), -1 where none."""
    out = np.full(points.shape[0], -1, np.int64)
    conf = np.flatnonzero(confirmed)
    if conf.shape[0] == 0 or points.shape[0] == 0:
        return out
    c, rc, tol = np.empty((conf.shape[0], 2)), np.empty(conf.shape[0]), np.empty(conf.shape[0])
    for k in range(conf.shape[0]):
        c[k, 0], c[k, 1], rc[k] = x[conf[k], 0], x[conf[k], 1], r[conf[k]]
    _surface_tolerance(P, conf, merge_tol, tol)
    _nearest_circle(points, c, rc, tol, conf, out)
    return out


@kernel
def _gate(z, radii, R, x, P, r, chi2, gate_min, gate_max, gate_radius, infeasible, cost, ok):
    """:meth:`Tracker.associate`'s gate and cost (n tracks, m measurements) into ``cost`` and ``ok`` (n, m):
    y = z_j - p_i, S = P_i[:2, :2] + R_j, Mahalanobis distance squared as ``kalman.mahalanobis2``, in its order."""
    for i in range(x.shape[0]):
        for j in range(z.shape[0]):
            y0, y1 = z[j, 0] - x[i, 0], z[j, 1] - x[i, 1]
            dist = math.sqrt(y0 * y0 + y1 * y1)
            a, b = P[i, 0, 0] + R[j, 0, 0], P[i, 0, 1] + R[j, 0, 1]
            c, d = P[i, 1, 0] + R[j, 1, 0], P[i, 1, 1] + R[j, 1, 1]
            d2 = (d * y0 * y0 - (b + c) * y0 * y1 + a * y1 * y1) / (a * d - b * c)
            good = (d2 <= chi2 or dist <= gate_min) and dist <= gate_max and abs(radii[j] - r[i]) <= gate_radius
            ok[i, j] = good
            cost[i, j] = dist if good else infeasible


@kernel
def _apply_hits(rows, cols, x, P, radii, rnd, t, sigma, a, b, confirm_hits, classify_after, v_dynamic,
                dynamic_sigma, v_static, n_dynamic, n_static, r, roundness, hits, misses, last_hit, confirmed, static,
                n_dyn, n_stat, Ps, P_hit):
    """The bookkeeping of :meth:`Tracker.step` for the tracks ``rows`` updated by measurements ``cols`` (their
    updated states x[rows] and covariances P[rows], the speed's std ``sigma``): radius and roundness smoothed
    (factors a, b), hits, misses, time of the hit, confirmation, the static/dynamic hysteresis
    (``classify._hysteresis``; a young track keeps its class and zero counters) and the reported covariance at
    the hit, in place, in the numpy formulation's order."""
    K = rows.shape[0]
    st_in, nd_in, ns_in, speed = np.empty(K, np.bool_), np.empty(K, np.int64), np.empty(K, np.int64), np.empty(K)
    for k in range(K):
        i, j = rows[k], cols[k]
        r[i] = (1 - a) * r[i] + a * radii[j]
        roundness[i] = (1 - b) * roundness[i] + b * rnd[j]
        hits[i] += 1
        misses[i] = 0
        last_hit[i] = t
        confirmed[i] = confirmed[i] or hits[i] >= confirm_hits
        st_in[k], nd_in[k], ns_in[k] = static[i], n_dyn[i], n_stat[i]
        speed[k] = math.sqrt(x[i, 2] * x[i, 2] + x[i, 3] * x[i, 3])
    st, nd, ns = np.empty(K, np.bool_), np.empty(K, np.int64), np.empty(K, np.int64)
    _hysteresis(st_in, nd_in, ns_in, speed, sigma, v_dynamic, dynamic_sigma, v_static, n_dynamic, n_static, st, nd,
                ns)
    for k in range(K):
        i = rows[k]
        young = hits[i] <= classify_after
        static[i] = st_in[k] if young else st[k]
        n_dyn[i] = 0 if young else nd[k]
        n_stat[i] = 0 if young else ns[k]
        for p in range(2):
            for q in range(2):
                P_hit[i, p, q] = Ps[i, p, q] if static[i] else P[i, p, q]


@kernel
def _missed(rows, t, coast, tentative_max, misses, confirmed, last_hit):
    """:meth:`Tracker.step`'s misses and deletion test: one more miss for every track not in ``rows``; returns
    whether each track is kept (confirmed: its last hit at most ``coast`` before t; tentative: at most
    ``tentative_max`` misses) and whether all are."""
    n = misses.shape[0]
    hit = np.zeros(n, np.bool_)
    for k in range(rows.shape[0]):
        hit[rows[k]] = True
    alive = np.empty(n, np.bool_)
    every = True
    for i in range(n):
        if not hit[i]:
            misses[i] += 1
        alive[i] = t - last_hit[i] <= coast if confirmed[i] else misses[i] <= tentative_max
        every = every and alive[i]
    return alive, every


@kernel
def _plus_eye(A, c):
    """A + c I for 2x2 matrices A (n, 2, 2), as numpy's ``A + c * np.eye(2)`` (c * 0 added off the diagonal)."""
    out = np.empty_like(A)
    off = c * 0.0
    for i in range(A.shape[0]):
        out[i, 0, 0], out[i, 1, 1] = A[i, 0, 0] + c * 1.0, A[i, 1, 1] + c * 1.0
        out[i, 0, 1], out[i, 1, 0] = A[i, 0, 1] + off, A[i, 1, 0] + off
    return out


@kernel
def _gated(rows, cols, ok):
    """The assigned pairs (rows[k], cols[k]) that pass the gate ``ok``, in order."""
    keep = np.empty(rows.shape[0], np.bool_)
    for k in range(rows.shape[0]):
        keep[k] = ok[rows[k], cols[k]]
    return rows[keep], cols[keep]


@kernel
def _sym2_lmax(a, b, c):
    """The largest eigenvalue of the symmetric 2x2 matrix [[a, b], [b, c]] (closed form)."""
    return 0.5 * (a + c) + math.sqrt(0.25 * (a - c) * (a - c) + b * b)


@kernel
def _predict_tracks(x, P, F, Q):
    """``kalman.kf_predict`` (its reference) in place: x = F x, P = F P F^T + Q for every track (4x4 products summed
    in index order)."""
    xn = np.empty(4)
    T = np.empty((4, 4))
    for i in range(x.shape[0]):
        for a in range(4):
            acc = 0.0
            for c in range(4):
                acc += F[a, c] * x[i, c]
            xn[a] = acc
        for a in range(4):
            x[i, a] = xn[a]
            for b in range(4):
                acc = 0.0
                for c in range(4):
                    acc += F[a, c] * P[i, c, b]
                T[a, b] = acc
        for a in range(4):
            for b in range(4):
                acc = 0.0
                for c in range(4):
                    acc += T[a, c] * F[b, c]
                P[i, a, b] = acc + Q[a, b]


@kernel
def _reported(idx, static, x, P, xs, Ps, P_hit, sv_hit, last_hit, t, v_max, a_max, p, cov):
    """:meth:`Tracker.reported` compiled, track by track: the static filter's position and covariance for a static
    track, the CV filter's for a dynamic one; a coasting track's covariance (tau = t - last hit > 1e-9) capped at
    sqrt(lambda_max(P_hit)) + :func:`coast_bound` (:func:`cap_covariance`)."""
    for k in range(idx.shape[0]):
        i = idx[k]
        st = static[i]
        for a in range(2):
            p[k, a] = xs[i, a] if st else x[i, a]
            for b in range(2):
                cov[k, a, b] = Ps[i, a, b] if st else P[i, a, b]
        tau = t - last_hit[i]
        if tau > 1e-9:
            lam0 = _sym2_lmax(P_hit[i, 0, 0], 0.5 * (P_hit[i, 0, 1] + P_hit[i, 1, 0]), P_hit[i, 1, 1])
            bound = 0.0
            if not st:
                speed = math.sqrt(x[i, 2] * x[i, 2] + x[i, 3] * x[i, 3])
                bound = min((v_max + speed) * tau, 0.5 * a_max * tau * tau + sv_hit[i] * tau)
            sigma_max = math.sqrt(max(lam0, 0.0)) + bound
            lam = _sym2_lmax(cov[k, 0, 0], 0.5 * (cov[k, 0, 1] + cov[k, 1, 0]), cov[k, 1, 1])
            cap = sigma_max * sigma_max
            if lam > cap:
                f = cap / max(lam, 1e-300)
                for a in range(2):
                    for b in range(2):
                        cov[k, a, b] *= f


@kernel
def _surface_tolerance(P, conf, merge_tol, out):
    """:meth:`Tracker.surface_owner`'s tolerance of each confirmed track conf[k]: merge_tol plus twice the largest
    standard deviation of its position (closed-form eigenvalue of the 2x2 block)."""
    for k in range(conf.shape[0]):
        i = conf[k]
        lam = _sym2_lmax(P[i, 0, 0], 0.5 * (P[i, 0, 1] + P[i, 1, 0]), P[i, 1, 1])
        out[k] = merge_tol + 2.0 * math.sqrt(max(lam, 0.0))


@kernel
def _cv_update(i, j, x, P, z, R, Kg, A, T, Pn):
    """Track i's CV filter with measurement j (``kalman.kf_update``): S = P_pp + R, K = P H^T S^-1 (closed-form 2x2
    inverse), x += K (z - H x), P = (I - K H) P (I - K H)^T + K R K^T (Joseph form), symmetrised; Kg (4, 2), A, T, Pn
    (4, 4) are scratch."""
    r00, r01, r10, r11 = R[j, 0, 0], R[j, 0, 1], R[j, 1, 0], R[j, 1, 1]
    s00, s01, s10, s11 = P[i, 0, 0] + r00, P[i, 0, 1] + r01, P[i, 1, 0] + r10, P[i, 1, 1] + r11
    det = s00 * s11 - s01 * s10
    i00, i01, i10, i11 = s11 / det, -s01 / det, -s10 / det, s00 / det
    for a in range(4):
        Kg[a, 0] = P[i, a, 0] * i00 + P[i, a, 1] * i10
        Kg[a, 1] = P[i, a, 0] * i01 + P[i, a, 1] * i11
    y0, y1 = z[j, 0] - x[i, 0], z[j, 1] - x[i, 1]
    for a in range(4):
        x[i, a] += Kg[a, 0] * y0 + Kg[a, 1] * y1
    for a in range(4):                                     # A = I - K H
        for b in range(4):
            A[a, b] = (1.0 if a == b else 0.0) - (Kg[a, b] if b < 2 else 0.0)
    for a in range(4):                                     # T = A P
        for b in range(4):
            acc = 0.0
            for c in range(4):
                acc += A[a, c] * P[i, c, b]
            T[a, b] = acc
    for a in range(4):                                     # Pn = T A^T + K R K^T
        for b in range(4):
            acc = 0.0
            for c in range(4):
                acc += T[a, c] * A[b, c]
            kr0 = Kg[a, 0] * r00 + Kg[a, 1] * r10
            kr1 = Kg[a, 0] * r01 + Kg[a, 1] * r11
            Pn[a, b] = acc + kr0 * Kg[b, 0] + kr1 * Kg[b, 1]
    for a in range(4):
        for b in range(4):
            P[i, a, b] = 0.5 * (Pn[a, b] + Pn[b, a])


@kernel
def _static_update(i, j, x, P, xs, Ps, z, R, gate_chi2):
    """Track i's constant-position filter with measurement j (``kalman.static_update``): the Joseph-form update of
    xs, Ps, symmetrised, restarted from the CV filter's (already updated) position block where the two disagree
    beyond gate_chi2 (``kalman.mahalanobis2``)."""
    r00, r01, r10, r11 = R[j, 0, 0], R[j, 0, 1], R[j, 1, 0], R[j, 1, 1]
    p00, p01, p10, p11 = Ps[i, 0, 0], Ps[i, 0, 1], Ps[i, 1, 0], Ps[i, 1, 1]
    s00, s01, s10, s11 = p00 + r00, p01 + r01, p10 + r10, p11 + r11
    det = s00 * s11 - s01 * s10
    i00, i01, i10, i11 = s11 / det, -s01 / det, -s10 / det, s00 / det
    k00, k01 = p00 * i00 + p01 * i10, p00 * i01 + p01 * i11
    k10, k11 = p10 * i00 + p11 * i10, p10 * i01 + p11 * i11
    e0, e1 = z[j, 0] - xs[i, 0], z[j, 1] - xs[i, 1]
    xs0, xs1 = xs[i, 0] + k00 * e0 + k01 * e1, xs[i, 1] + k10 * e0 + k11 * e1
    a00, a01, a10, a11 = 1.0 - k00, -k01, -k10, 1.0 - k11
    t00, t01 = a00 * p00 + a01 * p10, a00 * p01 + a01 * p11
    t10, t11 = a10 * p00 + a11 * p10, a10 * p01 + a11 * p11
    kr00, kr01 = k00 * r00 + k01 * r10, k00 * r01 + k01 * r11
    kr10, kr11 = k10 * r00 + k11 * r10, k10 * r01 + k11 * r11
    q00 = t00 * a00 + t01 * a01 + kr00 * k00 + kr01 * k01
    q01 = t00 * a10 + t01 * a11 + kr00 * k10 + kr01 * k11
    q10 = t10 * a00 + t11 * a01 + kr10 * k00 + kr11 * k01
    q11 = t10 * a10 + t11 * a11 + kr10 * k10 + kr11 * k11
    q01 = q10 = 0.5 * (q01 + q10)
    c00, c01, c10, c11 = P[i, 0, 0], P[i, 0, 1], P[i, 1, 0], P[i, 1, 1]
    m00, m01, m10, m11 = q00 + c00, q01 + c01, q10 + c10, q11 + c11
    d0, d1 = xs0 - x[i, 0], xs1 - x[i, 1]
    md = m00 * m11 - m01 * m10
    if (m11 * d0 * d0 - (m01 + m10) * d0 * d1 + m00 * d1 * d1) / md > gate_chi2:
        xs[i, 0], xs[i, 1] = x[i, 0], x[i, 1]
        Ps[i, 0, 0], Ps[i, 0, 1], Ps[i, 1, 0], Ps[i, 1, 1] = c00, c01, c10, c11
    else:
        xs[i, 0], xs[i, 1] = xs0, xs1
        Ps[i, 0, 0], Ps[i, 0, 1], Ps[i, 1, 0], Ps[i, 1, 1] = q00, q01, q10, q11


@kernel
def _measurement_update(rows, cols, x, P, xs, Ps, z, R, gate_chi2, sigma, sv_hit):
    """The measurement updates of :meth:`Tracker.step`, track rows[k] with measurement cols[k], in place: the CV
    filter (:func:`_cv_update`; ``kalman.kf_update`` its reference), the constant-position filter
    (:func:`_static_update`; ``kalman.static_update``), and sigma[k] the speed's standard deviation
    (``classify.speed_sigma``) and sv_hit[i] the largest velocity standard deviation of the updated filter. The
    formulas are the references' term by term; their sums run in another order (to rounding:
    tests/perception/test_tracker_compiled.py)."""
    Kg, A, T, Pn = np.empty((4, 2)), np.empty((4, 4)), np.empty((4, 4)), np.empty((4, 4))
    for k in range(rows.shape[0]):
        i, j = rows[k], cols[k]
        _cv_update(i, j, x, P, z, R, Kg, A, T, Pn)
        _static_update(i, j, x, P, xs, Ps, z, R, gate_chi2)
        v0, v1 = x[i, 2], x[i, 3]
        va, vb, vc = P[i, 2, 2], P[i, 2, 3], P[i, 3, 3]
        lmax = _sym2_lmax(va, vb, vc)
        sp = math.sqrt(v0 * v0 + v1 * v1)
        if sp > 1e-12:
            u0, u1 = v0 / sp, v1 / sp
            var = u0 * (va * u0 + vb * u1) + u1 * (P[i, 3, 2] * u0 + vc * u1)
        else:
            var = lmax
        sigma[k] = math.sqrt(max(var, 0.0))
        sv_hit[i] = math.sqrt(lmax)


class Tracker:
    """Tracks of compact objects in odom (see the module docstring)."""

    def __init__(self, params: PerceptionParams = PerceptionParams()):
        self.params = params
        self.reset()

    def reset(self) -> None:
        self.t: float | None = None
        self.next_id = 0
        self.x = np.zeros((0, 4))
        self.P = np.zeros((0, 4, 4))
        self.xs = np.zeros((0, 2))            # constant-position filter (static tracks): position
        self.Ps = np.zeros((0, 2, 2))         # ... and its covariance
        self.P_hit = np.zeros((0, 2, 2))      # reported position covariance at the last update
        self.sv_hit = np.zeros(0)             # velocity std (largest) at the last update
        self.ids = np.zeros(0, int)
        self.r = np.zeros(0)
        self.hits = np.zeros(0, int)
        self.misses = np.zeros(0, int)
        self.confirmed = np.zeros(0, bool)
        self.static = np.zeros(0, bool)
        self.n_dyn = np.zeros(0, int)
        self.n_stat = np.zeros(0, int)
        self.last_hit = np.zeros(0)
        self.roundness = np.zeros(0)          # smoothed share of circle-model measurements (1 = round)
        self.surface = np.empty(0, object)    # the points (k, 2) of the last measured cluster, odom [m]

    def __len__(self) -> int:
        return len(self.ids)

    def _keep(self, mask: np.ndarray) -> None:
        for name in _FIELDS:
            setattr(self, name, getattr(self, name)[mask])

    def _append(self, z: np.ndarray, r: np.ndarray, R: np.ndarray, round_: np.ndarray, surface: np.ndarray,
                t: float) -> None:
        m = len(z)
        pr = self.params
        x = np.hstack([z, np.zeros((m, 2))])
        P = np.zeros((m, 4, 4))
        P[:, :2, :2] = R
        P[:, 2, 2] = P[:, 3, 3] = pr.init_vel_sigma_mps ** 2
        new = dict(x=x, P=P, xs=np.asarray(z, float).reshape(m, 2).copy(), Ps=R.copy(), P_hit=R.copy(),
                   sv_hit=np.full(m, pr.init_vel_sigma_mps), ids=self.next_id + np.arange(m), r=np.asarray(r, float),
                   hits=np.ones(m, int),
                   misses=np.zeros(m, int), confirmed=np.full(m, pr.confirm_hits <= 1), static=np.ones(m, bool),
                   n_dyn=np.zeros(m, int), n_stat=np.zeros(m, int), last_hit=np.full(m, t),
                   roundness=np.asarray(round_, float), surface=surface)
        self.next_id += m
        for name in _FIELDS:
            setattr(self, name, np.concatenate([getattr(self, name), new[name]]))

    def predict(self, t: float) -> None:
        """Propagate every track to time t (constant velocity, eq:obs_prop (2); covariance grows)."""
        if self.t is not None and len(self) and t > self.t:
            F, Q = cv_model(float(t - self.t), float(self.params.accel_psd_m2ps3))
            _predict_tracks(self.x, self.P, F, Q)
            self.Ps = _plus_eye(self.Ps, self.params.static_pos_psd_m2ps * (t - self.t))
        self.t = t

    def measurement_covariance(self, cov: np.ndarray | None, m: int) -> np.ndarray:
        """R (m, 2, 2) [m^2] of m cluster centres: their fit covariance ``cov`` (``geometry.measure_compact``; none
        given: 0) plus fit_model_sigma_m^2 I (what the fit's own covariance leaves out: the object's shape is not
        exactly the model's, the scan is not instantaneous)."""
        if cov is None:
            return np.broadcast_to(self.params.fit_model_sigma_m ** 2 * np.eye(2), (m, 2, 2)).copy()
        return _plus_eye(np.asarray(cov, float).reshape(m, 2, 2), self.params.fit_model_sigma_m ** 2)

    def surface_owner(self, points: np.ndarray) -> np.ndarray:
        """(n,) int: for each point (n, 2), the index (into the track arrays) of the confirmed track on whose
        predicted circle it lies (|p - c| - r within merge_tol_m plus twice the track's position std; the nearest
        such circle), or -1. Call after :meth:`predict`: the pipeline splits clusters that hold known objects along
        this (track-aided segmentation)."""
        return _surface_owner(np.ascontiguousarray(points, dtype=float), self.confirmed, self.x, self.P, self.r,
                              float(self.params.merge_tol_m))

    def associate(self, z: np.ndarray, radii: np.ndarray, R: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Matched (track index, measurement index) pairs for cluster centres z (M,2) with radii (M,) and
        measurement covariances R (M,2,2) (default: ``measurement_covariance(None, M)``), gated (module
        docstring)."""
        n, m = len(self), len(z)
        if n == 0 or m == 0:
            return np.zeros(0, int), np.zeros(0, int)
        pr = self.params
        if R is None:
            R = self.measurement_covariance(None, m)
        cost, ok = np.empty((n, m)), np.empty((n, m), np.bool_)
        _gate(np.ascontiguousarray(z, dtype=float), np.ascontiguousarray(radii, dtype=float),
              np.ascontiguousarray(R, dtype=float), np.ascontiguousarray(self.x), np.ascontiguousarray(self.P),
              np.ascontiguousarray(self.r), float(pr.gate_chi2), float(pr.gate_min_m), float(pr.gate_max_m),
              float(pr.gate_radius_m), _INFEASIBLE, cost, ok)
        rows, cols = linear_sum_assignment(cost)
        return _gated(rows, cols, ok)

    def step(self, t: float, z: np.ndarray, radii: np.ndarray, robot_xy: np.ndarray, cov: np.ndarray | None = None,
             round_: np.ndarray | None = None, surface: list | None = None) -> np.ndarray:
        """One scan: predict to t, associate cluster centres z (M,2) with radii (M,), update, birth, delete.

        ``cov`` (M,2,2): the centres' fit covariances (``measurement_covariance``); ``round_`` (M,) bool: whether
        the circle model explained the cluster (default all); ``surface``: the cluster's points (k, 2) per
        measurement, kept with the track that takes it (``report``). Returns the indices of the measurements that
        neither updated a track nor started one (a cluster inside a known object's circle whose radius does not
        match it, e.g. two objects merged into one cluster).

        Length: one scan's predict, update, delete, birth and cap in the order the tracks' state must change, all on one
        association (rows, cols); the update's maths is already in helpers (_measurement_update, _apply_hits)."""
        pr = self.params
        z = np.asarray(z, float).reshape(-1, 2)
        m = len(z)
        radii = np.asarray(radii, float).reshape(-1)
        R = self.measurement_covariance(cov, m)
        rnd = np.ones(m) if round_ is None else np.asarray(round_, float).reshape(m)
        surf = (lambda k: np.zeros((0, 2))) if surface is None else surface.__getitem__   # measurement k's points
        self.predict(t)
        rows, cols = self.associate(z, radii, R)
        rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
        if len(rows):
            # the CV and constant-position filters' updates, the speed's std (compiled: _measurement_update)
            sigma = np.empty(len(rows))
            _measurement_update(rows, cols, self.x, self.P, self.xs, self.Ps, np.ascontiguousarray(z),
                                np.ascontiguousarray(R), float(pr.gate_chi2), sigma, self.sv_hit)
            for i, j in zip(rows.tolist(), cols.tolist()):
                self.surface[i] = surf(j)
            # the smoothed radius and shape, the counters, and the classification (hysteresis_step), which starts
            # once the velocity rests on more than classify_after_hits measurements: a young track's velocity is the
            # difference of two or three noisy centres (module docstring); compiled (_apply_hits)
            _apply_hits(rows, cols, self.x, self.P, np.ascontiguousarray(radii),
                        np.ascontiguousarray(rnd, dtype=float), float(t), sigma, float(pr.radius_smoothing),
                        float(pr.shape_smoothing), int(pr.confirm_hits), int(pr.classify_after_hits),
                        float(pr.v_dynamic_mps), float(pr.dynamic_sigma), float(pr.v_static_mps), int(pr.n_dynamic),
                        int(pr.n_static), self.r, self.roundness, self.hits, self.misses, self.last_hit,
                        self.confirmed, self.static, self.n_dyn, self.n_stat, self.Ps, self.P_hit)
        alive, every = _missed(rows, float(t), float(pr.coast_s + 1e-9), int(pr.tentative_max_misses), self.misses,
                               self.confirmed, self.last_hit)
        if not every:                             # (all alive: the arrays stay as they are)
            self._keep(alive)
        # births from unclaimed clusters, unless the centre lies inside a known object's circle (a split cluster)
        rejected = np.zeros(0, np.intp)
        if len(cols) < m:                         # (a cluster no track claimed)
            free = np.ones(m, bool)
            free[cols] = False
            if len(self):
                d = np.linalg.norm(z[:, None, :] - self.x[None, :, :2], axis=2)
                out = free & (d < np.maximum(self.r[None, :], radii[:, None])).any(axis=1)
                free &= ~out
                rejected = np.flatnonzero(out)
            if free.any():
                new = np.empty(m, object)
                for k in range(m):
                    new[k] = surf(k)
                self._append(z[free], radii[free], R[free], rnd[free], new[free], t)
        if len(self) > pr.max_candidates:
            keep = np.argsort(self.surface_distance(robot_xy), kind="stable")[: pr.max_candidates]
            self._keep(np.sort(keep))
        return rejected

    def reported(self, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position (K, 2) and covariance (K, 2, 2) of tracks ``idx`` as reported: the constant-position filter's
        for static tracks, the CV filter's for dynamic ones; while coasting (no measurement at the current time),
        the covariance is capped at the standard deviation of the last update plus :func:`coast_bound`
        (:func:`cap_covariance`; compiled: ``_reported``)."""
        idx = np.ascontiguousarray(idx, dtype=np.int64)
        p, cov = np.empty((len(idx), 2)), np.empty((len(idx), 2, 2))
        pr = self.params
        _reported(idx, self.static, self.x, self.P, self.xs, self.Ps, self.P_hit, self.sv_hit, self.last_hit,
                  self.t if self.t is not None else 0.0, float(pr.walk_speed_max_mps), float(pr.walk_accel_max_mps2),
                  p, cov)
        return p, cov

    def surface_distance(self, robot_xy: np.ndarray) -> np.ndarray:
        return np.linalg.norm(self.x[:, :2] - robot_xy, axis=1) - self.r

    def is_round(self) -> np.ndarray:
        """Whether each track's object is round: most of its recent clusters were explained by the circle model
        (smoothed share of circle-model measurements, factor shape_smoothing, at least 1/2)."""
        return self.roundness >= 0.5

    def report(self, robot_xy: np.ndarray) -> tuple[Obstacles, list]:
        """What the tracks tell the stack: (circles, surfaces).

        Circles: the confirmed tracks that are dynamic or round, at most max_tracks, nearest first (surface
        distance). Static tracks have v = 0 and the constant-position filter's position and covariance; coasting
        covariances are bounded (``reported``).

        Surfaces: the points (k, 2) of the last measured cluster of every other track, which the pipeline turns
        into wall points: a static object that is not round (a box, a wall end, a corner: its circle would cover
        free space around it) and the confirmed tracks beyond the budget (those measured now when dynamic, since a
        walker's old points are stale), and the tentative tracks measured now (an object seen for the first time
        is an obstacle before its track is confirmed)."""
        since = (self.t if self.t is not None else 0.0) - 1e-9                # measured now: hit since then
        order, as_points, v, r, static, ids = _circles(
            self.confirmed, self.static, self.is_round(), self.last_hit, since, self.x, self.r, self.ids,
            float(robot_xy[0]), float(robot_xy[1]), int(self.params.max_tracks))
        surfaces = [self.surface[k] for k in np.flatnonzero(as_points).tolist() if len(self.surface[k])]
        if len(order) == 0:
            return Obstacles.empty(), surfaces
        p, cov = self.reported(order)
        return Obstacles(p, v, cov, r, static, ids), surfaces

    def obstacles(self, robot_xy: np.ndarray) -> Obstacles:
        """The circles of :meth:`report`."""
        return self.report(robot_xy)[0]


@kernel
def _circles(confirmed, static, round_, last_hit, since, x, r, ids, rx, ry, max_tracks):
    """:meth:`Tracker.report`'s choice, compiled: the circles (confirmed tracks, dynamic or ``round_``), at most
    ``max_tracks``, nearest first (:func:`_nearest_first`), and the tracks reported by their surface
    (``as_points``: the circles beyond the budget and the confirmed tracks that are not circles, each when static
    or measured now, i.e. hit at ``since`` or later; the tentative tracks measured now). Returns (order,
    as_points, and the circles' velocities (0 when static), radii, static flags and ids)."""
    n = confirmed.shape[0]
    circle = np.empty(n, np.bool_)
    for i in range(n):
        circle[i] = confirmed[i] and (not static[i] or round_[i])
    ranked = _nearest_first(np.flatnonzero(circle), x, r, rx, ry)
    order = ranked[:max_tracks]
    as_points = np.zeros(n, np.bool_)
    for i in ranked[max_tracks:]:
        as_points[i] = True
    for i in range(n):
        measured = last_hit[i] >= since
        as_points[i] = (((as_points[i] or (confirmed[i] and not circle[i])) and (static[i] or measured))
                        or (not confirmed[i] and measured))
    k = order.shape[0]
    v, r_o, st, id_o = np.empty((k, 2)), np.empty(k), np.empty(k, np.bool_), np.empty(k, ids.dtype)
    for q in range(k):
        i = order[q]
        v[q, 0], v[q, 1] = (0.0, 0.0) if static[i] else (x[i, 2], x[i, 3])
        r_o[q], st[q], id_o[q] = r[i], static[i], ids[i]
    return order, as_points, v, r_o, st, id_o


@kernel
def _nearest_first(idx, x, r, rx, ry):
    """``idx[np.argsort(surface_distance(robot)[idx], kind="stable")]`` compiled (:meth:`Tracker.report`): the
    tracks ``idx`` by their surface distance |p - robot| - r (numpy's 2-norm of a pair: sqrt(dx dx + dy dy)),
    ties in ``idx``'s order."""
    d = np.empty(idx.shape[0])
    for k in range(idx.shape[0]):
        i = idx[k]
        dx, dy = x[i, 0] - rx, x[i, 1] - ry
        d[k] = math.sqrt(dx * dx + dy * dy) - r[i]
    return idx[np.argsort(d, kind="mergesort")]
