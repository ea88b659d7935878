"""The bench hands its episodes out longest first, by the cost model's estimate (issue 26, item 2)."""
import re
from dataclasses import replace

from bigcbf.bench import engines
from bigcbf.bench.runner import BenchConfig, plan
from bigcbf.bench.tasks import estimated_cost, longest_first


def test_longest_first_orders_by_the_cost_model(tmp_path):
    cfg = BenchConfig(out=tmp_path / "b", methods=("cbf-only", "big-cbf", "mppi"),
                      scenarios=("single_person_crossing", "mixed_dense_traffic"), seeds=(0, 1), workers=1)
    tasks, _, _ = plan(cfg)
    ordered = longest_first(tasks)
    assert sorted(ordered, key=lambda t: t.key) == sorted(tasks, key=lambda t: t.key)      # the same tasks
    costs = [estimated_cost(t) for t in ordered]
    assert all(c > 0 for c in costs)
    # grouped by world (scenario, seed): each group contiguous, its episodes the most work first, and the groups by
    # their longest episode, the most work first
    worlds = [(t.scenario_sha, t.seed) for t in ordered]
    runs = [w for k, w in enumerate(worlds) if k == 0 or worlds[k - 1] != w]
    assert len(runs) == len(set(worlds)) == 4
    heads = [costs[worlds.index(w)] for w in runs]
    assert heads == sorted(heads, reverse=True)
    for w in runs:
        c = [costs[k] for k in range(len(worlds)) if worlds[k] == w]
        assert c == sorted(c, reverse=True) and c[0] == max(c)
    # the longest-running pairs lead: mppi in the dense scene (longer time limit, more walkers), cbf-only last
    assert (ordered[0].method, ordered[0].scenario) == ("mppi", "mixed_dense_traffic")
    assert ordered[-1].method == "cbf-only" and ordered[-1].scenario == "single_person_crossing"
    # a longer time limit alone moves a task ahead of its twin
    text = re.sub(r"(?m)^time_limit_s = .*$", "time_limit_s = 100.0", tasks[0].scenario_toml)
    long_ = replace(tasks[0], scenario_toml=text, scenario_sha="other")
    assert estimated_cost(long_) > estimated_cost(tasks[0])


def test_unreadable_task_goes_last_and_engine_submits_in_that_order(tmp_path, monkeypatch):
    cfg = BenchConfig(out=tmp_path / "b", methods=("cbf-only", "big-cbf"), scenarios=("single_person_crossing",),
                      seeds=(0,), workers=1)
    tasks, _, _ = plan(cfg)
    broken = replace(tasks[0], scenario_toml="not toml [", seed=7)
    assert estimated_cost(broken) == 0.0
    seen = []
    monkeypatch.setattr(engines, "run_local", lambda t, w, on_row, fn: seen.extend(t))
    engines.run("local", [broken] + tasks, 1, lambda row: None)
    assert seen == longest_first([broken] + tasks) and seen[-1] is broken
    assert [t.method for t in seen[:2]] == ["big-cbf", "cbf-only"]
