"""Procedural worlds (bigcbf/worlds/): every family generates valid, solvable, reproducible scenario files; the
checks reject what they should; the command line writes and lists them."""
import math

import numpy as np
import pytest

from bigcbf import worlds
from bigcbf.cli import main
from bigcbf.episode import Episode
from bigcbf.scenario import load_scenario
from bigcbf.worlds import FAMILIES, FOOTPRINT_M, Draft, check, generate

SEEDS = (0, 1, 2, 1000)


def _sampled_distance(d: Draft, poly: np.ndarray, step: float = 0.01) -> float:
    """Exact distance from a polyline (sampled every 1 cm) to the draft's static geometry."""
    pts = worlds._polyline_points(poly, step)
    return float(worlds.distance(pts, *worlds._primitives(d)).min())


@pytest.mark.parametrize("family", list(FAMILIES))
def test_every_family_writes_loadable_solvable_worlds_with_the_documented_time_limit(family, tmp_path):
    for seed in SEEDS:
        w = generate(family, seed)
        f = tmp_path / f"{w.name}.toml"
        worlds.write(w, f)
        sc = load_scenario(f, 0)                    # the loader reads what the generator wrote
        assert sc.name == w.name == f"{family}_{seed:05d}"
        assert sc == worlds.parse(w.toml, file=str(f))
        assert f"seed {seed}" in sc.description and "time limit" in sc.description.lower()
        assert sc.time_limit_s == w.time_limit_s == math.ceil(w.path_length_m / 0.5 + 8 + 1.5 * len(sc.pedestrians))
        assert len(sc.walls) + len(sc.boxes) + len(sc.cylinders) > 0 and sc.robot.start[:2] != sc.robot.goal
        res = check(w.draft)
        assert res.ok and res.path_length_m == pytest.approx(w.path_length_m)
        # the route the check found keeps the footprint and its clearance from every surface (checked exactly,
        # not on the grid), and is no shorter than the straight line
        assert _sampled_distance(w.draft, res.route) >= FOOTPRINT_M
        assert res.route[0] == pytest.approx(sc.robot.start[:2]) and res.route[-1] == pytest.approx(sc.robot.goal)
        assert w.path_length_m >= math.dist(sc.robot.start[:2], sc.robot.goal) - 1e-9
        assert res.passage_m >= worlds.MIN_PASSAGE_M - 0.1
        for p in sc.pedestrians:               # pedestrians are routed around static geometry
            assert _sampled_distance(w.draft, np.array(p.waypoints)) >= p.radius_m + 0.04


def test_same_seed_same_file_other_seed_other_world():
    for family in FAMILIES:
        assert generate(family, 7).toml == generate(family, 7).toml
        assert generate(family, 7).draft != generate(family, 8).draft


def test_corridor_slow_walker_is_too_slow_to_follow_and_directions_keep_to_their_sides():
    found = 0
    for seed in range(12):
        w = generate("corridor", seed)
        ys = {+1: [], -1: []}
        for p in w.draft.pedestrians:
            (x0, y0), (x1, y1) = p["waypoints"]
            assert y0 == y1
            ys[1 if x1 > x0 else -1].append(y0)
        assert all(a * b <= 0 for a in ys[1] for b in ys[-1])
        slow = [p for p in w.draft.pedestrians if p["name"] == "slow_ahead"]
        if slow:
            found += 1
            p = slow[0]
            follow_s = (w.draft.goal[0] + 0.9 - p["waypoints"][0][0]) / p["speed_mps"]
            assert 0.2 <= p["speed_mps"] <= 0.35 and follow_s >= w.time_limit_s + 4.0 - 0.05
    assert found >= 4


def _lane(gap_m: float, **kw) -> Draft:
    """A 4 m wide walled lane, 10 m long, with a cross wall at x = 4 that leaves one gap of ``gap_m`` on the axis."""
    d = Draft(start=(0.0, 0.0, 0.0), goal=(8.0, 0.0), bounds=(-1.0, 9.0, -2.0, 2.0), **kw)
    d.wall((-1.0, -2.0), (9.0, -2.0))
    d.wall((-1.0, 2.0), (9.0, 2.0))
    d.box((4.0, (-2.0 - gap_m / 2) / 2), (0.1, (2.0 - gap_m / 2) / 2))
    d.box((4.0, (2.0 + gap_m / 2) / 2), (0.1, (2.0 - gap_m / 2) / 2))
    return d


