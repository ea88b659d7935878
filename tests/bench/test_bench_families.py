"""The generated suite in the bench: splits, families and the chatter/stall columns in the reports."""
from __future__ import annotations

import csv
import dataclasses
import json

import matplotlib.image as mpimg
import pytest

from bigcbf import worlds
from bigcbf.bench import report
from bigcbf.bench.runner import BenchConfig, run_bench
from bigcbf.bench.testing import fake_episode
from bigcbf.cli import build_parser, main
from bigcbf.cli.bench import config_from_args
from bigcbf.worlds import FAMILIES


def test_generated_suite_has_300_worlds_or_more_in_disjoint_splits():
    assert sum(len(seeds) for fam in FAMILIES.values() for seeds in fam.splits.values()) >= 300
    assert all(not set(fam.splits["dev"]) & set(fam.splits["test"]) for fam in FAMILIES.values())


@pytest.fixture
def small_splits(monkeypatch):
    """Two dev worlds and one test world per family (generating all 360 takes seconds)."""
    small = {"dev": range(0, 2), "test": range(1000, 1001)}
    for name, fam in FAMILIES.items():
        monkeypatch.setitem(FAMILIES._items, name, dataclasses.replace(fam, splits=small))
    return small


def test_generated_suite_writes_its_worlds_and_selects_a_split(tmp_path, small_splits):
    out = tmp_path / "o"
    config = config_from_args(build_parser().parse_args(["bench", "--out", str(out), "--suite", "generated",
                                                         "--split", "dev"]))
    n_dev = len(FAMILIES) * 2
    assert len(config.scenarios) == len(config.labels) == n_dev and config.seeds == (0,)
    assert {split for _, split, _ in config.labels} == {"dev"}
    per_family = {f: sum(fam == f for _, _, fam in config.labels) for f in FAMILIES}
    assert set(per_family.values()) == {2}
    # interleaved: the first len(FAMILIES) entries are one world of each family
    assert [fam for _, _, fam in config.labels[:len(FAMILIES)]] == list(FAMILIES)
    assert len(list((out / "worlds" / "dev").glob("*.toml"))) == n_dev
    assert not (out / "worlds" / "test").exists()
    assert (out / "worlds" / "dev" / "posts_00001.toml").read_text() == worlds.generate("posts", 1).toml
    total = len(FAMILIES) * 3
    everything = config_from_args(build_parser().parse_args(["bench", "--out", str(out), "--suite", "generated"]))
    assert len(everything.scenarios) == total
    # a subset given by path keeps its labels
    some = [str(out / "worlds" / "test" / "room_01000.toml"), str(out / "worlds" / "dev" / "posts_00001.toml")]
    sub = config_from_args(build_parser().parse_args(["bench", "--out", str(out), "--suite", "generated",
                                                      "--scenarios", *some]))
    assert sub.labels == ((some[0], "test", "room"), (some[1], "dev", "posts"))


