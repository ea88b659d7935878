"""Scenario files: every shipped scenario loads, builds and runs; paired seeds; errors name file and field."""
import numpy as np
import pytest

from bigcbf.cli import main
from bigcbf.errors import UserError
from bigcbf.scenario import load_scenario, scenario_files
from bigcbf.sim.pedestrians import Pedestrians

NAMES = ["blind_corner", "corridor_meeting", "single_person_crossing", "crowd_crossing", "delay_and_slip",
         "double_squeeze", "mixed_dense_traffic", "multi_static_clutter", "required_sidestepping"]


def test_the_nine_scenarios_ship():
    assert sorted(scenario_files()) == sorted(NAMES)


@pytest.mark.parametrize("name", NAMES)
def test_same_seed_same_world_other_seed_other_world(name):
    a, b, c = load_scenario(name, 3), load_scenario(name, 3), load_scenario(name, 4)
    assert a == b
    assert a != c or not any("uniform" in line for line in open(scenario_files()[name]))


def test_scenario_from_a_path_outside_the_folder(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text('name = "mine"\ndescription = "a test"\ntime_limit_s = 5\n[robot]\nstart = [0, 0, 0]\ngoal = [1, 0]\n')
    sc = load_scenario(str(f), 0)
    assert sc.name == "mine" and sc.file == str(f)


BASE = 'name = "x"\ndescription = "d"\ntime_limit_s = 10\n[robot]\nstart = [0, 0, 0]\ngoal = [5, 0]\n'


@pytest.mark.parametrize("extra, field, words", [
    ("colour = 3\n", "colour", "unknown key"),
    ("[[pedestrians]]\nname = 'p'\nwaypoints = [[0, 1]]\nspeed_mps = 1\n", "pedestrians[0].waypoints",
     "at least 2 waypoints"),
    ("[[pedestrians]]\nname = 'p'\nwaypoints = [[0, 1], [1, 1]]\nspeed_mps = 'fast'\n", "pedestrians[0].speed_mps",
     "expected a number"),
    ("[[cylinders]]\ncenter = [1, { uniform = [2, 1] }]\nradius_m = 0.2\n", "cylinders[0].center[1]", "lo <= hi"),
    ("[[walls]]\nstart = [0, 0]\n", "walls[0].end", "missing key"),
    ("[robot_profile]\nlatency = 0.1\n", "robot_profile.latency", "unknown key"),
])
def test_errors_name_the_file_and_the_field(tmp_path, extra, field, words):
    f = tmp_path / "bad.toml"
    text = BASE + extra if not extra.startswith("colour") else extra + BASE
    f.write_text(text)
    with pytest.raises(UserError) as err:
        load_scenario(str(f), 0)
    msg = str(err.value)
    assert str(f) in msg and f"'{field}'" in msg and words in msg


def test_unknown_scenario_name_lists_the_known_ones():
    with pytest.raises(UserError, match="required_sidestepping"):
        load_scenario("no_such_scenario")


def test_cli_lists_scenarios(capsys):
    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 9 and all(len(line.split()) > 3 for line in out)


def test_pedestrian_walks_its_path_at_its_speed():
    peds = Pedestrians([[(0, 0), (5, 0)]], [1.0], [0.5], [0.25], [False], [False])
    for k in range(1500):                      # 3 s at 2 ms
        peds.step(k * 0.002, 0.002)
    # stood until 0.5 s, relaxed to 1 m/s with tau = 0.5 s: x(3) = 2.5 - 0.5 (1 - e^-5) = 2.0034
    assert peds.p[0, 0] == pytest.approx(2.5 - 0.5 * (1 - np.exp(-5)), abs=0.01)
    assert peds.p[0, 1] == pytest.approx(0.0, abs=1e-9)


def test_reactive_pedestrian_steps_aside_for_the_robot_non_reactive_does_not():
    out = []
    for reactive in (True, False):
        peds = Pedestrians([[(0, 0), (6, 0)]], [1.0], [0.0], [0.25], [False], [reactive])
        dev = 0.0
        for k in range(2000):
            peds.step(k * 0.002, 0.002, robot_xy=(3.0, -0.2))
            dev = max(dev, abs(peds.p[0, 1]))
        out.append(dev)
    assert out[0] > 0.1 and out[1] < 1e-9


HARDWARE = ["lab_required_sidestepping", "lab_static_clutter", "lab_pedestrian_crossing"]


def test_hardware_scenes_ship_beside_the_nine_and_load_by_name_or_path():
    from bigcbf.scenario import load_robot_profile
    assert sorted(scenario_files("hardware")) == sorted(HARDWARE)
    for name in HARDWARE:
        a = load_scenario(name, 2)
        b = load_scenario(str(scenario_files("hardware")[name]), 2)
        assert a == b and a.name == name
        assert a.robot_profile == load_robot_profile("x3_hardware")


@pytest.mark.parametrize("name", HARDWARE)
def test_hardware_scene_runs_with_the_physical_preset(name):
    from bigcbf.bench.suites import SUITES
    from bigcbf.episode import Episode
    params = SUITES.get("hardware").params()
    assert (params.uncertainty.r_robot_m, params.uncertainty.d0_m, params.uncertainty.beta,
            params.uncertainty.e_zoh_m, params.uncertainty.kappa_img) == (0.15, 0.05, 1.0, 0.0716, 0.8)
    res = Episode(load_scenario(name, 0), "big-cbf", 0, params, time_limit_s=2.0).run()
    assert not res.collision and res.control_steps >= 39
