"""Intervals and paired comparisons for the bench's rates, so that every success or collision rate a report shows
carries its 95 % interval and methods are compared on the episodes they share (the same scenes and seeds).

- :func:`wilson` -- the Wilson score interval of a binomial proportion (Wilson 1927; Agresti & Coull 1998 advise it
  over the Wald interval for the small n and the rates near 0 or 1 that benchmarks have).
- :func:`paired_difference` -- the difference of two success rates measured on the same episodes (a method and a
  reference, episode by episode): its 95 % interval by Newcombe's method 10 (Newcombe 1998, "Improved confidence
  intervals for the difference between binomial proportions based on paired data", Stat. Med. 17: the hybrid of
  the two Wilson intervals with the pairs' correlation), and the exact McNemar test's two-sided p-value (the
  binomial test of the discordant pairs, b successes of b + c at 1/2).

- :func:`ratio_ci_pct` / :func:`paired_ratio_difference` -- a pooled fraction of control steps (e.g. the QP
  infeasible fraction: infeasible steps of all episodes / all their steps) and the paired difference of two such
  fractions, with 95 % intervals that count the episode, not the step, as the independent unit: the ratio
  estimator's linearization with the between-episode (cluster) variance (Cochran 1977, Sampling Techniques,
  Sec. 6.3-6.4), normal quantile, clipped to [0, 100] %. A fraction that is 0 in every episode has the interval
  [0, 0] (no spread to measure).

- :func:`two_sample_difference` -- the difference of two success rates from independent samples (ours against a
  published figure, e.g. the paper's Table II at n = 450): its 95 % interval by Newcombe's method 10 for
  independent proportions (Newcombe 1998, "Interval estimation for the difference between independent
  proportions: comparison of eleven methods", Stat. Med. 17: the hybrid of the two Wilson intervals), and Fisher's
  exact test's two-sided p-value (the hypergeometric probabilities of all tables with the same margins no more
  likely than the observed one).

Pure Python (math only): the report runs without scipy; the tests check these against scipy's own computations.
"""
from __future__ import annotations

import math
from typing import Sequence

#: the normal quantile of a two-sided 95 % interval
Z95 = 1.959963984540054


def wilson(k: int, n: int, z: float = Z95) -> tuple[float, float] | None:
    """The Wilson score interval (lo, hi) of k successes in n trials, as fractions in [0, 1]; None when n = 0."""
    if n <= 0:
        return None
    p = k / n
    z2 = z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def wilson_pct(k: int, n: int) -> list[float] | None:
    """:func:`wilson` in percent, rounded to 0.01 (for summary.json)."""
    ci = wilson(k, n)
    return None if ci is None else [round(100.0 * ci[0], 2), round(100.0 * ci[1], 2)]


def _binom_two_sided_half(k: int, n: int) -> float:
    """Exact two-sided p-value of k successes in n trials at p = 1/2 (symmetric: twice the smaller tail)."""
    if n == 0:
        return 1.0
    k = min(k, n - k)
    tail = sum(math.comb(n, i) for i in range(k + 1)) / 2.0 ** n
    return min(1.0, 2.0 * tail)


def paired_difference(mine: Sequence[bool], ref: Sequence[bool]) -> dict:
    """The success-rate difference ``mine - ref`` over paired episodes (element i of both is the same scene and
    seed). Returns n, the counts a (both succeed), b (only mine), c (only ref), d (neither), the difference and its
    95 % interval in percentage points (Newcombe's method 10), and the exact McNemar p-value."""
    if len(mine) != len(ref):
        raise ValueError("paired samples of different lengths")
    n = len(mine)
    a = sum(1 for x, y in zip(mine, ref) if x and y)
    b = sum(1 for x, y in zip(mine, ref) if x and not y)
    c = sum(1 for x, y in zip(mine, ref) if not x and y)
    d = n - a - b - c
    out = {"n": n, "a": a, "b": b, "c": c, "d": d, "diff_pct": None, "ci95_pct": None, "mcnemar_p": None}
    if n == 0:
        return out
    p1, p2 = (a + b) / n, (a + c) / n
    l1, u1 = wilson(a + b, n)
    l2, u2 = wilson(a + c, n)
    den = (a + b) * (c + d) * (a + c) * (b + d)
    phi = (a * d - b * c) / math.sqrt(den) if den > 0 else 0.0
    theta = p1 - p2
    delta = math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2))
    eps = math.sqrt(max(0.0, (u1 - p1) ** 2 - 2 * phi * (u1 - p1) * (p2 - l2) + (p2 - l2) ** 2))
    out.update(diff_pct=round(100.0 * theta, 2),
               ci95_pct=[round(100.0 * max(-1.0, theta - delta), 2), round(100.0 * min(1.0, theta + eps), 2)],
               mcnemar_p=_binom_two_sided_half(b, b + c))
    return out


def fmt_ci(pct: float | None, ci: Sequence[float] | None, digits: int = 1) -> str:
    """'94.4 [88.1, 97.5]' (a rate in % with its interval), '–' without data."""
    if pct is None:
        return "–"
    if ci is None:
        return f"{pct:.{digits}f}"
    return f"{pct:.{digits}f} [{ci[0]:.{digits}f}, {ci[1]:.{digits}f}]"


