"""bigcbf record / calibrate / replay end to end, and the layering rules of the twin and log I/O."""
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

import bigcbf
from bigcbf.cli import main


@pytest.fixture(scope="module")
def short_drive(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    robot = d / "robot.toml"
    robot.write_text("latency_s = 0.05\ngain = [[0.9, 0, 0], [0, 0.9, 0], [0, 0, 0.9]]\n")
    log = d / "drive.mcap"
    assert main(["record", "calibration", "--robot-profile", str(robot), "--out", str(log), "--seed", "1",
                 "--duration", "30"]) == 0
    return d, log


def test_record_calibrate_replay(short_drive, capsys):
    d, log = short_drive
    capsys.readouterr()
    prof, rep = d / "profile.toml", d / "report"
    assert main(["calibrate", str(log), "--out", str(prof), "--report", str(rep), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["identified"] == {"vx": True, "vy": True, "wz": True}
    assert out["A"][0][0] == pytest.approx(0.9, rel=0.05)
    assert sorted(p.name for p in rep.iterdir()) == ["calibration.json", "command_response.png", "delay.png",
                                                     "index.md", "limits.png", "residuals.png"]
    # the command-to-wheel latency per axis, with its interval (the profile's 0.05 s on the model's own response)
    assert set(out["latency_s"]) == {"vx", "vy", "wz"}
    for a in ("vx", "vy", "wz"):
        lat = out["latency_s"][a]
        assert 0.03 < lat["latency"] < 0.12 and lat["ci90"][0] <= lat["latency"] + 1e-9
    assert out["limits"]["wheel_speed_max_mps"] is None
    assert str(prof) in out["written"]
    saved = d / "model.robot.toml"
    assert main(["replay", str(log), "--profile", str(prof), "--json", "--save-robot-profile", str(saved)]) == 0
    res = json.loads(capsys.readouterr().out)
    assert res["runs"]["calibrated"]["drift_mean_m"] < res["runs"]["nominal"]["drift_mean_m"]
    assert any("from the given profile" in n for n in res["notes"])
    # the saved model profile drives a new recording
    assert main(["record", "calibration", "--robot-profile", str(saved), "--out", str(d / "again.mcap"),
                 "--duration", "6"]) == 0


def test_user_mistakes_exit_2_with_one_line(short_drive, capsys):
    d, log = short_drive
    bad = d / "bad_robot.toml"
    bad.write_text("latency_s = -1\n")
    cases = [
        (["record", "calibration", "--robot-profile", str(bad), "--out", str(d / "x.mcap")], "latency_s"),
        (["record", "calibration", "--robot-profile", str(d / "missing.toml"), "--out", str(d / "x.mcap")],
         "file not found"),
        (["replay", str(log), "--profile", str(bad)], "uncertainty.execution"),
        (["calibrate", str(log), "--cmd-topic", "/odom"], "is nav_msgs/msg/Odometry"),
        (["calibrate", str(d)], "metadata.yaml"),
    ]
    for argv, needle in cases:
        capsys.readouterr()
        assert main(argv) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and needle in err[0], (argv, err)
    assert main(["calibrate", str(log), "--coverage", "1.5"]) == 2          # argparse's own message


def test_calibrate_and_log_io_run_without_mujoco():
    """Log I/O and calibration run on a robot: they never import MuJoCo."""
    code = ("import sys, bigcbf.logio, twin.calibrate, twin.report; "
            "bad = [m for m in ('mujoco', 'dm_control', 'bigcbf.sim') if m in sys.modules]; print(bad)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=Path(__file__).resolve().parents[2], check=True)
    assert out.stdout.strip() == "[]"


def test_no_bigcbf_module_imports_twin_except_the_cli():
    pat = re.compile(r"^\s*(from\s+twin[\s.]|import\s+twin\b)", re.M)
    pkg = Path(bigcbf.__file__).parent
    offenders = [str(p.relative_to(pkg)) for p in pkg.rglob("*.py") if pat.search(p.read_text())
                 and p.parent.name != "cli"]
    assert offenders == []
    # and the CLI loads it lazily (inside run), so `bigcbf --help` does not import it
    for name in ("record", "calibrate", "replay"):
        text = (pkg / "cli" / f"{name}.py").read_text()
        top = text.split("\ndef run(")[0]
        assert not pat.search(top), name


def test_twin_api_gives_what_the_commands_print(short_drive, capsys):
    """twin.calibrate_log and twin.replay_log (the Python API) are what bigcbf calibrate and replay run."""
    import twin
    d, log = short_drive
    cal = twin.calibrate_log(log)
    assert isinstance(cal, twin.Calibration)
    capsys.readouterr()
    assert main(["calibrate", str(log), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    mine = cal.to_json()
    assert (mine["A"], mine["d"], mine["tau95_s"], mine["e_zoh_m"]) == (out["A"], out["d"], out["tau95_s"],
                                                                         out["e_zoh_m"])
    prof = twin.write_profile(cal, d / "api_profile.toml")
    rep = twin.replay_log(log, prof)
    assert isinstance(rep, twin.ReplayResult) and set(rep.runs) == {"nominal", "calibrated"}
    assert main(["replay", str(log), "--profile", str(prof), "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    assert rep.to_json()["runs"]["calibrated"]["velocity_rmse"] == cli["runs"]["calibrated"]["velocity_rmse"]


def test_failed_drive_is_one_line_and_leaves_no_log(tmp_path, capsys, monkeypatch):
    """A drive that leaves its room (here a room shrunk to 0.75 m) ends in one error line, exit 2, and neither the
    log nor its temporary file is left behind."""
    import twin.record
    monkeypatch.setattr(twin.record, "ROOM_EXTENT_M", 0.75)
    robot = tmp_path / "robot.toml"
    robot.write_text("")
    out = tmp_path / "drive.mcap"
    capsys.readouterr()
    assert main(["record", "calibration", "--robot-profile", str(robot), "--out", str(out), "--duration", "20"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "left the room's free space" in err[0] and "no log written" in err[0]
    assert list(tmp_path.iterdir()) == [robot]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_drive_stays_in_its_room_with_a_bias(tmp_path, seed):
    """The issue's case: a bias of -0.029 m/s (in range) took the open-loop drive out of its room on 3 of 5 seeds;
    closed loop it comes back between segments."""
    from bigcbf.params.robot import RobotProfile
    from twin.record import ROOM_EXTENT_M, record_calibration
    s = record_calibration(RobotProfile(bias=(-0.029, 0.0, 0.0)), tmp_path / "d.mcap", seed=seed, duration_s=120.0)
    assert s["max_distance_m"] < ROOM_EXTENT_M - 1.5 and s["recentrings"] > 0


def test_drive_stays_in_its_room_at_the_edges_of_the_documented_ranges(tmp_path):
    from bigcbf.params.robot import RobotProfile
    from twin.record import ROOM_EXTENT_M, record_calibration
    worst = RobotProfile(latency_s=0.3, latency_jitter_s=0.05, gain=((1.2, 0.1, 0.1), (0.1, 0.7, -0.1), (-0.1, 0.1, 0.7)),
                         bias=(0.05, -0.05, 0.1), residual_max=(0.05, 0.05, 0.05), floor_friction=0.3,
                         wheel_speed_max_mps=0.3, wheel_accel_max_mps2=0.5)
    s = record_calibration(worst, tmp_path / "d.mcap", seed=3, duration_s=90.0)
    assert s["max_distance_m"] < ROOM_EXTENT_M - 1.5


def test_replay_carries_the_damaged_mcap_note(short_drive, tmp_path, capsys):
    """A log cut short (the recorder crashed): calibrate reads what is whole and says so; replay says it too."""
    _, log = short_drive
    cut = tmp_path / "cut.mcap"
    data = log.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.8)])
    capsys.readouterr()
    assert main(["replay", str(cut), "--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert any("damaged MCAP" in n for n in res["notes"])
    assert set(res["runs"]) == {"nominal", "calibrated"} and "calibrated_worse_on" in res