@pytest.mark.parametrize("extra, message", [
    (["--suite", "paper", "--split", "dev"], "suite 'paper' has no splits"),
    (["--suite", "generated", "--split", "train"], "suite 'generated' has no split 'train'; known: dev, test"),
    (["--suite", "generated", "--split", "dev", "--scenarios", "corridor_meeting"], "drop it when giving"),
])
def test_split_mistakes_are_one_line(extra, message, tmp_path, capsys):
    assert main(["bench", "--out", str(tmp_path / "o"), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()


def test_generated_suite_at_fresh_world_seeds(tmp_path, small_splits):
    """--world-seeds: every family at those seeds, split fresh, seed by seed across families, in the order given."""
    out = tmp_path / "o"
    config = config_from_args(build_parser().parse_args(["bench", "--out", str(out), "--suite", "generated",
                                                         "--world-seeds", "2001-2002", "7", "2001"]))
    assert len(config.scenarios) == len(FAMILIES) * 3 and {sp for _, sp, _ in config.labels} == {"fresh"}
    assert [fam for _, _, fam in config.labels[:len(FAMILIES)]] == list(FAMILIES)
    names = [p.rsplit("/", 1)[1] for p, _, fam in config.labels if fam == "posts"]
    assert names == ["posts_02001.toml", "posts_02002.toml", "posts_00007.toml"]
    assert (out / "worlds" / "fresh" / "room_02002.toml").read_text() == worlds.generate("room", 2002).toml
    assert not (out / "worlds" / "dev").exists() and not (out / "worlds" / "test").exists()
    # the Python API takes the seeds themselves
    from bigcbf.api import bench_config
    api = bench_config(tmp_path / "a", suite="generated", world_seeds=range(3000, 3001), methods=["cbf-only"])
    assert [fam for _, _, fam in api.labels] == list(FAMILIES) and {sp for _, sp, _ in api.labels} == {"fresh"}
    from bigcbf.errors import UserError
    for bad, message in [("2000", "expected a count of seeds or a list of seeds"), ([2000, -1], "-1"),
                         ([2000, 1000], "world seed 1000 is a seed of the test split")]:
        with pytest.raises(UserError, match=message) as err:
            bench_config(tmp_path / "c", suite="generated", world_seeds=bad)
        assert err.value.field == "world_seeds"
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("extra, message", [
    (["--suite", "generated", "--world-seeds", "1"], "world seed 1 is a seed of the dev split of the family"),
    (["--suite", "generated", "--world-seeds", "990-1000"], "world seed 1000 is a seed of the test split"),
    (["--suite", "generated", "--world-seeds", "2010-2000"], "the range 2010-2000 ends before it starts"),
    (["--suite", "generated", "--world-seeds", "20x"], "--world-seeds expects seeds N or ranges A-B, got '20x'"),
    (["--suite", "generated", "--world-seeds", "-3"], "--world-seeds expects seeds N or ranges A-B, got '-3'"),
    (["--suite", "generated", "--world-seeds", "99999999999"], "--world-seeds must be <= 4294967295"),
    (["--suite", "generated", "--world-seeds", "0-20000"], "at most 10000 world seeds"),
    (["--suite", "generated", "--world-seeds", "2000", "--split", "dev"], "drop --split and --scenarios"),
    (["--suite", "paper", "--world-seeds", "2000"], "suite 'paper' has no worlds drawn by seed"),
])
def test_world_seed_mistakes_are_one_line(extra, message, tmp_path, capsys, small_splits):
    assert main(["bench", "--out", str(tmp_path / "o"), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()


def _row(scenario, method, success, collision=False, **kw):
    m = dict(success=success, collision=collision, timeout=not (success or collision), time_s=10.0,
             min_clearance_m=0.5, e_cbf=0.0, cbf_active_ratio=0.0, qp_infeasible_ratio=0.0, planner_p95_ms=0.0,
             cbf_p95_ms=0.0, perception_p95_ms=0.0, stopped_time_s=0.0, final_goal_dist_m=0.1, sim_time_s=10.0,
             wall_time_s=1.0, control_steps=200, mode_history=[[0.0, "GOAL"]], perception="lidar", warnings={},
             mode_switches_per_min=0.0, side_reversals=0, lateral_reversals=0, no_progress_s=0.0)
    m.update(kw)
    return dict(scenario=scenario, method=method, seed=0, params_hash="p", scenario_sha="s", status="ok",
                error=None, metrics=m, worker_wall_s=1.0, host="h", attempts=1, code_sha="c")


def test_summary_per_family_and_split_by_hand(tmp_path):
    groups = {"posts_00000": {"split": "dev", "family": "posts"}, "posts_00001": {"split": "dev", "family": "posts"},
              "room_00000": {"split": "dev", "family": "room"}, "room_01000": {"split": "test", "family": "room"}}
    scen = list(groups)
    rows = [_row("posts_00000", "big-cbf", True, side_reversals=1, lateral_reversals=2, no_progress_s=0.0),
            _row("posts_00001", "big-cbf", False, side_reversals=5, lateral_reversals=6, no_progress_s=20.0,
                 mode_switches_per_min=30.0),
            _row("room_00000", "big-cbf", False, collision=True, side_reversals=0, lateral_reversals=1),
            _row("room_01000", "big-cbf", True)]
    s = report.build_summary(rows, ["big-cbf"], scen, [0], groups=groups)
    fam = s["by_family"]["big-cbf"]
    assert list(fam) == ["dev", "test"] and list(fam["dev"]) == ["posts", "room", "all"]
    # posts (dev): 1 of 2 succeeded; reversals (1 + 5) / 2 modes, (2 + 6) / 2 command; no progress 10 s;
    # switches 15 / min; room (dev): a collision; dev overall: 1 of 3, 1 collision
    posts = fam["dev"]["posts"]
    assert posts["success_pct"] == pytest.approx(50.0) and posts["side_reversals"] == pytest.approx(3.0)
    assert posts["lateral_reversals"] == pytest.approx(4.0) and posts["no_progress_s"] == pytest.approx(10.0)
    assert posts["mode_switches_per_min"] == pytest.approx(15.0)
    assert fam["dev"]["room"]["collisions"] == 1 and fam["dev"]["all"]["success_pct"] == pytest.approx(100 / 3)
    assert fam["test"]["room"]["success_pct"] == 100.0 and list(fam["test"]) == ["room", "all"]
    md = report.summary_markdown(s)
    assert "Success per family (%), split dev" in md and "Success per family (%), split test" in md
    assert "| BIG-CBF | 50 | 0 | 33 |" in md                     # posts, room, all of the dev split
    assert "Chatter and stall" in md and "Ours beside the paper" not in md
    # the paper's suite (no groups): per-scenario table and the paper's numbers as before
    plain = report.summary_markdown(report.build_summary(rows, ["big-cbf"], scen, [0]))
    assert "Success per scenario" in plain and "per family" not in plain
    assert "Not comparable with the paper's Table II" in plain        # made-up scenes: no paper figures beside them
    report.write_reports(tmp_path, rows, ["big-cbf"], scen, [0], groups=groups)
    with (tmp_path / "episodes.csv").open() as fh:
        lines = list(csv.DictReader(fh))
    assert [(r["scenario"], r["split"], r["family"]) for r in lines][-1] == ("room_01000", "test", "room")
    assert json.loads((tmp_path / "summary.json").read_text())["groups"] == groups
    assert mpimg.imread(tmp_path / "success_heatmap.png").shape[0] > 100


def test_bench_of_generated_worlds_reports_families(tmp_path, small_splits):
    out = tmp_path / "b"
    config = config_from_args(build_parser().parse_args(["bench", "--out", str(out), "--suite", "generated",
                                                         "--split", "test", "--methods", "cbf-only"]))
    config = BenchConfig(**{**config.__dict__, "workers": 1})
    outcome = run_bench(config, progress=False, episode_fn=fake_episode, log=lambda msg: None)
    fam = outcome.summary["by_family"]["cbf-only"]
    assert list(fam) == ["test"] and sorted(fam["test"]) == sorted(list(FAMILIES) + ["all"])
    assert all(fam["test"][f]["ok"] == 1 for f in FAMILIES)
    assert "split test" in (out / "summary.md").read_text()
