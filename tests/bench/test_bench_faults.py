"""The faults suite: its plan (files with the fault, the same worlds as the shipped scenes), its report (a table per
fault and level), and a tiny version of it that runs real episodes."""
from __future__ import annotations

import json
import tomllib

import pytest

from bigcbf.bench import report
from bigcbf.bench.faults import FAULTS, LEVELS, REFERENCE, dumps, scenes, variant_name, variant_text
from bigcbf.bench.runner import BenchConfig, run_bench
from bigcbf.bench.suites import SUITES
from bigcbf.cli import build_parser, main
from bigcbf.cli.bench import config_from_args
from bigcbf.scenario import all_scenario_files, load_scenario


def test_the_catalogue_has_two_levels_of_each_fault_on_shipped_scenes():
    shipped = all_scenario_files()
    assert set(FAULTS) == {"lidar_noise", "scan_dropout", "blanked_sector", "latency_spikes", "odometry_drift",
                           "pedestrian_stops", "pedestrian_turns"}
    for f in FAULTS.values():
        assert tuple(f.levels) == LEVELS and f.scenes and all(s in shipped for s in f.scenes)
        for level in f.levels.values():
            assert level.summary and (level.robot_profile or level.pedestrian)
        if f.name.startswith("pedestrian") or f.name == "latency_spikes":       # dynamic scenes
            assert all(load_scenario(s, 0).pedestrians for s in f.scenes), f.name
    assert "faults" in SUITES.names() and SUITES.get("faults").splits == (REFERENCE, *LEVELS)


def test_the_suite_plans_every_fault_level_and_scene_beside_the_scenes_themselves(tmp_path):
    out = tmp_path / "o"
    config = config_from_args(build_parser().parse_args(["bench", "--out", str(out), "--suite", "faults"]))
    n_variants = sum(len(f.scenes) * len(LEVELS) for f in FAULTS.values())
    assert len(config.scenarios) == len(config.labels) == len(scenes()) + n_variants and config.seeds == tuple(range(5))
    assert config.suite == "faults"
    ref = [s for s, split, fam in config.labels if split == REFERENCE]
    assert ref == scenes() and all(fam == REFERENCE for _, split, fam in config.labels if split == REFERENCE)
    files = sorted((out / "faults").rglob("*.toml"))
    assert len(files) == n_variants
    for f in FAULTS.values():
        for level in LEVELS:
            for scene in f.scenes:
                path = out / "faults" / f.name / f"{variant_name(scene, f.name, level)}.toml"
                assert (str(path), level, f.name) in config.labels
    # --split picks a level
    severe = config_from_args(build_parser().parse_args(["bench", "--out", str(out), "--suite", "faults",
                                                         "--split", "severe"]))
    assert {split for _, split, _ in severe.labels} == {"severe"} and len(severe.scenarios) == n_variants // 2


@pytest.mark.parametrize("fault", list(FAULTS))
def test_a_variant_is_its_scene_with_the_fault_and_the_same_worlds(fault):
    f = FAULTS[fault]
    for scene in f.scenes:
        name, text = variant_text(scene, fault, "severe")
        v = tomllib.loads(text)
        assert v["name"] == name and v["draws_as"] == scene
        for seed in (0, 3):
            a = load_scenario(scene, seed)
            from bigcbf.scenario import parse_scenario
            b = parse_scenario(text, f"{name}.toml", seed)
            # the same world ...
            assert (a.walls, a.boxes, a.cylinders, a.robot, a.time_limit_s) == (b.walls, b.boxes, b.cylinders,
                                                                               b.robot, b.time_limit_s)
            assert [(p.waypoints, p.speed_mps, p.start_time_s) for p in a.pedestrians] == \
                [(p.waypoints, p.speed_mps, p.start_time_s) for p in b.pedestrians]
            # ... with the fault
            level = f.levels["severe"]
            if level.pedestrian:
                key = next(iter(level.pedestrian))
                assert all(getattr(p, key).enabled for p in b.pedestrians) and a.pedestrians
            else:
                assert b.robot_profile != a.robot_profile
                assert b.robot_profile.merged(**{k: getattr(a.robot_profile, k) for k in level.robot_profile}) \
                    == a.robot_profile            # only the tables the fault sets differ


def test_the_writer_keeps_inline_tables_where_a_value_follows_them():
    doc = {"name": "x", "robot": {"start": [0.0, 0.0, 0.0]}, "time_limit_s": {"uniform": [1.0, 2.0]},
           "walls": [{"start": [0.0, 1.0], "end": [1.0, 1.0]}], "robot_profile": {"lidar": {"n_beams": 90}}}
    back = tomllib.loads(dumps(doc))
    assert back == doc and list(back) == list(doc)


def _row(scenario, method, success, collision=False, **kw):
    m = dict(success=success, collision=collision, timeout=not (success or collision), time_s=10.0,
             min_clearance_m=0.5, e_cbf=0.0, cbf_active_ratio=0.0, qp_infeasible_ratio=0.0, planner_p95_ms=0.0,
             cbf_p95_ms=0.0, perception_p95_ms=0.0, stopped_time_s=0.0, final_goal_dist_m=0.1, sim_time_s=10.0,
             wall_time_s=1.0, control_steps=200, mode_history=[[0.0, "GOAL"]], perception="lidar", warnings={},
             mode_switches_per_min=0.0, side_reversals=0, lateral_reversals=0, no_progress_s=0.0, missed_scans=0)
    m.update(kw)
    return dict(scenario=scenario, method=method, seed=0, params_hash="p", scenario_sha="s", status="ok",
                error=None, metrics=m, worker_wall_s=1.0, host="h", attempts=1, code_sha="c")


