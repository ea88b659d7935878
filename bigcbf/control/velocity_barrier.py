"""The velocity-aware barrier of the common CBF filter (issue 23): a collision-cone row per moving obstacle.

Why: the distance barrier of eq:cbf_condition (25), h_i = |q_i|^2 - D_i^2, constrains only the closing speed along
q_i = p - p_i. At its boundary it reads q_i^T (v_R - v_i) >= 0, so a walker faster than the robot's speed limit
that walks at it cannot be held off there (the issue: 19-31 % infeasible steps with a 1.2 m/s walker against the
robot's 0.8 m/s), and before the boundary it only slows the approach, pushing the robot down the walker's own path.
Holding such a walker off needs a *lateral* move early, while the walker is still far: a barrier on the relative
velocity, not only on the distance.

Sources. The collision-cone CBF (C3BF; Tayal et al., arXiv:2403.07043) and the dynamic parabolic CBF (DPCBF; Park,
Kim, Panagou, ICRA 2026, arXiv:2510.01402), as implemented in tkkim-robot/safe_control
(dynamic_env/kinematic_bicycle2D_c3bf.py, kinematic_bicycle2D_dpcbf.py). With p_rel = p_i - p, v_rel = v_i - v_R,
R = r_i + r_R:

- C3BF:  h = <p_rel, v_rel> + |p_rel| |v_rel| cos(phi),  cos(phi) = sqrt(|p_rel|^2 - R^2) / |p_rel|: h >= 0 iff the
  relative velocity is outside the collision cone of half-angle phi = asin(R / |p_rel|) around the line of sight;
- DPCBF: h = v_los,x + lambda v_los,y^2 + mu  (v_rel in the line-of-sight frame; lambda = k_l sqrt(|p_rel|^2 - R^2)
  / |v_rel| sqrt(s^2 - 1) / R, mu = k_m sqrt(|p_rel|^2 - R^2) sqrt(s^2 - 1) / R): the cone replaced by a parabola that
  widens with the clearance.

There, the robot's velocity is a *state* (a kinematic bicycle with acceleration input), h has relative degree 1 and
the QP imposes dh/dt >= -gamma h, affine in the acceleration. Here the filter's decision variable u (the body twist)
*is* the velocity: v_R = R(theta)(A u + d) (eq:execution (1)), so h(q_i, v_R(u)) >= 0 is imposed directly, at every
control tick, on the command (the set {q, w: h >= 0} is a state-input constraint; its dh/dt would involve du/dt,
which the filter does not choose). Imposed directly, both sets are non-convex in u (the complement of a cone, the
outside of a parabola), so the QP needs an affine row, and

- the DPCBF's relaxation mu ~ clearance, which is what makes it less conservative there, is not recursively feasible
  as a direct constraint: a relative velocity admitted at 3 m (closing speed <= mu(3 m)) is refused at 1.5 m on the
  same straight line, and then the robot must accelerate within one tick (the DPCBF's own dh/dt condition is what
  prevents this in the paper, and it needs the velocity as a state);
- the collision cone is: with the obstacle's velocity constant, a relative velocity w = v_R - v_i outside the cone
  at q_i stays outside it at every later q_i + t w (the ray q + t w misses the disk, and so does every ray it
  contains), so the command that satisfied the row keeps satisfying it. At the boundary |q_i| = D_i the cone is the
  half-plane q_i^T w >= 0, the distance barrier's own condition: the row never admits what the boundary forbids.

So the filter uses the **collision cone (C3BF's set)**, with two adaptations:

1. *Radius*: the shared D_i^exec of eq:shared_barrier (20) (r_R + r_i + d0 + kappa_exec m_i, m_i of
   eq:uncertainty_margin (21) at u_in, as the distance row), not r_R + r_i: the same margin in both rows.
2. *Horizon and affine row*: the cone is truncated at a time horizon tau (``cbf_velocity_horizon_s``): only relative
   velocities that reach the disk within tau count, as in velocity obstacles (VO_tau; van den Berg et al., "Reciprocal
   n-body collision avoidance", ISRR 2011). VO_tau = {w: |q_i + t w| < D_i for some t in (0, tau]} is convex (the
   union of the disks B(-q_i / t, D_i / t), t <= tau: the disk's cone beyond the cut-off disk B(-q_i / tau, D_i /
   tau)). The row is its supporting half-plane at the boundary point nearest to w_in = R(A u_in + d) - v_i (u_in the
   incoming command): n_i^T w >= beta_i with n_i the outward unit normal there (a cone leg, beta = 0; or the cut-off
   arc, beta = n^T c + D/tau). Every w in the half-plane is outside VO_tau (convexity), and when w_in is outside
   VO_tau the half-plane contains it (the row does not act: minimum intervention, no cost for people passing wide
   or walking away). In u the row is affine: a_i = A_xy^T R(theta)^T n_i, b_i = beta_i - n_i^T (R(theta) d_xy - v_i),
   normalized by ||a_i|| (a violation in m/s, as the distance rows). When that half-plane holds nowhere in the
   actuator box (the nearest side asks to outrun a faster walker), the other leg is taken if the box can satisfy it
   (pass behind it): of the two legs, the one satisfiable in the box with the least violation at u_in.

Which obstacles: the tracked obstacles (ids >= 0) that ``select_constraints`` made rows and whose estimated speed
is at least ``cbf_velocity_min_speed_mps``; not wall points (ids < 0), not static obstacles (their cone would only
forbid heading at a post, which the distance row already handles without the cost), and not an obstacle already
within D_i (the cone is undefined there; its distance row is violated and acts). The distance row of every
obstacle stays: the velocity row is added, so the paper's guarantee is kept and the switch can only shrink the set of
admitted commands.
"""
from __future__ import annotations

