"""Aggregation and report files, from synthetic rows (no physics)."""
from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path

import matplotlib.image as mpimg
import pytest

from bigcbf.bench import paper, report
from bigcbf.errors import UserError


def metrics(**kw) -> dict:
    base = dict(success=False, collision=False, timeout=True, time_s=40.0, min_clearance_m=0.5, e_cbf=0.0,
                cbf_active_ratio=0.0, qp_infeasible_ratio=0.0, planner_p95_ms=0.0, cbf_p95_ms=0.0,
                perception_p95_ms=0.0, stopped_time_s=0.0, final_goal_dist_m=1.0, sim_time_s=40.0, wall_time_s=1.0,
                control_steps=800, mode_history=[[0.0, "GOAL"]], perception="lidar", warnings={})
    base.update(kw)
    return base


def row(scenario, method, seed, status="ok", error=None, **kw) -> dict:
    return dict(scenario=scenario, method=method, seed=seed, params_hash="p", scenario_sha="s", status=status,
                error=error, metrics=metrics(**kw) if status == "ok" else None, worker_wall_s=1.0, host="h",
                attempts=1)


def three_rows():
    """Two finished episodes and a crashed one."""
    return [
        row("a", "big-cbf", 0, success=True, timeout=False, time_s=10.0, min_clearance_m=0.5, e_cbf=2.0,
            cbf_active_ratio=0.25, qp_infeasible_ratio=0.01, control_steps=100, planner_p95_ms=50.0),
        row("b", "big-cbf", 0, success=False, timeout=True, time_s=40.0, min_clearance_m=0.3, e_cbf=4.0,
            cbf_active_ratio=0.5, qp_infeasible_ratio=0.0, control_steps=200, planner_p95_ms=70.0),
        row("a", "big-cbf", 1, status="error", error="RuntimeError: boom"),
    ]


def test_summarize_hand_computed():
    s = report.summarize(three_rows())
    # by hand: 2 finished of 3; 1 of 2 succeeded; time over successes only = 10 s; clearance (0.5+0.3)/2;
    # E_CBF (2+4)/2; active steps 0.25*100 + 0.5*200 = 125 of 300; infeasible 0.01*100 = 1 of 300;
    # planner P95 (50+70)/2
    assert (s["episodes"], s["ok"], s["errors"]) == (3, 2, 1)
    assert s["success_pct"] == pytest.approx(50.0)
    assert s["time_s"] == pytest.approx(10.0)
    assert s["min_clearance_m"] == pytest.approx(0.4)
    assert s["e_cbf"] == pytest.approx(3.0)
    assert s["cbf_active_pct"] == pytest.approx(100 * 125 / 300)
    assert s["qp_infeasible_pct"] == pytest.approx(100 * 1 / 300)
    assert s["planner_p95_ms"] == pytest.approx(60.0)
    assert (s["collisions"], s["timeouts"]) == (0, 1)


def test_summarize_empty_and_infinite_clearance():
    s = report.summarize([row("a", "m", 0, status="error", error="x")])
    assert s["success_pct"] is None and s["time_s"] is None and s["cbf_active_pct"] is None
    s = report.summarize([row("a", "m", 0, min_clearance_m=math.inf), row("a", "m", 1, min_clearance_m=0.2)])
    assert s["min_clearance_m"] == pytest.approx(0.2)   # an episode without obstacles has no finite clearance


def test_build_summary_keys_by_method_and_scenario():
    rows = three_rows() + [row("a", "cbf-only", 0, success=True, timeout=False, time_s=20.0)]
    s = report.build_summary(rows, ["cbf-only", "big-cbf"], ["a", "b"], [0, 1])
    assert s["methods"]["cbf-only"]["success_pct"] == 100.0
    assert s["by_scenario"]["big-cbf"]["a"]["success_pct"] == 100.0     # seed 1 crashed: 1 of 1 finished
    assert s["by_scenario"]["big-cbf"]["b"]["success_pct"] == 0.0
    assert s["by_scenario"]["cbf-only"]["b"]["ok"] == 0
    assert s["bench"]["episodes_expected"] == 8 and s["bench"]["errors"] == 1
    assert s["error_episodes"] == [{"scenario": "a", "method": "big-cbf", "seed": 1, "error": "RuntimeError: boom"}]
    assert s["paper"]["table_ii"]["big-cbf"]["success_pct"] == 99.78


