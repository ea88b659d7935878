"""Bad files get the promised errors (UserError naming the file); a truncated MCAP is read up to the damage;
topics are found by type when their names differ."""
import shutil
from pathlib import Path

import numpy as np
import pytest

from bigcbf.cli import main
from bigcbf.errors import UserError
from bigcbf.logio import CMD, ODOM, SCAN, LogWriter, find_topic, open_log, read_series
from bigcbf.types import LaserScan, RobotState

TURTLEBOT = Path(__file__).resolve().parents[1] / "data/turtlebot3.bag"


def _drive_log(path: Path, seconds=40.0, cmd_topic="/cmd_vel", odom_topic="/odom", extra_twist=None):
    """A log of a robot following u with a 0.1 s delay (enough messages for many MCAP chunks)."""
    rng = np.random.default_rng(0)
    levels = rng.uniform(-0.5, 0.5, (int(seconds), 3))
    with LogWriter(path) as w:
        for k in range(int(seconds * 50)):
            t = 0.02 * k
            u = levels[int(t)]
            ud = levels[int(max(t - 0.1, 0.0))]
            if k % 2 == 0:
                w.cmd_vel(t, u, topic=cmd_topic)
                if extra_twist:
                    w.cmd_vel(t, -u, topic=extra_twist)
            w.odom(t, RobotState(0.0, 0.0, 0.0, *ud), topic=odom_topic)
            if k % 5 == 0:
                w.scan(t, LaserScan(t, -np.pi, np.pi / 180, 0.1, 8.0, np.full(360, 3.0, np.float32)))
    return path


def test_missing_file_and_folder_without_metadata(tmp_path):
    with pytest.raises(UserError, match="file not found") as e:
        open_log(tmp_path / "nope.mcap")
    assert str(tmp_path / "nope.mcap") in str(e.value)
    with pytest.raises(UserError, match="metadata.yaml"):
        open_log(tmp_path)


def test_empty_file(tmp_path):
    p = tmp_path / "empty.mcap"
    p.write_bytes(b"")
    with pytest.raises(UserError, match="empty") as e:
        open_log(p)
    assert e.value.file == str(p)


def test_wrong_format(tmp_path):
    for name in ("notes.mcap", "notes.bag", "notes.txt"):
        p = tmp_path / name
        p.write_text("this is not a robot log\n")
        with pytest.raises(UserError, match="not a robot log") as e:
            open_log(p)
        assert e.value.file == str(p)


def test_sqlite_file_alone_is_explained(tmp_path):
    p = tmp_path / "x.db3"
    p.write_bytes(b"SQLite format 3\x00" + b"\x00" * 100)
    with pytest.raises(UserError, match="bag folder"):
        open_log(p)


def test_truncated_mcap_is_read_up_to_the_damage(tmp_path):
    full = _drive_log(tmp_path / "full.mcap")
    with open_log(full) as log:
        n_full = sum(t.count for t in log.topics.values())
    data = full.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    with open_log(cut) as log:
        assert log.recovered and any("damaged MCAP" in w for w in log.warnings)
        n_cut = sum(t.count for t in log.topics.values())
        d = read_series(log, cmd="/cmd_vel", odom="/odom")
    assert 0.3 * n_full < n_cut < n_full
    assert np.all(np.diff(d.cmd.t) > 0) and d.cmd.t[-1] < 40.0
    # what was recovered is sound: the commands are those written
    rng = np.random.default_rng(0)
    levels = rng.uniform(-0.5, 0.5, (40, 3))
    np.testing.assert_allclose(d.cmd.u, levels[d.cmd.t.astype(int)])


