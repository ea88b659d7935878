"""The two-sample comparison of a success rate with a published one (bigcbf.bench.stats.two_sample_difference):
Newcombe's method 10 against the values his paper prints, Fisher's exact p against scipy's, the paper's counts."""
from __future__ import annotations

import pytest

from bigcbf.bench import paper
from bigcbf.bench.stats import fisher_exact_p, two_sample_difference


@pytest.mark.parametrize("k1, n1, k2, n2, lo, hi", [
    (56, 70, 48, 80, 0.0524, 0.3339),      # Newcombe 1998 (Stat. Med. 17:873), Table II, example (a), method 10
    (9, 10, 3, 10, 0.1705, 0.8090),        # example (b)
    (6, 7, 2, 7, 0.0582, 0.8062),          # example (c)
    (5, 56, 0, 29, -0.0381, 0.1926),       # example (d)
])
def test_newcombe_method_10_as_printed(k1, n1, k2, n2, lo, hi):
    t = two_sample_difference(k1, n1, k2, n2)
    assert t["ci95_pct"][0] == pytest.approx(100 * lo, abs=0.011)
    assert t["ci95_pct"][1] == pytest.approx(100 * hi, abs=0.011)
    assert t["diff_pct"] == pytest.approx(100 * (k1 / n1 - k2 / n2), abs=0.005)


@pytest.mark.parametrize("table", [(9, 10, 3, 10), (309, 450, 300, 450), (450, 450, 449, 450), (0, 50, 25, 50),
                                   (5, 56, 0, 29), (3, 4, 0, 4)])
def test_fisher_exact_matches_scipy(table):
    stats = pytest.importorskip("scipy.stats")
    k1, n1, k2, n2 = table
    ref = stats.fisher_exact([[k1, n1 - k1], [k2, n2 - k2]])[1]
    assert fisher_exact_p(*table) == pytest.approx(ref, rel=1e-9, abs=1e-12)


def test_paper_counts_from_its_percentages():
    """Table II prints k/450 to two decimals: every method's k is a whole number within the print's rounding."""
    for m, row in paper.PAPER_TABLE_II.items():
        k = paper.paper_successes(row["success_pct"], 450)
        assert abs(100 * k / 450 - row["success_pct"]) < 0.005, m
    assert paper.paper_successes(68.67, 450) == 309 and paper.paper_successes(98, 50) == 49


def test_empty_sample_and_bad_counts():
    assert two_sample_difference(0, 0, 3, 10)["diff_pct"] is None
    with pytest.raises(ValueError):
        two_sample_difference(11, 10, 3, 10)
