"""Issue 27: the model behind the command layer fitted with mujoco.sysid (twin/model_fit.py), its robot folder, its
intervals, and the CLI's --model / --robot options."""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bigcbf import robots
from bigcbf.cli import main
from bigcbf.errors import UserError
from bigcbf.params.robot import RobotProfile
from twin import model_fit as mf
from twin.calibrate import CalibrationOptions, read_log
from twin.record import record_calibration
from twin.timebase import prepare

ROOT = Path(__file__).resolve().parents[2]
FAST = mf.ModelFitOptions(starts=0, max_iters=4, n_boot=40, bin_s=0.5)


def test_robot_folder_round_trip(tmp_path):
    """A written model is a robot folder robots.py loads by its path, with the given parameters in its MJCF."""
    values = {"wheel_kv": 2.2, "wheel_damping": 0.05, "floor_friction": 0.7, "base_mass": 4.1}
    out = tmp_path / "my_robot"
    written = mf.write_robot_folder(mf.model_with("rosmaster_x3", values, RobotProfile(latency_s=0.05)), out)
    assert {p.name for p in written} >= {"my_robot.xml", "scene.xml", "my_robot.toml", "fit.json", "README.md"}
    r = robots.robot(str(out))
    assert r.wheels == robots.robot().wheels and r.folder == out
    m = mujoco.MjModel.from_xml_path(str(r.scene_xml))
    base = mujoco.MjModel.from_xml_path(str(robots.robot().scene_xml))
    a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, r.actuators[0])
    j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, r.wheels[0])
    assert m.actuator_gainprm[a, 0] == pytest.approx(2.2) and m.actuator_biasprm[a, 2] == pytest.approx(-2.2)
    assert m.dof_damping[m.jnt_dofadr[j]] == pytest.approx(0.05)
    assert m.geom_friction[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor"), 0] == pytest.approx(0.7)
    b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "base_link")
    assert m.body_mass[b] - base.body_mass[b] == pytest.approx(4.1 - 3.6)
    from bigcbf.scenario import load_robot_profile
    assert load_robot_profile(out / "profiles" / "my_robot.toml").latency_s == pytest.approx(0.05)