def test_check_rejects_closed_and_narrow_worlds_and_measures_the_passage():
    assert "no free path" in check(_lane(0.45)).reason              # < 2 x 0.25 m + grid allowance
    assert "narrower than 0.8" in check(_lane(0.65)).reason          # solvable in principle, narrower than 0.8 m
    res = check(_lane(1.0))
    assert res.ok and res.passage_m == pytest.approx(1.0, abs=2 * worlds.GRID_M)
    # the straight line through the gap: the route is the straight line
    assert res.path_length_m == pytest.approx(8.0, abs=1e-6)


def test_path_length_around_a_post_matches_the_tangent_arc_tangent_length():
    d = Draft(start=(0.0, 0.0, 0.0), goal=(8.0, 0.0), bounds=(-1.0, 9.0, -3.0, 3.0))
    d.cylinder((4.0, 0.0), 0.5)
    res = check(d)
    # the route keeps R = 0.5 + c from the centre, c = 0.4 - 0.035 m (the 0.8 m passage rule on the grid):
    # L = 2 sqrt(d^2 - R^2) + R (pi - 2 acos(R / d)) with d = 4
    R = 0.5 + worlds.MIN_PASSAGE_M / 2 - worlds.GRID_M / 2 - worlds.GRID_ALLOWANCE_M / 2
    exact = 2 * math.sqrt(16 - R ** 2) + R * (math.pi - 2 * math.acos(R / 4))
    assert res.ok and exact - 0.02 <= res.path_length_m <= exact * 1.03


def test_check_rejects_trivial_worlds_and_blocking_pedestrians():
    d = Draft(start=(0.0, 0.0, 0.0), goal=(8.0, 0.0), bounds=(-1.0, 9.0, -3.0, 3.0), needs_detour=True)
    d.cylinder((4.0, 2.0), 0.3)                    # 1.7 m from the line: a straight drive passes it
    assert check(d).reason.startswith("trivial")
    d.cylinder((4.0, 0.6), 0.3)
    assert check(d).ok
    # a pedestrian that stops in the gap closes the only way
    d = _lane(1.0)
    d.pedestrian("stopper", [(6.0, 0.0), (4.0, 0.0)], 1.0, 0.0, 0.3, True)
    assert "block every path" in check(d).reason
    d = _lane(1.0)
    d.pedestrian("waiter", [(4.0, 0.0), (6.0, 0.0), (6.0, 1.5)], 1.0, 3.0, 0.3, True)   # waits 3 s in the gap
    assert "block every path" in check(d).reason
    d = _lane(1.0)
    d.pedestrian("walker", [(6.0, 1.4), (6.0, -1.4)], 1.0, 0.0, 0.25, True)   # crosses, stops at the wall
    assert check(d).ok
    d = _lane(1.0)
    d.pedestrian("ghost", [(6.0, 1.4), (2.0, 1.4)], 1.0, 0.0, 0.25, True)     # through the cross wall
    assert "through static geometry" in check(d).reason
    d = _lane(1.0)
    d.pedestrian("close", [(0.6, 0.3), (2.0, 1.4)], 1.0, 0.0, 0.25, True)
    assert "too close to the robot" in check(d).reason


def test_generated_world_runs_as_an_episode():
    w = generate("crowd", 3)
    res = Episode(worlds.parse(w.toml), "cbf-only", 0, time_limit_s=1.0).run()
    assert res.control_steps == 20 and not res.collision


def test_cli_generates_lists_and_refuses_mistakes(tmp_path, capsys):
    out = tmp_path / "w.toml"
    assert main(["scenarios", "generate", "posts", "--seed", "4", "--out", str(out)]) == 0
    assert out.read_text() == generate("posts", 4).toml
    assert "posts_00004" in capsys.readouterr().out
    assert main(["scenarios", "generate", "posts", "--seed", "4", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert str(out) in err and "--force" in err and err.count("\n") == 1
    assert main(["scenarios", "generate", "posts", "--seed", "5", "--out", str(out), "--force"]) == 0
    assert "posts_00005" in out.read_text()
    assert main(["scenarios", "generate", "nope"]) == 2
    assert "unknown world family 'nope'" in capsys.readouterr().err
    assert main(["scenarios", "generate", "room", "--out", str(tmp_path / "no" / "w.toml")]) == 2
    capsys.readouterr()
    assert main(["scenarios", "generate", "--list"]) == 0
    listing = capsys.readouterr().out
    assert all(f"{name}:" in listing for name in FAMILIES) and "0.8-1.2 m" in listing
    assert main(["scenarios", "generate", "room", "--seed", "2"]) == 0      # no --out: print it
    assert capsys.readouterr().out == generate("room", 2).toml
