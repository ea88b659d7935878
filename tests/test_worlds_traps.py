"""The ``traps`` world family (bigcbf/worlds/traps.py): U-shaped pockets and L-shaped dead ends of several depths on
the start-goal line, always with a route around; dev and test splits like the other families; the other families'
worlds unchanged by its registration."""
import hashlib
import math

import numpy as np
import pytest

from bigcbf import worlds
from bigcbf.cli import main
from bigcbf.episode import Episode
from bigcbf.scenario import load_scenario
from bigcbf.worlds import FAMILIES, FOOTPRINT_M, check, generate
from bigcbf.worlds.traps import DEPTHS, first_hit

SPLIT_SEEDS = list(range(0, 30)) + list(range(1000, 1030))

#: sha256 of ``bigcbf scenarios generate FAMILY --seed 3`` for the six families before traps was added (generator
#: version 1): adding a family must leave every other family's worlds byte for byte as they were
BEFORE_TRAPS = {
    "posts": "5e8aac96fbda0631289f3c1897311cce62c00f8d7bca5f60b88eba7e32e9e3c5",
    "clutter": "c93be3d5da0a2755a5bdb6a6632fae12b76e4f408cd07a65b9f7d34a9c542e81",
    "corridor": "f8db407e36b43a67fb0157ba884a31598f19f6cd2ebb1935bb27563370306871",
    "doorway": "b7aaf4b555c395136b78fd0aaad1a4f4fbfc9f94ce6ce5e0cb9c53971fdf8eef",
    "crowd": "da814e24dd1cf775744de94f1549b4b8aa86c3f3328cab19072e5ab8db456abf",
    "room": "2d181fec5d6eeebb75c772f462d3b43a17c052ce4bb2c850973a238a778f6950",
}


def test_registered_with_the_usual_splits_after_the_other_families():
    fam = FAMILIES["traps"]
    assert fam.splits == {"dev": range(0, 30), "test": range(1000, 1030)}
    names = FAMILIES.names()
    assert names.index("traps") > max(names.index(f) for f in BEFORE_TRAPS) and fam.order == 7
    assert FAMILIES.tags("traps") == ("dev", "test")


def test_the_other_families_worlds_are_unchanged(capsys):
    for name, digest in BEFORE_TRAPS.items():
        assert main(["scenarios", "generate", name, "--seed", "3"]) == 0
        assert hashlib.sha256(capsys.readouterr().out.encode()).hexdigest() == digest, name


def _trap_extent(d) -> tuple[float, float]:
    """(interior depth, interior width) measured on the boxes: the arms' length, the gap between the arms."""
    back, arms = d.boxes[0], d.boxes[1:]
    depth = 2 * arms[0]["half_size"][0]
    width = 2 * back["half_size"][1] - 2 * 2 * back["half_size"][0]
    return depth, width


def test_every_split_world_is_a_trap_on_the_goal_line_with_a_route_around():
    shapes, classes = set(), set()
    deep = 0
    for seed in SPLIT_SEEDS:
        w = generate("traps", seed)
        d = w.draft
        shape = "U" if len(d.boxes) == 3 else "L"
        assert len(d.boxes) in (2, 3) and len(d.walls) == 2 and not d.pedestrians
        depth, width = _trap_extent(d)
        assert 0.4 - 1e-3 <= depth <= 2.5 + 1e-3 and 0.9 - 1e-2 <= width <= 2.2 + 1e-2
        klass = next(k for k, (lo, hi) in DEPTHS.items() if lo - 1e-3 <= depth <= hi + 1e-3)
        assert f"({klass})" in d.params["depth"] and d.params["trap"].startswith(shape)
        shapes.add(shape)
        classes.add(klass)
        deep += depth > 1.5 * 0.8
        # driving straight at the goal runs into the back wall, from inside the trap
        assert first_hit(d) == 0
        # the arms and the back wall are one concave piece: the back wall's ends cover the arms' outer faces
        # and the route goes around it, never closer than the footprint to any surface, and is longer
        res = check(d)
        assert res.ok and res.passage_m >= worlds.MIN_PASSAGE_M - 0.1
        pts = worlds._polyline_points(res.route, 0.01)
        assert float(worlds.distance(pts, *worlds._primitives(d)).min()) >= FOOTPRINT_M
        assert w.path_length_m > math.dist(d.start[:2], d.goal) + 0.05
    assert shapes == {"U", "L"} and classes == set(DEPTHS) and deep >= 10


def test_the_requirement_rejects_a_trap_off_the_line():
    d = generate("traps", 4).draft
    moved = worlds.Draft(start=d.start, goal=d.goal, bounds=d.bounds, walls=d.walls,
                         boxes=[dict(b, center=[b["center"][0], b["center"][1] + 2.0]) for b in d.boxes])
    assert first_hit(moved) is None and first_hit(d) == 0
    assert d.requirement(moved, 30.0) and d.requirement(d, 30.0) is None


def test_a_deep_trap_runs_as_an_episode(tmp_path):
    seed = next(s for s in SPLIT_SEEDS if "(deep)" in generate("traps", s).draft.params["depth"])
    w = generate("traps", seed)
    f = tmp_path / f"{w.name}.toml"
    worlds.write(w, f)
    sc = load_scenario(f, 0)
    assert len(sc.boxes) == len(w.draft.boxes) and sc.time_limit_s == w.time_limit_s
    r = Episode(sc, "cbf-only", 0, time_limit_s=3.0).run()
    assert r.control_steps == 60 and not r.collision
    assert r.final_goal_dist_m < math.dist(sc.robot.start[:2], sc.robot.goal) - 0.5     # it drove toward the goal


def test_cli_lists_and_writes_a_trap(tmp_path, capsys):
    assert main(["scenarios", "generate", "--list"]) == 0
    out = capsys.readouterr().out
    assert "traps: a U-shaped pocket or an L-shaped dead end" in out and "deep 1.3-2.5 m" in out
    f = tmp_path / "t.toml"
    assert main(["scenarios", "generate", "traps", "--seed", "1001", "--out", str(f)]) == 0
    assert f.read_text() == generate("traps", 1001).toml and load_scenario(f, 0).name == "traps_01001"


@pytest.mark.parametrize("seed", [0, 1000])
def test_same_seed_same_world(seed):
    assert generate("traps", seed).toml == generate("traps", seed).toml != generate("traps", seed + 1).toml
