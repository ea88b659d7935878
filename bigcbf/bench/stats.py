"""Intervals and paired comparisons for the bench's rates, so that every success or collision rate a report shows
carries its 95 % interval and methods are compared on the episodes they share (the same scenes and seeds).

- :func:`wilson` -- the Wilson score interval of a binomial proportion (Wilson 1927; Agresti & Coull 1998 advise it
  over the Wald interval for the small n and the rates near 0 or 1 that benchmarks have).
- :func:`paired_difference` -- the difference of two success rates measured on the same episodes (a method and a
  reference, episode by episode): its 95 % interval by Newcombe's method 10 (Newcombe 1998, "Improved confidence
  intervals for the difference between binomial proportions based on paired data", Stat. Med. 17: the hybrid of
  the two Wilson intervals with the pairs' correlation), and the exact McNemar test's two-sided p-value (the
  binomial test of the discordant pairs, b successes of b + c at 1/2).

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
