"""Issue 26: the imagination's compiled rollout loop (imagination._rollout_loop) gives the same bits as the numpy
step loop it replaced (imagination._rollout_steps, still used with the speed governor or the push)."""
from __future__ import annotations

import numpy as np
import pytest

from bigcbf.control import imagination as im
from bigcbf.control.behaviors import BEHAVIORS, PolicyData
from bigcbf.control.prediction import predict_obstacles, q_sigma_for
from bigcbf.params import PHYSICAL, SIMULATION
from bigcbf.params.stack import PAPER_RULES, PlusRules

from test_control_imagination import IMPERFECT, scene


def _both(state, obs, goal, params, modes, rules, release=None, start=None):
    """(compiled rollout, numpy step loop) of the same inputs."""
    ro = im._rollout(state, obs, goal, params, modes, release, start, rules)
    N, dt = params.N, params.dt_s
    K = im._constants(modes, params)
    Ok = np.zeros((N + 1, 0), complex)
    if len(obs):
        P_obs, _ = predict_obstacles(obs, N, dt, q_sigma_for(obs, params.uncertainty))
        Ok = P_obs[..., 0] + 1j * P_obs[..., 1]
    policy = PolicyData.build(K.midx, goal, obs.p, obs.r, params, obs_v=obs.v, release=release, rows=K.rows,
                              rules=rules)
    p, th = ((np.full(K.B, complex(state.px, state.py)), np.full(K.B, float(state.theta))) if start is None
             else (np.array(start[0], complex), np.array(start[1], float)))
    arrs = [np.empty((N + 1, K.B), complex) for _ in range(3)] + [np.empty((N + 1, K.B))]
    im._rollout_steps(policy, None, Ok, Ok, p, th, N, dt, K, rules, *arrs)
    return ro, [a.T for a in arrs]


@pytest.mark.parametrize("params", [SIMULATION, IMPERFECT, PHYSICAL])
@pytest.mark.parametrize("rules", [PAPER_RULES, PlusRules(speed_governor=False)])
@pytest.mark.parametrize("seed", range(6))
def test_compiled_rollout_is_the_step_loop_bit_for_bit(params, rules, seed):
    state, obs, goal = scene(seed)
    if seed == 5:
        obs = obs.subset(np.zeros(len(obs), bool))          # no obstacles at all
    ro, (P, V, U, TH) = _both(state, obs, goal, params, BEHAVIORS, rules)
    for got, want in ((ro.P, P), (ro.V, V), (ro.U, U), (ro.TH, TH)):
        assert np.array_equal(got, want)
    # the fallback's rows: chosen release velocities, from several start states
    cand = np.array([0.3 + 0.1j, -0.2j, 0j])
    start = (np.array([0.1 + 0.2j, -0.3 + 0j, 0.5 - 0.5j]), np.array([0.3, -2.0, 1.0]))
    ro, (P, V, U, TH) = _both(state, obs, goal, params, ("REVERSE",) * 3, rules, cand, start)
    for got, want in ((ro.P, P), (ro.V, V), (ro.U, U), (ro.TH, TH)):
        assert np.array_equal(got, want)


def _barrier_terms_numpy(ro, speed, obstacles, params, shared):
    """The numpy _barrier_terms the compiled one replaced (as of d27bf46), the reference bit for bit."""
    from bigcbf.control import kernels
    from bigcbf.control.uncertainty import kappa_img
    unc, ex = params.uncertainty, params.uncertainty.execution
    N, K, M = params.N, ro.K, len(obstacles)
    B = K.B
    Pc, Vc, TH, Oc, cov = ro.P, ro.V, ro.TH, ro.Oc, ro.cov
    Ov = obstacles.v[:, 0] + 1j * obstacles.v[:, 1]
    q = Pc[:, :, None] - Oc[None]
    q2 = q.real ** 2 + q.imag ** 2
    relv = Vc[:, :, None] - Ov
    if shared:
        kap = kappa_img(obstacles, unc)
        m = kernels.uncertainty_radius(np.abs(relv), kernels.prediction_term(cov, unc)[None],
                                       kernels.e_exec_speed(speed, ex)[:, :, None], unc)
        margin = kap * m
    else:
        margin = np.full((B, N + 1, M), params.noshared_margin_m)
    D = kernels.inflated_radius(obstacles.r, margin, unc)
    h = kernels.barrier(q2, D)
    h_min = h.reshape(B, -1).min(axis=1)
    deficit = np.maximum(-h[:, 1:].min(axis=2), 0.0).sum(axis=1)
    qn, hn, rn = q[:, :N], h[:, :N], relv[:, :N]
    gamma = 2.0 * (qn.real * rn.real + qn.imag * rn.imag) + params.alpha_per_s * hn
    if K.unit_gradient:
        grad2 = 4.0 * q2[:, :N]
    else:
        A = K.A
        qb = qn * np.exp(-1j * TH[:, :N])[:, :, None]
        G = A[:2] @ A[:2].T
        grad2 = 4.0 * (G[0, 0] * qb.real ** 2 + 2 * G[0, 1] * qb.real * qb.imag + G[1, 1] * qb.imag ** 2)
    viol = np.maximum(-gamma, 0.0)
    W = (viol * viol / (grad2 + params.w_eps)).reshape(B, -1).sum(axis=1)
    return h_min, W, deficit, margin


@pytest.mark.parametrize("params", [SIMULATION, IMPERFECT, PHYSICAL])
@pytest.mark.parametrize("shared", [True, False])
@pytest.mark.parametrize("seed", range(8))
def test_compiled_barrier_terms_are_numpy_bit_for_bit(params, shared, seed):
    state, obs, goal = scene(seed, n_dyn=seed % 4, n_static=2, n_wall=seed % 5)
    ro = im._rollout(state, obs, goal, params, BEHAVIORS)
    speed = np.abs(ro.U)
    got = im._barrier_terms(ro, speed, obs, params, shared)
    want = _barrier_terms_numpy(ro, speed, obs, params, shared)
    for g, w in zip(got, want):
        assert g.shape == w.shape and np.array_equal(g, w)


@pytest.mark.parametrize("rules", [PAPER_RULES, PlusRules()])
def test_cached_groups_and_predictions_are_those_of_the_scene(rules):
    """imagination._groups and _predicted keep the last scene's obstacle groups and predictions: alternating
    scenes (the same positions with other radii, velocities or covariances too) must each get their own."""
    scenes = [scene(s) for s in range(4)]
    st, o, g = scenes[0]
    Obs = o.__class__
    scenes.append((st, Obs(o.p, o.v, o.cov, o.r * 3.0, o.static, o.ids), g))
    scenes.append((st, Obs(o.p, o.v * 1.5, o.cov, o.r, o.static, o.ids), g))
    scenes.append((st, Obs(o.p, o.v, o.cov * 2.0, o.r, o.static, o.ids), g))
    fresh = []
    for state, obs, goal in scenes:
        im._GROUPS[:] = [None, None]
        im._PREDICTED[:] = [None, None]
        fresh.append(im.imagine(state, obs, goal, SIMULATION, rules=rules))
    for k in [0, 1, 0, 2, 3, 4, 0, 4, 5, 0, 6, 5, 6]:
        state, obs, goal = scenes[k]
        img = im.imagine(state, obs, goal, SIMULATION, rules=rules)
        for f in ("p", "J", "h_min", "W", "margin"):
            assert np.array_equal(getattr(img, f), getattr(fresh[k], f)), (k, f)
