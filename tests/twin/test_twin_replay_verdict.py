"""The replay's verdict weighs every score its table prints: on a hand-made pair of runs where the calibrated model
tracks the velocities better but drifts further, the verdict says so per score and warns; the CLI's summary line
names the score."""
import numpy as np

from bigcbf.params.robot import RobotProfile
from twin.replay import ReplayResult, ReplayRun, compare, scores


def _run(name, rmse, drift_mean, drift_max, yaw_mean, final, windows=None):
    r = ReplayRun(name, RobotProfile(), np.zeros(2), np.zeros((2, 3)), np.zeros((2, 3)))
    r.rmse = np.asarray(rmse, float)
    r.drift_mean_m, r.drift_max_m, r.yaw_drift_mean_rad, r.final_error_m = drift_mean, drift_max, yaw_mean, final
    if windows is not None:
        r.windows = np.asarray(windows, float)
    return r


def _runs():
    # the user test's numbers: the calibrated RMSE is lower on every axis, its largest 5-s drift 0.573 m where the
    # nominal one's is 0.345 m; windows (start s, drift m, heading drift rad)
    nominal = _run("nominal", [0.1285, 0.0831, 0.1939], 0.113, 0.345, 0.097, 0.363,
                   [[0, 0.146, 0.13], [5, 0.103, 0.13], [10, 0.345, 0.17]])
    calibrated = _run("calibrated", [0.0094, 0.0088, 0.1338], 0.083, 0.573, 0.103, 0.304,
                      [[0, 0.023, 0.03], [5, 0.014, 0.05], [10, 0.573, 0.43]])
    return {"nominal": nominal, "calibrated": calibrated}


def test_rmse_better_drift_worse_warns():
    runs = _runs()
    sc = {s.label: s.better for s in scores(runs["calibrated"], runs["nominal"], [True, True, True])}
    assert sc == {"rmse vx": "model", "rmse vy": "model", "rmse wz": "model", "drift mean": "model",
                  "drift max": "nominal", "yaw mean": "nominal", "final err": "model"}
    notes = compare(runs, np.array([True, True, True]), 5.0)
    verdict = notes[0]
    assert verdict.startswith("verdict, calibrated vs nominal") and "calibrated WORSE on drift max, yaw mean" in verdict
    assert "rmse vx: calibrated better" in verdict and "drift max: nominal better (calibrated 0.573, nominal 0.345 m)" \
        in verdict
    warn = [n for n in notes if n.startswith("WORSE")]
    assert len(warn) == 2
    assert "drift max is larger than the nominal one's (calibrated 0.573, nominal 0.345 m)" in warn[0]
    assert "larger on 1 of 3 5-s windows" in warn[0] and "10.0-15.0 s" in warn[0]
    res = ReplayResult("hand", 5.0, runs, notes, np.array([True, True, True]))
    assert res.worse_on == ["drift max", "yaw mean"] and res.worse_axes == res.worse_on
    js = res.to_json()
    assert js["calibrated_worse_on"] == ["drift max", "yaw mean"]
    assert {v["score"]: v["better"] for v in js["verdict"]["calibrated"]}["drift max"] == "nominal"


def test_unidentified_axis_and_ties_are_not_warned():
    runs = _runs()
    c = runs["calibrated"]
    c.rmse[1] = 0.5                                       # vy much worse, but the log does not identify vy
    c.drift_max_m, c.yaw_drift_mean_rad = 0.3465, 0.0975  # within 1 % of the nominal one's: about equal
    ident = np.array([True, False, True])
    notes = compare(runs, ident, 5.0)
    assert not any(n.startswith("WORSE") for n in notes)
    assert "no worse on any score" in notes[0] and "rmse vy not compared (vy not identified)" in notes[0]
    assert "drift max: about equal" in notes[0]
    assert ReplayResult("hand", 5.0, runs, notes, ident).worse_on == []
    # and the other way round: the calibrated drift within tolerance, its wz RMSE worse -> a tracking warning
    c.rmse[2] = 0.25
    notes = compare(runs, ident, 5.0)
    assert any(n.startswith("WORSE: the calibrated replay tracks wz worse") for n in notes)


def test_cli_summary_names_the_worse_score(monkeypatch, capsys):
    """bigcbf replay's summary line lists every worse score, the drift included (not 'no worse')."""
    import twin.replay
    from bigcbf.cli import main
    runs = _runs()
    ident = np.array([True, True, True])
    res = ReplayResult("hand.mcap", 5.0, runs, compare(runs, ident, 5.0), ident)
    monkeypatch.setattr(twin.replay, "replay_log", lambda *a, **k: res)
    assert main(["replay", __file__]) == 0
    out = capsys.readouterr().out
    assert "calibrated worse than nominal on: drift max, yaw mean" in out and "no worse" not in out
    assert "note: verdict, calibrated vs nominal" in out and "note: WORSE: the calibrated replay's drift max" in out
