"""One implementation of each of the paper's equations that several layers evaluate (issue 17).

The behaviors, the imagination, the CBF rows, the speed governor and every baseline call these functions instead
of writing the formula again; each names its equation as ``eq:label (N)``, the LaTeX label in the paper's source
and the number the paper prints (every numbered display counted; see ``bigcbf/control/__init__.py``): eq:execution
(1), eq:obs_prop (2), eq:cov_prop (3), eq:goal_region (5), eq:shared_barrier (20), eq:uncertainty_margin (21),
eq:cbf_condition (25). The paper: S. Li, Z. Wang, J. Cao, J. Yang, K. Wu, "BIG-CBF: Behavior-Imagination-Guided
Control Barrier Function with Shared Uncertainty for Mobile Robot Navigation".

Bit-for-bit: the physics runs are deterministic and their golden values are checked, so each kernel keeps the
arithmetic order its callers had (the order is part of the contract, written next to each formula); the
uncertainty radius, for instance, is ``tau95 ||v_rel|| + sigma_term + (e_exec + e_ZOH)`` in every layer.

Two forms of eq:execution exist on purpose: a real one (2-vectors, R(theta) as a matrix; the baselines and the
reference functions of ``uncertainty``) and a complex one (planar vectors as x + i y, R(theta) as multiplication
by e^{i theta}; the imagination's rollout and the governor, which advance every behavior at once). They agree to
rounding, not bit for bit (tests/control/test_control_kernels.py), so each caller keeps the form it always used.

Copies left on purpose, each checked against these kernels in tests/control/test_control_kernels.py:

- ``cbf._rows_kernel`` and ``baselines.mppi._rollout_costs`` (numba) inline eq:execution, eq:uncertainty_margin,
  eq:shared_barrier and the Euler rollout in per-obstacle / per-sample scalar loops (compiled code cannot call these
  numpy functions; the CBF rows sum D_i as (r_R + d0) + r_i + kappa m, equal to :func:`inflated_radius` to rounding).
- ``governor.govern_c`` keeps that (r_R + d0) + r_i order too (it models the filter) and writes the realized velocity
  as s R A u + R d over its speed grid (the linear part scaled), which is not :func:`execution_velocity_c`'s
  R (A u + d) bit for bit.
- The simulator's hardware layer (``bigcbf.sim.firmware``) is the plant, not the model: eq:execution with the residual,
  3-axis, with latency and limits.

Pure numpy; no state. Broadcasting over leading axes everywhere.
"""
from __future__ import annotations

import numpy as np

from ..params.stack import ExecutionModel, UncertaintyParams

# ---------------------------------------------------------------------------------------------------- eq:execution


def execution_velocity(theta, u, model: ExecutionModel) -> np.ndarray:
    """``eq:execution`` (1) without the residual r: v = R(theta) (A_xy u + d_xy) [m/s] in odom, shape (..., 2).

    ``u`` (..., 3) is the body twist (vx, vy, wz); A_xy are the translational rows of A (2x3). Order: body = u A_xy^T
    + d_xy (a matrix product), then [c b0 - s b1, s b0 + c b1].
    """
    A = np.asarray(model.A, float)
    body = np.asarray(u, float) @ A[:2].T + np.asarray(model.d[:2], float)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * body[..., 0] - s * body[..., 1], s * body[..., 0] + c * body[..., 1]], -1)


def body_from_world(theta, v_world) -> np.ndarray:
    """The body twist u = [R(theta)^T v, 0] (..., 3) that asks for the world-frame velocity v (..., 2) (yaw rate 0):
    ``eq:execution`` inverted for A = I, d = 0 (the behaviors and the baselines command world velocities)."""
    v = np.asarray(v_world, float)
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1], np.zeros(v.shape[:-1])], -1)


def execution_yaw_rate(u, model: ExecutionModel) -> np.ndarray:
    """``eq:execution`` (1), rotational row: the realized yaw rate (A u + d)_wz = u A[2]^T + d_wz [rad/s], (...,)."""
    A, d = np.asarray(model.A, float), np.asarray(model.d, float)
    return np.asarray(u, float) @ A[2] + d[2]


