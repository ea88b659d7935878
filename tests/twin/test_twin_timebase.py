"""Logs as they come (twin.timebase): the odometry's time base, its twist, the command stream's publication."""
import numpy as np
import pytest

from twin.timebase import (command_publication, lower_envelope, odometry_timing, twist_from_poses,
                           twist_is_empty)


def _bursty(rng, n=3000, period=0.02, hold_every=40, hold_s=0.2):
    """Production every ``period``; received 3-6 ms later, except that now and then the link stalls for
    ``hold_s`` and releases the held messages within a millisecond."""
    produced = 1.0 + np.arange(n) * period
    recv = produced + rng.uniform(0.003, 0.006, n)
    k = 0
    while k < n:
        k += int(rng.integers(hold_every // 2, hold_every * 2))
        stall_end = produced[min(k, n - 1)] + hold_s
        held = (produced >= produced[min(k, n - 1)]) & (produced < stall_end)
        recv[held] = stall_end + np.linspace(0, 0.0008, held.sum())
    return produced, np.maximum.accumulate(recv)


def test_lower_envelope_recovers_production_times_of_bursty_messages():
    rng = np.random.default_rng(0)
    produced, recv = _bursty(rng)
    dt = np.diff(recv)
    assert np.mean(dt < 0.004) > 0.05                    # bursts: over 5 % of the intervals under 4 ms
    est = lower_envelope(recv, gap_s=0.5)
    err = est - produced
    # the envelope sits between the production time and 4 ms after it (the transport latency is 3-6 ms, less for
    # the last messages released by a stall), where the receive times are up to 0.2 s late
    assert np.max(np.abs(recv - produced)) > 0.19
    assert np.all((err > 0) & (err < 0.004))
    assert np.all(np.diff(est) > 0)


def test_timing_prefers_stamps_on_the_log_clock_and_maps_a_second_clock():
    rng = np.random.default_rng(1)
    produced, recv = _bursty(rng)
    same = odometry_timing(recv, produced)
    assert same.source == "header stamps"
    np.testing.assert_allclose(same.t, produced)
    assert any("bursty" in n for n in same.notes)
    # a second clock: the robot's epoch time, 1.7e9 s off and 0.05 % fast; mapped by its lowest latency (3 ms)
    robot = 1.7e9 + produced * 1.0005
    other = odometry_timing(recv, robot)
    assert other.source == "header stamps (second clock)"
    assert np.quantile(np.abs(other.t - produced), 0.98) < 0.004
    assert any("second clock" in n for n in other.notes)
    # no usable stamps (all zero) and bursts: the robust time base
    robust = odometry_timing(recv, np.zeros_like(recv))
    assert robust.source == "robust time base"
    assert np.all((robust.t - produced > 0) & (robust.t - produced < 0.004))
    # regular receive times and no stamps: the receive times as they are
    plain = odometry_timing(produced + 0.004, np.zeros_like(produced))
    assert plain.source == "receive times" and plain.period_s == pytest.approx(0.02)


def test_gaps_are_reported():
    t = np.concatenate([np.arange(0, 10, 0.02), np.arange(11.5, 20, 0.02)])
    timing = odometry_timing(t, t)
    assert any("1 gaps" in n and "1.52 s" in n for n in timing.notes)


def test_twist_from_poses_by_hand():
    # a circle of radius 2 m at 0.5 m/s (wz 0.25 rad/s), sampled every 20 ms: body twist (0.5, 0, 0.25)
    t = np.arange(0, 10, 0.02)
    th = 0.25 * t
    pose = np.column_stack([2 * np.sin(th), 2 - 2 * np.cos(th), th])
    tw = twist_from_poses(t, pose, 0.06)
    np.testing.assert_allclose(tw[5:-5], np.tile([0.5, 0.0, 0.25], (len(t) - 10, 1)), atol=1e-4)
    assert twist_is_empty(np.zeros_like(pose), pose) and not twist_is_empty(tw, pose)


def test_command_publication():
    assert command_publication(np.arange(0, 10, 0.05)) == ("periodic", pytest.approx(0.05))
    # 11 messages over a 60 s drive (a teleoperation tool publishing changes)
    pub, med = command_publication(np.array([0, 3.1, 8.0, 9.5, 15, 22, 23.4, 30, 41, 47.5, 60.0]))
    assert pub == "on change" and med > 1
