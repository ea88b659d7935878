"""scripts/fidelity_ablations.py (issue 24, item 2): its variants are run configurations that change exactly one
switch of big-cbf-plus (or none, or every one: big-cbf), and its table pairs episodes by scene and seed."""
from __future__ import annotations

import csv
import dataclasses
import importlib.util
import sys
from pathlib import Path

import pytest

from bigcbf.config import load_run_config
from bigcbf.params.stack import PAPER_RULES, PlusRules

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def fa():
    spec = importlib.util.spec_from_file_location("fidelity_ablations", ROOT / "scripts" / "fidelity_ablations.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod           # its dataclass looks its module up
    spec.loader.exec_module(mod)
    yield mod
    sys.modules.pop(spec.name, None)


def test_each_variant_is_a_configuration_that_flips_one_switch(fa, tmp_path):
    vs = fa.variants()
    names = [v.name for v in vs]
    assert names[0] == "plus" and names[-1] == "big-cbf" and len(set(names)) == len(names)
    flipped = set()
    from bigcbf.config import RunConfig
    base = RunConfig().method_params("big-cbf-plus")        # the shipped defaults (tuned numbers, when shipped)
    for v in vs:
        p = tmp_path / f"{v.name}.toml"
        p.write_text(fa.config_text(v))
        rules = load_run_config(p).method_params("big-cbf-plus")
        diff = {f.name for f in dataclasses.fields(PlusRules) if getattr(rules, f.name) != getattr(base, f.name)}
        if v.method == "big-cbf":
            assert v.name == "big-cbf" and diff == set()
        else:
            assert v.method == "big-cbf-plus" and diff == set(v.switches)
            assert len(diff) <= 1 and (diff or v.name == "plus")
            flipped |= diff
    # every switch is measured, the on-by-default ones turned off and the off-by-default ones turned on
    assert flipped == set(PlusRules().switches)
    assert PAPER_RULES.switches == {k: False for k in PlusRules().switches}
    assert "no_release_fan" in names and "with_speed_governor" in names


def _write_episodes(path: Path, rows: list[dict]) -> None:
    cols = ["scenario", "method", "seed", "status", "error", "success", "collision", "timeout", "e_cbf",
            "cbf_active_ratio", "qp_infeasible_ratio", "control_steps", "side_reversals", "at_fault_collision",
            "passive_collision"]
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, cols)
        w.writeheader()
        for r in rows:
            w.writerow({"status": "ok", "error": "", "collision": False, "timeout": not r["success"], "e_cbf": 1.0,
                        "cbf_active_ratio": 0.1, "qp_infeasible_ratio": 0.0, "control_steps": 100,
                        "side_reversals": 1, "at_fault_collision": False, "passive_collision": False, **r})


def test_the_table_pairs_by_scene_and_seed_not_by_order(fa, tmp_path):
    vs = [v for v in fa.variants() if v.name in ("plus", "no_release_fan")]
    ok = {("a", 0): True, ("a", 1): True, ("b", 0): False, ("/w/posts_00000.toml", 0): True}
    other = {("a", 0): False, ("a", 1): True, ("b", 0): True, ("/x/posts_00000.toml", 0): True}
    for name, res in (("plus", ok), ("no_release_fan", other)):
        rows = [{"scenario": s, "method": "big-cbf-plus", "seed": k, "success": v} for (s, k), v in res.items()]
        paper = [r for r in rows if not r["scenario"].endswith(".toml")]
        dev = [r for r in rows if r["scenario"].endswith(".toml")]
        if name == "no_release_fan":
            paper.reverse()
            paper[0].update(control_steps=300, cbf_active_ratio=0.5)
        _write_episodes(tmp_path / name / "paper" / "episodes.csv", paper)
        _write_episodes(tmp_path / name / "dev" / "episodes.csv", dev)
    data = fa.collect(tmp_path, vs)
    pd = fa.paired(data["no_release_fan"], data["plus"])
    assert (pd["n"], pd["a"], pd["b"], pd["c"], pd["d"]) == (4, 2, 1, 1, 0) and pd["diff_pct"] == 0.0
    text, rows = fa.table(data, vs)
    s = rows[1]
    assert (s["success_paper"], s["episodes_paper"], s["success_dev"], s["success_all"]) == (2, 3, 1, 3)
    assert s["active_pct"] == pytest.approx(100 * (0.5 * 300 + 0.1 * 300) / 600)
    assert s["timeouts"] == 1 and rows[0]["paired_vs_plus"] is None
    assert "| no_release_fan | 2/3 [" in text
    # a smaller sample of the same folder: exactly the episodes asked for, and a missing one stops the table
    wanted = {"paper": {("a", 0), ("b", 0)}, "dev": {("posts_00000", 0)}}
    small = fa.collect(tmp_path, vs, wanted)
    assert set(small["plus"]) == {("paper", "a", 0), ("paper", "b", 0), ("dev", "posts_00000", 0)}
    assert fa.paired(small["no_release_fan"], small["plus"])["n"] == 3
    with pytest.raises(SystemExit, match="lacks 1 episodes"):
        fa.collect(tmp_path, vs, {**wanted, "paper": {("a", 2)}})


def test_a_failed_episode_stops_the_table(fa, tmp_path):
    vs = [v for v in fa.variants() if v.name == "plus"]
    _write_episodes(tmp_path / "plus" / "paper" / "episodes.csv",
                    [{"scenario": "a", "method": "big-cbf-plus", "seed": 0, "success": False, "status": "error",
                      "error": "boom"}])
    _write_episodes(tmp_path / "plus" / "dev" / "episodes.csv", [])
    with pytest.raises(SystemExit, match="boom"):
        fa.collect(tmp_path, vs)
