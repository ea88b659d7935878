"""Hardening, the security and data-loss class (issue 21): no path the program writes comes from a file's content
(a scenario's name), no output lands on an input or on another output of the same command, a bench --out is new,
empty or an earlier bench's, and an ffmpeg that fails (a full disk) is an error that leaves nothing behind.

Every case runs the real command (``bigcbf.cli.main`` in-process, or the installed ``bigcbf`` where a process
limit or a mount is needed) and checks that the user's files are intact byte for byte."""
from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import os
import resource
import sqlite3
import subprocess
import sys
import tempfile
import uuid
from pathlib import Path

import pytest

from bigcbf.cli import main
from bigcbf.errors import UserError
from bigcbf.outputs import check_distinct, same_file

BIGCBF = str(Path(sys.executable).with_name("bigcbf"))
BAG = Path(__file__).resolve().parent / "data" / "turtlebot3.bag"


def cli(*argv) -> tuple[int, str, str]:
    """``bigcbf argv`` in-process: (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        status = main([str(a) for a in argv])
    return status, out.getvalue(), err.getvalue()


def refused(result, *words) -> str:
    """Exit 2 with one error line (after optional note: lines) holding ``words``; returns that line."""
    status, out, err = result
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert status == 2, (status, out, err)
    assert lines and all(ln.startswith("note:") for ln in lines[:-1]), err
    assert ": error: " in lines[-1] and "Traceback" not in err, err
    for w in words:
        assert w in lines[-1], (w, lines[-1])
    return lines[-1]


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> bytes); symbolic links as their target's path."""
    snap = {}
    for p in sorted(folder.rglob("*")):
        if p.is_symlink():
            snap[str(p.relative_to(folder))] = b"-> " + os.readlink(p).encode()
        elif p.is_file():
            snap[str(p.relative_to(folder))] = p.read_bytes()
    return snap


@pytest.fixture(scope="module")
def short_scene(tmp_path_factory) -> Path:
    """single_person_crossing with a 2 s time limit (a real episode in about a second)."""
    from bigcbf.scenario import scenario_files
    text = scenario_files()["single_person_crossing"].read_text()
    lines = ["time_limit_s = 2.0" if ln.startswith("time_limit_s") else ln for ln in text.splitlines()]
    path = tmp_path_factory.mktemp("scene") / "spc_short.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def _scene_named(short_scene: Path, folder: Path, name: str) -> Path:
    text = short_scene.read_text().replace('name = "single_person_crossing"', f"name = {json.dumps(name)}")
    assert text != short_scene.read_text()
    path = folder / "evil.toml"
    path.write_text(text)
    return path


BENCH = ("--methods", "cbf-only", "--seeds", "1", "--workers", "1", "--progress", "off")


# --- 1. a scenario's name never becomes a path -----------------------------------------------------------------------

@pytest.mark.parametrize("evil", ["../../ESCAPE", "../ESCAPE", "ABSOLUTE", "a\x01b", "with space"])
def test_a_scenario_name_that_is_not_an_identifier_is_refused_by_the_bench(tmp_path, short_scene, evil):
    """The worker's temporary folder was tempfile's /tmp/bigcbf-bench-XXX: "../ESCAPE" wrote /tmp/ESCAPE.toml,
    "../../ESCAPE" /ESCAPE.toml, an absolute name anywhere (here: over victim.toml)."""
    victim = tmp_path / "victim.toml"
    victim.write_text("the user's file\n")
    tag = f"bigcbf-escape-{uuid.uuid4().hex[:10]}"
    name = str(tmp_path / "victim") if evil == "ABSOLUTE" else evil.replace("ESCAPE", tag)
    scene = _scene_named(short_scene, tmp_path, name)
    before = snapshot(tmp_path)
    refused(cli("bench", "--out", tmp_path / "b", "--scenarios", scene, *BENCH), str(scene), "field 'name'")
    assert snapshot(tmp_path) == before            # nothing written: no victim.toml overwritten, no bench folder
    escaped = (Path(tempfile.gettempdir()) / f"{tag}.toml", Path(tempfile.gettempdir()).parent / f"{tag}.toml")
    assert not any(p.exists() for p in escaped)


def test_a_pedestrian_name_with_a_slash_or_a_control_character_is_one_line(tmp_path, short_scene):
    for bad in ("crosser/x", "cross\\u0007er"):
        text = short_scene.read_text().replace('name = "crosser"', f'name = "{bad}"')
        assert bad in text
        scene = tmp_path / "peds.toml"
        scene.write_text(text)
        refused(cli("run", scene), str(scene), "field 'pedestrians[0].name'")