def execution_complex(model: ExecutionModel) -> tuple[complex, complex, complex]:
    """``eq:execution`` (1) on complex planar vectors: the body-frame realized translation of a command u_x + i u_y
    (u_w = 0) is a u + b conj(u) + d, with (a, b) the real 2x2 map A[:2, :2] written as z -> a z + b conj(z) and
    d = d_x + i d_y. Returns (a, b, d)."""
    A = np.asarray(model.A, float)
    a = complex(A[0, 0] + A[1, 1], A[1, 0] - A[0, 1]) / 2
    b = complex(A[0, 0] - A[1, 1], A[1, 0] + A[0, 1]) / 2
    return a, b, complex(model.d[0], model.d[1])


def execution_velocity_c(rot, u, a: complex, b: complex, d: complex) -> np.ndarray:
    """``eq:execution`` (1) without the residual on complex numbers: v = e^{i theta} (a u + b conj(u) + d) [m/s],
    with ``rot`` = e^{i theta} and (a, b, d) from :func:`execution_complex`; u = u_x + i u_y (u_w = 0)."""
    return rot * (a * u + b * np.conj(u) + d)


def execution_yaw_rate_c(u, a20: float, a21: float, d_w: float):
    """``eq:execution`` (1), rotational row, for complex commands u = u_x + i u_y (u_w = 0): a20 u_x + a21 u_y + d_w
    [rad/s] with a20 = A[2, 0], a21 = A[2, 1], d_w = d[2]."""
    return a20 * u.real + a21 * u.imag + d_w


def euler_step(p, v, dt):
    """One forward-Euler step of the robot's position under eq:execution (1): p + dt v (real (..., 2) or complex)."""
    return p + dt * v


def euler_paths(p0, theta0: float, u, dt: float, model: ExecutionModel) -> tuple[np.ndarray, np.ndarray]:
    """``eq:execution`` (1) without the residual, integrated with forward Euler: body twists u (B, K, 3) held for dt
    each from position p0 (2,) and yaw theta0. theta_{k+1} = theta_k + dt (A u + d)_wz, p_{k+1} = p_k +
    dt R(theta_k)(A u + d)_xy, both summed as p0 + dt cumsum(...) (the baselines' order). Returns positions
    (B, K+1, 2) [m] and yaws (B, K+1) [rad]."""
    u = np.asarray(u, float)
    B, K = u.shape[:2]
    wz = execution_yaw_rate(u, model)                                             # (B, K)
    theta = np.concatenate([np.full((B, 1), theta0), theta0 + dt * np.cumsum(wz, axis=1)], axis=1)
    v = execution_velocity(theta[:, :-1], u, model)                               # (B, K, 2)
    p = np.concatenate([np.broadcast_to(p0, (B, 1, 2)), p0 + dt * np.cumsum(v, axis=1)], axis=1)
    return p, theta

# ------------------------------------------------------------------------------------ eq:obs_prop, eq:cov_prop


def advance_obstacles(p, v, cov, q_sigma, t: float, grow_s: float | None = None):
    """One step of ``eq:obs_prop`` (2) and ``eq:cov_prop`` (3) of length t [s] for M obstacles: p + t v and
    Sigma + q_Sigma,i g I_2 with g = t, or g = ``grow_s`` when given (a g <= 0 leaves Sigma as it is: not even
    + 0 is added). p, v (M, 2), cov (M, 2, 2), q_sigma (M,). Returns (p, cov)."""
    g = t if grow_s is None else grow_s
    if g <= 0:
        return p + t * v, cov
    return p + t * v, cov + (g * q_sigma)[:, None, None] * np.eye(2)

# --------------------------------------------------------------------------------------------- eq:goal_region


def goal_distance(p, goal) -> np.ndarray:
    """||p - p_g|| [m] for positions p (..., 2) (``eq:goal_region`` (5))."""
    p, goal = np.asarray(p, float), np.asarray(goal, float)
    return np.hypot(p[..., 0] - goal[..., 0], p[..., 1] - goal[..., 1])


