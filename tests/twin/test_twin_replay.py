"""Replay the logged commands through the MuJoCo model: the calibrated model tracks the log better than the
nominal one; the model profile mapping by hand; a video with both paths."""
import numpy as np
import pytest

from bigcbf.params.robot import RobotProfile
from twin.calibrate import read_log
from twin.replay import ReplayOptions, model_profile, replay, scene_for, simulate


def test_model_profile_by_hand():
    # the model's own response A0 = diag(0.98, 0.96, 0.95), d0 = (0, 0.01, 0), delay0 = 0.015 s; the log's
    # A = diag(0.9 * 0.98, 0.85 * 0.96, 0.95 * 0.95), d = A0 (0.02, 0, 0) + d0 = (0.0196, 0.01, 0), delay 0.105 s:
    # G = A0^-1 A = diag(0.9, 0.85, 0.95), b = A0^-1 (d - d0) = (0.02, 0, 0), latency 0.09 s
    A0, d0 = np.diag([0.98, 0.96, 0.95]), np.array([0.0, 0.01, 0.0])
    A = np.diag([0.9 * 0.98, 0.85 * 0.96, 0.95 * 0.95])
    p = model_profile(A, A0 @ [0.02, 0.0, 0.0] + d0, 0.105, A0, d0, 0.015)
    np.testing.assert_allclose(p.gain, np.diag([0.9, 0.85, 0.95]), atol=1e-12)
    np.testing.assert_allclose(p.bias, [0.02, 0.0, 0.0], atol=1e-12)
    assert p.latency_s == pytest.approx(0.09)
    assert model_profile(A, d0, 0.01, A0, d0, 0.015).latency_s == 0.0     # never negative


def _first(data, seconds):
    import dataclasses
    c, o = data.cmd, data.odom
    kc, ko = c.t < seconds, o.t < seconds
    return dataclasses.replace(data, cmd=dataclasses.replace(c, t=c.t[kc], u=c.u[kc]),
                               odom=dataclasses.replace(o, t=o.t[ko], stamp=o.stamp[ko], pose=o.pose[ko],
                                                        twist=o.twist[ko]))


@pytest.fixture(scope="module")
def result(profile_drive):
    """The first 45 s of the recorded drive (every kind of motion of the program) replayed."""
    return replay(_first(read_log(profile_drive[0], use_scan=False), 45.0), opt=ReplayOptions(window_s=5.0))


def test_calibrated_replay_beats_nominal(result, profile):
    nom, cal = result.runs["nominal"], result.runs["calibrated"]
    assert np.all(cal.rmse < nom.rmse)                                   # every axis
    assert cal.drift_mean_m < 0.5 * nom.drift_mean_m
    assert cal.rmse[0] < 0.5 * nom.rmse[0] and cal.rmse[1] < 0.5 * nom.rmse[1]
    # the calibrated model profile is close to the one that made the log
    np.testing.assert_allclose(np.diag(cal.profile.gain), np.diag(profile.gain), rtol=0.05)
    assert cal.profile.latency_s == pytest.approx(profile.latency_s + profile.latency_jitter_s / 2, abs=0.015)


def test_replay_result_json(result):
    out = result.to_json()
    assert set(out["runs"]) == {"nominal", "calibrated"}
    assert set(out["runs"]["nominal"]["velocity_rmse"]) == {"vx", "vy", "wz"}
    assert out["runs"]["nominal"]["profile"]["latency_s"] == 0.0


def test_simulate_starts_at_the_logged_pose_and_a_video_shows_the_paths(profile_drive, tmp_path):
    data = read_log(profile_drive[0], use_scan=False)
    k = data.odom.t <= 3.0
    data.odom.pose[:, :2] += (1.0, -0.5)                 # a logged initial pose away from the origin
    data.cmd.t, data.cmd.u = data.cmd.t[data.cmd.t < 3.0], data.cmd.u[data.cmd.t < 3.0]
    t, pose, twist = simulate(data.cmd.t, data.cmd.u, data.odom, RobotProfile(), t_end=3.0)
    np.testing.assert_allclose(pose[0, :2], [1.0, -0.5], atol=1e-9)
    assert len(t) == k.sum() and t[-1] <= 3.0
    from twin.replay import ReplayRun, write_video
    run = ReplayRun("calibrated", RobotProfile(), t, pose, twist)
    video = tmp_path / "replay.mp4"
    data.odom.t, data.odom.pose, data.odom.twist = data.odom.t[k], data.odom.pose[k], data.odom.twist[k]
    write_video(data, run, run, video, ReplayOptions(video_fps=5.0), scene_for(data.odom.pose[:, :2]))
    assert video.stat().st_size > 1000


def test_fit_moves_the_model_toward_the_log(profile_drive, profile):
    """Nelder-Mead from the nominal profile on 6 s of the drive: the error drops, the latency moves toward the
    truth (0.09 s on average). The gains are not asserted: 6 s of the program with +-0.03 m/s residual noise do
    not pin them (16, 30 and 60 evaluations gave vx gains 1.13, 1.04, 1.04 for a true 0.9); the least-squares
    calibration on the whole log identifies them (test_calibrated_replay_beats_nominal). 24 evaluations: since the
    latency jitter and the residual draw from separate random streams, 16 stopped at 0.82 of the nominal error on
    this drive (24: 0.74)."""
    from twin.replay import fit_profile, run_profile
    data = _first(read_log(profile_drive[0], use_scan=False), 6.0)
    scene = scene_for(data.odom.pose[:, :2])
    opt = ReplayOptions(fit=True, fit_window_s=6.0, fit_evals=24)
    start = RobotProfile()
    before = run_profile("nominal", data, start, opt.window_s, scene=scene)
    fitted = fit_profile(data, start, opt, scene)
    scale = np.maximum(data.odom.twist.std(axis=0), 1e-3)
    assert np.sum(fitted.rmse / scale) < 0.8 * np.sum(before.rmse / scale)
    assert 0.03 < fitted.profile.latency_s < 0.15                  # from 0 toward 0.09
    assert fitted.profile.floor_friction is not None