def test_the_bench_worker_writes_no_file_named_by_the_task(tmp_path, short_scene):
    """At the cause: a task whose scenario name is an absolute path (as a hand-made or old task could carry) runs
    its real episode from the text it carries and writes nothing there (it used to write <name>.toml)."""
    from bigcbf.bench.runner import BenchConfig, plan
    from bigcbf.bench.tasks import guarded, run_episode

    victim = tmp_path / "victim.toml"
    victim.write_text("the user's file\n")
    tasks, _, _ = plan(BenchConfig(out=tmp_path / "b", methods=("cbf-only",), scenarios=(str(short_scene),),
                                   seeds=(0,)))
    row = guarded(run_episode, dataclasses.replace(tasks[0], scenario=str(tmp_path / "victim")))
    assert row["status"] == "ok", row["error"]
    assert row["metrics"]["time_s"] <= 2.0 + 1e-9
    assert victim.read_text() == "the user's file\n" and sorted(os.listdir(tmp_path)) == ["victim.toml"]


# --- 2. outputs onto inputs ------------------------------------------------------------------------------------------

def test_check_distinct_sees_through_symbolic_and_hard_links(tmp_path):
    f = tmp_path / "log.bag"
    f.write_bytes(b"log")
    (tmp_path / "sym").symlink_to(f)
    os.link(f, tmp_path / "hard")
    assert same_file(f, tmp_path / "sym") and same_file(f, tmp_path / "hard")
    assert not same_file(f, tmp_path / "other")
    for alias in ("sym", "hard", "./log.bag"):
        with pytest.raises(UserError, match="--out is the same file as the log"):
            check_distinct({"log": f}, {"--out": tmp_path / alias if alias != "./log.bag" else
                                        Path(str(tmp_path) + "/./log.bag")})
    with pytest.raises(UserError, match="--video and --log are the same file"):
        check_distinct({}, {"--log": tmp_path / "x.mp4", "--video": tmp_path / "sub" / ".." / "x.mp4"})
    check_distinct({"log": f, "--profile": None}, {"--out": tmp_path / "p.toml", "--video": None})   # all distinct


