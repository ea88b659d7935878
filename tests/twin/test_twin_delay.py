"""Delay estimation (twin.delay) on synthetic signals with known delays, and tau95 of eq:uncertainty_margin (21) by
hand."""
import numpy as np
import pytest
from scipy.signal import lfilter

from twin.delay import (DelayOptions, edge_delays, estimate_delay, grid_signals, perception_latency, scan_clock,
                        tau95, xcorr_delay)
from twin.signals import interp_columns, intervals, quantile_upper, zoh


def test_zoh_holds_and_marks_times_before_the_first_sample():
    t = np.array([0.0, 1.0, 2.0])
    x = np.array([[1.0], [2.0], [3.0]])
    out = zoh(t, x, np.array([-0.5, 0.0, 0.99, 1.0, 5.0]))
    assert np.isnan(out[0, 0])
    np.testing.assert_array_equal(out[1:, 0], [1.0, 1.0, 2.0, 3.0])


def test_interp_marks_gaps_and_the_outside():
    t = np.array([0.0, 0.1, 0.2, 1.2, 1.3])
    x = np.arange(5.0)
    v, ok = interp_columns(t, x, np.array([0.05, 0.15, 0.7, 1.25, 2.0]), max_gap_s=0.25)
    np.testing.assert_allclose(v[:2, 0], [0.5, 1.5])
    np.testing.assert_array_equal(ok, [True, True, False, True, False])


def test_quantile_upper_and_intervals_by_hand():
    x = [0.3, 0.1, 0.2, 0.4]
    assert quantile_upper(x, 0.95) == 0.4        # ceil(3.8) = 4th smallest
    assert quantile_upper(x, 0.5) == 0.2         # ceil(2.0) = 2nd smallest
    assert quantile_upper(x, 0.51) == 0.3        # ceil(2.04) = 3rd
    np.testing.assert_allclose(intervals([0.0, 0.05, 0.05, 0.1, 0.25]), [0.05, 0.05, 0.15])


def test_tau95_pairs_every_actuation_delay_with_every_latency():
    # eq:uncertainty_margin (21) tau95 by hand: sums {0.1, 0.2, 0.2, 0.3}; 95 %: ceil(0.95 * 4) = 4th smallest = 0.3
    assert tau95([0.1, 0.2], [0.0, 0.1]) == pytest.approx(0.3)
    assert tau95([0.1, 0.2], [0.0, 0.1], q=0.5) == pytest.approx(0.2)       # ceil(2) = 2nd = 0.2
    assert tau95([0.1, 0.2, 0.3], []) == pytest.approx(0.3)                  # no scans: the actuation delays alone
    # 19 delays 0.1 and one 1.0, latency 0: the 95 % quantile is the 19th = 0.1, the 96 % one the 20th = 1.0
    a = [0.1] * 19 + [1.0]
    assert tau95(a, [0.0]) == pytest.approx(0.1) and tau95(a, [0.0], q=0.96) == pytest.approx(1.0)


def _random_steps(rng, seconds, dt=0.05, hold=(0.6, 1.2)):
    t, u = [], []
    now = 0.0
    while now < seconds:
        level = rng.uniform(-0.8, 0.8, 3)
        h = rng.uniform(*hold)
        for k in range(int(round(h / dt))):
            t.append(now + k * dt)
            u.append(level)
        now += round(h / dt) * dt
    t, u = np.round(np.array(t), 9), np.array(u)
    return t[t < seconds], u[t < seconds]


def _response(t_cmd, u_cmd, t_meas, dead_s, jitter_s=0.0, lag_s=0.0, rng=None, noise=0.0):
    """Measured velocity: each command takes effect dead_s (+ U(0, jitter_s)) after it was sent, then a first-order
    lag lag_s (exact discretisation on a 1 ms grid)."""
    apply = t_cmd + dead_s + (rng.uniform(0, jitter_s, len(t_cmd)) if jitter_s else 0.0)
    fine = np.arange(0.0, t_meas[-1] + 1e-9, 0.001)
    target = zoh(apply, u_cmd, fine, before=0.0)
    if lag_s > 0:                                   # y[k] = a y[k-1] + (1 - a) x[k]
        a = np.exp(-0.001 / lag_s)
        target = lfilter([1 - a], [1, -a], target, axis=0)
    out = np.column_stack([np.interp(t_meas, fine, target[:, j]) for j in range(3)])
    if noise:
        out = out + rng.normal(0, noise, out.shape)
    return out


