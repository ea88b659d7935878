"""`bigcbf bench --variant NAME=V1,V2`: every method under every combination of switches of the common filter and
layers around a method, in one report with paired comparisons (bigcbf/bench/variants.py, report.py).

A real small bench (2 methods x 2 variants x 1 short scenario x 1 seed) checks the rows, the keys, resuming and
the report; the planner checks that a bench without variants keeps today's keys and that the first value of an
axis equal to the configuration shares them; bad input is one line, before anything is written."""
from __future__ import annotations

import csv
import json
import random
from pathlib import Path

import pytest

import bigcbf
from bigcbf.bench import testing
from bigcbf.bench.runner import BenchConfig, plan, run_bench
from bigcbf.bench.stats import paired_ratio_difference, ratio_ci_pct
from bigcbf.bench.store import ResultStore
from bigcbf.bench.variants import VARIANT_AXES, parse_variants
from bigcbf.cli import main
from bigcbf.errors import UserError

METHODS = ["cbf-only", "dwa"]
VARIANT = "cbf_velocity_rows=off,on"
ARMS = [f"{m} [cbf_velocity_rows={v}]" for m in METHODS for v in ("off", "on")]


def _config(out, scenarios, variants=(), seeds=(0,), methods=METHODS) -> BenchConfig:
    return BenchConfig(out=Path(out), methods=tuple(methods), scenarios=tuple(scenarios), seeds=tuple(seeds),
                       workers=1, variants=tuple(variants))


def test_no_variant_keeps_todays_keys_and_the_first_value_shares_them(tmp_path, short_scenarios):
    plain, _, _ = plan(_config(tmp_path / "o", short_scenarios[:1]))
    assert all(t.variant == () for t in plain)
    for spec in ("route=off,on", VARIANT, "cbf_last_resort=slack,brake,evade"):
        axis, values = parse_variants([spec])[0]
        tasks, methods, _ = plan(_config(tmp_path / "o", short_scenarios[:1], [spec]))
        assert len(tasks) == len(plain) * len(values)
        assert [t.method for t in tasks] == [m for m in methods for _ in values]      # method, then its variants
        first = [t for t in tasks if t.variant == ((axis, values[0]),)]
        assert [t.key for t in first] == [t.key for t in plain], spec     # the default value: today's episodes
        hashes = {t.params_hash for t in tasks}
        assert len(hashes) == len(values), spec                           # each combination: its own key
    two, _, _ = plan(_config(tmp_path / "o", short_scenarios[:1], ["route=off,on", "cbf_last_resort=slack,brake"]))
    assert len({t.params_hash for t in two}) == 4 and len(two) == 4 * len(plain)
    assert {t.variant for t in two} == {(("route", r), ("cbf_last_resort", c)) for r in ("off", "on")
                                        for c in ("slack", "brake")}


@pytest.fixture(scope="module")
def variant_bench(tmp_path_factory, short_scenarios):
    """2 methods x cbf_velocity_rows off/on x 1 short scenario x 1 seed, through the CLI."""
    out = tmp_path_factory.mktemp("variants") / "out"
    args = ["bench", "--out", str(out), "--methods", *METHODS, "--scenarios", short_scenarios[0], "--seeds", "1",
            "--variant", VARIANT, "--workers", "1", "--progress", "off"]
    assert main(args) == 0
    with ResultStore(out / "results.sqlite") as st:
        rows = st.rows()
        params = dict(st.db.execute("SELECT params_hash, toml FROM params").fetchall())
    return out, args, rows, params


def test_a_real_variant_bench_runs_every_method_under_each_value(variant_bench):
    out, _, rows, params = variant_bench
    assert len(rows) == 4 and all(r["status"] == "ok" for r in rows)
    hashes = {r["params_hash"] for r in rows}
    assert len(hashes) == 2 and {(r["method"], r["params_hash"]) for r in rows} == {(m, h) for m in METHODS
                                                                                      for h in hashes}
    on = {h for h in hashes if "cbf_velocity_rows = true" in params[h]}
    assert len(on) == 1 and all("cbf_velocity_rows = false" in params[h] for h in hashes - on)
    s = json.loads((out / "summary.json").read_text())
    assert s["bench"]["methods"] == ARMS and list(s["methods"]) == ARMS
    assert s["bench"]["episodes_expected"] == s["bench"]["episodes_recorded"] == 4
    var = s["variants"]
    assert var["axes"] == [{"name": "cbf_velocity_rows", "path": "[stack] cbf_velocity_rows", "values": ["off", "on"]}]
    assert var["arms"][ARMS[1]]["params_hash"] in on and var["arms"][ARMS[0]]["params_hash"] not in on
    by_row = {(r["method"], r["params_hash"] in on): r["metrics"] for r in rows}
    for m in METHODS:
        for v, is_on in (("off", False), ("on", True)):
            fig, met = var["by_method"][m][f"cbf_velocity_rows={v}"], by_row[(m, is_on)]
            assert fig["ok"] == 1 and fig["success_pct"] == 100.0 * met["success"]
            assert fig["at_fault_collisions"] == int(met["at_fault_collision"])
            assert fig["qp_infeasible_pct"] == pytest.approx(100.0 * met["qp_infeasible_ratio"], abs=1e-9)
            assert fig["success_ci95_pct"] is not None and fig == {k: s["methods"][f"{m} [cbf_velocity_rows={v}]"][k]
                                                                   for k in fig}
        (pair,) = var["paired"][m]
        assert (pair["axis"], pair["from"], pair["to"], pair["pairs"]) == ("cbf_velocity_rows", "off", "on", 1)
        want = int(by_row[(m, True)]["success"]) - int(by_row[(m, False)]["success"])
        assert pair["success"]["diff_pct"] == 100.0 * want and pair["at_fault_collision"]["n"] == 1
    # the cross-method comparison pairs rows under the same variant
    assert set(s["paired"]["by_method"]) == {ARMS[2], ARMS[3]} and s["paired"]["reference"] == "cbf-only"
    with (out / "episodes.csv").open() as fh:
        lines = list(csv.DictReader(fh))
    assert sorted((ln["method"], ln["variant"]) for ln in lines) == sorted(
        (m, f"cbf_velocity_rows={v}") for m in METHODS for v in ("off", "on"))
    md = (out / "summary.md").read_text()
    assert "Variants: every method under each combination" in md and "off: At fault" in md
    assert "| CBF-only | cbf_velocity_rows: off → on | 1 |" in md and "| DWA + CBF [cbf_velocity_rows=on] |" in md