def test_calibrate_never_writes_onto_its_log(tmp_path):
    log = tmp_path / "run.bag"
    log.write_bytes(BAG.read_bytes())
    (tmp_path / "link.toml").symlink_to(log)
    os.link(log, tmp_path / "hard.toml")
    bag2 = tmp_path / "bag2"                  # a ROS 2 bag folder: no output inside it
    bag2.mkdir()
    (bag2 / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    before = snapshot(tmp_path)
    refused(cli("calibrate", log, "--out", log), "--out is the same file as the log")
    refused(cli("calibrate", log, "--out", tmp_path / "link.toml"), "the same file as the log")
    refused(cli("calibrate", log, "--out", tmp_path / "hard.toml"), "the same file as the log")
    refused(cli("calibrate", log, "--out", tmp_path / "r" / "calibration.json", "--report", tmp_path / "r"),
            "are the same file")
    refused(cli("calibrate", bag2, "--out", bag2 / "metadata.yaml"), "inside the log folder")
    refused(cli("calibrate", bag2, "--out", bag2 / "p.toml"), "inside the log folder")
    assert snapshot(tmp_path) == before
    # distinct paths work, and --report writes exactly the files the check protects
    from bigcbf.cli.calibrate import REPORT_FILES
    status, out, err = cli("calibrate", log, "--out", tmp_path / "p.toml", "--report", tmp_path / "rep")
    assert status == 0, err
    written = set(os.listdir(tmp_path / "rep"))
    assert {"calibration.json", "command_response.png"} <= written <= set(REPORT_FILES), written
    assert log.read_bytes() == BAG.read_bytes()


def test_replay_and_record_never_write_onto_their_inputs(tmp_path):
    log = tmp_path / "run.bag"
    log.write_bytes(b"a log the user recorded")
    prof = tmp_path / "robot.toml"
    prof.write_text("latency_s = 0.05\n")
    before = snapshot(tmp_path)
    refused(cli("replay", log, "--save-robot-profile", log), "--save-robot-profile is the same file as the log")
    refused(cli("replay", log, "--video", log), "--video is the same file as the log")
    refused(cli("replay", log, "--profile", prof, "--save-robot-profile", prof), "the same file as the --profile")
    refused(cli("replay", log, "--video", tmp_path / "o.toml", "--save-robot-profile", tmp_path / "o.toml"),
            "are the same file")
    refused(cli("record", "calibration", "--robot-profile", prof, "--out", prof),
            "--out is the same file as the --robot-profile")
    refused(cli("profile", "simulate", "--robot-profile", prof, "--out", prof),
            "--out is the same file as the --robot-profile")
    refused(cli("profile", "simulate", "--robot-profile", prof, "--out", tmp_path / "x", "--log", tmp_path / "x"),
            "are the same file")
    assert snapshot(tmp_path) == before


def test_scenarios_generate_never_overwrites_a_shipped_scenario(tmp_path, monkeypatch):
    import bigcbf.scenario
    shipped = tmp_path / "pkg" / "required_sidestepping.toml"      # stands in for the package's file
    shipped.parent.mkdir()
    shipped.write_text("the shipped scene\n")
    monkeypatch.setattr(bigcbf.scenario, "all_scenario_files", lambda: {"required_sidestepping": shipped})
    refused(cli("scenarios", "generate", "posts", "--out", shipped, "--force"), "shipped scenario")
    assert shipped.read_text() == "the shipped scene\n"
    status, _, err = cli("scenarios", "generate", "posts", "--out", tmp_path / "w.toml")
    assert status == 0, err
    assert "name = " in (tmp_path / "w.toml").read_text() and sorted(os.listdir(tmp_path)) == ["pkg", "w.toml"]


def test_bench_docs_page_is_none_of_the_bench_files(tmp_path, short_scene):
    scene = tmp_path / "scene.toml"
    scene.write_bytes(short_scene.read_bytes())
    before = snapshot(tmp_path)
    refused(cli("bench", "--out", tmp_path / "b", "--scenarios", scene, "--docs", scene, *BENCH),
            "--docs is the same file as the scenario")
    refused(cli("bench", "--out", tmp_path / "b", "--scenarios", scene, "--docs", tmp_path / "b" / "summary.md",
                *BENCH), "--docs and the bench's summary.md are the same file")
    refused(cli("bench", "--out", tmp_path / "b", "--scenarios", scene, "--config", tmp_path / "b" / "summary.json",
                *BENCH))
    assert snapshot(tmp_path) == before


def test_run_never_logs_onto_its_scenario(tmp_path, short_scene):
    scene = tmp_path / "sc.toml"
    scene.write_bytes(short_scene.read_bytes())
    refused(cli("run", scene, "--method", "cbf-only", "--log", scene), "--log is the same file as the scenario")
    assert scene.read_bytes() == short_scene.read_bytes()


def test_run_video_and_log_on_one_path_is_refused(tmp_path, short_scene):
    out = tmp_path / "x.mp4"
    status, stdout, err = cli("run", short_scene, "--method", "cbf-only", "--video", out, "--log", out)
    assert "wrote" not in stdout
    refused((status, stdout, err), "are the same file")
    assert not out.exists()


# --- the bench's --out folder ----------------------------------------------------------------------------------------

def test_bench_out_must_be_new_empty_or_an_earlier_bench(tmp_path, short_scene):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "summary.md").write_text("# my notes\n")
    (user / "episodes.csv").write_text("my,own,data\n1,2,3\n")
    before = snapshot(user)
    refused(cli("bench", "--out", user, "--scenarios", short_scene, *BENCH), "neither empty nor an earlier bench")
    refused(cli("bench", "--out", user, "--suite", "generated", "--seeds", "1"), "neither empty")   # no worlds/ there
    refused(cli("bench", "--out", user, "--report-only", "--scenarios", short_scene, *BENCH), "neither empty")
    from bigcbf.api import run_bench
    with pytest.raises(UserError, match="neither empty nor an earlier bench"):             # the Python API too
        run_bench(user, scenarios=[str(short_scene)], methods=["cbf-only"], seeds=1, workers=1)
    assert snapshot(user) == before

    foreign = tmp_path / "db"                   # someone else's results.sqlite is not ours either
    foreign.mkdir()
    with sqlite3.connect(foreign / "results.sqlite") as con:
        con.execute("CREATE TABLE mine (x)")
    con.close()
    before = snapshot(foreign)
    refused(cli("bench", "--out", foreign, "--scenarios", short_scene, *BENCH), "not a bigcbf bench's")
    assert snapshot(foreign) == before

    empty = tmp_path / "empty"                  # an empty folder: a real 1-episode bench
    empty.mkdir()
    status, _, err = cli("bench", "--out", empty, "--scenarios", short_scene, *BENCH)
    assert status == 0, err
    assert "0 already done, 1 run now" in err and (empty / "summary.md").is_file()
    summary = (empty / "summary.md").read_bytes()
    status, _, err = cli("bench", "--out", empty, "--scenarios", short_scene, *BENCH)     # an earlier bench: resumes
    assert status == 0, err
    assert "1 already done, 0 run now" in err
    assert (empty / "summary.md").read_bytes().splitlines()[:3] == summary.splitlines()[:3]

    new = tmp_path / "new" / "bench"            # a new folder
    status, _, err = cli("bench", "--out", new, "--report-only", "--scenarios", short_scene, *BENCH)
    assert status == 0, err
    assert (new / "results.sqlite").is_file() and (new / "summary.md").is_file()


