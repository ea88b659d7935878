"""The examples of docs/extending.md do what the page says: its planner code drives an episode, its scenario file
loads and runs for several seeds, its sensor example logs a second LiDAR without changing the episode."""
from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from bigcbf.episode import DETERMINISTIC_KEYS, Episode
from bigcbf.params.stack import SIMULATION
from bigcbf.scenario import load_scenario

DOCS = Path(__file__).resolve().parents[1] / "docs"
PAGE = (DOCS / "extending.md").read_text()


def test_the_pages_planner_is_the_tested_plugin_and_drives_an_episode():
    code = re.search(r"```python\n(.*?)```", PAGE, re.S).group(1)
    plugin = (Path(__file__).parent / "plugins" / "my_planners.py").read_text()
    body = lambda text: re.sub(r"\s+#[^\n]*", "", text[text.index("class GoalSeeker:"):].split("\ndef ")[0]).strip()  # noqa: E731
    assert body(code) == body(plugin)                 # the page shows the file the tests run (comments aside)
    ns: dict = {}
    exec(code, ns)
    planner = ns["GoalSeeker"](SIMULATION, ns["GoalSeekerParams"](speed_mps=0.4))
    ep = Episode(load_scenario("single_person_crossing", 0), None, 0, time_limit_s=3.0)
    ep.begin()
    while not ep.done:
        u, info = planner.plan(ep.world.t, ep.state, ep.obstacles_now(), ep.goal)
        ep.act(u)
    res = ep.result()
    assert res.final_goal_dist_m == pytest.approx(9.0 - 0.4 * 3.0, abs=0.25)   # 0.4 m/s for 3 s towards the goal


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_pages_scenario_loads_and_runs(seed):
    sc = load_scenario(DOCS / "examples" / "my_scene.toml", seed)
    assert sc.name == "doorway_and_walker" and len(sc.walls) == 2 and sc.robot_profile.latency_s == 0.04
    res = Episode(sc, "big-cbf", seed, SIMULATION, time_limit_s=4.0).run()
    assert not res.collision and res.warnings == {}


def test_the_pages_sensor_example_logs_a_second_lidar_and_changes_nothing(tmp_path):
    spec = importlib.util.spec_from_file_location("extra_lidar", DOCS / "examples" / "extra_lidar.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    out = mod.run(str(tmp_path / "x.mcap"), time_limit_s=2.0)
    assert out["scans"] == out["control_steps"] == 40 and out["mean_hits"] > 0
    with AnyReader([tmp_path / "x.mcap"]) as r:
        con = [c for c in r.connections if c.topic == "/scan_coarse"]
        assert len(con) == 1 and con[0].msgcount == 40
        _, _, raw = next(r.messages(connections=con))
        msg = r.deserialize(raw, con[0].msgtype)
    assert len(msg.ranges) == 90 and msg.range_max == 4.0 and msg.header.frame_id == "laser"
    plain = Episode(load_scenario("crowd_crossing", 0), "big-cbf", 0, time_limit_s=2.0).run()
    with_sensor = Episode(load_scenario("crowd_crossing", 0), "big-cbf", 0, time_limit_s=2.0)
    from bigcbf.sim.lidar import Lidar, LidarConfig
    extra = Lidar(with_sensor.world.model, LidarConfig(n_beams=90), rng=np.random.default_rng(7))
    with_sensor.observers.append(lambda rec: extra.scan(with_sensor.world.data, rec.t))
    res = with_sensor.run()
    assert {k: getattr(res, k) for k in DETERMINISTIC_KEYS} == {k: getattr(plain, k) for k in DETERMINISTIC_KEYS}
