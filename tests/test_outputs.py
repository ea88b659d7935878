"""Outputs (bigcbf/outputs.py and its users): checked before the work, written atomically (nothing the user made is
lost or left half-written), strict JSON; the results database on a full disk."""
import json
import math
import os

import numpy as np
import pytest

from bigcbf.bench.store import ResultStore
from bigcbf.errors import UserError
from bigcbf.outputs import atomic_output, check_output_dir, check_output_file, strict_json, write_text


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    f = tmp_path / "summary.json"
    f.write_text("the user's file")
    with pytest.raises(RuntimeError):
        with atomic_output(f) as tmp:
            tmp.write_text("half")
            raise RuntimeError("the work failed")
    assert f.read_text() == "the user's file" and os.listdir(tmp_path) == ["summary.json"]
    write_text(f, "new")
    assert f.read_text() == "new" and os.listdir(tmp_path) == ["summary.json"]
    umask = os.umask(0)
    os.umask(umask)
    assert (f.stat().st_mode & 0o777) == (0o666 & ~umask)


def test_a_symbolic_link_is_written_through(tmp_path):
    target = tmp_path / "real.toml"
    target.write_text("a")
    link = tmp_path / "link.toml"
    link.symlink_to(target)
    write_text(link, "b")
    assert link.is_symlink() and target.read_text() == "b"


@pytest.mark.parametrize("where, words", [
    ("dir", "is a directory"), ("/dev/full", "not a regular file"), ("under-file", "is a file, not a folder"),
    ("/sys/x.mp4", "cannot write"),
])
def test_output_paths_are_checked_before_the_work(tmp_path, where, words):
    (tmp_path / "f").write_text("x")
    path = {"dir": tmp_path, "under-file": tmp_path / "f" / "v.mp4"}.get(where, where)
    with pytest.raises(UserError, match=words):
        check_output_file(path, "video")
    assert os.listdir(tmp_path) == ["f"]          # the probe left nothing behind


def test_output_folders_are_checked(tmp_path):
    assert check_output_dir(tmp_path / "a" / "b", "report folder").is_dir()
    (tmp_path / "f").write_text("x")
    with pytest.raises(UserError, match="found a file"):
        check_output_dir(tmp_path / "f", "report folder")
    with pytest.raises(UserError, match="cannot"):
        check_output_dir("/sys/bigcbf-test", "report folder")


def test_strict_json_has_no_nan_or_infinity():
    text = strict_json({"a": math.inf, "b": [np.float64("nan"), 1.5, np.int64(3)], "c": (np.array([1.0, -math.inf]),)})
    assert json.loads(text) == {"a": None, "b": [None, 1.5, 3], "c": [[1.0, None]]}


def test_video_writer_ffmpeg_failure_is_one_line_and_drops_the_file(tmp_path, monkeypatch):
    """ffmpeg stopping mid-video (a full disk, say) is a UserError naming the path; the unfinished file goes."""
    import imageio_ffmpeg

    from bigcbf.sim.render import VideoWriter

    def dying_writer(path, *args, **kwargs):
        open(path, "wb").close()
        yield
        yield
        raise BrokenPipeError(32, "Broken pipe")
    monkeypatch.setattr(imageio_ffmpeg, "write_frames", dying_writer)
    out = tmp_path / "v.mp4"
    out.write_bytes(b"previous video")
    w = VideoWriter(out, fps=10)
    frame = np.zeros((16, 16, 3), np.uint8)
    w.write(frame)
    with pytest.raises(UserError, match="cannot write the video"):
        w.write(frame)
    assert out.read_bytes() == b"previous video" and os.listdir(tmp_path) == ["v.mp4"]


def test_mcap_log_appears_only_when_complete(tmp_path):
    from bigcbf.logio import LogWriter
    from bigcbf.types import RobotState
    path = tmp_path / "x.mcap"
    with pytest.raises(RuntimeError):
        with LogWriter(path) as w:
            w.odom(0.0, RobotState(0, 0, 0))
            raise RuntimeError("the episode failed")
    assert os.listdir(tmp_path) == []
    with LogWriter(path) as w:
        w.odom(0.0, RobotState(0, 0, 0))
    assert os.listdir(tmp_path) == ["x.mcap"] and path.stat().st_size > 0


def _row(seed):
    return dict(scenario="a", method="m", seed=seed, params_hash="p", scenario_sha="s", status="ok", error=None,
                metrics={"pad": "x" * 3000}, worker_wall_s=1.0, host="h", pid=1)


def test_results_database_on_a_full_disk(tmp_path):
    """SQLite's "database or disk is full" (simulated with max_page_count) is a UserError that says the episodes
    already saved are kept and a rerun resumes; they are."""
    path = tmp_path / "results.sqlite"
    saved = 0
    with ResultStore(path) as st:
        st.db.execute(f"PRAGMA max_page_count = {st.db.execute('PRAGMA page_count').fetchone()[0] + 8}")
        with pytest.raises(UserError, match="rerun the same command to resume") as err:
            for seed in range(100):
                st.put(_row(seed))
                saved += 1
        assert "database or disk is full" in str(err.value) and str(path) in str(err.value)
    with ResultStore(path) as st:
        assert 0 < saved == st.count()


def test_an_empty_database_file_left_by_a_full_disk_opens(tmp_path):
    """A disk full at the start left a 0-byte results.sqlite: once there is space, it is a fresh database (it
    was called "not a bigcbf results database")."""
    path = tmp_path / "results.sqlite"
    path.write_bytes(b"")
    with ResultStore(path) as st:
        st.put(_row(0))
        assert st.count() == 1
    path.write_bytes(b"not sqlite at all" * 100)
    with pytest.raises(UserError, match="not a bigcbf results database"):
        ResultStore(path)
