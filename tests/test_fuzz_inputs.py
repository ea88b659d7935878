"""Fuzzing every user input (issue 16): scenario files, profiles (stack, robot, perception), logs and the command
line of every subcommand. For any input: no traceback, no hang; a mistake is exit status 2 with one line on stderr
(``bigcbf CMD: error: ...``; informational ``note:`` lines may precede it).

The command line runs in-process (``bigcbf.cli.main``). The work a valid command would start (an episode, a
calibration, a replay, a recording, a bench's engine, a perf provider) is replaced by a stand-in that raises
``Reached``: what is fuzzed is everything a command checks before its work, and reaching the work with a valid
input is a pass. File contents that load are then exercised for real: a loaded scenario is built and stepped in
MuJoCo, a loaded stack profile drives the CBF filter and every planner for a step, a robot profile drives the
simulated robot, perception parameters process a scan.

Every input class of the issue has a row in ``ISSUE_CASES`` (each issue failure, reproduced before the fix, now a
one-line error); the hypothesis tests then mutate valid inputs and combine options at random.
"""
from __future__ import annotations

import contextlib
import io
import json
import math
import os
import signal
import sys
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bigcbf.cli import COMMANDS, EXIT_CLOSED_PIPE, main
from bigcbf.errors import UserError

#: seconds any single input may take before it counts as a hang (the machine is shared: generous)
HANG_S = 30.0


class Reached(Exception):
    """A valid input got through every check to the command's work."""


class Hang(Exception):
    pass


@contextlib.contextmanager
def deadline(seconds: float = HANG_S):
    def on_alarm(signum, frame):
        raise Hang(f"no answer within {seconds} s")
    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _reach(*args, **kwargs):
    raise Reached()


class _ReachEpisode:
    def __init__(self, *args, **kwargs):
        raise Reached()

    @classmethod
    def from_config(cls, *args, **kwargs):
        raise Reached()


@pytest.fixture
def stand_ins(monkeypatch):
    """Replace each command's work by ``_reach`` (module docstring)."""
    import importlib

    import bigcbf.bench.engines
    import bigcbf.bench.report
    import bigcbf.cli.demo
    import bigcbf.episode
    import bigcbf.logio.live
    import twin.calibrate
    import twin.record
    import twin.replay
    from bigcbf.cli.perf import BENCHES

    # every module that binds a name from those patched below is imported first: a module imported for the first
    # time while Episode is the stand-in would keep it after the test (bigcbf.episode_perf: `from .episode import
    # Episode`), and later tests in the same process would run the stand-in
    import bigcbf.gym_env
    import bigcbf.ros2.sim_node
    import bigcbf.video
    benches = [(importlib.import_module(mod), fn) for mod, fn in (spec.split(":") for spec in BENCHES)]
    monkeypatch.setattr(bigcbf.episode, "Episode", _ReachEpisode)
    monkeypatch.setattr(bigcbf.cli.demo, "run_manoeuvre", _reach)
    monkeypatch.setattr(twin.calibrate, "calibrate_series", _reach)
    monkeypatch.setattr(twin.replay, "replay", _reach)
    monkeypatch.setattr(twin.record, "record_calibration", _reach)
    monkeypatch.setattr(bigcbf.bench.engines, "run", _reach)
    monkeypatch.setattr(bigcbf.bench.report, "write_reports", _reach)
    monkeypatch.setattr(bigcbf.logio.live, "LiveWriter", _reach)      # run --live: no server on a real port
    import bigcbf.ros2.transport
    monkeypatch.setattr(bigcbf.ros2.transport, "Node", _reach)         # sim/filter --ros2: no DDS participant
    for mod, fn in benches:
        monkeypatch.setattr(mod, fn, _reach)


def call(argv: list[str]) -> tuple[str, int | None, str, str]:
    """Run ``bigcbf argv`` in-process: (outcome, exit status, stdout, stderr); outcome is "exit", "reached",
    "hang" or "traceback: ..."."""
    out, err = io.StringIO(), io.StringIO()
    try:
        with deadline(), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            status = main(argv)
    except Reached:
        return "reached", None, out.getvalue(), err.getvalue()
    except Hang:
        return "hang", None, out.getvalue(), err.getvalue()
    except SystemExit as exc:          # --help and friends
        return "exit", int(exc.code or 0), out.getvalue(), err.getvalue()
    except BaseException as exc:       # noqa: BLE001 - this is what the test hunts
        import traceback
        return f"traceback: {type(exc).__name__}: {exc}\n{traceback.format_exc()}", None, out.getvalue(), \
            err.getvalue()
    return "exit", status, out.getvalue(), err.getvalue()