def test_write_reports(tmp_path):
    rows = three_rows() + [row("a", "cbf-only", 0, success=True, timeout=False, time_s=20.0,
                               min_clearance_m=math.inf, mode_history=[[0.0, "GOAL"], [1.5, "SIDE-L"]])]
    s = report.write_reports(tmp_path, rows, ["cbf-only", "big-cbf"], ["a", "b"], [0, 1], {"engine": "local"})
    for name in ("episodes.csv", "summary.json", "summary.md") + report.FIGURES:
        assert (tmp_path / name).stat().st_size > 0, name
    # CSV: one line per row, every metric, lists as JSON
    with (tmp_path / "episodes.csv").open() as fh:
        lines = list(csv.DictReader(fh))
    assert len(lines) == 4
    assert set(metrics()) - {"scenario", "method", "seed"} <= set(lines[0])
    assert json.loads(lines[3]["mode_history"]) == [[0.0, "GOAL"], [1.5, "SIDE-L"]]
    assert lines[2]["status"] == "error" and lines[2]["error"] == "RuntimeError: boom"
    # JSON: strict (no Infinity), same numbers as returned
    text = (tmp_path / "summary.json").read_text()
    assert "Infinity" not in text and "NaN" not in text
    js = json.loads(text)
    assert js["methods"]["big-cbf"]["cbf_active_pct"] == pytest.approx(s["methods"]["big-cbf"]["cbf_active_pct"])
    assert js["methods"]["cbf-only"]["min_clearance_m"] is None
    # Markdown: Table II columns, per-scenario table, the paper's numbers, the crashed episode
    md = (tmp_path / "summary.md").read_text()
    for col in ("Success (%) [95 % CI]", "Time (s)", "Clearance (m)", "E_CBF", "Active (%)", "QP infeas. (%)", "Collisions",
                "Planner P95 (ms)"):
        assert col in md
    # success 1 of 2 with its Wilson interval, collisions 0 of 2 with theirs; no code version recorded; hash "p"
    assert "| BIG-CBF | 2 | 50.0 [9.4, 90.5] | 10.00 | 0.40 | 3.00 | 41.67 | 0.33 | 0: 0.0 [0.0, 65.8] | 60.00 | – | p |" in md
    # two made-up scenes at two seeds: the paper's figures are not put beside them, and the page says why
    assert "50.00 / 99.78" not in md and "Not comparable with the paper's Table II" in md
    assert "9 of the paper's 9 scenes not in this bench" in md and "2 seeds per scene, the paper's 50" in md
    assert "## Success per scenario (%)" in md
    assert "a / big-cbf / seed 1: RuntimeError: boom" in md
    for fig in report.FIGURES:
        img = mpimg.imread(tmp_path / fig)
        assert img.shape[0] > 200 and img.shape[1] > 400


def nine_at_fifty(edit: str | None = None, seeds: int = paper.PAPER_SEEDS, params: str | None = None):
    """Rows of the nine shipped scenes at ``seeds`` seeds with their real content keys and the default parameter
    hash (``edit``: that scene's rows carry another content key, as a user's copy of it with the same name)."""
    keys = paper.shipped_scene_keys(paper.SCENARIO_ORDER)
    phash = params or report.default_params_hash("paper")
    rows = []
    for sc in paper.SCENARIO_ORDER:
        for seed in range(seeds):
            r = row(sc, "big-cbf", seed, success=True, timeout=False, time_s=10.0)
            r.update(scenario_sha="0123456789abcdef" if sc == edit else keys[sc], params_hash=phash)
            rows.append(r)
    return rows


