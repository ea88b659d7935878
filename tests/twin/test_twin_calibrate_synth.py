"""calibrate_series on synthetic logs (numpy, no simulator): e_ZOH by hand, the profile written and read back,
and the errors for logs that cannot be calibrated."""
from pathlib import Path

import numpy as np
import pytest

from bigcbf.errors import UserError
from bigcbf.logio import LogData, OdomSeries, StampSeries, TwistSeries
from bigcbf.params.stack import PHYSICAL, load_stack_params
from twin.calibrate import calibrate_series, summary_lines, write_profile, zoh_displacement
from twin.signals import zoh

A = np.array([[0.9, 0.0, 0.0], [0.0, 1.0, 0.0], [0.05, 0.0, 0.95]])
D = np.array([0.02, 0.0, -0.01])


def test_zoh_displacement_by_hand():
    # eq:uncertainty_margin (21) e_ZOH = T_C * v: commands every 0.05 s except one 0.2 s gap among 40 intervals -> the
    # 95 % quantile of the intervals is the 38th smallest of 40 = 0.05; speeds 0..0.99 (100 values) -> 99 %: 99th = 0.98
    # m/s
    t = np.concatenate([np.arange(0, 1.0, 0.05), 1.15 + np.arange(0, 1.0, 0.05)])
    v = np.column_stack([np.arange(100) / 100.0, np.zeros(100)])
    e, T, s = zoh_displacement(t, v)
    assert T == pytest.approx(0.05) and s == pytest.approx(0.98) and e == pytest.approx(0.049)
    v2 = np.column_stack([np.full(100, 0.3), np.full(100, 0.4)])          # ||(0.3, 0.4)|| = 0.5
    assert zoh_displacement(t, v2)[0] == pytest.approx(0.025)


def _synthetic_log(seconds=120.0, delay=0.1, noise=0.01, seed=0, vy=False):
    rng = np.random.default_rng(seed)
    holds = rng.uniform(0.8, 1.2, int(seconds))
    starts = np.concatenate([[0.0], np.cumsum(holds)])
    levels = rng.uniform(-0.6, 0.6, (len(starts), 3))
    if not vy:
        levels[:, 1] = 0.0                                   # a differential drive
    t_cmd = np.round(np.arange(0, seconds, 0.05), 9)
    u = levels[np.searchsorted(starts, t_cmd, side="right") - 1]
    t_odom = np.round(np.arange(0.0, seconds, 0.02), 9)
    ud = zoh(t_cmd, u, t_odom - delay, before=0.0)
    v = ud @ A.T + D + rng.uniform(-noise, noise, (len(t_odom), 3))
    v[:, 1] = ud[:, 1] if not vy else v[:, 1]
    pose = np.zeros((len(t_odom), 3))
    t_scan = np.round(np.arange(0, seconds, 0.1), 9)
    return LogData(Path("synthetic.mcap"), cmd=TwistSeries("/cmd_vel", t_cmd, u),
                   odom=OdomSeries("/odom", t_odom, t_odom, pose, v), scan=StampSeries("/scan", t_scan, t_scan))


def test_calibrate_synthetic_differential_drive(tmp_path):
    cal = calibrate_series(_synthetic_log())
    np.testing.assert_array_equal(cal.fit.identified, [True, False, True])
    np.testing.assert_allclose(cal.fit.A, A, atol=0.01)
    np.testing.assert_allclose(cal.fit.d, D, atol=0.005)
    assert cal.delay.xcorr_s == pytest.approx(0.1, abs=0.006)
    assert cal.delay.actuation_median_s == pytest.approx(0.1, abs=0.012)   # half-way within one odometry period
    # scans at 10 Hz, commands at 20 Hz: perception ages 0 and 0.05 s are added
    assert cal.delay.tau95_s == pytest.approx(cal.delay.actuation95_s + 0.05, abs=0.021)
    # residual: uniform +-0.01 on vx (vy exact): ||r_xy|| <= 0.01, 95 % quantile 0.0095
    assert np.all(cal.bound.bound_knots <= 0.0105) and np.all(cal.bound.bound_knots >= 0.009)
    assert cal.bound.coverage_heldout == pytest.approx(0.95, abs=0.03)
    # T_C = 0.05 s and the largest speeds 0.9 * 0.6 + 0.02 + 0.01 ~ 0.57 m/s
    assert cal.control_period_s == pytest.approx(0.05)
    assert cal.e_zoh_m == pytest.approx(0.05 * cal.speed_mps) and 0.5 < cal.speed_mps < 0.58
    assert cal.residual_horizon_s == pytest.approx(0.05 + cal.delay.tau95_s)
    assert np.all(cal.rmse_model[[0, 2]] < cal.rmse_nominal[[0, 2]])
    text = "\n".join(summary_lines(cal))
    assert "NOT identified" in text and "vy" in text