def test_not_a_robot_folder_is_one_line(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(UserError, match="unknown robot .*robot folder's path"):
        robots.folder(str(tmp_path / "empty"))


def test_block_bootstrap_covers_under_autocorrelation():
    """On a linear problem with AR(1) residuals, the block bootstrap's 90 % intervals cover the truth near 90 % of
    the time (somewhat under: 0.76 measured), where the iid ones (mujoco.sysid.calculate_intervals) are far too
    narrow."""
    from mujoco import sysid
    rng = np.random.default_rng(1)
    n, reps, covered, covered_iid = 600, 120, 0, 0
    t = np.linspace(0, 1, n)
    J = np.column_stack([np.sin(7 * t), t])
    for _ in range(reps):
        e = np.zeros(n)
        for k in range(1, n):
            e[k] = 0.9 * e[k - 1] + rng.normal()
        theta = np.linalg.lstsq(J, e, rcond=None)[0]        # the truth is 0
        r = J @ theta - e
        lo, hi = mf.block_bootstrap(J, r, 1, 60, 200, 0.9, rng)
        covered += bool(theta[0] + lo[0] <= 0 <= theta[0] + hi[0])
        _, half = sysid.calculate_intervals([r], J, alpha=0.1)
        covered_iid += bool(abs(theta[0]) <= half[0])
    assert covered / reps >= 0.65           # measured 0.76 over 200 repetitions (iid: 0.32); blocks of a tenth
    assert covered_iid < 0.6 * covered      # of the series under-cover a little at this autocorrelation


@pytest.mark.slow
def test_fit_finds_damping_and_keeps_the_rest_honest(tmp_path):
    """A hidden model with a large wheel damping: the fit identifies it within 10 %; every parameter it does not
    identify is kept at the model's own value with no interval."""
    hidden = tmp_path / "hidden"
    mf.write_robot_folder(mf.model_with("rosmaster_x3", {"wheel_damping": 0.1}), hidden)
    log = tmp_path / "h.mcap"
    record_calibration(RobotProfile(), log, seed=3, duration_s=10.0, robot=str(hidden))
    data, _, _ = prepare(read_log(log, use_scan=False), CalibrationOptions().timebase)
    fit = mf.fit_model(data, RobotProfile(), "rosmaster_x3", FAST,
                       imu=mf.read_imu_yaw_rate(log, float(data.cmd.t[0])))
    k = fit.names.index("wheel_damping")
    assert fit.identified[k], fit.reasons[k]
    assert fit.value[k] == pytest.approx(0.1, rel=0.10)
    assert fit.lo[k] <= fit.value[k] <= fit.hi[k]
    for i in np.flatnonzero(~fit.identified):
        assert fit.value[i] == fit.nominal[i] and np.isnan(fit.lo[i]) and fit.reasons[i]
    assert fit.rms_fit[0] < 0.3 * fit.rms_nominal[0]
    assert fit.channels == ["vx", "vy", "wz", "imu wz"] and fit.cpu_s > 0


@pytest.mark.slow
def test_model_recovery_script_one_case(tmp_path):
    """scripts/twin_model_recovery.py on one short hidden model: a row per parameter and the summary's fields."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import twin_model_recovery as rec
    finally:
        sys.path.pop(0)
    rows = rec.run(1, 2700, 10.0, FAST)
    s = rec.summary(rows)
    assert s["cases"] == 1 and set(rows[0]["params"]) == set(mf.PARAMS_NAMES)
    for name in mf.PARAMS_NAMES:
        p = rows[0]["params"][name]
        assert (p["rel_err"] is None) == (not p["identified"])
    assert rec.binomial_band(20, 0.9) == (15, 20)
    assert s["cpu_s_per_log_minute"]["median"] > 0


@pytest.mark.parametrize("args, words", [
    (["calibrate", "LOG", "--model", "OUT", "--robot", "no_such_robot"], "unknown robot 'no_such_robot'"),
    (["calibrate", "LOG", "--robot", "mecanum_large"], "--robot names the model --model fits"),
    (["replay", "LOG", "--robot", "NOTDIR"], "unknown robot"),
])
def test_cli_bad_model_options_one_line(tmp_path, capsys, args, words):
    log = ROOT / "tests" / "data" / "turtlebot3.bag"
    args = [str(log) if a == "LOG" else str(tmp_path / "out") if a == "OUT" else
            str(tmp_path / "nope") if a == "NOTDIR" else a for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and len(err.splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_replay_robot_folder_scores_held_out(tmp_path, capsys):
    """bigcbf replay --robot DIR --holdout: the model run behind the folder's command layer, every run scored on
    the held-out part only."""
    log = tmp_path / "d.mcap"
    record_calibration(RobotProfile(), log, seed=1, duration_s=12.0)
    folder = tmp_path / "same"
    mf.write_robot_folder(mf.model_with("rosmaster_x3", {}), folder)
    assert main(["replay", str(log), "--robot", str(folder), "--holdout", "0.5", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["runs"]) == {"nominal", "calibrated", "model"}
    assert 5.0 < out["scored_from_s"] < 7.0
    # the folder holds the very model the log was recorded with, behind an ideal command layer: the model run
    # tracks the log at least as well as the nominal one
    assert out["runs"]["model"]["velocity_rmse"]["vx"] <= out["runs"]["nominal"]["velocity_rmse"]["vx"] * 1.05


def test_run_takes_a_fitted_robot_folder(tmp_path, capsys):
    """bigcbf run: a scenario whose [robot] model is a fitted robot folder's path, with the folder's command layer
    as --robot-profile, runs an episode on that model."""
    import tomli_w

    from bigcbf.params.toml_io import load_toml
    from bigcbf.scenario import resolve_path
    folder = tmp_path / "slippery_x3"
    mf.write_robot_folder(mf.model_with("rosmaster_x3", {"floor_friction": 0.6}, RobotProfile(latency_s=0.04)),
                          folder)
    raw = load_toml(resolve_path("required_sidestepping"))
    raw["robot"]["model"] = str(folder)
    scen = tmp_path / "scen.toml"
    scen.write_bytes(tomli_w.dumps(raw).encode())
    assert main(["run", str(scen), "--robot-profile", str(folder / "profiles" / "slippery_x3.toml"),
                 "--time-limit", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["time_s"] == pytest.approx(2.0) and out["control_steps"] >= 30
    from bigcbf.sim.scene import SceneSpec, build_model       # the scene such an episode composes: the folder's
    m = build_model(SceneSpec(robot=str(folder)))                # floor friction
    assert m.geom_friction[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "floor"), 0] == pytest.approx(0.6)


def test_robot_folder_path_relative_to_the_scenario_file(tmp_path, monkeypatch):
    """A relative [robot] model names a robot folder relative to the scenario file's folder (as a relative
    robot_profile_base does), not to the working directory: the same file loads from any directory, and a path
    that is not there is one UserError naming the file, the field and the path it looked at."""
    import tomli_w

    from bigcbf.params.toml_io import load_toml
    from bigcbf.scenario import load_scenario, resolve_path
    scenes = tmp_path / "scenes"
    mf.write_robot_folder(mf.model_with("rosmaster_x3", {}), scenes / "robots" / "my_x3")
    raw = load_toml(resolve_path("required_sidestepping"))
    raw["robot"]["model"] = "robots/my_x3"
    scen = scenes / "scen.toml"
    scen.write_bytes(tomli_w.dumps(raw).encode())
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    sc = load_scenario(str(scen))
    assert Path(sc.robot.model).resolve() == (scenes / "robots" / "my_x3").resolve()
    raw["robot"]["model"] = "robots/not_there"
    scen.write_bytes(tomli_w.dumps(raw).encode())
    with pytest.raises(UserError) as err:
        load_scenario(str(scen))
    msg = str(err.value)
    assert "\n" not in msg and str(scen) in msg and "model" in msg and "scenes/robots/not_there" in msg


def test_ensemble_members_are_the_model_with_its_wheels_turned(tmp_path):
    """twin.model_fit.ensemble_bins: a member with the wheels not turned is simulate_bins itself, to the bit; members
    with turned wheels are the same drive (vx within a few cm/s per bin) with another draw of the contact's yaw
    jitter; the problem's own initial state is left as it was."""
    log = tmp_path / "d.mcap"
    record_calibration(RobotProfile(), log, seed=4, duration_s=7.0)
    data, _, _ = prepare(read_log(log, use_scan=False), CalibrationOptions().timebase)
    pb = mf.problem(data, RobotProfile(), "rosmaster_x3", FAST)
    params = mf.parameters("rosmaster_x3")
    own = np.array(pb.initial_state, copy=True)
    alone = mf.simulate_bins(pb, params)
    ens = mf.ensemble_bins(pb, params, np.array([[0.0, 0.0, 0.0, 0.0], [0.3, 1.1, 2.0, 0.7], [2.5, 0.2, 1.3, 3.0]]))
    assert ens.shape == (3,) + alone.shape
    np.testing.assert_array_equal(ens[0], alone)
    np.testing.assert_array_equal(pb.initial_state, own)
    assert np.max(np.abs(ens[1:, :, 0] - alone[:, 0])) < 0.05
    assert np.sqrt(np.mean((ens[1, :, 2] - ens[2, :, 2]) ** 2)) > 1e-4


