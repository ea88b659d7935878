"""The bench's intervals and paired tests against independent computations (scipy) and their coverage."""
from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as sps

from bigcbf.bench import report
from bigcbf.bench.stats import fmt_ci, paired_difference, wilson


@pytest.mark.parametrize("k, n", [(0, 10), (1, 10), (5, 10), (10, 10), (449, 450), (0, 450), (37, 50), (3, 7)])
def test_wilson_equals_scipys(k, n):
    ci = sps.binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    assert wilson(k, n) == pytest.approx((ci.low, ci.high), abs=1e-9)
    assert wilson(k, 0) is None


@pytest.mark.parametrize("b, c", [(0, 0), (5, 0), (3, 9), (12, 12), (40, 7)])
def test_mcnemar_p_is_the_exact_binomial_test_of_the_discordant_pairs(b, c):
    mine = [True] * b + [False] * c + [True] * 20 + [False] * 10
    ref = [False] * b + [True] * c + [True] * 20 + [False] * 10
    d = paired_difference(mine, ref)
    assert (d["a"], d["b"], d["c"], d["d"]) == (20, b, c, 10)
    want = 1.0 if b + c == 0 else sps.binomtest(b, b + c, 0.5).pvalue
    assert d["mcnemar_p"] == pytest.approx(want, rel=1e-12)
    assert d["diff_pct"] == pytest.approx(100 * (b - c) / (b + c + 30), abs=0.01)
    lo, hi = d["ci95_pct"]
    assert lo <= d["diff_pct"] <= hi


def test_newcombe_interval_by_hand():
    """a = 20, b = 8, c = 2, d = 20 (n = 50): p1 = 0.56, p2 = 0.44, theta = 0.12; the Wilson limits and phi worked
    out step by step here (not with the module's function)."""
    z = 1.959963984540054
    n = 50

    def w(p):
        c = (p + z * z / (2 * n)) / (1 + z * z / n)
        h = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
        return c - h, c + h
    (l1, u1), (l2, u2) = w(0.56), w(0.44)
    phi = (20 * 20 - 8 * 2) / np.sqrt(28 * 22 * 22 * 28)
    lo = 0.12 - np.sqrt((0.56 - l1) ** 2 - 2 * phi * (0.56 - l1) * (u2 - 0.44) + (u2 - 0.44) ** 2)
    hi = 0.12 + np.sqrt((u1 - 0.56) ** 2 - 2 * phi * (u1 - 0.56) * (0.44 - l2) + (0.44 - l2) ** 2)
    d = paired_difference([True] * 28 + [False] * 22, [True] * 20 + [False] * 8 + [True] * 2 + [False] * 20)
    assert d["diff_pct"] == pytest.approx(12.0)
    assert d["ci95_pct"] == pytest.approx([100 * lo, 100 * hi], abs=0.006)
    assert 0 < d["ci95_pct"][0] < 12 < d["ci95_pct"][1]     # this one excludes 0; McNemar p = 0.109 does not
    assert d["mcnemar_p"] == pytest.approx(sps.binomtest(8, 10, 0.5).pvalue)


def test_the_paired_interval_covers_the_true_difference_at_about_95_percent():
    """Correlated pairs (a shared scene difficulty), n = 60, 1,500 draws: the coverage is within the binomial band
    of 95 % for that many draws."""
    rng = np.random.default_rng(7)
    hits, draws, n = 0, 1500, 60
    for _ in range(draws):
        hard = rng.random(n) < 0.3
        mine = rng.random(n) < np.where(hard, 0.6, 0.95)
        ref = rng.random(n) < np.where(hard, 0.3, 0.9)
        lo, hi = paired_difference(list(mine), list(ref))["ci95_pct"]
        true = 100 * ((0.3 * 0.6 + 0.7 * 0.95) - (0.3 * 0.3 + 0.7 * 0.9))
        hits += lo <= true <= hi
    band = 1.96 * np.sqrt(0.95 * 0.05 / draws)
    assert 0.95 - band - 0.01 <= hits / draws <= 0.95 + band + 0.02


def test_the_summary_carries_intervals_paired_differences_and_provenance():
    def row(method, seed, success, collision=False):
        m = dict(success=success, collision=collision, timeout=not success and not collision, time_s=10.0,
                 min_clearance_m=0.3, e_cbf=0.0, cbf_active_ratio=0.0, qp_infeasible_ratio=0.0, planner_p95_ms=0.0,
                 cbf_p95_ms=0.0, perception_p95_ms=0.0, stopped_time_s=0.0, final_goal_dist_m=0.1, sim_time_s=10.0,
                 wall_time_s=1.0, control_steps=200, mode_history=[], perception="lidar", warnings={})
        return dict(scenario="s", method=method, seed=seed, params_hash="cafe", scenario_sha="x", status="ok",
                    error=None, metrics=m, worker_wall_s=1.0, host="h", attempts=1, code_sha="abc1234")
    rows = [row("big-cbf", k, k < 9) for k in range(10)] + [row("dwa", k, k < 5, collision=k == 9) for k in range(10)]
    s = report.build_summary(rows, ["dwa", "big-cbf"], ["s"], list(range(10)))
    dwa = s["methods"]["dwa"]
    assert dwa["success_ci95_pct"] == pytest.approx([100 * x for x in wilson(5, 10)], abs=0.01)
    assert dwa["collision_pct"] == 10.0 and dwa["code_versions"] == ["abc1234"] and dwa["params_hashes"] == ["cafe"]
    p = s["paired"]
    assert p["reference"] == "big-cbf" and p["by_method"]["dwa"]["diff_pct"] == -40.0
    md = report.summary_markdown(s)
    assert fmt_ci(50.0, dwa["success_ci95_pct"]) in md and "Paired differences in success (vs BIG-CBF)" in md
    assert "| DWA + CBF | 10 | 0 | 4 | -40.0 [" in md and "abc1234" in md and "cafe" in md
