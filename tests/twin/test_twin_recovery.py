"""Recovery: record a calibration drive with a known profile in the simulator, calibrate, get the profile back.

The twin measures the whole robot: the profile's imperfection layer *and* the model's own response (wheel
dynamics, roller slip, the odometry's averaging over its 20 ms period). The latter is measured on the same
program driven with the ideal profile, and the comparisons below name which of the two each one uses.
"""
import numpy as np
import pytest

from twin.calibrate import calibrate_log
from twin.drive import DriveLimits, calibration_program


@pytest.fixture(scope="module")
def cals(profile_drive, ideal_drive):
    return calibrate_log(profile_drive[0]), calibrate_log(ideal_drive)


def test_drive_program_covers_the_axes_up_to_the_limits():
    t, u = calibration_program(80.0, DriveLimits(), seed=0)
    assert len(t) == 1600 and np.all(np.diff(t) == pytest.approx(0.05))
    np.testing.assert_array_equal(u[:20], 0.0)                        # starts at rest
    np.testing.assert_array_equal(u[-10:], 0.0)                       # ends at rest
    assert np.abs(u[:, 0]).max() == pytest.approx(0.8) and np.abs(u[:, 1]).max() == pytest.approx(0.55)
    assert np.abs(u[:, 2]).max() == pytest.approx(1.0)
    assert np.hypot(u[:, 0], u[:, 1]).max() <= 0.8 + 1e-9
    both = (np.abs(u[:, 0]) > 0.05) & (np.abs(u[:, 1]) > 0.05) & (np.abs(u[:, 2]) > 0.1)
    assert both.mean() > 0.05                                         # combined motions


def test_recording_stays_in_the_room_and_logs_every_topic(profile_drive):
    _, summary = profile_drive
    assert summary["messages"] == {"/odom": 4000, "/tf": 4000, "/ground_truth/odom": 4000, "/imu": 4000,
                                   "/scan": 800, "/cmd_vel": 1600}
    assert summary["max_distance_m"] < 3.4 and not summary["warnings"]


def test_latency_recovered_within_15_ms(cals, profile):
    cal, ideal = cals
    # per command the profile delays by 0.08 + U(0, 0.02): mean 0.09 s, 95th percentile 0.099 s
    mean_latency = profile.latency_s + profile.latency_jitter_s / 2
    assert cal.delay.actuation_median_s - ideal.delay.actuation_median_s == pytest.approx(mean_latency, abs=0.015)
    assert cal.delay.xcorr_s - ideal.delay.xcorr_s == pytest.approx(mean_latency, abs=0.015)
    assert len(cal.delay.edge_delays_s) > 60
    # tau95 adds the scan age at command time (scans 10 Hz, commands 20 Hz: 0 or 0.05 s)
    assert cal.delay.perception_source == "header stamps"
    assert cal.delay.actuation95_s < cal.delay.tau95_s <= cal.delay.actuation95_s + 0.05 + 1e-9


def test_gains_and_bias_recovered(cals, profile):
    cal, ideal = cals
    gains = np.diag(np.asarray(profile.gain))
    assert cal.fit.identified.all() and cal.counts["saturated"] < 0.05 * cal.counts["aligned"]
    np.testing.assert_allclose(np.diag(cal.fit.A), gains, rtol=0.05)                     # the 5 %
    # relative to the model's own gains the translational ones come out within 2 %. Not yaw: the drive's fast corner
    # steps (diagonal at 0.72 m/s with 0.9 rad/s) make the model's own rollers slip in yaw (its yaw gain reads
    # ~0.93 on the ideal robot, less slip at the profile's slower yaw), so the ratio is no measure there
    np.testing.assert_allclose((np.diag(cal.fit.A) / np.diag(ideal.fit.A))[:2], gains[:2], rtol=0.02)
    np.testing.assert_allclose(cal.fit.d, profile.bias, atol=0.02)
    assert abs(cal.fit.d[0] - 0.02) < 0.005


def test_residual_bound_held_out_coverage_within_3_points(cals):
    cal, _ = cals
    b = cal.bound
    assert b.coverage == 0.95 and b.n_heldout > 200
    assert b.coverage_heldout == pytest.approx(0.95, abs=0.03)
    # the profile's residual is uniform within +-0.03 m/s per axis: ||r_xy|| <= 0.042 plus the odometry's noise
    assert 0.03 < b.bound_knots.min() and b.bound_knots.max() < 0.09
    # the calibrated model beats the nominal v = u(t) on the held-out samples, on every axis
    assert np.all(cal.rmse_model < cal.rmse_nominal)


def test_random_profiles_with_wheel_limits_recovered(limited_drives):
    """Issue 14's tolerances on random hidden profiles with limits: wheel-speed limit within 10 %, acceleration
    limit within 20 %, latency within 15 ms (the dead time less the model's own behind the same limits: the simulated
    wheels' ~17 ms lag reads as dead time behind a ramp), gains within 5 %."""
    for prof, cal, ref in limited_drives:
        st, dyn = cal.model.static, cal.model.dynamic
        assert st.v_max == pytest.approx(prof.wheel_speed_max_mps, rel=0.10)
        assert dyn.accel_max == pytest.approx(prof.wheel_accel_max_mps2, rel=0.20)
        latency = np.nanmedian(cal.latency_s) - np.nanmedian(ref.latency_s)
        assert latency == pytest.approx(prof.latency_s + prof.latency_jitter_s / 2, abs=0.015)
        np.testing.assert_allclose(np.diag(cal.fit.A), np.diag(np.asarray(prof.gain)), rtol=0.05)
        # the summary says plainly that a linear model would be wrong, and what it would claim
        assert any("A linear model v = A u + d is wrong above the limit" in n for n in cal.notes())
        # coverage on all held-out samples (saturated ones fall outside eq:execution (1)) and on the unsaturated ones
        assert cal.coverage_heldout_all <= cal.coverage_heldout_transients
        assert cal.bound.coverage_heldout == pytest.approx(0.95, abs=0.04)
        # the profile written carries the limits and tau95's parts, and the stack reads it
        d = cal.profile_dict()["uncertainty"]
        assert d["execution"]["wheel_speed_max_mps"] == pytest.approx(st.v_max, abs=1e-4)
        assert set(d["tau95_parts"]) == {"latency_s", "actuation_median_s", "actuation95_s", "perception95_s"}


def test_a_log_without_limits_reports_none(cals):
    """The drive of the profile without wheel limits: no wheel-speed limit is claimed."""
    cal, ideal = cals
    for c in (cal, ideal):
        assert c.model.static.v_max is None
        assert not any("saturates" in n for n in c.notes())