def test_profile_is_a_partial_stack_params_toml(tmp_path):
    cal = calibrate_series(_synthetic_log())
    p = write_profile(cal, tmp_path / "robot.toml")
    text = p.read_text()
    assert "[uncertainty]" in text and "[uncertainty.execution]" in text and "T_B_s" not in text
    params = load_stack_params(p, base=PHYSICAL)
    u = params.uncertainty
    assert u.tau95_s >= cal.delay.tau95_s and u.tau95_s - cal.delay.tau95_s < 1e-5      # rounded up
    assert u.e_zoh_m >= cal.e_zoh_m and u.r_robot_m == PHYSICAL.uncertainty.r_robot_m    # the rest from the base
    ex = u.execution
    assert ex.identified == (True, False, True) and ex.A[1] == (0.0, 1.0, 0.0)
    np.testing.assert_allclose(ex.A, cal.fit.A, atol=1e-5)
    assert all(b >= c for b, c in zip(ex.residual_bound_mps, cal.bound.bound_knots))
    assert ex.residual_speed_mps[0] == 0.0 and ex.residual_coverage == 0.95
    with pytest.raises(UserError, match="directory"):
        write_profile(cal, tmp_path)


def test_logs_that_cannot_be_calibrated():
    log = _synthetic_log(seconds=20)
    one = LogData(log.path, cmd=TwistSeries("/cmd_vel", log.cmd.t[:1], log.cmd.u[:1]), odom=log.odom)
    with pytest.raises(UserError, match="too few commands"):
        calibrate_series(one)
    # published on change, a single step and nothing else: the held command excites vx, but one change is no delay
    u = np.array([[0.0, 0, 0], [0.5, 0, 0]])
    step = LogData(log.path, cmd=TwistSeries("/cmd_vel", np.array([0.0, 5.0]), u), odom=log.odom)
    with pytest.raises(UserError, match="change 1 time"):
        calibrate_series(step)
    still = LogData(log.path, cmd=TwistSeries("/cmd_vel", log.cmd.t, np.zeros_like(log.cmd.u)), odom=log.odom)
    with pytest.raises(UserError, match="do not excite any axis"):
        calibrate_series(still)
    apart = LogData(log.path, cmd=log.cmd, odom=OdomSeries("/odom", log.odom.t + 100.0, log.odom.stamp,
                                                           log.odom.pose, log.odom.twist))
    with pytest.raises(UserError, match="overlap"):
        calibrate_series(apart)


def test_command_timeout_leaves_stale_samples_out():
    """A robot that stops on a 0.3 s command timeout: during a 3 s gap in the commands the synthetic robot stands
    still. Holding the last command through the gap pairs it with a stopped robot and biases the fit; with the
    timeout given, those samples are left out and A is recovered."""
    import dataclasses
    from twin.calibrate import CalibrationOptions
    data = _synthetic_log(seed=2)
    c, o = data.cmd, data.odom
    gap = (c.t > 50.0) & (c.t < 53.0)
    stopped = (o.t > 50.0 + 0.1 + 0.3) & (o.t < 53.0 + 0.1)
    v = o.twist.copy()
    v[stopped] = 0.0
    data = dataclasses.replace(data, cmd=dataclasses.replace(c, t=c.t[~gap], u=c.u[~gap]),
                               odom=dataclasses.replace(o, twist=v))
    held = calibrate_series(data)
    assert any("gaps of up to 3" in w and "--cmd-timeout" in w for w in held.warnings)
    cal = calibrate_series(data, CalibrationOptions(max_command_age_s=0.3))
    assert cal.counts["stale"] > 100 and any("command timeout 0.3 s" in w for w in cal.warnings)
    np.testing.assert_allclose(np.diag(cal.fit.A)[[0, 2]], np.diag(A)[[0, 2]], rtol=0.02)


def test_axes_moving_together_are_flagged():
    """vx and wz always commanded in the same proportion: both excited, their cross gains not separable."""
    import dataclasses
    data = _synthetic_log(seed=3)
    u = data.cmd.u.copy()
    u[:, 2] = 2.0 * u[:, 0]
    data = dataclasses.replace(data, cmd=dataclasses.replace(data.cmd, u=u))
    cal = calibrate_series(data)
    assert any("move together" in w and "vx, wz" in w for w in cal.warnings)
    assert not any("move together" in w for w in calibrate_series(_synthetic_log(seed=3)).warnings)
