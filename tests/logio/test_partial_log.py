"""An interrupted ``bigcbf run --log X.mcap``: Ctrl-C (SIGINT) or SIGTERM keeps what was recorded as X.partial.mcap,
a complete MCAP (summary and footer) that rosbags reads, never X.mcap, and leaves no temporary file.

The command runs in a real subprocess, its signal handling as ``bigcbf run`` installs it
(``bigcbf.logio.interrupts.interrupts_as_keyboard_interrupt`` around the CLI's main); the signal comes once the
log has been open for 2 s (several seconds into the simulated episode)."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from bigcbf.logio import LogWriter
from bigcbf.logio.writer import partial_path
from bigcbf.types import RobotState

# an open floor with a far goal: the episode outlasts the test by far
SCENARIO = """name = "long_drive"
description = "Open floor, a goal 100 m away."
time_limit_s = 300.0
extent_m = 5.0

[robot]
start = [0.0, 0.0, 0.0]
goal = [100.0, 0.0]
"""
DRIVER = ("import sys\n"
          "from bigcbf.cli import main\n"
          "from bigcbf.logio.interrupts import interrupts_as_keyboard_interrupt\n"
          "with interrupts_as_keyboard_interrupt():\n"
          "    status = main(sys.argv[1:])\n"
          "sys.exit(status)\n")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_an_interrupted_run_keeps_a_valid_partial_log(tmp_path, sig):
    scenario = tmp_path / "long_drive.toml"
    scenario.write_text(SCENARIO)
    out = tmp_path / "out"
    log = out / "run.mcap"
    env = dict(os.environ, MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    proc = subprocess.Popen([sys.executable, "-c", DRIVER, "run", str(scenario), "--log", str(log)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        deadline = time.monotonic() + 90
        tmp = []
        while time.monotonic() < deadline and proc.poll() is None:    # the log opens as the episode starts
            tmp = list(out.glob(".run.*.tmp.mcap")) if out.exists() else []
            if tmp:
                break
            time.sleep(0.05)
        # then wait until control steps are being written (the file grows by 64 KiB chunks of hundreds of steps:
        # on a loaded machine the first steps can come seconds after the log opens), not a fixed time
        start = tmp[0].stat().st_size if tmp else 0
        while time.monotonic() < deadline and proc.poll() is None and tmp and tmp[0].stat().st_size <= start:
            time.sleep(0.05)
        time.sleep(0.5)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "bigcbf run: interrupted"
    assert sorted(p.name for p in out.iterdir()) == ["run.partial.mcap"]      # no run.mcap, no temporary file
    partial = out / "run.partial.mcap"
    with open(partial, "rb") as fh:
        summary = make_reader(fh).get_summary()                              # the footer points to a summary
    assert summary is not None and summary.statistics.message_count > 0
    counts, last = {}, 0
    with AnyReader([partial]) as reader:
        for con, t, raw in reader.messages():
            reader.deserialize(raw, con.msgtype)
            counts[con.topic] = counts.get(con.topic, 0) + 1
            last = max(last, t)
    assert sum(counts.values()) == summary.statistics.message_count
    assert {"/tf_static", "/robot_description", "/goal_pose", "/map"} <= set(counts)
    # whole control steps: every step's messages are in (an interrupt waits for the step's last one)
    assert counts["/clock"] == counts["/tf"] == counts["/odom"] == counts["/behavior"] >= 20
    assert last >= 1e9


def test_finish_partial_replaces_an_older_partial_and_keeps_the_final_path(tmp_path):
    final = tmp_path / "x.mcap"
    final.write_bytes(b"the previous run's log")
    partial_path(final).write_bytes(b"an older partial log")
    w = LogWriter(final)
    for k in range(3):
        w.odom(0.1 * k, RobotState(0.1 * k, 0, 0, 1, 0, 0))
    assert w.finish_partial() == partial_path(final) == tmp_path / "x.partial.mcap"
    assert final.read_bytes() == b"the previous run's log"                  # the final file is untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.mcap", "x.partial.mcap"]
    with AnyReader([partial_path(final)]) as reader:
        assert [t for _, t, _ in reader.messages()] == [0, 100_000_000, 200_000_000]
    assert w.finish_partial() is None                                        # once
    w.close()                                                                # then a no-op
    assert partial_path(Path("a/b.log")) == Path("a/b.log.partial.mcap")


def test_a_signal_inside_a_log_write_waits_for_its_end():
    """Inside ``critical`` (a message, a control step) SIGTERM and SIGINT are held until the section ends, then
    raise KeyboardInterrupt naming the signal; outside, at once; the previous handlers come back afterwards."""
    from bigcbf.logio.interrupts import critical, interrupts_as_keyboard_interrupt
    before = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)
    with interrupts_as_keyboard_interrupt():
        for sig in (signal.SIGTERM, signal.SIGINT):
            done = []
            with pytest.raises(KeyboardInterrupt, match=sig.name):
                with critical:
                    with critical:                                   # nested: held to the outermost end
                        os.kill(os.getpid(), sig)
                        time.sleep(0.01)
                    done.append("inner")
                    time.sleep(0.01)
                    done.append("outer")
            assert done == ["inner", "outer"]
        with pytest.raises(KeyboardInterrupt, match="SIGTERM"):
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1.0)
    assert (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)) == before


def test_a_signal_inside_a_compiled_kernel_is_a_keyboard_interrupt():
    """A signal whose handler runs inside numba's code (``_numba_unpickle``, called back on every array the CBF
    filter's row kernel returns) would leave the kernel as SystemError; it is delivered again a few ms later and
    raises KeyboardInterrupt outside the kernel. A profile hook at the callback's call event runs the installed
    handler with the callback's frame, as Python's signal machinery would for a signal pending at its first bytecode
    (where CI's SIGTERM landed); the second delivery is a real signal."""
    from bigcbf.control.cbf import cbf_rows
    from bigcbf.logio.interrupts import interrupts_as_keyboard_interrupt
    from bigcbf.params import SIMULATION
    from bigcbf.types import Obstacles

    state, u_in = RobotState(0.0, 0.0, 0.0), np.array([0.7, 0.3, 0.0])
    obs = Obstacles.from_lists([[1.0, 0.0]], r=0.2)
    expected = cbf_rows(state, obs, u_in, SIMULATION)                    # compiled (or loaded) here
    landed = []

    def hook(frame, event, arg):
        if event == "call" and frame.f_code.co_name == "_numba_unpickle" and not landed:
            landed.append(frame.f_globals["__name__"])
            signal.getsignal(signal.SIGTERM)(signal.SIGTERM, frame)
    with interrupts_as_keyboard_interrupt():
        with pytest.raises(KeyboardInterrupt, match="SIGTERM"):
            sys.setprofile(hook)
            try:
                rows = cbf_rows(state, obs, u_in, SIMULATION)
            finally:
                sys.setprofile(None)
            np.testing.assert_array_equal(rows.a, expected.a)                # the kernel finished untouched
            time.sleep(1.0)                                                  # then the signal, again
    assert landed and landed[0].startswith("numba.")


def test_an_interrupt_while_the_logger_starts_leaves_no_file(tmp_path, monkeypatch):
    from bigcbf.episode import Episode
    from bigcbf.logio.episode_log import EpisodeLogger
    from bigcbf.params.stack import SIMULATION
    from bigcbf.scenario import load_scenario

    def interrupted(self, *a, **k):
        raise KeyboardInterrupt
    monkeypatch.setattr(LogWriter, "scene_markers", interrupted)          # after /tf_static, URDF, goal, map
    ep = Episode(load_scenario("corridor_meeting", 0), "big-cbf", 0, SIMULATION, time_limit_s=0.5)
    with pytest.raises(KeyboardInterrupt):
        EpisodeLogger(ep, tmp_path / "x.mcap")
    assert list(tmp_path.iterdir()) == []
