"""Logs shaped like real ones, built synthetically (numpy, no simulator): a differential drive with a wheel-speed
limit, an acceleration limit, a dead time and a lag; commands published only when they change; odometry received
in bursts, its header stamps on a second clock; a gap. ``bigcbf calibrate`` must recover the robot from them, and
say what it did with the log."""
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from bigcbf.logio import LogData, LogWriter, OdomSeries, TwistSeries, convert, msgdefs
from bigcbf.types import RobotState
from twin.calibrate import calibrate_series, read_log, summary_lines
from twin.limits import rim_matrix

# the robot: vx, wz gains and biases, a 0.3 m/s wheel limit with a 0.08 m half track, 1.5 m/s^2 of wheel
# acceleration, 0.12 s dead time and a 30 ms lag
A = np.diag([0.95, 1.0, 0.9])
D = np.array([0.01, 0.0, -0.02])
V_MAX, LEVER, ACCEL, DEAD, LAG = 0.3, 0.08, 1.5, 0.12, 0.03


def _robot(t_cmd, u_cmd, seconds, h=0.002, rng=None):
    """Simulate the robot on a fine grid: returns (t, twist (n, 3), pose (n, 3))."""
    t = np.arange(0.0, seconds, h)
    k = np.clip(np.searchsorted(t_cmd, t - DEAD, side="right") - 1, 0, None)
    u = np.where((t - DEAD >= t_cmd[0])[:, None], u_cmd[k], 0.0)
    R = rim_matrix(LEVER)
    x = np.zeros(3)
    y = np.zeros(3)
    out = np.zeros((len(t), 3))
    for n in range(len(t)):
        p = A @ u[n] + D
        peak = np.max(np.abs(R @ p))
        if peak > V_MAX:
            p = p * V_MAX / peak
        step = p - x
        rim = np.max(np.abs(R @ step))
        if rim > ACCEL * h:
            step *= ACCEL * h / rim
        x = x + step
        y = y + (x - y) * (1 - np.exp(-h / LAG))
        out[n] = y
    out[:, 1] = 0.0                                            # a differential drive never moves sideways
    th = np.cumsum(out[:, 2]) * h
    c, s = np.cos(th), np.sin(th)
    pose = np.column_stack([np.cumsum(c * out[:, 0]) * h, np.cumsum(s * out[:, 0]) * h, th])
    if rng is not None:
        out = out + rng.normal(0, [0.004, 0.0, 0.01], out.shape)
    return t, out, pose


def shaped_log(seed=0, seconds=150.0, empty_twist=False, stamps="second clock"):
    """(commands on change, odometry at 30 Hz received in bursts, stamps as asked, a 1.5 s gap)."""
    rng = np.random.default_rng(seed)
    t_cmd, u_cmd, now = [0.0], [np.zeros(3)], 1.0
    while now < seconds - 3:
        level = np.array([rng.uniform(-0.5, 0.5), 0.0, rng.uniform(-1.5, 1.5)])
        level[rng.random(3) < 0.25] = 0.0
        level[1] = 0.0
        t_cmd.append(now)
        u_cmd.append(level)
        now += rng.uniform(1.0, 3.0)
    t_cmd.append(now)
    u_cmd.append(np.zeros(3))
    t_cmd, u_cmd = np.array(t_cmd), np.array(u_cmd)
    tf, vf, pf = _robot(t_cmd, u_cmd, seconds, rng=rng)
    produced = np.arange(0.5, seconds - 0.5, 1 / 30)
    keep = ~((produced > 70.0) & (produced < 71.5))              # a gap: 1.5 s without odometry
    produced = produced[keep]
    idx = np.searchsorted(tf, produced)
    twist, pose = vf[idx], pf[idx]
    recv = produced + rng.uniform(0.004, 0.012, len(produced))
    k = 0
    while k < len(produced) - 1:                                 # stalls of the link, released in a burst
        k += int(rng.integers(20, 60))
        if k >= len(produced):
            break
        end = produced[k] + rng.uniform(0.1, 0.3)
        held = (produced >= produced[k]) & (produced < end)
        recv[held] = end + np.linspace(0, 0.0008, held.sum())
    recv = np.maximum.accumulate(recv)
    stamp = {"second clock": 1.7e9 + produced, "log clock": produced, "none": np.zeros_like(produced)}[stamps]
    cmd = TwistSeries("/cmd_vel", t_cmd, u_cmd)
    odom = OdomSeries("/odom", recv, stamp, pose, np.zeros_like(twist) if empty_twist else twist)
    return LogData(Path(f"shaped-{seed}.mcap"), cmd=cmd, odom=odom), produced