import math

import numpy as np

from .jit import kernel


@kernel
def _affine(nx, ny, beta, c, s, rdx, rdy, vix, viy, Axy, ident):
    """n^T (R (A u + d) - v_i) >= beta as a normalized row C u >= l: (C0, C1, C2, l)."""
    nb0, nb1 = nx * c + ny * s, ny * c - nx * s          # R^T n
    b = beta - (nx * (rdx - vix) + ny * (rdy - viy))
    if ident:
        a0, a1, a2 = nb0, nb1, 0.0
    else:
        a0 = nb0 * Axy[0, 0] + nb1 * Axy[1, 0]
        a1 = nb0 * Axy[0, 1] + nb1 * Axy[1, 1]
        a2 = nb0 * Axy[0, 2] + nb1 * Axy[1, 2]
    nrm = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    if nrm > 1e-12:
        return a0 / nrm, a1 / nrm, a2 / nrm, b / nrm
    return 0.0, 0.0, 0.0, b


@kernel
def _grade(C0, C1, C2, l, u, lo, hi):
    """(violation of the row at u, its largest slack over the box)."""
    viol = l - (C0 * u[0] + C1 * u[1] + C2 * u[2])
    best = -l
    for j, cj in enumerate((C0, C1, C2)):
        best += max(cj * lo[j], cj * hi[j])
    return viol, best


