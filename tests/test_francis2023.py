"""The francis2023 suite (bigcbf/bench/francis2023.py, bigcbf/scenarios/francis2023/): the 13 archetypes of Francis
et al. 2023 as scenario files at the X3's scale, every file solvable for each of its 30 paired seeds, the check
refusing what it should, and ``bigcbf bench --suite francis2023`` reporting success per archetype."""
import json
import math
import re

import numpy as np
import pytest

from bigcbf.bench import francis2023
from bigcbf.bench.suites import SUITES
from bigcbf.cli import build_parser, main
from bigcbf.cli.bench import config_from_args
from bigcbf.episode import Episode
from bigcbf.scenario import all_scenario_files, load_scenario, parse_scenario

FILES = francis2023.files()

#: whether the person reacts to the robot, as each archetype describes it (the files' descriptions say why)
REACTIVE = {"frontal_approach": True, "pedestrian_obstruction": False, "pedestrian_overtaking": True,
            "robot_overtaking": False, "down_path": True, "intersection": True, "blind_corner": False,
            "narrow_hallway": True, "narrow_doorway": True, "entering_room": True, "exiting_room": True,
            "entering_elevator": False, "exiting_elevator": True}


def test_thirteen_archetypes_shipped_in_francis_order():
    assert list(FILES) == [n for n, _ in francis2023.ARCHETYPES] == list(REACTIVE)
    assert sorted(p.name for p in francis2023.FOLDER.glob("*.toml")) == sorted(f"francis2023_{n}.toml" for n in FILES)
    shipped = all_scenario_files()
    for name, path in FILES.items():
        sc = load_scenario(path, 0)
        assert sc.name == f"francis2023_{name}" and shipped[sc.name] == path      # loadable by name too
        text = path.read_text()
        assert "Francis et al. 2023" in text and "Scale:" in text and "robot_sf" in text      # how it was scaled
        assert len(sc.pedestrians) == 1 and sc.pedestrians[0].reactive is REACTIVE[name], name
        assert sc.robot.model == "rosmaster_x3" and sc.time_limit_s <= 40


def test_every_file_is_solvable_for_each_of_its_30_seeds():
    assert SUITES.get("francis2023").default_seeds == francis2023.SEEDS == 30
    for name, path in FILES.items():
        for seed in range(francis2023.SEEDS):
            res = francis2023.check_file(path, seed)
            assert res.ok, (name, seed, res.reason)
            assert res.passage_m >= 0.8 - 0.1 and res.path_length_m >= 5.0


def test_seeds_are_paired_and_draw_different_worlds():
    for name, path in FILES.items():
        a, b, c = load_scenario(path, 4), load_scenario(path, 4), load_scenario(path, 5)
        assert a == b and a != c, name


def _variant(name: str, old: str, new: str, count: int = 1) -> str:
    text = FILES[name].read_text()
    changed, n = re.subn(old, new, text, count=count)
    assert n == count, (old, name)
    return changed


def _check_text(text: str, tmp_path, seed: int = 0):
    f = tmp_path / "variant.toml"
    f.write_text(text)
    return francis2023.check_file(f, seed)


@pytest.mark.parametrize("name, old, new, count, reason", [
    # a door 0.5 m wide: the robot's footprint cannot pass, or only through a passage under 0.8 m
    ("narrow_doorway", r"\{ uniform = \[-0.575, -0.5\] \}", "-0.3", 1, "narrower than 0.8 m"),
    # the hallway closed: a wall across it
    ("frontal_approach", r"\[\[pedestrians\]\]", "[[walls]]\nstart = [5.0, -1.55]\nend = [5.0, 1.55]\n\n"
     "[[pedestrians]]", 1, "no free path"),
    # the person walked through the room's wall
    ("entering_room", r"\[\{ uniform = \[4.2, 4.5\] \}, \{ uniform = \[-1.6, -1.3\] \}\]", "[4.2, -3.0]", 1,
     "runs through static geometry"),
    # the passenger stepping onto the goal
    ("entering_elevator", r"\[6.2, \{ choice = \[-0.45, 0.45\] \}\]", "[5.5, 0.05]", 1, "on the goal"),
    # a time limit below the rule's for the route
    ("blind_corner", r"time_limit_s = 32.0", "time_limit_s = 20.0", 1, "shorter than the rule's"),
])
def test_the_check_refuses_broken_variants(name, old, new, count, reason, tmp_path):
    res = _check_text(_variant(name, old, new, count), tmp_path)
    assert not res.ok and reason in res.reason, res.reason


def test_draft_bounds_keep_the_route_inside_the_walls():
    d = francis2023.draft(load_scenario(FILES["blind_corner"], 0))
    assert d.bounds == pytest.approx((-1.0, 7.05, -1.05, 7.0))
    assert len(d.walls) == 2 and len(d.boxes) == 1 and d.pedestrians[0]["reactive"] is False


@pytest.mark.parametrize("name", list(FILES))
def test_each_archetype_runs_as_an_episode(name):
    sc = load_scenario(FILES[name], 0)
    r = Episode(sc, "cbf-only", 0, time_limit_s=2.0).run()
    assert r.control_steps == 40 and not r.collision
    assert r.final_goal_dist_m < math.dist(sc.robot.start[:2], sc.robot.goal) - 0.3      # it set off


def test_the_suite_runs_13_files_30_seeds_labelled_by_archetype(tmp_path):
    out = tmp_path / "o"
    config = config_from_args(build_parser().parse_args(["bench", "--out", str(out), "--suite", "francis2023"]))
    assert config.seeds == tuple(range(30)) and len(config.scenarios) == 13
    assert [(fam, split) for _, split, fam in config.labels] == [(n, "francis2023") for n in FILES]
    assert main(["bench", "--out", str(out), "--suite", "francis2023", "--split", "dev"]) == 2


def test_bench_reports_success_per_archetype(tmp_path, capsys):
    out = tmp_path / "b"
    some = [str(FILES["exiting_elevator"]), str(FILES["entering_elevator"])]
    assert main(["bench", "--out", str(out), "--suite", "francis2023", "--scenarios", *some, "--seeds", "1",
                 "--methods", "cbf-only", "--workers", "1"]) in (0, 1)
    summary = json.loads((out / "summary.json").read_text())
    fam = summary["by_family"]["cbf-only"]["francis2023"]
    assert list(fam) == ["exiting_elevator", "entering_elevator", "all"] or \
        list(fam) == ["entering_elevator", "exiting_elevator", "all"]
    assert all(fam[f]["ok"] == 1 for f in ("exiting_elevator", "entering_elevator")) and fam["all"]["ok"] == 2
    md = (out / "summary.md").read_text()
    assert "Success per family (%), split francis2023" in md and "entering_elevator" in md
    assert np.isfinite(fam["all"]["success_pct"])