def test_a_variant_bench_resumes_and_a_plain_bench_finds_its_default_half(variant_bench, capsys, short_scenarios):
    out, args, rows, _ = variant_bench
    capsys.readouterr()
    assert main(args) == 0                                          # the same command: nothing runs again
    assert "4 episodes: 4 already done, 0 run now" in capsys.readouterr().err
    plain = [a for a in args if a not in ("--variant", VARIANT)]
    assert main(plain) == 0                                         # without --variant: today's keys = the off half
    assert "2 episodes: 2 already done, 0 run now" in capsys.readouterr().err
    with ResultStore(out / "results.sqlite") as st:
        again = st.rows()
    assert sorted((r["method"], r["params_hash"], r["finished_utc"]) for r in again) == sorted(
        (r["method"], r["params_hash"], r["finished_utc"]) for r in rows)
    s = json.loads((out / "summary.json").read_text())
    assert list(s["methods"]) == METHODS and "variants" not in s    # the plain report: methods alone


@pytest.mark.parametrize("extra, message", [
    (["--variant", "speed=off,on"], "unknown axis 'speed'; known: route=off,on"),
    (["--variant", "route=maybe"], "route ([route] enabled) takes off, on, got 'maybe'"),
    (["--variant", "route"], "expected NAME=V1,V2"),
    (["--variant", "route="], "takes off, on, got ''"),
    (["--variant", "cbf_last_resort=slack,slack"], "value listed more than once: slack"),
    (["--variant", "route=off", "--variant", "route=on"], "axis route given more than once"),
    (["--variant", "route=off,on", "--route", "on"], "--route and --variant route=... both set the route layer"),
])
def test_bad_variant_input_is_one_line_before_any_work(extra, message, tmp_path, capsys, short_scenarios):
    assert main(["bench", "--out", str(tmp_path / "o"), "--methods", "dwa", "--suite", "generated", "--split", "test",
                 "--seeds", "1", *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()                            # not even the suite's worlds


@pytest.mark.parametrize("variants, message", [("route=on", "expected a list"), (["route=up"], "takes off, on"),
                                               ([5], "expected NAME=V1,V2")])
def test_the_python_api_refuses_bad_variants_naming_the_field(variants, message, tmp_path, short_scenarios):
    for fn in (bigcbf.bench_config, bigcbf.run_bench):
        with pytest.raises(UserError, match="field 'variants'") as err:
            fn(tmp_path / "o", methods=["dwa"], scenarios=short_scenarios[:1], seeds=1, workers=1, variants=variants)
        assert message in str(err.value) and "\n" not in str(err.value)
    assert not (tmp_path / "o").exists()
    with pytest.raises(UserError, match="field 'variants'"):        # a BenchConfig built by hand: plan() checks
        plan(_config(tmp_path / "o", short_scenarios[:1], ["route=sideways"]))


@pytest.mark.parametrize("suite, split", [("paper", None), ("francis2023", None), ("generated", "test")])
def test_every_suite_takes_variants(suite, split, tmp_path):
    cfg = bigcbf.bench_config(tmp_path / "o", methods=["dwa"], suite=suite, split=split, seeds=1, workers=1,
                              variants=["route=off,on"])
    tasks, _, names = plan(cfg)
    assert len(tasks) == 2 * len(names) and {t.variant for t in tasks} == {(("route", "off"),), (("route", "on"),)}


def test_two_axes_pair_each_value_with_the_first_over_the_others(tmp_path, short_scenarios):
    """Fake episodes (no physics): 2 x 3 combinations; each axis's later values paired with its first, pooled over
    the other axis, every row labelled with its combination."""
    cfg = _config(tmp_path, short_scenarios, ["route=off,on", "cbf_last_resort=slack,brake,evade"], seeds=(0, 1),
                  methods=["cbf-only"])
    out = run_bench(cfg, episode_fn=testing.fake_episode, progress=False, log=lambda _: None)
    assert (out.total, out.errors) == (2 * 2 * 6, 0)
    var = out.summary["variants"]
    assert len(var["combinations"]) == 6 and var["combinations"][0] == "route=off, cbf_last_resort=slack"
    assert "cbf-only [route=on, cbf_last_resort=evade]" in out.summary["methods"]
    pairs = {(e["axis"], e["to"]): e for e in var["paired"]["cbf-only"]}
    assert set(pairs) == {("route", "on"), ("cbf_last_resort", "brake"), ("cbf_last_resort", "evade")}
    assert pairs[("route", "on")]["pairs"] == 2 * 2 * 3 and pairs[("cbf_last_resort", "brake")]["pairs"] == 2 * 2 * 2
    # fake metrics depend on the seed only: no differences, and no contact classification to compare
    assert all(e["success"]["diff_pct"] == 0.0 and e["at_fault_collision"]["n"] == 0 for e in pairs.values())
    assert all(e["qp_infeasible"]["diff_pct"] == 0.0 for e in pairs.values())


def test_every_axis_names_a_real_field_and_its_values_set_it():
    from bigcbf.config import RunConfig, config_toml
    base = config_toml(RunConfig())
    for name, axis in VARIANT_AXES.items():
        texts = {v: config_toml(axis.apply(RunConfig(), v)) for v in axis.values}
        assert len(set(texts.values())) == len(axis.values), name   # every value is a different configuration
        assert texts[axis.values[0]] == base, name                   # the first value: the paper's default
        table, key = axis.path.strip("[").split("] ")
        assert all(f"[{table}]" in t and key in t for v, t in texts.items() if t != base), name
    from bigcbf.bench.variants import apply_combination
    from bigcbf.config import run_config_from_dict
    own = run_config_from_dict({"methods": {"dwa": {"stack": {"cbf_velocity_rows": True}}}})
    for v in ("off", "on"):      # a stack axis is the switch for every method, over a method's own stack key too
        c = apply_combination(own, (("cbf_velocity_rows", v),))
        assert c.stack_for("dwa").cbf_velocity_rows == c.stack_for("apf").cbf_velocity_rows == (v == "on")


def _bootstrap_ci(nums, dens, reps=4000, seed=1):
    rng = random.Random(seed)
    n, out = len(nums), []
    for _ in range(reps):
        idx = [rng.randrange(n) for _ in range(n)]
        out.append(100.0 * sum(nums[i] for i in idx) / sum(dens[i] for i in idx))
    out.sort()
    return out[int(0.025 * reps)], out[int(0.975 * reps)]


def test_the_step_fraction_interval_counts_episodes_not_steps():
    rng = random.Random(7)
    dens = [rng.randint(100, 700) for _ in range(200)]
    nums = [round(d * rng.choice([0.0, 0.0, 0.0, 0.02, 0.2])) for d in dens]
    lo, hi = ratio_ci_pct(nums, dens)
    blo, bhi = _bootstrap_ci(nums, dens)
    assert lo == pytest.approx(blo, abs=0.6) and hi == pytest.approx(bhi, abs=0.6)   # as wide as a bootstrap
    r = 100.0 * sum(nums) / sum(dens)
    assert lo < r < hi and hi - lo > 4 * 1.96 * (r * (100 - r) / sum(dens)) ** 0.5      # far wider than per-step
    assert ratio_ci_pct([0, 0, 0], [10, 20, 30]) == [0.0, 0.0] and ratio_ci_pct([1], [10]) is None
    same = paired_ratio_difference(nums, dens, nums, dens)
    assert same["diff_pct"] == 0.0 and same["ci95_pct"] == [0.0, 0.0]
    more = paired_ratio_difference([x + 5 for x in nums], dens, nums, dens)
    assert more["diff_pct"] > 0 and more["ci95_pct"][0] > 0 and more["n"] == 200


def test_a_suite_with_families_reports_each_method_under_each_variant(tmp_path):
    """francis2023 (a family per archetype) with fake episodes: the per-family tables and the heatmap rows are
    the methods under each variant."""
    cfg = bigcbf.bench_config(tmp_path / "o", methods=["dwa", "cbf-only"], suite="francis2023", seeds=1, workers=1,
                              variants=["route=off,on"])
    out = run_bench(cfg, episode_fn=testing.fake_episode, progress=False, log=lambda _: None)
    arms = [f"{m} [route={v}]" for m in ("cbf-only", "dwa") for v in ("off", "on")]
    assert out.errors == 0 and list(out.summary["by_family"]) == arms
    assert out.summary["variants"]["by_method"]["dwa"]["route=on"]["ok"] == len(cfg.scenarios)
    md = (tmp_path / "o" / "summary.md").read_text()
    assert "| DWA + CBF [route=on] | frontal_approach | 1 |" in md and "| DWA + CBF [route=on] | all | 13 |" in md
    assert (tmp_path / "o" / "success_heatmap.png").stat().st_size > 0