def _ratio_terms(nums: Sequence[float], dens: Sequence[float]) -> tuple[float, list[float]] | None:
    """R = sum(nums) / sum(dens) and each cluster's linearized term (y_i - R x_i) / X; None when sum(dens) = 0."""
    total = float(sum(dens))
    if total <= 0:
        return None
    r = float(sum(nums)) / total
    return r, [(y - r * x) / total for y, x in zip(nums, dens)]


def _clip_pct(lo: float, hi: float) -> list[float]:
    return [round(100.0 * max(-1.0, lo), 2), round(100.0 * min(1.0, hi), 2)]


def ratio_ci_pct(nums: Sequence[float], dens: Sequence[float], z: float = Z95) -> list[float] | None:
    """The 95 % interval [lo, hi] in % of the pooled fraction sum(nums) / sum(dens) over independent clusters
    (nums[i] of dens[i] in cluster i; module docstring); None with fewer than 2 clusters or no denominator."""
    n = len(nums)
    if len(dens) != n:
        raise ValueError("numerators and denominators of different lengths")
    terms = _ratio_terms(nums, dens) if n >= 2 else None
    if terms is None:
        return None
    r, e = terms
    half = z * math.sqrt(n / (n - 1) * sum(t * t for t in e))
    lo, hi = _clip_pct(r - half, r + half)
    return [max(0.0, lo), hi]


def paired_ratio_difference(nums: Sequence[float], dens: Sequence[float], ref_nums: Sequence[float],
                            ref_dens: Sequence[float], z: float = Z95) -> dict:
    """The difference of two pooled fractions measured on paired clusters (element i of both: the same scene and
    seed), ``nums/dens - ref_nums/ref_dens``: n, diff_pct and its 95 % interval in percentage points (the
    linearized terms of both ratios subtracted pair by pair; module docstring). None figures without data."""
    n = len(nums)
    if not (len(dens) == len(ref_nums) == len(ref_dens) == n):
        raise ValueError("paired samples of different lengths")
    a, b = _ratio_terms(nums, dens), _ratio_terms(ref_nums, ref_dens)
    out = {"n": n, "diff_pct": None, "ci95_pct": None}
    if n == 0 or a is None or b is None:
        return out
    diff = a[0] - b[0]
    out["diff_pct"] = round(100.0 * diff, 2)
    if n >= 2:
        half = z * math.sqrt(n / (n - 1) * sum((x - y) ** 2 for x, y in zip(a[1], b[1])))
        out["ci95_pct"] = _clip_pct(diff - half, diff + half)
    return out


def _log_comb(n: int, k: int) -> float:
    return math.lgamma(n + 1) - math.lgamma(k + 1) - math.lgamma(n - k + 1)


def fisher_exact_p(k1: int, n1: int, k2: int, n2: int) -> float:
    """Fisher's exact test, two-sided: the probability under equal rates (given both margins) of a 2x2 table no
    more likely than the observed [[k1, n1 - k1], [k2, n2 - k2]] (the relative tolerance 1e-7 for ties, as
    scipy.stats.fisher_exact uses)."""
    total, succ = n1 + n2, k1 + k2
    lo, hi = max(0, succ - n2), min(succ, n1)
    logs = {x: _log_comb(n1, x) + _log_comb(n2, succ - x) - _log_comb(total, succ) for x in range(lo, hi + 1)}
    observed = logs[k1]
    p = sum(math.exp(v) for v in logs.values() if v <= observed + 1e-7 * abs(observed) + 1e-12)
    return min(1.0, p)


def two_sample_difference(k1: int, n1: int, k2: int, n2: int) -> dict:
    """The success-rate difference k1/n1 - k2/n2 of two independent samples: the counts, diff_pct and its 95 %
    interval in percentage points (Newcombe's method 10: theta - sqrt((p1 - l1)^2 + (u2 - p2)^2), theta +
    sqrt((u1 - p1)^2 + (p2 - l2)^2) with the Wilson intervals (l, u)), and Fisher's exact two-sided p-value. None
    figures when a sample is empty."""
    out = {"k1": k1, "n1": n1, "k2": k2, "n2": n2, "diff_pct": None, "ci95_pct": None, "fisher_p": None}
    if n1 <= 0 or n2 <= 0:
        return out
    if not (0 <= k1 <= n1 and 0 <= k2 <= n2):
        raise ValueError(f"counts out of range: {k1}/{n1}, {k2}/{n2}")
    p1, p2 = k1 / n1, k2 / n2
    l1, u1 = wilson(k1, n1)
    l2, u2 = wilson(k2, n2)
    theta = p1 - p2
    out.update(diff_pct=round(100.0 * theta, 2),
               ci95_pct=[round(100.0 * max(-1.0, theta - math.hypot(p1 - l1, u2 - p2)), 2),
                         round(100.0 * min(1.0, theta + math.hypot(u1 - p1, p2 - l2)), 2)],
               fisher_p=fisher_exact_p(k1, n1, k2, n2))
    return out