@kernel
def velocity_rows(px, py, theta, u0, u1, u2, P, V, D, ids, idx, Axy, d0, d1, tau, v_min, ident, lo, hi):
    """The collision-cone rows (module docstring) of the obstacles ``idx`` (indices into P, V, D, ids) that qualify:
    (C (K, 3), l (K,), owner (K,): the obstacle index of each row), normalized as the distance rows. ``lo``, ``hi``:
    the actuator box, for the choice of the half-plane.

    Length: a numba kernel: one pass over the obstacles; each row's geometry (the legs, their normals, the cut-off disk)
    feeds both the nearest half-plane and the fallback choice of a leg."""
    n = idx.shape[0]
    C = np.zeros((n, 3))
    lv = np.zeros(n)
    owner = np.zeros(n, np.int64)
    c, s = math.cos(theta), math.sin(theta)
    # the robot's nominal world velocity R(theta)(A u_in + d) (eq:execution (1)) and R(theta) d
    bx = Axy[0, 0] * u0 + Axy[0, 1] * u1 + Axy[0, 2] * u2 + d0
    by = Axy[1, 0] * u0 + Axy[1, 1] * u1 + Axy[1, 2] * u2 + d1
    vrx, vry = c * bx - s * by, s * bx + c * by
    rdx, rdy = c * d0 - s * d1, s * d0 + c * d1
    u = np.empty(3)
    for j, x in enumerate((u0, u1, u2)):
        u[j] = min(max(x, lo[j]), hi[j])
    K = 0
    for k in range(n):
        i = idx[k]
        if ids[i] < 0:
            continue
        vix, viy = V[i, 0], V[i, 1]
        if math.hypot(vix, viy) < v_min:
            continue
        ex, ey = P[i, 0] - px, P[i, 1] - py                   # e = -q_i: robot -> obstacle
        dist2 = ex * ex + ey * ey
        Di = D[i]
        if dist2 <= Di * Di:
            continue
        wx, wy = vrx - vix, vry - viy                        # w_in = v_R(u_in) - v_i
        cx, cy = ex / tau, ey / tau                          # the cut-off disk's centre, radius D / tau
        wcx, wcy = wx - cx, wy - cy
        wc2 = wcx * wcx + wcy * wcy
        dot1 = wcx * ex + wcy * ey
        # the two legs (tangents through the origin): e rotated by -+phi, with their outward unit normals
        leg = math.sqrt(dist2 - Di * Di)
        dlx, dly = (ex * leg - ey * Di) / dist2, (ex * Di + ey * leg) / dist2
        nlx, nly = -dly, dlx
        nl = math.hypot(nlx, nly)
        nlx, nly = nlx / nl, nly / nl
        drx, dry = (ex * leg + ey * Di) / dist2, (-ex * Di + ey * leg) / dist2
        nrx, nry = dry, -drx
        nr = math.hypot(nrx, nry)
        nrx, nry = nrx / nr, nry / nr
        if dot1 < 0.0 and dot1 * dot1 > Di * Di * wc2:
            # nearest boundary point on the cut-off arc: n = (w_in - c) / |w_in - c|, n^T w >= n^T c + D / tau
            wl = math.sqrt(wc2)
            nx, ny = wcx / wl, wcy / wl
            beta = nx * cx + ny * cy + Di / tau
        elif ex * wcy - ey * wcx > 0.0:                      # nearest on the left leg
            nx, ny, beta = nlx, nly, 0.0
        else:                                                # nearest on the right leg
            nx, ny, beta = nrx, nry, 0.0
        r0, r1, r2, rl = _affine(nx, ny, beta, c, s, rdx, rdy, vix, viy, Axy, ident)
        viol, room = _grade(r0, r1, r2, rl, u, lo, hi)
        if viol > 0.0 and room < 0.0:
            # the nearest half-plane holds nowhere in the box (e.g. outrunning a faster walker): the leg, of the
            # two, that the box can satisfy with the least violation at u_in (else the one it comes closest to)
            best_key = -np.inf
            for side in range(2):
                mx, my = (nlx, nly) if side == 0 else (nrx, nry)
                t0, t1, t2, tl = _affine(mx, my, 0.0, c, s, rdx, rdy, vix, viy, Axy, ident)
                tv, troom = _grade(t0, t1, t2, tl, u, lo, hi)
                key = -tv if troom >= 0.0 else -1e6 + troom
                if key > best_key:
                    best_key = key
                    r0, r1, r2, rl = t0, t1, t2, tl
        C[K, 0], C[K, 1], C[K, 2], lv[K] = r0, r1, r2, rl
        owner[K] = i
        K += 1
    return C[:K].copy(), lv[:K].copy(), owner[:K].copy()


def sidestep_target(theta: float, q: np.ndarray, v_obs: np.ndarray, speed: float, Axy: np.ndarray,
                    d_xy: np.ndarray) -> np.ndarray:
    """The ``evade`` last resort's target (bigcbf.control.cbf): the body command whose nominal world velocity is
    ``speed`` across the obstacle's path (perpendicular to v_obs), on the side of that path where the robot already
    is (q = p - p_i; the left of v_obs when exactly on it). Solved for (vx, vy) with wz = 0 through eq:execution (1);
    least squares when A's xy block is singular."""
    vo = np.asarray(v_obs, float)
    perp = np.array([-vo[1], vo[0]]) / max(float(np.hypot(vo[0], vo[1])), 1e-12)   # left of the path
    if float(perp @ np.asarray(q, float)) < 0.0:
        perp = -perp
    vw = speed * perp
    c, s = math.cos(theta), math.sin(theta)
    body = np.array([c * vw[0] + s * vw[1], -s * vw[0] + c * vw[1]]) - np.asarray(d_xy, float)   # R^T v - d
    sol = np.linalg.lstsq(np.asarray(Axy, float)[:, :2], body, rcond=None)[0]
    return np.array([sol[0], sol[1], 0.0])
