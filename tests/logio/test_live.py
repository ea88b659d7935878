"""bigcbf run --live: the episode's topics streamed over Foxglove's WebSocket protocol, read by a client on the
loopback interface (the protocol spoken by hand: JSON text frames, binary message and time frames)."""
from __future__ import annotations

import json
import struct
import threading

import pytest

pytest.importorskip("foxglove")
ws_client = pytest.importorskip("websockets.sync.client")

from bigcbf.episode import Episode  # noqa: E402
from bigcbf.logio.episode_log import EpisodeLogger  # noqa: E402
from bigcbf.logio.live import LiveWriter  # noqa: E402
from bigcbf.logio.msgdefs import typestore  # noqa: E402
from bigcbf.params.stack import SIMULATION  # noqa: E402
from bigcbf.scenario import load_scenario  # noqa: E402

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA, TIME = 1, 2


def test_a_loopback_client_receives_the_episodes_topics():
    live = LiveWriter(port=0)                          # a free port on 127.0.0.1
    try:
        ep = Episode(load_scenario("single_person_crossing", 0), "big-cbf", 0, SIMULATION, time_limit_s=1.0)
        EpisodeLogger(ep, writer=live)                 # writes /tf_static, /robot_description, /goal_pose now
        channels, subs, got, times = {}, {}, {}, []
        with ws_client.connect(live.url, subprotocols=[SUBPROTOCOL], open_timeout=10, close_timeout=1) as ws:

            def receive_until(done, limit_s=30.0):
                while not done():
                    m = ws.recv(timeout=limit_s)
                    if isinstance(m, str):
                        d = json.loads(m)
                        if d["op"] == "advertise":
                            new = [c for c in d["channels"] if c["id"] not in channels]
                            channels.update({c["id"]: c for c in new})
                            if new:
                                ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                                    {"id": c["id"], "channelId": c["id"]} for c in new]}))
                                subs.update({c["id"]: c for c in new})
                    elif m[0] == MESSAGE_DATA:
                        sub, log_time = struct.unpack_from("<IQ", m, 1)
                        c = subs[sub]
                        msg = typestore().deserialize_cdr(m[13:], c["schemaName"])
                        got.setdefault(c["topic"], []).append((log_time, msg))
                    elif m[0] == TIME:
                        times.append(struct.unpack_from("<Q", m, 1)[0])

            # latched topics reach a client that subscribes after they were sent; /goal_pose (not latched) does not
            receive_until(lambda: {"/tf_static", "/robot_description"} <= set(got))
            assert "/goal_pose" not in got
            runner = threading.Thread(target=ep.run)
            runner.start()
            receive_until(lambda: len(got.get("/clock", [])) >= 15 and "/scan" in got and "/plan" in got)
            runner.join(timeout=60)
            assert not runner.is_alive()
            # a time frame can arrive before the /clock message of the same instant (seen once in CI: a time of
            # 0.75 s without its /clock when the loop above stopped): read on until every broadcast time's clock is in
            receive_until(lambda: bool(times) and got["/clock"][-1][0] >= max(times))
        topics = {c["topic"]: c for c in channels.values()}
        assert {"/clock", "/tf", "/tf_static", "/scan", "/odom", "/cmd_vel", "/obstacles", "/plan"} <= set(topics)
        assert topics["/scan"]["schemaName"] == "sensor_msgs/msg/LaserScan" and topics["/scan"]["encoding"] == "cdr"
        static = got["/tf_static"][0][1]
        assert {t.child_frame_id for t in static.transforms} == {"laser", "imu_link"}
        assert "rosmaster_x3" in got["/robot_description"][0][1].data
        clock = [m.clock.sec * 10**9 + m.clock.nanosec for _, m in got["/clock"]]
        assert clock == sorted(clock) and clock[0] == 0 and [t for t, _ in got["/clock"]] == clock
        assert times and set(times) <= set(clock)          # the server's time follows the simulation clock
        assert len(got["/scan"][0][1].ranges) == 360
    finally:
        live.close()


def test_run_live_without_the_sdk_is_one_line(monkeypatch, capsys):
    import builtins

    from bigcbf.cli import main
    real_import = builtins.__import__

    def no_foxglove(name, *a, **k):
        if name == "foxglove" or name.startswith("foxglove."):
            raise ImportError("no foxglove")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_foxglove)
    assert main(["run", "single_person_crossing", "--live"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pip install 'bigcbf[live]'" in err[0]