def in_goal_region(dist, eps_g: float):
    """``eq:goal_region`` (5): x in G iff ||p - p_g|| <= eps_g, given dist = ||p - p_g|| (a NaN is outside)."""
    return dist <= eps_g


def outside_goal_region(dist, eps_g: float):
    """Not ``eq:goal_region`` (5): ||p - p_g|| > eps_g (a NaN is neither in nor out: False here too)."""
    return dist > eps_g

# -------------------------------------------------------------------------------------- eq:uncertainty_margin


def residual_bound(speed_xy, model: ExecutionModel) -> np.ndarray:
    """The calibrated bound on ||r|| of ``eq:execution`` [m/s] at command speed ||u_xy||: linear interpolation of
    the knots, clamped beyond the last knot."""
    return np.interp(speed_xy, model.residual_speed_mps, model.residual_bound_mps)


def e_exec_speed(speed_xy, model: ExecutionModel) -> np.ndarray:
    """The robot-execution term of ``eq:uncertainty_margin`` (21) at command speed ||u_xy||:
    e_exec = residual_horizon_s * bound(||u_xy||) [m]."""
    return model.residual_horizon_s * residual_bound(speed_xy, model)


def lambda_max_2x2(cov) -> np.ndarray:
    """Largest eigenvalue of symmetric 2x2 matrices (..., 2, 2), closed form (clamped at 0)."""
    cov = np.asarray(cov, float)
    a, b, c = cov[..., 0, 0], 0.5 * (cov[..., 0, 1] + cov[..., 1, 0]), cov[..., 1, 1]
    return np.maximum(0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b), 0.0)


def prediction_term(cov, unc: UncertaintyParams) -> np.ndarray:
    """The obstacle-prediction term of ``eq:uncertainty_margin`` (21): beta sqrt(lambda_max(Sigma_i)) [m]."""
    return unc.beta * np.sqrt(lambda_max_2x2(cov))


def uncertainty_radius(rel_speed, pred_term, e_exec, unc: UncertaintyParams) -> np.ndarray:
    """``eq:uncertainty_margin`` (21), the common relative-position uncertainty radius from its terms [m]:

        m_i = tau95 ||R(theta)(A u_ref + d) - v_i||  +  beta sqrt(lambda_max(Sigma_i))  +  (e_exec(u_ref) + e_ZOH)

    ``rel_speed`` = ||R(theta)(A u_ref + d) - v_i|| (:func:`execution_velocity` or :func:`execution_velocity_c`),
    ``pred_term`` from :func:`prediction_term`, ``e_exec`` from :func:`e_exec_speed`; broadcast together.
    Order: (tau95 rel_speed + pred_term) + (e_exec + e_ZOH), as in the compiled CBF rows."""
    return unc.tau95_s * rel_speed + pred_term + (e_exec + unc.e_zoh_m)

# ----------------------------------------------------------------------------------------- eq:shared_barrier


def inflated_radius(r_obs, margin, unc: UncertaintyParams) -> np.ndarray:
    """``eq:shared_barrier`` (20): D_i = r_R + r_i + d0 + margin [m], margin = kappa_l m_i (or a fixed margin for
    BIG-CBF-NoShared). Order: ((r_R + r_i) + d0) + margin."""
    return unc.r_robot_m + np.asarray(r_obs, float) + unc.d0_m + margin


def barrier(q2, D) -> np.ndarray:
    """``eq:shared_barrier`` (20): h_i = ||q_i||^2 - D_i^2 [m^2], given q2 = ||q_i||^2 (q_i = p - p_i,
    eq:relative_position_error)."""
    return q2 - D * D


def squared_norm(q) -> np.ndarray:
    """||q||^2 = q_x^2 + q_y^2 of real 2-vectors (..., 2)."""
    q = np.asarray(q, float)
    return q[..., 0] ** 2 + q[..., 1] ** 2