def test_xcorr_finds_a_pure_delay():
    rng = np.random.default_rng(1)
    t_cmd, u = _random_steps(rng, 60)
    t_odom = np.arange(0, 60, 0.02)
    v = _response(t_cmd, u, t_odom, dead_s=0.12, rng=rng, noise=0.01)
    tg, ug, vg, ok = grid_signals(t_cmd, u, t_odom, v, 0.005, 0.25)
    d, lags, curve = xcorr_delay(ug, vg, ok, [0, 1, 2], 0.005, 1.0)
    assert d == pytest.approx(0.12, abs=0.006)
    assert lags[np.argmax(curve)] == pytest.approx(0.12, abs=0.0051)


def test_edge_delay_of_dead_time_plus_first_order_lag():
    # half-way crossing of a dead time L followed by a first-order lag T: L + T ln 2 = 0.1 + 0.03 * 0.693 = 0.1208 s
    t_cmd = np.arange(0, 4, 0.05)
    u = np.zeros((len(t_cmd), 3))
    u[t_cmd >= 1.0, 0] = 0.5
    u[t_cmd >= 2.5, 0] = -0.3
    t_odom = np.arange(0, 4, 0.005)
    v = _response(t_cmd, u, t_odom, dead_s=0.1, lag_s=0.03)
    d, te, ax = edge_delays(t_cmd, u, t_odom, v, [0], DelayOptions())
    np.testing.assert_allclose(te, [1.0, 2.5])
    np.testing.assert_allclose(d, 0.1 + 0.03 * np.log(2), atol=0.002)
    np.testing.assert_array_equal(ax, [0, 0])


def test_edges_need_a_held_command_and_a_real_response():
    t_cmd = np.arange(0, 4, 0.05)
    u = np.zeros((len(t_cmd), 3))
    u[(t_cmd >= 1.0) & (t_cmd < 1.2), 0] = 0.5          # held only 0.2 s: not a clean edge
    u[t_cmd >= 2.5, 0] = 0.02                            # below edge_min
    t_odom = np.arange(0, 4, 0.01)
    v = _response(t_cmd, u, t_odom, dead_s=0.1)
    d, _, _ = edge_delays(t_cmd, u, t_odom, v, [0], DelayOptions())
    assert len(d) == 0
    u2 = np.zeros((len(t_cmd), 3))
    u2[t_cmd >= 1.0, 0] = 0.5
    d, _, _ = edge_delays(t_cmd, u2, t_odom, np.zeros((len(t_odom), 3)), [0], DelayOptions())   # robot never moved
    assert len(d) == 0


def test_perception_latency_same_clock_and_other_clock():
    t_scan = np.array([0.0, 0.1, 0.2])
    t_cmd = np.array([-0.05, 0.05, 0.15, 0.25])
    # stamps = acquisition 10 ms before the log time: ages 0.05 + 0.01 = 0.06 for the three commands after a scan
    lat, src = perception_latency(t_cmd, t_scan, t_scan - 0.01)
    assert src == "header stamps"
    np.testing.assert_allclose(lat, [0.06, 0.06, 0.06])
    # stamps on another clock (e.g. robot epoch time in a bag replayed later): log times are used
    lat, src = perception_latency(t_cmd, t_scan, t_scan + 1.7e9)
    assert src == "log times"
    np.testing.assert_allclose(lat, [0.05, 0.05, 0.05])
    assert scan_clock(t_scan, t_scan + 0.003) == "header stamps"       # a few ms ahead: same clock (clamped)
    lat, _ = perception_latency([0.15], t_scan, t_scan + 0.003)
    np.testing.assert_allclose(lat, [0.05])
    # stamps 0.5 s behind the log: no driver takes that long, another clock -> log times (it was counted before)
    lat, src = perception_latency(t_cmd, t_scan, t_scan - 0.5)
    assert src == "log times"
    np.testing.assert_allclose(lat, [0.05, 0.05, 0.05])
    # the user decides: forced stamps or forced log times
    lat, src = perception_latency(t_cmd, t_scan, t_scan - 0.5, clock="stamps")
    assert src == "header stamps"
    np.testing.assert_allclose(lat, [0.55, 0.55, 0.55])
    assert perception_latency(t_cmd, t_scan, t_scan - 0.01, clock="log")[1] == "log times"