def test_mcap_with_a_damaged_chunk_in_the_middle_is_read_up_to_it(tmp_path):
    """Footer and index intact, one chunk in the middle corrupted: the messages before the damage are used."""
    from mcap.reader import make_reader
    full = _drive_log(tmp_path / "full.mcap")
    with open(full, "rb") as fh:
        chunks = make_reader(fh).get_summary().chunk_indexes
    c = chunks[len(chunks) // 2]
    data = bytearray(full.read_bytes())
    mid = c.chunk_start_offset + c.chunk_length // 2
    data[mid:mid + 64] = bytes(64)                  # zero a stretch inside the middle chunk's compressed records
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with open_log(bad) as log:
        d = read_series(log, cmd="/cmd_vel", odom="/odom")
        assert any("damaged MCAP" in w for w in d.warnings)
    assert 5.0 < d.cmd.t[-1] < 35.0 and np.all(np.diff(d.cmd.t) > 0)
    rng = np.random.default_rng(0)
    levels = rng.uniform(-0.5, 0.5, (40, 3))
    np.testing.assert_allclose(d.cmd.u, levels[d.cmd.t.astype(int)])


def test_mcap_that_is_not_ros2_says_so(tmp_path):
    import json

    from mcap.writer import Writer
    p = tmp_path / "foxglove.mcap"
    with open(p, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema("Pose", "jsonschema", b'{"type": "object"}')
        cid = w.register_channel("/pose", "json", sid)
        for k in range(10):
            w.add_message(cid, log_time=k * 10**8, publish_time=k * 10**8, data=json.dumps({"x": k}).encode())
        w.finish()
    with pytest.raises(UserError, match="not a ROS 2 log: this MCAP holds json messages with jsonschema") as e:
        open_log(p)
    assert e.value.file == str(p)


def test_mcap_cut_before_any_message(tmp_path):
    full = _drive_log(tmp_path / "full.mcap", seconds=5)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(full.read_bytes()[:40])
    with pytest.raises(UserError, match="truncated") as e:
        open_log(cut)
    assert e.value.file == str(cut)


def test_truncated_ros1_bag(tmp_path):
    cut = tmp_path / "tb.bag"
    cut.write_bytes(TURTLEBOT.read_bytes()[:600_000])
    with pytest.raises(UserError, match="corrupt or truncated") as e:
        open_log(cut)
    assert e.value.file == str(cut)


def test_ros1_bag_under_another_name_opens(tmp_path):
    p = tmp_path / "turtlebot_log.dat"
    shutil.copy(TURTLEBOT, p)
    with open_log(p) as log:
        assert log.format == "ros1" and log.topics["/odom"].count == 2741


def test_missing_topics_list_what_the_log_has(tmp_path):
    p = tmp_path / "scan_only.mcap"
    with LogWriter(p) as w:
        for k in range(3):
            w.scan(0.1 * k, LaserScan(0.1 * k, -np.pi, np.pi / 180, 0.1, 8.0, np.full(360, 3.0, np.float32)))
            w.behavior(0.1 * k, "GOAL")
    with open_log(p) as log:
        with pytest.raises(UserError) as e:
            find_topic(log, CMD)
    msg = str(e.value)
    assert str(p) in msg and "no commands topic" in msg
    assert "/scan (sensor_msgs/msg/LaserScan, 3)" in msg and "/behavior (std_msgs/msg/String, 3)" in msg


def test_cli_reports_one_line_and_exit_2(tmp_path, capsys):
    p = tmp_path / "scan_only.mcap"
    with LogWriter(p) as w:
        w.scan(0.0, LaserScan(0.0, -np.pi, np.pi / 180, 0.1, 8.0, np.full(360, 3.0, np.float32)))
    assert main(["calibrate", str(p)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("bigcbf calibrate: error:") and "/scan" in err[0]
    empty = tmp_path / "empty.bag"
    empty.write_bytes(b"")
    assert main(["replay", str(empty)]) == 2
    assert "empty" in capsys.readouterr().err


def test_topics_found_by_type_when_names_differ(tmp_path):
    p = _drive_log(tmp_path / "renamed.mcap", seconds=3, cmd_topic="/robot/vel_cmd", odom_topic="/robot/wheel_odom")
    with open_log(p) as log:
        assert find_topic(log, CMD) == "/robot/vel_cmd"
        assert find_topic(log, ODOM) == "/robot/wheel_odom"
        assert find_topic(log, SCAN) == "/scan"
        with pytest.raises(UserError, match="is nav_msgs/msg/Odometry"):
            find_topic(log, CMD, named="/robot/wheel_odom")


def test_ambiguous_topics_ask_the_user_to_name_one(tmp_path):
    p = _drive_log(tmp_path / "two.mcap", seconds=3, cmd_topic="/base/twist_a", extra_twist="/base/twist_b")
    with open_log(p) as log:
        with pytest.raises(UserError, match="--cmd-topic") as e:
            find_topic(log, CMD)
        assert "/base/twist_a" in str(e.value) and "/base/twist_b" in str(e.value)
        assert find_topic(log, CMD, named="/base/twist_b") == "/base/twist_b"


def test_our_names_and_exclusions(tmp_path):
    """/cmd_vel_in (the planner's input) and /ground_truth/odom are never taken for what the robot did."""
    p = tmp_path / "ep.mcap"
    with LogWriter(p) as w:
        for k in range(3):
            w.cmd_vel_in(0.1 * k, (0.1, 0, 0))
            w.cmd_vel(0.1 * k, (0.1, 0, 0), topic="/mobile_base/cmd_vel")
            w.ground_truth(0.1 * k, RobotState(0, 0, 0))
            w.odom(0.1 * k, RobotState(0, 0, 0), topic="/wheel/odometry")
    with open_log(p) as log:
        assert find_topic(log, CMD) == "/mobile_base/cmd_vel"
        assert find_topic(log, ODOM) == "/wheel/odometry"
        assert find_topic(log, SCAN, required=False) is None