@pytest.mark.parametrize("case, why", [
    ("shipped", None),
    ("edited", "not the shipped file (by content): corridor_meeting"),
    ("seeds", "10 seeds per scene, the paper's 50"),
    ("config", "a run configuration other than the defaults"),
    ("subset", "1 of the paper's 9 scenes not in this bench"),
])
def test_the_paper_is_shown_only_beside_its_own_benchmark(case, why):
    """Table II and the quoted per-scene figures appear beside ours only for the shipped files (by content, not by
    name), at 50 seeds, with the defaults; anything else is labelled not comparable, saying why."""
    rows = nine_at_fifty(edit="corridor_meeting" if case == "edited" else None, seeds=10 if case == "seeds" else 50,
                         params="ffffffffffffffff" if case == "config" else None)
    scenes = list(paper.SCENARIO_ORDER)
    if case == "subset":
        scenes.remove("blind_corner")
        rows = [r for r in rows if r["scenario"] != "blind_corner"]
    seeds = sorted({r["seed"] for r in rows})
    s = report.build_summary(rows, ["big-cbf"], scenes, seeds, {"suite": "paper", "perception": "lidar"})
    verdict = s["paper"]["comparable"]["table_ii"]
    md = report.summary_markdown(s)
    if why is None:
        assert verdict == {"comparable": True, "why": ""}
        assert "| BIG-CBF | 100.00 / 99.78 |" in md and "100 / 98" in md      # Table II; corridor meeting's quote
        # the two-sample tests against the paper: 450/450 vs its 449/450; corridor meeting 50/50 vs its 49/50
        t = s["paper"]["tests"]["big-cbf"]
        assert (t["overall"]["k1"], t["overall"]["n1"], t["overall"]["k2"], t["overall"]["n2"]) == (450, 450, 449, 450)
        assert t["overall"]["diff_pct"] == 0.22 and t["overall"]["fisher_p"] == pytest.approx(1.0)
        assert t["scenes"]["corridor_meeting"]["k2"] == 49 and set(t["scenes"]) == set(s["paper"]["comparable"]["scenes"])
        assert "Success against the paper's, two-sample tests" in md and "| BIG-CBF | +0.2 [" in md
    else:
        assert not verdict["comparable"] and why in verdict["why"]
        assert "99.78" not in md and why in md
        assert "tests" not in s["paper"] and "two-sample tests" not in md
        # the per-scene figures the paper quotes: beside each shipped scene run at 50 seeds with the defaults
        quoted = s["paper"]["comparable"]["scenes"]
        assert quoted == {"edited": ["multi_static_clutter", "required_sidestepping"], "seeds": [], "config": [],
                          "subset": ["corridor_meeting", "multi_static_clutter", "required_sidestepping"]}[case]