def test_edges_found_with_10_hz_odometry():
    """The settled levels are averaged over at least 2.5 odometry periods: at 10 Hz (0.1 s apart) a 0.1 s window
    held one sample and every edge was dropped, which silently turned tau95 into the dead time alone."""
    rng = np.random.default_rng(3)
    t_cmd, u = _random_steps(rng, 60)
    t_odom = np.round(np.arange(0, 60, 0.1), 9)
    v = _response(t_cmd, u, t_odom, dead_s=0.1, lag_s=0.1)
    d, _, _ = edge_delays(t_cmd, u, t_odom, v, [0, 1, 2], DelayOptions())
    assert len(d) > 50
    # dead time 0.1 s + a first-order lag of 0.1 s: half-way after 0.1 + 0.1 ln 2 = 0.169 s (odometry every 0.1 s)
    assert np.median(d) == pytest.approx(0.1 + 0.1 * np.log(2), abs=0.03)


def test_estimate_delay_recovers_latency_and_jitter_distribution():
    rng = np.random.default_rng(2)
    t_cmd, u = _random_steps(rng, 120)
    t_odom = np.arange(0, 120, 0.01)
    v = _response(t_cmd, u, t_odom, dead_s=0.08, jitter_s=0.04, lag_s=0.005, rng=rng, noise=0.005)
    t_scan = np.round(np.arange(0, 120, 0.1), 9)
    est = estimate_delay(t_cmd, u, t_odom, v, [0, 1, 2], t_scan, t_scan)
    lag50 = 0.005 * np.log(2)
    # per-command delays U(0.08, 0.12): median 0.10, 95th percentile 0.118 (+ the lag's half-way time)
    assert est.actuation_median_s == pytest.approx(0.10 + lag50, abs=0.006)
    assert est.actuation95_s == pytest.approx(0.118 + lag50, abs=0.008)
    assert est.xcorr_s == pytest.approx(0.10, abs=0.012)
    assert len(est.edge_delays_s) > 100
    # commands at 20 Hz, scans at 10 Hz: ages 0 and 0.05 -> the sum's 95 % quantile = 0.05 + actuation's upper part
    assert set(np.round(est.perception_latency_s, 6)) == {0.0, 0.05}
    # tau95 from the translational axes' edges (eq:uncertainty_margin (21) multiplies it by a translational velocity)
    assert est.tau95_axes == (0, 1)
    trans = np.isin(est.edge_axes, [0, 1])
    assert est.tau95_s == pytest.approx(tau95(est.edge_delays_s[trans], est.perception_latency_s))
    assert est.actuation95_s < est.tau95_s <= est.actuation95_s + 0.05 + 1e-9


def test_per_axis_delays_with_bootstrap_intervals():
    """vx responds after 0.08 s, wz after 0.2 s (a filtered yaw rate, say): each axis gets its own delay, and the
    bootstrap interval over segments covers it."""
    from twin.delay import axis_delays
    rng = np.random.default_rng(4)
    t_cmd, u = _random_steps(rng, 120)
    t_odom = np.arange(0, 120, 0.02)
    v = _response(t_cmd, u, t_odom, dead_s=0.08, rng=rng, noise=0.01)
    v[:, 2] = _response(t_cmd, u, t_odom, dead_s=0.2, rng=rng, noise=0.01)[:, 2]
    opt = DelayOptions()
    tg, ug, vg, ok = grid_signals(t_cmd, u, t_odom, v, opt.grid_s, opt.max_gap_s)
    ax = axis_delays(ug, vg, ok, [0, 2], opt)
    assert ax[0].delay_s == pytest.approx(0.08, abs=0.006) and ax[2].delay_s == pytest.approx(0.2, abs=0.006)
    for j, true in ((0, 0.08), (2, 0.2)):
        lo, hi = ax[j].ci_s
        assert lo - 0.006 <= true <= hi + 0.006 and hi - lo < 0.03
        assert not ax[j].tie


def test_two_candidate_delays_that_nearly_tie_are_flagged():
    from twin.delay import ties
    # a curve with peaks 0.126 at 0.105 s and 0.124 at 0.295 s (the example), grid 5 ms
    lags = np.arange(0, 1.0001, 0.005)
    curve = 0.126 * np.exp(-((lags - 0.105) / 0.02) ** 2) + 0.124 * np.exp(-((lags - 0.295) / 0.02) ** 2)
    lag2, h2 = ties(curve, 0.005, 0.95, 0.04)
    assert lag2 == pytest.approx(0.295, abs=0.003) and h2 == pytest.approx(0.124, abs=0.001)
    # a second peak at 80 % is no tie; neither is the shoulder of the main peak
    lag2, _ = ties(0.126 * np.exp(-((lags - 0.105) / 0.02) ** 2) + 0.1 * np.exp(-((lags - 0.295) / 0.02) ** 2),
                   0.005, 0.95, 0.04)
    assert np.isnan(lag2)
