"""Issue 21, item 4: results that were false without a word. Each case a real run (short drives and episodes)."""
import numpy as np
import pytest

from bigcbf.errors import UserError
from bigcbf.params.robot import RobotProfile

SCENARIO = """name = "{name}"
description = "issue 21 false-result check"
time_limit_s = {limit}
extent_m = 5.0

[robot]
start = [0.0, 0.0, 0.0]
goal = [{goal}, 0.0]
{extra}
"""


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """A short real calibration drive (latency 0.08 s, gains 0.9/0.85/0.95, as README's tour) and its tau95."""
    from twin.calibrate import calibrate_log
    from twin.record import record_calibration
    path = tmp_path_factory.mktemp("drive") / "d.mcap"
    prof = RobotProfile(latency_s=0.08, gain=((0.9, 0, 0), (0, 0.85, 0), (0, 0, 0.95)))
    record_calibration(prof, path, seed=0, duration_s=20.0)
    return path, calibrate_log(path)


def rewrite(src, dst, topic, mode, seed=0):
    """``src`` re-written with the mcap writer, the messages in the file's order; on ``topic``: "shuffle" permutes
    the log times, "shuffle-all" permutes them and the publish times and zeroes the sequence numbers (no witness),
    "duplicate" gives every other message its predecessor's log time and header stamp (not its content)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer
    rng = np.random.default_rng(seed)
    with open(src, "rb") as fh:
        r = make_reader(fh)
        summ = r.get_summary()
        msgs = list(r.iter_messages(log_time_order=False))
    idx = [i for i, (_, c, _) in enumerate(msgs) if c.topic == topic]
    times = np.array([msgs[i][2].log_time for i in idx])
    new = times.copy()
    if mode.startswith("shuffle"):
        rng.shuffle(new)
    data = {i: msgs[i][2].data for i in idx}
    if mode == "duplicate":
        from rosbags.typesys import Stores, get_typestore
        ts = get_typestore(Stores.ROS2_HUMBLE)
        for k in range(1, len(idx), 2):
            prev = ts.deserialize_cdr(msgs[idx[k - 1]][2].data, "nav_msgs/msg/Odometry")
            m = ts.deserialize_cdr(msgs[idx[k]][2].data, "nav_msgs/msg/Odometry")
            m.header.stamp = prev.header.stamp
            data[idx[k]] = ts.serialize_cdr(m, "nav_msgs/msg/Odometry")
            new[k] = times[k - 1]
        new = new[rng.permutation(len(new))]                 # and out of order
    lt = dict(zip(idx, (int(x) for x in new)))
    with open(dst, "wb") as out:
        w = Writer(out)
        w.start(profile="ros2", library="test")
        sids = {s.id: w.register_schema(s.name, s.encoding, s.data) for s in summ.schemas.values()}
        cids = {c.id: w.register_channel(c.topic, c.message_encoding, sids[c.schema_id], c.metadata)
                for c in summ.channels.values()}
        for i, (_, c, m) in enumerate(msgs):
            t = lt.get(i, m.log_time)
            bare = mode == "shuffle-all" and i in lt
            w.add_message(cids[c.id], log_time=t, publish_time=t if bare else m.publish_time,
                          data=data.get(i, m.data), sequence=0 if bare else m.sequence)
        w.finish()
    return dst


@pytest.mark.parametrize("topic", ["/odom", "/cmd_vel"])
def test_shuffled_log_times_are_repaired_and_said(drive, tmp_path, topic):
    from twin.calibrate import calibrate_log
    path, ref = drive
    bad = rewrite(path, tmp_path / "shuffled.mcap", topic, "shuffle")
    cal = calibrate_log(bad)
    assert abs(cal.delay.tau95_s - ref.delay.tau95_s) < 0.003
    notes = [n for n in cal.notes() if n.startswith(f"{topic}:") and "out of order" in n]
    assert len(notes) == 1 and "repaired" in notes[0]
    clock = "header stamps" if topic == "/odom" else "file's order"
    assert clock in notes[0]
    assert not any("out of order" in n for n in ref.notes())


def test_shuffled_commands_without_witness_are_refused(drive, tmp_path):
    from twin.calibrate import calibrate_log
    bad = rewrite(drive[0], tmp_path / "bare.mcap", "/cmd_vel", "shuffle-all")
    with pytest.raises(UserError, match="/cmd_vel: its log times go back at .* places") as e:
        calibrate_log(bad)
    assert e.value.file == str(bad) and "\n" not in str(e.value)


def test_duplicated_odometry_stamps_out_of_order_are_refused(drive, tmp_path):
    from twin.calibrate import calibrate_log
    bad = rewrite(drive[0], tmp_path / "dup.mcap", "/odom", "duplicate")
    with pytest.raises(UserError, match="/odom: .* header stamps are shared by messages with different contents"):
        calibrate_log(bad)


def test_replay_says_the_repair(drive, tmp_path):
    from twin.replay import replay_log
    bad = rewrite(drive[0], tmp_path / "shuffled.mcap", "/odom", "shuffle")
    res = replay_log(bad)
    assert any(n.startswith("/odom:") and "out of order" in n for n in res.notes)


def test_a_drive_the_robot_does_not_follow_is_an_error_and_writes_no_log(tmp_path):
    from twin.record import record_calibration
    out = tmp_path / "still.mcap"
    with pytest.raises(UserError, match="did not follow the calibration drive: .* moved 0.00 m") as e:
        record_calibration(RobotProfile(latency_s=2.0), out, duration_s=3.0)
    assert e.value.file == str(out) and not list(tmp_path.iterdir())
    with pytest.raises(UserError, match=r"moved 0\.\d\d m \(odometry \d"):       # wheels spinning on ice
        record_calibration(RobotProfile(floor_friction=1e-4), out, duration_s=6.0)
    assert not list(tmp_path.iterdir())


def test_calibrate_says_the_robot_never_moved(tmp_path):
    """A log recorded past the recorder's check (its own LogWriter): commands, odometry at rest."""
    from bigcbf.logio import LogWriter
    from bigcbf.types import RobotState
    from twin.calibrate import calibrate_log
    path = tmp_path / "still.mcap"
    with LogWriter(path) as w:
        for k in range(200):
            t = 0.05 * k
            w.odom(t, RobotState(0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
            w.cmd_vel(t, np.array([0.4 if (k // 20) % 2 else 0.0, 0.0, 0.0]))
    with pytest.raises(UserError, match="the robot never moved: .* ask for 1.9\\d m .* shows 0.000 m"):
        calibrate_log(path)


def _scenario(tmp_path, name, goal, limit, extra=""):
    p = tmp_path / f"{name}.toml"
    p.write_text(SCENARIO.format(name=name, goal=goal, limit=limit, extra=extra))
    return p


def test_start_inside_the_goal_region_is_said(tmp_path):
    from bigcbf.api import load_config, run_episode
    from bigcbf.config import RunConfig
    sc = _scenario(tmp_path, "near", 4.0, 2.0)
    cfg = tmp_path / "eps.toml"
    cfg.write_text("[stack]\neps_g_m = 10.0\n")
    res = run_episode(str(sc), "big-cbf", 0, config=str(cfg), time_limit_s=2.0)
    assert res.success and res.time_s == 0 and res.final_goal_dist_m == pytest.approx(4.0)
    assert res.warnings["started_in_goal_region"] == 1
    plain = run_episode(str(sc), "big-cbf", 0, config=RunConfig(), time_limit_s=1.0)
    assert "started_in_goal_region" not in plain.warnings


def test_odometry_that_diverged_is_said_beside_success(tmp_path):
    from bigcbf.api import run_episode
    sc = _scenario(tmp_path, "ice", 1.5, 4.0, "[robot_profile]\nfloor_friction = 1e-4\n")
    res = run_episode(str(sc), "big-cbf", 0, time_limit_s=4.0)
    assert res.success                                   # the paper's rule, on the odometry: unchanged
    assert res.final_goal_dist_m > 1.0
    assert res.warnings["odometry_diverged"] > 1.0
    from bigcbf.bench.report import write_csv            # the bench's table still takes the warnings
    row = {"scenario": "ice", "method": "big-cbf", "seed": 0, "status": "ok", "metrics": res.metrics()}
    write_csv([row], tmp_path / "episodes.csv")
    assert "odometry_diverged" in (tmp_path / "episodes.csv").read_text()


def test_blind_lidar_is_said_at_the_start(tmp_path, capsys):
    """``bigcbf run``'s own code (its parser and run(); the whole CLI's parser holds every other command too)."""
    import argparse
    import json

    from bigcbf.cli import run as run_cmd
    extra = ("[[cylinders]]\ncenter = [2.0, 0.0]\nradius_m = 0.1\n\n"
             "[robot_profile.lidar]\nn_beams = 8\nrange_max_m = 0.2\n")
    sc = _scenario(tmp_path, "blind", 4.0, 3.0, extra)
    p = argparse.ArgumentParser()
    run_cmd.add_arguments(p)
    assert run_cmd.run(p.parse_args([str(sc), "--method", "big-cbf", "--json"])) == 0
    out, err = capsys.readouterr()
    assert "note: the LiDAR (8 beams, range_max 0.2 m) cannot see the scene's obstacles in time: cylinders[0]" in err
    res = json.loads(out)
    assert res["warnings"]["lidar_sees_obstacles_late"] < 0 and res["collision"]


def test_the_two_beam_rule():
    from bigcbf.sanity import first_seen_gap
    # 360 beams, 8 m: a 0.1 m post is seen by two beams from r / sin(1 deg) = 5.73 m (centre), 5.48 m from a 0.15 m
    # footprint; 4 beams or fewer never give two beams on anything
    assert first_seen_gap(0.1, 360, 8.0, 0.15) == pytest.approx(0.1 / np.sin(2 * np.pi / 360) - 0.25)
    assert first_seen_gap(0.1, 360, 2.0, 0.15) == pytest.approx(1.85)     # range-limited: 2 m to the surface
    assert first_seen_gap(0.1, 4, 8.0, 0.15) == -np.inf
