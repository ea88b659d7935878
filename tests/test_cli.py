"""The command line, called in-process."""
import json

import pytest

from bigcbf.cli import main


def test_perf_json_has_the_simulator_figures(capsys):
    assert main(["perf", "--json", "--quick", "--only", "bigcbf.sim.perf"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["physics_steps_per_s"] > 1000 and 0 < out["lidar_scan_ms"] < 50


def test_perf_episode_and_its_own_bare_physics_from_one_run(capsys):
    """The episode's real-time factor, the bare physics of the same compiled model measured in the same run, and
    their ratio (a figure of speed: only its consistency is checked, never a wall-clock limit)."""
    assert main(["perf", "--json", "--quick", "--only", "bigcbf.episode_perf"]) == 0
    out = json.loads(capsys.readouterr().out)
    ep, phys = out["episode_realtime_factor"], out["episode_physics_realtime_factor"]
    assert ep > 0 and phys > 0 and out["episode_sim_time_s"] > 1.0
    assert out["episode_physics_ratio"] == pytest.approx(ep / phys, rel=0.02, abs=2e-3)
    replay = out["episode_replay_realtime_factor"]           # the same run's own physics, replayed without the stack
    assert replay > 0 and out["episode_replay_ratio"] == pytest.approx(ep / replay, rel=0.02, abs=2e-3)


def test_unknown_subcommand_and_bad_argument_exit_2(capsys):
    assert main(["no-such-command"]) == 2
    assert main(["perf", "--bogus"]) == 2


def test_demo_prints_commanded_and_achieved(capsys):
    assert main(["demo", "--manoeuvre", "--no-video"]) == 0
    out = capsys.readouterr().out
    assert "forward" in out and "spin" in out
    fwd = next(line for line in out.splitlines() if line.startswith("forward")).split()
    assert abs(float(fwd[4]) - 0.5) < 0.025      # achieved vx within 5 % of the commanded 0.5 m/s


@pytest.mark.parametrize("argv, message", [
    (["run", "required_sidestepping", "--seed", "-1"], "argument --seed: expected a seed in [0, 4294967295], got -1"),
    (["run", "required_sidestepping", "--seed", "1.5"], "argument --seed: expected a whole number, got '1.5'"),
    (["record", "calibration", "--robot-profile", "x3_sim", "--out", "o.mcap", "--duration", "inf"],
     "argument --duration: expected a finite number, got 'inf'"),
    (["record", "calibration", "--robot-profile", "x3_sim", "--out", "o.mcap", "--duration", "0"],
     "argument --duration: expected a number > 0, got 0"),
    (["calibrate", "log.mcap", "--coverage", "1.2"], "argument --coverage: expected a coverage in [0.5, 1), got 1.2"),
    (["perf", "--only", "bigcbf.nope"], "--only: unknown provider(s) bigcbf.nope; known: bigcbf.sim.perf"),
])
def test_bad_numbers_are_one_usage_error_naming_the_option(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
