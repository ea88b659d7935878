"""Residual bound of e_exec(u), eq:uncertainty_margin (21) (twin.residual): conformal quantiles, knots, held-out
coverage."""
import numpy as np
import pytest

from bigcbf.control.uncertainty import e_exec
from bigcbf.params.stack import ExecutionModel
from twin.residual import ResidualOptions, calibrate_bound, conformal_quantile, fit_bound, holdout_mask, speed_bins


def test_conformal_quantile_by_hand():
    x = np.arange(1.0, 20.0)                        # 1..19, n = 19
    assert conformal_quantile(x, 0.9) == 18.0       # ceil(20 * 0.9) = 18th smallest
    assert conformal_quantile(x, 0.95) == 19.0      # ceil(20 * 0.95) = 19th
    assert conformal_quantile(np.arange(1.0, 10.0), 0.95) == 9.0   # ceil(10 * .95) = 10 > n = 9: the largest


def test_one_bin_bound_is_the_conformal_quantile_by_hand():
    # one bin: scale = the 90 % quantile of 1..19 = ceil(17.1) = 18th = 18 at both knots; scores r / 18;
    # conformal 90 %: ceil(20 * 0.9) = 18th score = 1 -> bound 18 everywhere
    s = np.linspace(0.0, 0.5, 19)
    r = np.arange(1.0, 20.0)
    ks, bs = fit_bound(s, r, ResidualOptions(coverage=0.9, min_bin=1000))
    np.testing.assert_allclose(ks, [0.0, 0.5])
    np.testing.assert_allclose(bs, [18.0, 18.0])


def test_two_bins_knots_follow_the_scale_curve():
    # bins [0, 0.4) with residuals 0.001..0.200 and [0.4, 0.8] with 0.01..2.0 (200 each); 90 % quantiles
    # ceil(180) = 180th: 0.18 and 1.8; scale knots (0.18, (0.18 + 1.8) / 2, 1.8) = (0.18, 0.99, 1.8)
    s = np.concatenate([np.linspace(0.0, 0.39, 200), np.linspace(0.4, 0.8, 200)])
    r = np.concatenate([np.arange(1, 201) * 0.001, np.arange(1, 201) * 0.01])
    ks, bs = fit_bound(s, r, ResidualOptions(coverage=0.9, min_bin=200, max_bins=2))
    np.testing.assert_allclose(ks, [0.0, 0.395, 0.8])          # the median speed (0.39 + 0.4) / 2 splits the bins
    np.testing.assert_allclose(bs / bs[0], np.array([0.18, 0.99, 1.8]) / 0.18)      # k * scale
    inside = r <= np.interp(s, ks, bs)
    assert inside.mean() >= 0.9 and inside.mean() <= 0.9 + 2 / 400 + 1e-12          # ceil((n + 1) q) of n


def test_speed_bins_start_at_zero_and_merge_small_bins():
    s = np.concatenate([np.zeros(500), np.full(30, 0.5), np.linspace(0.6, 0.8, 500)])
    edges = speed_bins(s, ResidualOptions(min_bin=100, max_bins=6))
    assert edges[0] == 0.0 and edges[-1] == 0.8 and np.all(np.diff(edges) > 0)
    counts = np.bincount(np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(edges) - 2))
    assert counts.min() >= 100


def test_holdout_mask_every_fourth_block_and_the_final_block():
    # without the final block: 40 blocks of 1 s, blocks 3, 7, ..., 39 held out (10 of 40)
    t = np.arange(0, 40.0001, 0.01)
    held = holdout_mask(t, ResidualOptions(block_s=1.0, tail_fraction=0.0))
    assert held.mean() == pytest.approx(0.25, abs=0.001)
    assert not held[(t >= 0) & (t < 2.99)].any() and held[(t > 3.01) & (t < 3.99)].all()
    # with it (the default 15 %): the last 6 s held out whole; the 34 s before in 34 blocks, every fourth held out
    held = holdout_mask(t, ResidualOptions(block_s=1.0))
    assert held[t > 34.01].all() and not held[(t > 32.01) & (t < 33.99)].any()
    assert held.mean() == pytest.approx((6.0 + 8 * 1.0) / 40.0, abs=0.002)


def test_held_out_coverage_matches_the_stated_one_on_exchangeable_data():
    rng = np.random.default_rng(0)
    n = 40000
    t = np.arange(n) * 0.01
    s = rng.uniform(0, 0.8, n)
    r = np.abs(rng.normal(0, 0.01 + 0.05 * s))          # residual spread grows with speed
    b = calibrate_bound(t, s, r, ResidualOptions(coverage=0.95))
    assert b.speed_knots[0] == 0.0 and np.all(np.diff(b.speed_knots) > 0)
    assert b.coverage_heldout == pytest.approx(0.95, abs=0.01)
    assert b.coverage_tail == pytest.approx(0.95, abs=0.015)          # the final block alone
    assert b.coverage_calibration >= 0.95
    assert b.bound_knots[-1] > b.bound_knots[0]        # command-dependent


def test_e_exec_from_the_calibrated_knots_by_hand():
    # eq:uncertainty_margin (21) e_exec(u) = residual_horizon_s * interp(||u_xy||): ||(0.3, 0.4)|| = 0.5, halfway
    # between knots 0.4 and 0.6 -> bound 0.03 m/s; times 0.2 s = 0.006 m
    m = ExecutionModel(residual_speed_mps=(0.0, 0.4, 0.6), residual_bound_mps=(0.01, 0.02, 0.04),
                       residual_horizon_s=0.2)
    assert float(e_exec(np.array([0.3, 0.4, 1.0]), m)) == pytest.approx(0.006)