@pytest.mark.slow
def test_identifiability_script_resolves_damping_not_gain(tmp_path):
    """scripts/twin_identifiability.py on a short drive: a 10 % change of the wheel damping moves the expected vx
    beyond the ensemble's noise and the log's; the same change of the actuator gain does not (the wheels' time
    constant is about a millisecond, their speed capped by the torque limit and the damping)."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import twin_identifiability as ident
    finally:
        sys.path.pop(0)
    res = ident.measure(ident.HIDDEN, 0.05, 8.0, 7, 2, 0.5, 0.1, tmp_path)
    assert res["channels"] == ["vx", "vy", "wz", "imu wz"] and res["bins"] >= 10
    assert set(res["params"]) == set(mf.PARAMS_NAMES)
    assert res["params"]["wheel_damping"]["resolved"]
    assert not res["params"]["wheel_kv"]["resolved"]
    d = res["params"]["wheel_damping"]
    assert d["effect"][0] >= 2 * res["null"][0] and d["z"][0] >= 2


@pytest.mark.slow
@pytest.mark.parametrize("hidden, cap, kept", [
    ({"wheel_damping": 0.15}, None, False),        # the wheels' torque limit against their damping caps them
    ({"wheel_damping": 0.002}, 0.35, True),        # the firmware clamps them
])
def test_the_log_chooses_what_caps_the_wheels(tmp_path, hidden, cap, kept):
    """twin.model_fit.fit_behind with a wheel-speed cap in the command layer: the model is fitted with and without
    it and the smaller residual is kept, with a note giving both. A cap that is the model's own physics (a damped
    wheel at its torque limit) is left to the model; a firmware's clamp on an undamped robot stays in front."""
    front = RobotProfile(latency_s=0.03, wheel_speed_max_mps=cap)
    d = tmp_path / "hidden"
    mf.write_robot_folder(mf.model_with("rosmaster_x3", hidden, front), d)
    log = tmp_path / "h.mcap"
    record_calibration(front, log, seed=5, duration_s=10.0, robot=str(d))
    data, _, _ = prepare(read_log(log, use_scan=False), CalibrationOptions().timebase)
    # the layer as the calibration reads it: a cap either way
    read = mf.front_of(RobotProfile(latency_s=0.03, wheel_speed_max_mps=cap or 0.3))
    fit = mf.fit_behind(data, read, "rosmaster_x3", FAST)
    note = [n for n in fit.notes if "wheel-speed cap" in n]
    assert len(note) == 1, fit.notes
    without, with_cap = (float(x) for x in re.findall(r"residual is ([0-9.e+-]+), with it ([0-9.e+-]+)", note[0])[0])
    assert (fit.front.wheel_speed_max_mps is not None) == kept, note[0]
    assert fit.cost == pytest.approx(min(without, with_cap), rel=1e-3)
    assert (without <= with_cap) != kept and fit.evaluations > 0