def test_commands_on_change_bursty_odometry_on_a_second_clock():
    data, _ = shaped_log()
    assert len(data.cmd.t) < 90                                  # one message per change over 150 s
    cal = calibrate_series(data)
    text = "\n".join(summary_lines(cal))
    assert cal.publication == "on change" and "published on change" in text
    assert cal.timing.source == "header stamps (second clock)" and "second clock" in text
    assert "gaps in the odometry" in text
    np.testing.assert_array_equal(cal.fit.identified, [True, False, True])
    st, dyn = cal.model.static, cal.model.dynamic
    assert st.v_max == pytest.approx(V_MAX, rel=0.10)
    assert dyn.accel_max == pytest.approx(ACCEL, rel=0.20)
    # the mapped stamps sit 4 ms (the smallest transport latency) after production: dead time + 4 ms
    assert dyn.latency_s[0] == pytest.approx(DEAD + 0.004, abs=0.015)
    assert dyn.latency_s[2] == pytest.approx(DEAD + 0.004, abs=0.015)
    np.testing.assert_allclose(np.diag(cal.fit.A)[[0, 2]], np.diag(A)[[0, 2]], rtol=0.05)
    assert "the robot saturates" in text and "A linear model v = A u + d is wrong above the limit" in text
    # e_ZOH: no control period in the log, the stack's T_C
    assert cal.control_period_s == pytest.approx(0.05)
    # coverage reported on all held-out samples and on the unsaturated ones
    assert 0 < cal.coverage_heldout_all <= cal.coverage_heldout_transients <= 1


def test_bursty_receive_times_without_stamps_use_the_robust_time_base():
    data, produced = shaped_log(seed=1, stamps="none")
    cal = calibrate_series(data)
    assert cal.timing.source == "robust time base"
    dyn = cal.model.dynamic
    assert dyn.latency_s[0] == pytest.approx(DEAD, abs=0.02)
    # on the raw receive times the bursts would add their delay: the envelope removes it
    assert np.quantile(data.odom.t - produced, 0.9) > 0.05


def test_odometry_without_twist_uses_pose_differences():
    data, _ = shaped_log(seed=2, empty_twist=True, stamps="log clock")
    cal = calibrate_series(data)
    assert any("carry no twist" in n for n in cal.notes())
    np.testing.assert_allclose(np.diag(cal.fit.A)[[0, 2]], np.diag(A)[[0, 2]], rtol=0.05)
    assert cal.model.static.v_max == pytest.approx(V_MAX, rel=0.10)


def test_shaped_log_through_mcap_and_replay(tmp_path):
    """The same log written as MCAP (receive times as log times, stamps on the robot's clock): read back,
    calibrated, replayed; the replay reports nominal and calibrated, carries calibrate's notes about the log, and on
    every score the calibrated replay is no worse than the nominal one or says why."""
    from twin.replay import ReplayOptions, replay
    data, _ = shaped_log(seed=3, seconds=60.0)
    path = tmp_path / "shaped.mcap"
    with LogWriter(path) as w:
        for t, u in zip(data.cmd.t, data.cmd.u):
            w.cmd_vel(float(t), u)
        o = data.odom
        for k in range(len(o.t)):
            s = RobotState(*o.pose[k], *o.twist[k])
            w.write("/odom", msgdefs.ODOMETRY, float(o.t[k]), convert.odometry_msg(float(o.stamp[k]), s))
    back = read_log(path, use_scan=False)
    res = replay(back, opt=ReplayOptions(window_s=5.0))
    assert set(res.runs) == {"nominal", "calibrated"}
    notes = "\n".join(res.notes)
    assert "published on change" in notes and "second clock" in notes and "the robot saturates" in notes
    assert res.notes[0].startswith("verdict, calibrated vs nominal")
    for a in res.worse_on:                 # every score the calibrated replay is worse on has its warning
        assert (f"WORSE: the calibrated replay tracks {a.split()[-1]}" if a.startswith("rmse") else
                f"WORSE: the calibrated replay's {a} is larger") in notes
    nom, calr = res.runs["nominal"], res.runs["calibrated"]
    # the nominal model drives 0.5 m/s where this robot's wheels stop at 0.3: the calibrated one tracks vx
    assert calr.rmse[0] < 0.7 * nom.rmse[0]
    assert calr.profile.wheel_speed_max_mps is not None and calr.profile.wheel_yaw_lever_m is not None