# --- 3. ffmpeg failing (a full disk) ---------------------------------------------------------------------------------

@contextlib.contextmanager
def full_disk(kind: str, tmp_path: Path, size_kb: int):
    """A folder where writing beyond ``size_kb`` fails: a tiny tmpfs (needs root), or the process's file size
    limit (RLIMIT_FSIZE, inherited by ffmpeg) -> (folder, preexec_fn for subprocess)."""
    if kind == "tmpfs":
        d = tmp_path / f"tiny-{uuid.uuid4().hex[:8]}"
        d.mkdir()
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "tmpfs", str(d)], capture_output=True)
        if r.returncode != 0:
            pytest.skip(f"cannot mount a tmpfs here ({r.stderr.decode().strip()[:80]})")
        try:
            yield d, None
        finally:
            subprocess.run(["umount", str(d)], check=True)
    else:
        def limit():
            resource.setrlimit(resource.RLIMIT_FSIZE, (size_kb * 1024, size_kb * 1024))
        yield tmp_path, limit


VIDEO_CLOSE = """
import sys, numpy as np
from bigcbf.errors import UserError
from bigcbf.sim.render import VideoWriter
w = VideoWriter(sys.argv[1], fps=20)
rng = np.random.default_rng(0)
for _ in range(3):       # x264 holds these frames back: ffmpeg writes (and fails) only when close() ends it
    w.write(rng.integers(0, 255, (96, 96, 3), dtype=np.uint8))
try:
    w.close()
except UserError as exc:
    print(exc)
    sys.exit(2)
print("closed")
"""


@pytest.mark.parametrize("kind", ["tmpfs", "fsize"])
def test_video_writer_close_fails_when_ffmpeg_does(tmp_path, kind):
    """VideoWriter.close() raises a UserError when ffmpeg's exit is not clean, and deletes the unfinished file:
    the previous video stays; with room, the same script writes the video (the failure is the disk's)."""
    with full_disk(kind, tmp_path, 16) as (d, limit):
        video = d / "v.mp4"
        video.write_bytes(b"the previous video")
        r = subprocess.run([sys.executable, "-c", VIDEO_CLOSE, str(video)], capture_output=True, text=True,
                           preexec_fn=limit, timeout=120)
        assert r.returncode == 2, (r.stdout, r.stderr)
        assert "cannot write the video (ffmpeg" in r.stdout and str(video) in r.stdout
        assert video.read_bytes() == b"the previous video" and os.listdir(d) == ["v.mp4"]
    roomy = tmp_path / "roomy.mp4"
    r = subprocess.run([sys.executable, "-c", VIDEO_CLOSE, str(roomy)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip() == "closed", r.stderr
    assert roomy.read_bytes()[4:8] == b"ftyp"


def test_run_video_on_a_full_disk_is_an_error_and_leaves_nothing(tmp_path, short_scene):
    """The real `bigcbf run --video` onto a full disk (a 64 kB tmpfs as root, else a 64 kB file size limit): exit 2
    with one error line, no "wrote", the previous video intact and no temporary file left."""
    kind = "tmpfs" if os.geteuid() == 0 else "fsize"
    with full_disk(kind, tmp_path, 64) as (d, limit):
        video = d / "v.mp4"
        video.write_bytes(b"the previous video")
        r = subprocess.run([BIGCBF, "run", str(short_scene), "--method", "cbf-only", "--video", str(video)],
                           capture_output=True, text=True, preexec_fn=limit, timeout=300,
                           env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")})
        assert r.returncode == 2, (r.stdout[-500:], r.stderr[-2000:])
        assert "wrote" not in r.stdout
        last = r.stderr.strip().splitlines()[-1]
        assert last.startswith("bigcbf run: error: ") and "cannot write the video" in last and str(video) in last
        assert video.read_bytes() == b"the previous video" and os.listdir(d) == ["v.mp4"]
