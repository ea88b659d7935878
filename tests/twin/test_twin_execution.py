"""Execution model eq:execution (1) (twin.execution): least squares, identified axes, saturation, settled samples."""
import numpy as np
import pytest

from twin.execution import (ExecutionOptions, fit_execution, identified_axes, least_squares, runs_at_least,
                            saturated_samples, settled_samples)

A_TRUE = np.array([[0.9, 0.05, 0.0], [-0.03, 0.85, 0.01], [0.1, 0.0, 0.95]])
D_TRUE = np.array([0.02, -0.01, 0.03])


def test_least_squares_is_exact_on_noiseless_data():
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, (200, 3))
    v = u @ A_TRUE.T + D_TRUE                    # eq:execution (1) without residual
    A, d = least_squares(u, v, np.array([True, True, True]))
    np.testing.assert_allclose(A, A_TRUE, atol=1e-12)
    np.testing.assert_allclose(d, D_TRUE, atol=1e-12)


def test_least_squares_by_hand_one_axis():
    # v = 2 u + 1 through (0, 1), (1, 3), (2, 5): slope 2, intercept 1; vy, wz not identified
    u = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    v = np.array([[1.0, 0, 0], [3.0, 0, 0], [5.0, 0, 0]])
    A, d = least_squares(u, v, np.array([True, False, False]))
    np.testing.assert_allclose(A, [[2, 0, 0], [0, 1, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(d, [1, 0, 0], atol=1e-12)


def test_differential_drive_vy_is_not_identified_and_not_guessed():
    rng = np.random.default_rng(1)
    u = rng.uniform(-0.5, 0.5, (500, 3))
    u[:, 1] = 0.0                                     # a differential drive never commands vy
    v = u @ A_TRUE.T + D_TRUE + rng.normal(0, 0.01, (500, 3))
    axes = identified_axes(u)
    np.testing.assert_array_equal(axes, [True, False, True])
    fit = fit_execution(np.arange(500) * 0.02, u, v)
    np.testing.assert_array_equal(fit.A[1], [0, 1, 0])            # identity row
    assert fit.d[1] == 0.0
    assert fit.A[0, 1] == 0.0 and fit.A[2, 1] == 0.0               # no coefficient on the unexcited input
    np.testing.assert_allclose(fit.A[[0, 2]][:, [0, 2]], A_TRUE[[0, 2]][:, [0, 2]], atol=0.02)


def test_excitation_thresholds():
    u = np.zeros((100, 3))
    u[::2, 0] = 0.3                                    # std 0.15, 50 samples >= 0.05: identified
    u[:20, 2] = 0.5                                    # only 20 samples beyond 0.1 rad/s: not identified
    np.testing.assert_array_equal(identified_axes(u, ExecutionOptions(min_samples=50)), [True, False, False])


def test_runs_at_least_by_hand():
    t = np.arange(10) * 0.1
    flag = np.array([0, 1, 1, 1, 1, 0, 1, 1, 0, 1], bool)
    # run 1..4 spans 0.3 s (kept with min 0.3), run 6..7 spans 0.1 s, run 9 spans 0
    np.testing.assert_array_equal(runs_at_least(flag, t, 0.3), [0, 1, 1, 1, 1, 0, 0, 0, 0, 0])


def test_saturated_samples_are_found_and_left_out():
    rng = np.random.default_rng(3)
    n = 3000
    t = np.arange(n) * 0.02
    u = np.repeat(rng.uniform(-0.6, 0.6, (n // 50, 3)), 50, axis=0)    # 1-s holds
    big = np.repeat(rng.random(n // 50) < 0.15, 50)                     # some holds demand too much ...
    u[big, 0] = 1.6
    v = u @ A_TRUE.T + D_TRUE + rng.normal(0, 0.01, (n, 3))
    v[big] *= 0.6                                                       # ... and the drive delivers 60 %
    fit = fit_execution(t, u, v)
    assert fit.saturated[big].mean() > 0.9 and fit.saturated[~big].mean() < 0.01
    np.testing.assert_allclose(fit.A, A_TRUE, atol=0.01)
    np.testing.assert_allclose(fit.d, D_TRUE, atol=0.005)
    # a brief dip (one sample) is not saturation
    v2 = u @ A_TRUE.T + D_TRUE
    v2[100] *= 0.2
    sat = saturated_samples(t, u, v2, A_TRUE, D_TRUE, np.array([True] * 3))
    assert not sat.any()


def test_settled_samples_by_hand():
    t_cmd = np.arange(0, 2, 0.05)
    u = np.zeros((len(t_cmd), 3))
    u[t_cmd >= 1.0, 0] = 0.5
    u[t_cmd >= 1.6, 2] = 0.01                          # below hold_tol on wz (0.04 rad/s): still held
    ta = np.array([0.2, 0.99, 1.0, 1.29, 1.3, 1.7])
    # settle 0.3 s: held over [t - 0.3, t]; before 0.3 s the window starts before the first command
    np.testing.assert_array_equal(settled_samples(t_cmd, u, ta, ExecutionOptions(settle_s=0.3)),
                                  [False, True, False, False, True, True])


def test_fit_uses_settled_samples_when_there_are_enough():
    rng = np.random.default_rng(4)
    n = 2000
    t = np.arange(n) * 0.02
    u = rng.uniform(-0.5, 0.5, (n, 3))
    v = u @ A_TRUE.T + D_TRUE
    settled = np.zeros(n, bool)
    settled[::4] = True
    v[~settled] = 0.0                                  # garbage everywhere but the settled samples
    fit = fit_execution(t, u, v, settled=settled)
    assert fit.settled_only and fit.n_used == settled.sum()
    np.testing.assert_allclose(fit.A, A_TRUE, atol=1e-9)
    few = np.zeros(n, bool)
    few[:10] = True
    fit = fit_execution(t, u, u @ A_TRUE.T + D_TRUE, settled=few)
    assert not fit.settled_only
    np.testing.assert_allclose(fit.predict(u[:3]), u[:3] @ A_TRUE.T + D_TRUE, atol=1e-9)


def _held_drive(rng, n_blocks=40, per_block=100, phi=0.8, sigma=0.02, limit=None, dt=0.02):
    """A drive of held commands (one per 2-s block) with AR(1) residuals: v = sat(G u + d) + r, where ``limit``
    (rim-speed limit, lever) saturates the wheels (``twin.limits.saturate``) or is None."""
    from twin.limits import saturate
    t = np.arange(n_blocks * per_block) * dt
    u = np.repeat(rng.uniform(-0.6, 0.6, (n_blocks, 3)) * [1.0, 1.0, 1.5], per_block, axis=0)
    r = np.zeros_like(u)
    e = rng.normal(0, sigma, u.shape)
    for k in range(1, len(u)):
        r[k] = phi * r[k - 1] + e[k]
    G = np.diag([0.9, 1.1, 0.8])
    d = np.array([0.01, -0.02, 0.03])
    p = u @ G.T + d
    return t, u, (p if limit is None else saturate(p, *limit)) + r, G


@pytest.mark.parametrize("limit", [None, (0.55, 0.17)], ids=["linear", "wheel_limit"])
def test_gain_intervals_cover_the_truth_at_their_level_on_correlated_residuals(limit):
    """twin.limits.gain_intervals, the one-step block bootstrap of the static fit: over 30 independent drives with
    AR(1) residuals (phi 0.8), fitted by ``fit_static`` itself (linear, or with a wheel limit that 30-60 % of the
    samples reach: the saturating least squares), the 90 % intervals of the three gains hold the truth within the
    binomial band of 90 cases at 90 % (95 % band 75-86), and hold the reported gain."""
    from scipy.stats import binom

    from twin.limits import fit_static, gain_intervals
    rng = np.random.default_rng(7)
    axes = np.ones(3, bool)
    hits = []
    for _ in range(30):
        t, u, v, G = _held_drive(rng, per_block=25, dt=0.08, phi=0.4, limit=limit)
        st = fit_static(u, v, axes)
        assert (st.v_max is None) == (limit is None)
        ci = gain_intervals(t, u, v, axes, st, resamples=200)
        assert np.all(ci[:, 0] < np.diag(st.A)) and np.all(np.diag(st.A) < ci[:, 1])
        hits += [ci[j, 0] <= G[j, j] <= ci[j, 1] for j in range(3)]
    lo, hi = binom.interval(0.95, len(hits), 0.90)
    assert lo <= sum(hits) <= hi, sum(hits)


def test_gain_intervals_of_the_linear_fit_are_its_block_bootstrap():
    """Without a limit the model is linear and one Gauss-Newton step is the refit itself: the interval equals, to
    rounding, the percentile interval of least squares refitted on the same resampled blocks (the same counts
    drawn), computed here apart by weighted least squares."""
    from twin.execution import least_squares
    from twin.limits import fit_static, gain_intervals
    from twin.signals import expanded_levels
    rng = np.random.default_rng(5)
    t, u, v, _ = _held_drive(rng, n_blocks=12)
    axes = np.ones(3, bool)
    st = fit_static(u, v, axes)
    assert st.v_max is None
    np.testing.assert_allclose(st.A, least_squares(u, v, axes)[0], atol=1e-12)
    ci = gain_intervals(t, u, v, axes, st, resamples=50, seed=4)
    block = np.floor(t / 2.0).astype(int)
    counts = np.random.default_rng(4).multinomial(12, np.full(12, 1 / 12), size=50)
    X = np.column_stack([u, np.ones(len(u))])
    diag = []
    for c in counts:
        w = np.sqrt(c[block].astype(float))
        beta = np.linalg.lstsq(X * w[:, None], v * w[:, None], rcond=None)[0]
        diag.append(np.diag(beta[:3].T))
    np.testing.assert_allclose(ci, np.quantile(diag, expanded_levels(0.90, 12), axis=0).T, atol=1e-9)


def test_gain_intervals_by_block_not_by_sample():
    """Resampling whole 2-s blocks: with strongly correlated residuals (phi 0.98) the interval is wider than a
    bootstrap of single samples would give (independent samples: 1.645 sigma / sqrt(n) per side), and an axis that
    is not identified, or a log shorter than six blocks, gets no interval (nan)."""
    from twin.limits import fit_static, gain_intervals
    rng = np.random.default_rng(3)
    t, u, v, _ = _held_drive(rng, phi=0.98, sigma=0.01)
    axes = np.array([True, False, True])
    st = fit_static(u, v, axes)
    ci = gain_intervals(t, u, v, axes, st)
    assert np.isnan(ci[1]).all() and np.isfinite(ci[[0, 2]]).all()
    X = np.column_stack([u[:, [0, 2]], np.ones(len(u))])
    res = v[:, [0, 2]] - X @ np.linalg.lstsq(X, v[:, [0, 2]], rcond=None)[0]
    iid_half = 1.645 * res.std(axis=0) * np.sqrt(np.diag(np.linalg.inv(X.T @ X))[:2])
    assert np.all((ci[[0, 2], 1] - ci[[0, 2], 0]) / 2 > 2 * iid_half)
    short = t < 10.0
    assert np.isnan(gain_intervals(t[short], u[short], v[short], axes, st)).all()


def test_input_condition_leaves_out_unknown_commands():
    """Odometry before the first command has no command once delayed (NaN): input_condition leaves those rows out
    (a settled sample at the log's start made numpy's SVD fail: a traceback from ``bigcbf calibrate``)."""
    from twin.execution import input_condition
    rng = np.random.default_rng(0)
    u = rng.uniform(-1, 1, (200, 3))
    axes = np.ones(3, bool)
    clean = input_condition(u, axes)
    with_nan = np.vstack([np.full((5, 3), np.nan), u])
    assert input_condition(with_nan, axes) == pytest.approx(clean)
    assert input_condition(np.full((5, 3), np.nan), axes) == float("inf")