def assert_clean(argv, result, *, want_error: bool | None = None) -> None:
    """No traceback, no hang; a nonzero status is 2 with one error line (after optional note: lines)."""
    outcome, status, out, err = result
    assert not outcome.startswith("traceback"), (argv, outcome)
    assert outcome != "hang", argv
    assert "Traceback" not in err, (argv, err)
    if outcome == "reached" or status == 0:
        assert want_error is not True, (argv, outcome, status, err)
        return
    assert want_error is not False, (argv, status, err)
    assert status == 2, (argv, status, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert lines and all(ln.startswith("note:") for ln in lines[:-1]), (argv, err)
    assert lines[-1].startswith("bigcbf") and ": error: " in lines[-1], (argv, err)


# --- the corpus: bad and good files of every kind ----------------------------------------------------------------

SCENARIO = 'name = "fz"\ndescription = "fuzz"\ntime_limit_s = 10\nextent_m = 5\n[robot]\nstart = [0, 0, 0]\n' \
           'goal = [5, 0]\n'


def _peds(n: int) -> str:
    return "".join(f"[[pedestrians]]\nname = 'p{i}'\nwaypoints = [[{20 + i % 100 * 0.7:.1f}, {20 + i // 100 * 0.7:.1f}],"
                   f" [{20.1 + i % 100 * 0.7:.1f}, {20 + i // 100 * 0.7:.1f}]]\nspeed_mps = 1\n" for i in range(n))


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("fuzz")
    files: dict[str, Path] = {}

    def put(name: str, content: str | bytes) -> None:
        p = d / name
        (p.write_bytes if isinstance(content, bytes) else p.write_text)(content)
        files[name] = p

    put("good.toml", SCENARIO)
    put("latin1.toml", ("# caf\xe9\n" + SCENARIO).encode("latin-1"))
    put("binary.toml", bytes(range(256)) * 4)
    put("some.mcap", b"\x89MCAP0\r\n" + bytes(range(256)))
    put("empty.toml", "")
    put("u_nan.toml", SCENARIO + "[[cylinders]]\ncenter = [{ uniform = [nan, 1.2] }, 2]\nradius_m = 0.2\n")
    put("u_inf.toml", SCENARIO + "[[cylinders]]\ncenter = [{ uniform = [0, inf] }, 2]\nradius_m = 0.2\n")
    put("u_big.toml", SCENARIO + "[[cylinders]]\ncenter = [{ uniform = [-1e308, 1e308] }, 2]\nradius_m = 0.2\n")
    put("deep_arr.toml", SCENARIO + "x = " + "[" * 5000 + "]" * 5000 + "\n")
    put("deep_tab.toml", SCENARIO + "x = " + "{a = " * 3000 + "1" + "}" * 3000 + "\n")
    put("extent_huge.toml", SCENARIO.replace("extent_m = 5", "extent_m = 1e300"))
    put("extent_neg.toml", SCENARIO.replace("extent_m = 5", "extent_m = -3"))
    put("peds10k.toml", SCENARIO + _peds(10_000))
    put("time_limit.toml", SCENARIO.replace("time_limit_s = 10", "time_limit_s = 1e6")
        + "[[walls]]\nstart = [3, -20]\nend = [3, 20]\n")
    put("start_in_wall.toml", SCENARIO + "[[walls]]\nstart = [0, -2]\nend = [0, 2]\n")
    put("start_on_ped.toml", SCENARIO + "[[pedestrians]]\nname = 'a'\nwaypoints = [[0.2, 0], [3, 3]]\nspeed_mps = 1\n")
    put("goal_in_obstacle.toml", SCENARIO + "[[cylinders]]\ncenter = [5, 0]\nradius_m = 0.5\n")
    put("low_box.toml", SCENARIO + "[[boxes]]\ncenter = [3, 1]\nhalf_size = [0.2, 0.2]\nheight_m = 0.02\n")
    put("far_wall.toml", SCENARIO + "[[walls]]\nstart = [1e5, 0]\nend = [1e5, 1]\n")
    put("profile_latin1.toml", "# caf\xe9\n[uncertainty]\ntau95_s = 0.1\n".encode("latin-1"))
    put("profile_deep.toml", "x = " + "[" * 5000 + "]" * 5000 + "\n")
    put("profile_nan.toml", "[uncertainty]\ntau95_s = nan\n")
    put("profile_huge.toml", "alpha_per_s = 1e308\n")
    put("profile_tc.toml", "T_C_s = 1e-9\n")
    put("profile_n.toml", "N = 100000000\n")
    put("profile_unknown.toml", "[uncertainty]\ntau_95 = 0.1\n")
    put("robot_latin1.toml", "# caf\xe9\nlatency_s = 0.1\n".encode("latin-1"))
    put("robot_bad.toml", "latency_s = -1\ngain = [[1, 0], [0, 1]]\n")
    put("robot_good.toml", "latency_s = 0.05\n")
    put("docs_nomarkers.md", "# results\n")
    put("docs_latin1.md", "caf\xe9 <!-- bench-results:begin -->\n<!-- bench-results:end -->\n".encode("latin-1"))
    put("truncated.mcap", b"\x89MCAP0\r\n" + b"\x01" * 64)
    put("not_a_bag.bag", b"#ROSBAG V2.0\n" + b"\x00" * 32)
    put("a_file", "x")
    from bigcbf.logio import LogWriter
    from bigcbf.types import RobotState
    with LogWriter(d / "drive.mcap") as w:            # a small valid log: 4 s of commands and odometry
        for k in range(80):
            t = 0.05 * k
            w.cmd_vel(t, (0.2 * (k // 20 % 2), 0.0, 0.0))
            w.odom(t, RobotState(0.01 * k, 0.0, 0.0, 0.2 * (k // 20 % 2)))
    files["drive.mcap"] = d / "drive.mcap"
    (d / "a_dir").mkdir()
    files["a_dir"] = d / "a_dir"
    files["missing"] = d / "missing.toml"
    files["ro"] = _readonly_dir()
    files["root"] = d
    return files


def _readonly_dir() -> Path:
    """A folder nobody can create files in (root included): /sys on Linux."""
    return Path("/sys")


def _writable(p: Path) -> bool:
    try:
        (p / ".bigcbf-w").touch()
    except OSError:
        return False
    (p / ".bigcbf-w").unlink()
    return True


# --- every input class of the issue, each reproduced before the fix ----------------------------------------------

def ISSUE_CASES(f: dict[str, Path]) -> list[tuple[str, list[str]]]:
    ro, root = f["ro"], f["root"]
    long_name = str(root / ("x" * 300 + ".mp4"))
    return [
        ("Latin-1 scenario", ["run", str(f["latin1.toml"])]),
        ("binary scenario", ["run", str(f["binary.toml"])]),
        ("MCAP given as scenario", ["run", str(f["some.mcap"])]),
        ("empty scenario", ["run", str(f["empty.toml"])]),
        ("Latin-1 --profile", ["run", "required_sidestepping", "--profile", str(f["profile_latin1.toml"])]),
        ("Latin-1 --robot-profile", ["record", "calibration", "--robot-profile", str(f["robot_latin1.toml"]),
                                     "--out", str(root / "x.mcap")]),
        ("uniform [nan, 1.2]", ["run", str(f["u_nan.toml"])]),
        ("uniform [0, inf]", ["run", str(f["u_inf.toml"])]),
        ("uniform [-1e308, 1e308]", ["run", str(f["u_big.toml"])]),
        ("deeply nested arrays", ["run", str(f["deep_arr.toml"])]),
        ("deeply nested tables", ["run", str(f["deep_tab.toml"])]),
        ("deeply nested profile", ["run", "required_sidestepping", "--profile", str(f["profile_deep.toml"])]),
        ("extent_m = 1e300", ["run", str(f["extent_huge.toml"])]),
        ("negative extent", ["run", str(f["extent_neg.toml"])]),
        ("10,000 pedestrians", ["run", str(f["peds10k.toml"])]),
        ("time_limit_s = 1e6", ["run", str(f["time_limit.toml"])]),
        ("start inside a wall", ["run", str(f["start_in_wall.toml"])]),
        ("start on a pedestrian", ["run", str(f["start_on_ped.toml"])]),
        ("goal inside an obstacle", ["run", str(f["goal_in_obstacle.toml"])]),
        ("obstacle lower than the bumper", ["run", str(f["low_box.toml"])]),
        ("coordinates beyond the world", ["run", str(f["far_wall.toml"])]),
        ("NaN in a profile", ["run", "required_sidestepping", "--profile", str(f["profile_nan.toml"])]),
        ("1e308 in a profile", ["run", "required_sidestepping", "--profile", str(f["profile_huge.toml"])]),
        ("T_C_s = 1e-9", ["run", "required_sidestepping", "--profile", str(f["profile_tc.toml"])]),
        ("N = 1e8", ["run", "required_sidestepping", "--profile", str(f["profile_n.toml"])]),
        ("unknown profile key", ["run", "required_sidestepping", "--profile", str(f["profile_unknown.toml"])]),
        ("bad robot profile", ["record", "calibration", "--robot-profile", str(f["robot_bad.toml"]), "--out",
                               str(root / "x.mcap")]),
        ("--video on a read-only file system", ["run", "required_sidestepping", "--video", str(ro / "v.mp4")]),
        ("--video /dev/full", ["run", "required_sidestepping", "--video", "/dev/full"]),
        ("--video is a folder", ["run", "required_sidestepping", "--video", str(f["a_dir"])]),
        ("--video under a file", ["run", "required_sidestepping", "--video", str(f["a_file"] / "v.mp4")]),
        ("--video name too long", ["run", "required_sidestepping", "--video", long_name]),
        ("--log on a read-only file system", ["run", "required_sidestepping", "--log", str(ro / "x.mcap")]),
        ("demo --video read-only", ["demo", "--video", str(ro / "d.mp4")]),
        ("record --out read-only", ["record", "calibration", "--robot-profile", str(f["robot_good.toml"]),
                                    "--out", str(ro / "x.mcap")]),
        ("record --duration 1e9", ["record", "calibration", "--robot-profile", str(f["robot_good.toml"]),
                                   "--out", str(root / "x.mcap"), "--duration", "1e9"]),
        ("bench --out read-only", ["bench", "--out", str(ro / "b"), "--scenarios", str(f["good.toml"]),
                                   "--methods", "cbf-only", "--seeds", "1"]),
        ("bench --out read-only existing", ["bench", "--out", str(ro), "--scenarios", str(f["good.toml"]),
                                            "--methods", "cbf-only", "--seeds", "1"]),
        ("bench --report-only read-only", ["bench", "--out", str(ro), "--report-only", "--scenarios",
                                           str(f["good.toml"]), "--methods", "cbf-only", "--seeds", "1"]),
        ("bench --out is a file", ["bench", "--out", str(f["a_file"]), "--seeds", "1"]),
        ("bench --seeds 100000000", ["bench", "--out", str(root / "b1"), "--seeds", "100000000"]),
        ("bench --seed-list huge", ["bench", "--out", str(root / "b2"), "--seed-list", "9" * 25]),
        ("bench --workers 0", ["bench", "--out", str(root / "b3"), "--workers", "0"]),
        ("bench --workers huge", ["bench", "--out", str(root / "b4"), "--workers", "1000000"]),
        ("bench --docs without markers", ["bench", "--out", str(root / "b5"), "--docs", str(f["docs_nomarkers.md"]),
                                          "--scenarios", str(f["good.toml"]), "--methods", "cbf-only",
                                          "--seeds", "1"]),
        ("bench --docs Latin-1", ["bench", "--out", str(root / "b6"), "--docs", str(f["docs_latin1.md"]),
                                  "--scenarios", str(f["good.toml"]), "--methods", "cbf-only", "--seeds", "1"]),
        ("bench --docs missing", ["bench", "--out", str(root / "b7"), "--docs", str(f["missing"]),
                                  "--scenarios", str(f["good.toml"]), "--methods", "cbf-only", "--seeds", "1"]),
        ("bench bad scenario", ["bench", "--out", str(root / "b8"), "--scenarios", str(f["start_in_wall.toml"]),
                                "--methods", "cbf-only", "--seeds", "1"]),
        ("calibrate --report read-only", ["calibrate", str(f["some.mcap"]), "--report", str(ro / "rep")]),
        ("calibrate --out read-only", ["calibrate", str(f["truncated.mcap"]), "--out", str(ro / "p.toml")]),
        ("calibrate a binary file", ["calibrate", str(f["some.mcap"])]),
        ("calibrate a truncated MCAP", ["calibrate", str(f["truncated.mcap"])]),
        ("calibrate a broken bag", ["calibrate", str(f["not_a_bag.bag"])]),
        ("calibrate a TOML file", ["calibrate", str(f["good.toml"])]),
        ("calibrate a folder", ["calibrate", str(f["a_dir"])]),
        ("replay --save-robot-profile read-only", ["replay", str(f["truncated.mcap"]), "--save-robot-profile",
                                                   str(ro / "r.toml")]),
        ("replay --video read-only", ["replay", str(f["truncated.mcap"]), "--video", str(ro / "r.mp4")]),
        ("replay --profile Latin-1", ["replay", str(f["truncated.mcap"]), "--profile",
                                      str(f["profile_latin1.toml"])]),
        ("seed beyond 32 bits", ["run", "required_sidestepping", "--seed", "9" * 30]),
        ("seed nan", ["run", "required_sidestepping", "--seed", "nan"]),
        ("unknown method", ["run", "required_sidestepping", "--method", "teleport"]),
        ("unknown subcommand", ["teleport"]),
        ("perf --only unknown", ["perf", "--only", "nope"]),
        ("empty --out", ["bench", "--out", ""]),
        ("empty --video", ["run", "required_sidestepping", "--video", ""]),
    ]


def test_every_issue_input_class_is_one_line_exit_2(corpus, stand_ins, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert not _writable(corpus["ro"]), "needs a folder nobody can write in"
    results = {}
    for name, argv in ISSUE_CASES(corpus):
        res = call(argv)
        results[name] = res
        assert_clean(argv, res, want_error=True)
    print(f"fuzz: {len(results)} issue cases, each one line and exit 2")
    if os.environ.get("BIGCBF_FUZZ_SHOW"):
        for name, r in results.items():
            print(f"  {name:40s} {r[3].strip().splitlines()[-1]}")
    # the errors name the file, and the field where there is one
    err = {name: r[3] for name, r in results.items()}
    assert str(corpus["latin1.toml"]) in err["Latin-1 scenario"] and "UTF-8" in err["Latin-1 scenario"]
    assert "'cylinders[0].center[0]'" in err["uniform [nan, 1.2]"]
    assert "'extent_m'" in err["extent_m = 1e300"] and "'extent_m'" in err["negative extent"]
    assert "'pedestrians'" in err["10,000 pedestrians"] and "'time_limit_s'" in err["time_limit_s = 1e6"]
    assert "'robot.start'" in err["start inside a wall"] and "walls[0]" in err["start inside a wall"]
    assert "pedestrians[0]" in err["start on a pedestrian"]
    assert "'robot.goal'" in err["goal inside an obstacle"] and "cylinders[0]" in err["goal inside an obstacle"]
    assert "'boxes[0].height_m'" in err["obstacle lower than the bumper"]
    assert "'T_C_s'" in err["T_C_s = 1e-9"] or "T_C_s" in err["T_C_s = 1e-9"]
    assert "bench-results:begin" in err["bench --docs without markers"]


def test_a_closed_stdout_ends_quietly(monkeypatch):
    """``bigcbf scenarios | head -1``: the reader closes the pipe; no traceback, exit status 141."""
    r, w = os.pipe()
    os.close(r)
    stream = os.fdopen(w, "w", buffering=1)
    monkeypatch.setattr(sys, "stdout", stream)
    old = signal.signal(signal.SIGPIPE, signal.SIG_IGN)   # Python's default: EPIPE as BrokenPipeError
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            status = main(["scenarios"])
    finally:
        signal.signal(signal.SIGPIPE, old)
        monkeypatch.undo()
        with contextlib.suppress(OSError):
            stream.close()
    assert status == EXIT_CLOSED_PIPE and err.getvalue() == ""


def test_json_is_strict_and_episode_metrics_are_consistent(tmp_path, capsys):
    """--json prints no Infinity (min_clearance_m of a scene without obstacles is null); stopped time is within
    the simulated time; no negative clearance without a collision."""
    f = tmp_path / "open.toml"
    f.write_text(SCENARIO.replace("time_limit_s = 10", "time_limit_s = 1"))
    assert main(["run", str(f), "--method", "cbf-only", "--json"]) == 0
    text = capsys.readouterr().out

    def no_constants(name):
        raise AssertionError(f"non-strict JSON constant {name}")
    out = json.loads(text, parse_constant=no_constants)
    assert out["min_clearance_m"] is None
    assert 0 <= out["stopped_time_s"] <= out["sim_time_s"]


# --- random command lines ------------------------------------------------------------------------------------------

NUMBERS = ["-1", "0", "1", "2", "1.5", "nan", "inf", "-inf", "1e400", "9" * 25, "0x10", "", " ", "1e-9", "600",
           "100000000", "\u00e9", "\udce9"]


def _pools(f: dict[str, Path]) -> dict[str, list[str]]:
    root, ro = f["root"], f["ro"]
    files = [str(p) for k, p in f.items() if k not in ("root",)]
    outs = [str(root / "o" / "x.mp4"), str(root / "o2.mcap"), str(root / "o3.toml"), str(ro / "x"), "/dev/full",
            str(f["a_dir"]), str(f["a_file"] / "x"), str(root / ("y" * 300)), str(root / "\udce9.mp4"), ""]
    return {"file": files, "out": outs, "num": NUMBERS,
            "word": ["big-cbf", "cbf-only", "mppi", "teleport", "lidar", "truth", "local", "ray", "top", "track",
                     "paper", "nope", "auto", "stamps", "log", "on", "off", "--", "-x", "calibration",
                     "required_sidestepping", "single_person_crossing", "bigcbf.sim.perf", "/cmd_vel", "generated",
                     "hardware", "dev", "test", "physical", "simulation", "x3_sim", "my.module:Nope", ""]}


#: per subcommand: positional slots and options with the kind of value they take (None: a flag)
CLI = {
    "scenarios": ([], {}),                 # its `generate` action: see command_lines
    "methods": ([], {"--json": None}),
    "run": (["scenario"], {"--method": "word", "--seed": "num", "--config": "file", "--profile": "file",
                           "--perception": "word", "--video": "out", "--camera": "word", "--log": "out",
                           "--live": "num", "--json": None, "--robot-profile": "file", "--time-limit": "num",
                           "--live-wait": "num", "--route": "word"}),
    "demo": ([], {"--seed": "num", "--video": "out", "--no-video": None, "--manoeuvre": None}),
    "perf": ([], {"--json": None, "--quick": None, "--only": "word"}),
    "record": (["what"], {"--robot-profile": "file", "--out": "out", "--seed": "num", "--duration": "num",
                          "--json": None}),
    "calibrate": (["log"], {"--out": "out", "--json": None, "--report": "out", "--cmd-topic": "word",
                            "--odom-topic": "word", "--scan-topic": "word", "--no-scan": None, "--scan-clock": "word",
                            "--cmd-timeout": "num", "--coverage": "num", "--model": "out", "--robot": "word"}),
    "replay": (["log"], {"--profile": "file", "--video": "out", "--json": None, "--fit": None, "--window": "num",
                         "--cmd-topic": "word", "--odom-topic": "word", "--save-robot-profile": "out",
                         "--model": None, "--robot": "file", "--holdout": "num"}),
    "profile": (["what"], {"--robot-profile": "file", "--out": "out", "--seed": "num", "--duration": "num",
                           "--base": "word", "--log": "out", "--json": None}),
    "bench": ([], {"--out": "out", "--methods": "word", "--suite": "word", "--scenarios": "file", "--split": "word",
                   "--seeds": "num", "--seed-list": "num", "--workers": "num", "--engine": "word",
                   "--ray-address": "word", "--config": "file", "--profile": "file", "--perception": "word",
                   "--report-only": None, "--docs": "file", "--progress": "word", "--route": "word",
                   "--variant": "word", "--world-seeds": "num"}),
    "sim": (["scenario"], {"--ros2": None, "--domain-id": "num", "--loopback": None, "--lockstep": None,
                           "--seed": "num", "--config": "file", "--robot-profile": "file", "--time-limit": "num",
                           "--speed": "num", "--cmd-timeout": "num", "--wait": "num", "--json": None}),
    "filter": ([], {"--ros2": None, "--domain-id": "num", "--loopback": None, "--lockstep": None, "--method": "word",
                    "--profile": "file", "--seed": "num", "--goal": "word", "--scan-topic": "word",
                    "--odom-topic": "word", "--cmd-topic": "word", "--cmd-in-topic": "word", "--goal-topic": "word",
                    "--stamped": None, "--markers": None, "--scan-timeout": "num", "--odom-timeout": "num",
                    "--overrun-ms": "num", "--idle-exit": "num", "--json": None}),
    "tune": ([], {"--out": "out", "--methods": "word", "--workers": "num", "--grid": "file", "--configs": "num",
                  "--families": "word", "--world-seeds": "num", "--time-limit": "num", "--write-shipped": None,
                  "--progress": "word"}),
}
#: `bigcbf scenarios generate`'s options
GENERATE = {"--seed": "num", "--out": "out", "--force": None, "--list": None}


def test_the_fuzzer_knows_every_subcommand_and_option():
    from bigcbf.cli import build_parser
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert sorted(CLI) == sorted(COMMANDS)
    for name, (_, options) in CLI.items():
        known = {o for a in sub.choices[name]._actions for o in a.option_strings} - {"-h", "--help"}
        assert known == set(options), name


@st.composite
def command_lines(draw, pools):
    cmd = draw(st.sampled_from(sorted(CLI)))
    positionals, options = CLI[cmd]
    argv = [cmd]
    for slot in positionals:
        if draw(st.integers(0, 9)) == 0:
            continue                                          # a missing positional
        good = pools["good_" + slot]                           # valid half the time, so that some inputs pass
        kind = {"scenario": st.sampled_from(pools["file"] + ["required_sidestepping", "nope", ""]),
                "what": st.sampled_from(["calibration", "simulate", "nope"]),
                "log": st.sampled_from(pools["file"])}[slot]
        kind = st.one_of(st.sampled_from(good), kind) if good else kind
        argv.append(draw(kind))
    if cmd == "scenarios" and draw(st.booleans()):            # the generate action, with a family or not
        argv += ["generate"] + draw(st.lists(st.sampled_from(["posts", "crowd", "nope", ""]), max_size=1))
        options = GENERATE
    if cmd == "bench" and draw(st.booleans()):                # keep most benches small: one scenario, one method
        argv += ["--scenarios", str(pools["file"][0]), "--methods", "cbf-only", "--seeds", "1"]
    if cmd == "tune" and draw(st.booleans()):                 # keep most searches small: one method, world, config
        argv += ["--methods", "cbf-only", "--configs", "0", "--families", "posts", "--world-seeds", "0"]
    if cmd == "record" and draw(st.booleans()):               # its two required options, valid
        argv += ["--robot-profile", pools["good_robot"][0], "--out", pools["out"][1]]
    for opt in draw(st.lists(st.sampled_from(sorted(options) or ["--help"]), max_size=4)):
        kind = options.get(opt)
        argv.append(opt)
        if kind is not None:
            argv.append(draw(st.sampled_from(pools[kind])))
    return argv


def test_random_command_lines(corpus, stand_ins, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)            # relative defaults (renders/) land here, not in the checkout
    pools = _pools(corpus)
    pools["file"].insert(0, str(corpus["good.toml"]))
    pools.update(good_scenario=[str(corpus["good.toml"]), "single_person_crossing"],
                 good_log=[str(corpus["drive.mcap"])], good_what=["calibration"],
                 good_robot=[str(corpus["robot_good.toml"])])
    seen: dict[str, int] = {}

    @settings(max_examples=250, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                     HealthCheck.function_scoped_fixture])
    @given(command_lines(pools))
    def check(argv):
        res = call(argv)
        key = (argv[0], "error" if res[1] == 2 else res[0] if res[0] != "exit" else f"exit {res[1]}")
        seen[key] = seen.get(key, 0) + 1
        assert_clean(argv, res)

    check()
    print("fuzz: command lines", dict(sorted(seen.items())))
    assert {cmd for cmd, _ in seen} == set(CLI), seen


# --- random file contents ------------------------------------------------------------------------------------------

WEIRD_VALUES = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 1e300, -1.0, 0.0, 1e-300, 2**63, -2**63, 10**30,
                     True, "x", "", "\u00e9", [], {}, [[]], [1, 2, 3], {"uniform": [1, 0]}, {"choice": []},
                     {"uniform": [math.nan, 1]}, {"choice": [1, "a"]}, {"uniform": [0, 1], "choice": [1]}]),
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**12, 10**12), st.text(max_size=8),
    st.lists(st.floats(-1e3, 1e3), max_size=4))


def _fuzzer():
    """scripts/fuzz_inputs.py (the real-work fuzzer), whose TOML-tree helpers this stand-in fuzzer shares."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("fuzz_inputs", Path(__file__).resolve().parents[1] / "scripts"
                                                  / "fuzz_inputs.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("fuzz_inputs", mod)
    spec.loader.exec_module(mod)
    return mod


_FZ = _fuzzer()
_leaves, _parent = _FZ._leaves, _FZ._parent


@st.composite
def mutated(draw, base: dict):
    """``base`` with a few random edits: a leaf replaced by a weird value, a key removed or added, a list
    multiplied."""
    import copy
    doc = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _leaves(doc) if p]
        op = draw(st.sampled_from(["set", "set", "set", "delete", "add", "grow"]))
        path = draw(st.sampled_from(paths)) if paths else None
        if path is None:
            doc[draw(st.text(min_size=1, max_size=6))] = draw(WEIRD_VALUES)
            continue
        parent = _parent(doc, path)
        if op == "set":
            parent[path[-1]] = draw(WEIRD_VALUES)
        elif op == "delete":
            del parent[path[-1]]
        elif op == "add":
            if isinstance(parent, dict):
                parent[draw(st.sampled_from(["x", "radius", "seed", "file", "name", "waypoints"]))] = \
                    draw(WEIRD_VALUES)
        else:
            leaf = parent[path[-1]]
            if isinstance(leaf, list) and leaf:
                parent[path[-1]] = leaf * draw(st.sampled_from([2, 50, 300]))
    return doc


def _write_toml(path: Path, doc: dict) -> bool:
    try:
        text = tomli_w.dumps(doc)
    except (TypeError, ValueError):          # not representable in TOML (e.g. an empty key): nothing to test
        return False
    path.write_text(text)
    return True


#: the robot profile's fault keys (bigcbf/params/faults.py), with events early enough to happen in the fuzz's steps
FAULTS_TABLE = {"scan_dropout": {"times_s": [0.0], "rate_per_s": 5.0, "duration_s": 0.1},
                "latency_spikes": {"times_s": [0.05], "rate_per_s": 5.0, "duration_s": 0.1},
                "blanked_sectors_deg": [[0.0, 30.0], [120.0, 45.0]]}

BASE_SCENARIO = {
    "name": "fz", "description": "fuzz", "time_limit_s": 10.0, "extent_m": 5.0,
    "robot": {"start": [0.0, 0.0, 0.0], "goal": [5.0, 0.0]},
    "walls": [{"start": [-1.0, 1.5], "end": [7.0, 1.5]}],
    "boxes": [{"center": [2.5, -1.0], "half_size": [0.3, 0.2], "yaw_rad": 0.3}],
    "cylinders": [{"center": [3.5, 0.8], "radius_m": {"uniform": [0.15, 0.3]}}],
    "pedestrians": [{"name": "a", "waypoints": [[4.0, -3.0], [4.0, 3.0]], "speed_mps": {"uniform": [0.8, 1.2]},
                     "start_time_s": 1.0, "stop": {"times_s": [0.05], "rate_per_s": 2.0, "duration_s": 0.05},
                     "turn": {"rate_per_s": 5.0, "duration_s": 0.02, "angle_deg": 90.0, "random_side": True}}],
    "floor_patches": [{"center": [1.0, 0.0], "half_size": [0.5, 0.5], "friction": 0.4}],
    "draws_as": "other",
    "robot_profile": {"latency_s": 0.05, "faults": FAULTS_TABLE},
}


def test_random_scenario_files(tmp_path):
    """A mutated scenario either loads (and then builds and steps in MuJoCo, with a LiDAR scan) or is a
    UserError naming the file; nothing else."""
    from bigcbf.scenario import load_scenario
    from bigcbf.sim.world import SimWorld
    path = tmp_path / "fz.toml"
    counts = {"loaded": 0, "refused": 0}

    @settings(max_examples=150, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(mutated(BASE_SCENARIO), st.integers(0, 3))
    def check(doc, seed):
        if not _write_toml(path, doc):
            return
        with deadline():
            try:
                sc = load_scenario(path, seed)
            except UserError as err:
                assert str(path) in str(err) and "\n" not in str(err)
                counts["refused"] += 1
                return
            world = SimWorld(sc.scene(), profile=sc.robot_profile, seed=seed)
            world.command((0.3, 0.0, 0.0))
            world.step(50)
            world.scan()
            world.command((0.3, 0.0, 0.0))
            world.step(50)
            world.scan()
            if sc.pedestrians:          # the pedestrians' stops and turns
                from bigcbf.sim.pedestrians import Pedestrians
                peds = Pedestrians([p.waypoints for p in sc.pedestrians], [p.speed_mps for p in sc.pedestrians],
                                   [p.start_time_s for p in sc.pedestrians], [p.radius_m for p in sc.pedestrians],
                                   [p.loop for p in sc.pedestrians], [p.reactive for p in sc.pedestrians],
                                   stops=[p.stop for p in sc.pedestrians], turns=[p.turn for p in sc.pedestrians],
                                   seed=seed)
                for k in range(20):
                    peds.step(1.0 + 0.02 * k, 0.02)
                assert np.isfinite(peds.p).all()
            counts["loaded"] += 1

    check()
    print("fuzz: scenario files", counts)
    assert counts["loaded"] > 5 and counts["refused"] > 50, counts


def _stack_base() -> dict:
    from bigcbf.params.stack import SIMULATION
    from bigcbf.params.toml_io import to_dict
    return to_dict(SIMULATION)


def test_random_stack_profiles(tmp_path):
    """A mutated stack profile either loads (then the CBF filter and every planner take one step with finite
    commands inside the actuator box) or is a UserError naming the file."""
    from bigcbf.control.cbf import CbfFilter
    from bigcbf.control.methods import METHODS
    from bigcbf.params.stack import load_stack_params
    from bigcbf.types import Obstacles, RobotState
    path = tmp_path / "stack.toml"
    obstacles = Obstacles.from_lists([[1.0, 0.1], [2.0, -0.5]], v=[[0.0, 0.0], [-0.5, 0.3]], r=[0.2, 0.25],
                                     cov=np.eye(2) * 0.01)
    state, goal = RobotState(0.0, 0.0, 0.1, 0.2, 0.0, 0.0), np.array([5.0, 0.0])
    counts = {"loaded": 0, "refused": 0}

    @settings(max_examples=60, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(mutated(_stack_base()))
    def check(doc):
        if not _write_toml(path, doc):
            return
        with deadline():
            try:
                params = load_stack_params(path)
            except UserError as err:
                assert str(path) in str(err) and "\n" not in str(err)
                counts["refused"] += 1
                return
            lo, hi = np.asarray(params.u_min), np.asarray(params.u_max)
            for name in METHODS.names():
                planner = METHODS.get(name)(params)
                planner.reset(0)
                u_in, _ = planner.plan(0.0, state, obstacles, goal)
                assert np.isfinite(u_in).all(), name
                u, _ = CbfFilter(params).filter(state, obstacles, u_in)
                assert np.isfinite(u).all() and (u >= lo - 1e-9).all() and (u <= hi + 1e-9).all(), name
            counts["loaded"] += 1

    check()
    print("fuzz: stack profiles", counts)
    assert counts["loaded"] > 5 and counts["refused"] > 10, counts


def test_random_robot_profiles_and_perception_params(tmp_path):
    """Mutated robot profiles (loaded by ``params.toml_io.load``, as ``--robot-profile`` does) and perception
    parameters (a table, as scenario and profile files hold them): loaded ones drive the simulated robot / process
    a LiDAR scan; the rest are UserErrors naming the file."""
    from bigcbf.params.perception import PerceptionParams
    from bigcbf.params.robot import RobotProfile
    from bigcbf.params.toml_io import from_dict, load, to_dict
    from bigcbf.perception.pipeline import Perception
    from bigcbf.sim.scene import Cylinder, open_room
    from bigcbf.sim.world import SimWorld

    world0 = SimWorld(open_room(3.0))
    scene = open_room(3.0)
    scene = type(scene)(**{**scene.__dict__, "cylinders": (Cylinder(1.0, 0.3, 0.2),)})
    scan = SimWorld(scene).scan()
    path = tmp_path / "p.toml"
    counts = {"robot": 0, "perception": 0, "refused": 0}
    robot_base = {"latency_s": 0.05, "latency_jitter_s": 0.01, "gain": [[0.9, 0, 0], [0, 0.9, 0], [0, 0, 1.0]],
                  "bias": [0.01, 0.0, 0.0], "residual_max": [0.02, 0.02, 0.05], "residual_hold_s": 0.05,
                  "floor_friction": 0.8,
                  "odometry": {"encoder_counts_per_rev": 1320, "scale_error": 0.05,
                               "wheel_noise_density_radps_rthz": 0.1},
                  "imu": {"gyro_noise_density_radps_rthz": 1e-3, "gyro_bias_max_radps": 1e-3,
                          "gyro_bias_radps": 0.01},
                  "faults": FAULTS_TABLE}

    @settings(max_examples=50, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
    @given(mutated(robot_base), mutated(to_dict(PerceptionParams())))
    def check(robot_doc, perception_doc):
        with deadline():
            if _write_toml(path, robot_doc):
                try:
                    profile = load(RobotProfile, path)
                except UserError as err:
                    assert str(path) in str(err) and "\n" not in str(err)
                    counts["refused"] += 1
                else:
                    w = SimWorld(open_room(3.0), profile=profile, model=None if profile.floor_friction else
                                 world0.model)
                    for _ in range(3):
                        w.command((0.3, 0.1, 0.2))
                        w.step(50)
                        got = w.scan()
                        assert got is None or len(got.ranges) == profile.lidar.n_beams
                    assert np.isfinite(w.odom().px)
                    counts["robot"] += 1
            try:
                pp = from_dict(PerceptionParams, perception_doc, file=str(path))
            except UserError as err:
                assert str(path) in str(err) and "\n" not in str(err)
                counts["refused"] += 1
            else:
                perc = Perception(pp)
                for _ in range(3):
                    obs = perc.update(scan, (0.0, 0.0, 0.0))
                assert np.isfinite(obs.p).all()
                counts["perception"] += 1

    check()
    print("fuzz: robot profiles and perception parameters", counts)
    assert counts["robot"] > 3 and counts["perception"] > 3 and counts["refused"] > 10, counts