def test_the_report_has_collisions_and_success_per_fault_and_level_by_hand(tmp_path):
    v = variant_name
    groups = {"crowd_crossing": {"split": "none", "family": "none"},
              "multi_static_clutter": {"split": "none", "family": "none"},
              "corridor_meeting": {"split": "none", "family": "none"},
              v("crowd_crossing", "scan_dropout", "mild"): {"split": "mild", "family": "scan_dropout"},
              v("multi_static_clutter", "scan_dropout", "severe"): {"split": "severe", "family": "scan_dropout"},
              v("crowd_crossing", "latency_spikes", "severe"): {"split": "severe", "family": "latency_spikes"}}
    scen = list(groups)
    rows = [_row("crowd_crossing", "big-cbf", True), _row("multi_static_clutter", "big-cbf", True),
            _row("corridor_meeting", "big-cbf", False, final_goal_dist_m=3.0),
            _row(scen[3], "big-cbf", True, missed_scans=12, final_goal_dist_m=0.3),
            _row(scen[4], "big-cbf", False, collision=True, missed_scans=40),
            _row(scen[5], "big-cbf", False, collision=True)]
    s = report.build_summary(rows, ["big-cbf"], scen, [0], {"suite": "faults"}, groups=groups)
    bf = s["by_fault"]
    assert list(bf) == ["scan_dropout", "latency_spikes"]             # the catalogue's order, faults present
    sd = bf["scan_dropout"]["levels"]
    # none: the scan_dropout scenes (multi_static_clutter, crowd_crossing) without it: 2 of 2
    assert list(sd) == ["none", "mild", "severe"] and sd["none"]["big-cbf"]["ok"] == 2
    assert sd["none"]["big-cbf"]["success_pct"] == 100.0 and sd["mild"]["big-cbf"]["missed_scans"] == 12
    assert sd["mild"]["big-cbf"]["goal_error_m"] == pytest.approx(0.3)
    assert sd["severe"]["big-cbf"]["collisions"] == 1 and sd["severe"]["big-cbf"]["success_pct"] == 0.0
    ls = bf["latency_spikes"]["levels"]          # none: crowd_crossing and corridor_meeting: 1 of 2
    assert list(ls) == ["none", "severe"] and ls["none"]["big-cbf"]["success_pct"] == 50.0
    md = report.summary_markdown(s)
    assert "Collisions per method and fault" in md and "Success per method and fault" in md
    assert "| BIG-CBF | 0 / 0 / 1 | 0 / 1 |" in md                        # collisions: scan_dropout, latency_spikes
    assert "| BIG-CBF | 100 / 100 / 0 | 50 / 0 |" in md
    assert "Fault scan_dropout: whole LiDAR scans missing" in md and "| BIG-CBF | mild | 1 | 100.0 | 0 |" in md
    assert "Success per family" not in md and "Ours beside the paper" not in md


def test_a_tiny_faults_bench_runs_real_episodes_and_its_files_rerun(tmp_path, capsys):
    """Two faulted files of the suite and their scene, one method, one seed: real episodes; the report has the
    fault tables; a file reruns with ``bigcbf run FILE`` to the same outcome."""
    out = tmp_path / "b"
    full = config_from_args(build_parser().parse_args(["bench", "--out", str(out), "--suite", "faults"]))
    pick = [str(out / "faults" / f / f"{variant_name('single_person_crossing', f, 'severe')}.toml")
            for f in ("pedestrian_stops", "pedestrian_turns")]
    assert all(p in full.scenarios for p in pick)
    config = config_from_args(build_parser().parse_args(
        ["bench", "--out", str(out), "--suite", "faults", "--scenarios", "single_person_crossing", *pick,
         "--methods", "cbf-only", "--seed-list", "1"]))
    config = BenchConfig(**{**config.__dict__, "workers": 1})
    outcome = run_bench(config, progress=False, log=lambda msg: None)
    assert outcome.errors == 0 and outcome.ran == 3
    bf = outcome.summary["by_fault"]
    assert list(bf) == ["pedestrian_stops", "pedestrian_turns"]
    for f in bf.values():
        assert list(f["levels"]) == ["none", "severe"] and f["levels"]["severe"]["cbf-only"]["ok"] == 1
    md = (out / "summary.md").read_text()
    assert "Fault pedestrian_stops" in md and "Collisions per method and fault (none / severe)" in md
    rows = {r["scenario"]: r for r in json.loads((out / "summary.json").read_text())["error_episodes"]}
    assert not rows
    capsys.readouterr()
    assert main(["run", pick[0], "--method", "cbf-only", "--seed", "1", "--json"]) == 0
    ran = json.loads(capsys.readouterr().out)
    s = outcome.summary["by_fault"]["pedestrian_stops"]["levels"]["severe"]["cbf-only"]
    assert (100.0 if ran["success"] else 0.0) == s["success_pct"] and int(ran["collision"]) == s["collisions"]