def test_update_docs_page(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    report.write_reports(out, three_rows(), ["big-cbf"], ["a", "b"], [0, 1])
    page = tmp_path / "docs" / "benchmark.md"
    page.parent.mkdir()
    page.write_text(f"# Title\n\nintro\n\n{report.DOCS_BEGIN}\nold\n{report.DOCS_END}\n\nafter\n")
    report.update_docs_page(page, out)
    text = page.read_text()
    assert text.startswith("# Title\n\nintro\n") and text.endswith(f"{report.DOCS_END}\n\nafter\n")
    assert "old" not in text and "\n### Benchmark results\n" in text
    assert "![success rate per method and scenario](benchmark/success_heatmap.png)" in text
    assert (page.parent / "benchmark" / "success_heatmap.png").is_file()
    page.write_text("no markers\n")
    with pytest.raises(UserError, match="benchmark.md"):
        report.update_docs_page(page, out)


def test_paper_numbers_match_the_paper_source():
    """Our copy of Table II equals the table in the paper's LaTeX (parsed independently here)."""
    tex = Path(__file__).resolve().parents[3] / "shared" / "paper" / "big-cbf.tex"   # beside the checkout
    if not tex.is_file():
        pytest.skip(f"the paper's source is not beside this checkout ({tex})")
    body = tex.read_text().split(r"\label{tab:overall_sim}")[1].split(r"\bottomrule")[0]
    names = {v: k for k, v in paper.DISPLAY_NAME.items()}
    found = {}
    for line in body.splitlines():
        m = re.match(r"\s*(.+?)\s*&(.+)\\\\", line)
        if not m or "Method" in line or "(\\%)" in line:
            continue
        name = re.sub(r"\\textbf\{(.+?)\}", r"\1", m.group(1)).strip()
        vals = [float(re.sub(r"\\textbf\{(.+?)\}", r"\1", v).strip()) for v in m.group(2).split("&")]
        found[names[name]] = vals
    assert set(found) == set(paper.METHOD_ORDER)
    for m, vals in found.items():
        assert [paper.PAPER_TABLE_II[m][k] for k in paper.TABLE2_KEYS] == vals
    # Table III (hardware): "k/15" then five numbers
    body = tex.read_text().split(r"\label{tab:real_results}")[1].split(r"\bottomrule")[0]
    found = {}
    for line in body.splitlines():
        m = re.match(r"\s*(.+?)\s*&(.+)\\\\", line)
        if not m or "Method" in line or "(s)" in line:
            continue
        name = re.sub(r"\\textbf\{(.+?)\}", r"\1", m.group(1)).strip()
        cells = [re.sub(r"\\textbf\{(.+?)\}", r"\1", v).strip() for v in m.group(2).split("&")]
        k, n = cells[0].split("/")
        found[names[name]] = [int(k), int(n)] + [float(c) for c in cells[1:]]
    assert set(found) == set(paper.METHOD_ORDER)
    for m, vals in found.items():
        t = paper.PAPER_TABLE_III[m]
        assert [t["successes"], t["trials"]] + [t[k] for k in paper.TABLE3_KEYS[1:]] == vals


def test_order():
    assert paper.ordered(["big-cbf", "x", "cbf-only"], paper.METHOD_ORDER) == ["cbf-only", "big-cbf", "x"]
    m, s = report.default_order(["big-cbf", "dwa"], ["required_sidestepping", "blind_corner", "mine"])
    assert m == ["dwa", "big-cbf"] and s == ["blind_corner", "required_sidestepping", "mine"]


def test_rows_of_several_code_versions_are_flagged(tmp_path):
    rows = three_rows()
    rows[0]["code_sha"], rows[1]["code_sha"] = "aaa", "bbb"
    s = report.write_reports(tmp_path, rows, ["big-cbf"], ["a", "b"], [0, 1])
    assert s["bench"]["code_versions"] == ["aaa", "bbb"]
    assert "2 different versions of the code (aaa, bbb" in (tmp_path / "summary.md").read_text()
    rows[1]["code_sha"] = "aaa"
    report.write_reports(tmp_path, rows, ["big-cbf"], ["a", "b"], [0, 1])
    assert "Warning" not in (tmp_path / "summary.md").read_text()


def test_summarize_activation_both_ways_infeasible_share_and_margins():
    rows = [row("a", "big-cbf", 0, cbf_active_ratio=0.2, control_steps=100, e_cbf=2.0, e_cbf_infeasible=1.0,
                m_img_mean_m=0.2, m_img_p90_m=0.3, m_exec_mean_m=0.25, m_exec_p90_m=0.35),
            row("a", "big-cbf", 1, cbf_active_ratio=0.0, control_steps=900, e_cbf=0.0, e_cbf_infeasible=0.0,
                m_img_mean_m=0.4, m_img_p90_m=0.5, m_exec_mean_m=0.15, m_exec_p90_m=0.25),
            row("a", "dwa", 0, cbf_active_ratio=0.5, control_steps=100, e_cbf=4.0, e_cbf_infeasible=0.0,
                m_img_mean_m=None, m_img_p90_m=None, m_exec_mean_m=0.1, m_exec_p90_m=0.2)]
    s = report.summarize(rows[:2])
    # pooled: 20 active steps of 1000 = 2 %; episode mean: (20 % + 0 %) / 2 = 10 % (the stalled episode dilutes)
    assert s["cbf_active_pct"] == pytest.approx(2.0) and s["cbf_active_episode_pct"] == pytest.approx(10.0)
    assert s["e_cbf_infeasible_share_pct"] == pytest.approx(50.0)
    assert (s["m_img_mean_m"], s["m_img_p90_m"]) == (pytest.approx(0.3), pytest.approx(0.4))
    assert (s["m_exec_mean_m"], s["m_exec_p90_m"]) == (pytest.approx(0.2), pytest.approx(0.3))
    d = report.summarize(rows[2:])
    assert d["m_img_mean_m"] is None and d["e_cbf_infeasible_share_pct"] == 0.0
    md = report.summary_markdown(report.build_summary(rows, ["dwa", "big-cbf"], ["a"], [0, 1]))
    assert "E_CBF from infeasible (%)" in md and "0.300 / 0.400" in md


def test_hardware_suite_report_is_beside_table_iii(tmp_path):
    from bigcbf.bench.suites import SUITES
    suite = SUITES.get("hardware")
    assert suite.default_seeds == 20 and [e.scenario for e in suite.entries(tmp_path)] == list(
        paper.HARDWARE_SCENARIO_ORDER)
    rows = [row(s, "big-cbf", k, success=k < 2, time_s=12.0) for s in paper.HARDWARE_SCENARIO_ORDER for k in range(3)]
    info = {"suite": "hardware", "perception": "lidar"}
    md = report.summary_markdown(report.build_summary(rows, ["big-cbf"], list(paper.HARDWARE_SCENARIO_ORDER),
                                                      [0, 1, 2], info))
    assert "Not comparable with the paper's Table III" in md and "13.18" not in md   # made-up content keys
    keys, phash = paper.shipped_scene_keys(paper.HARDWARE_SCENARIO_ORDER), report.default_params_hash("hardware")
    for r in rows:      # the shipped lab scenes, by content, with the suite's defaults
        r.update(scenario_sha=keys[r["scenario"]], params_hash=phash)
    summary = report.build_summary(rows, ["big-cbf"], list(paper.HARDWARE_SCENARIO_ORDER), [0, 1, 2], info)
    md = report.summary_markdown(summary)
    assert "Table III" in md and "Table II\n" not in md
    assert "| BIG-CBF | 9 | 6/9 (66.7) / 15/15 (100.0) | 12.00 / 13.18 |" in md
    assert paper.PAPER_TABLE_III["apf"]["success_pct"] == pytest.approx(100 / 15)
