"""Argument types for the subcommands: a bad value is one argparse error line naming the option and the value."""
from __future__ import annotations

import argparse
import math


def _float(s: str) -> float:
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {s!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {s!r}")
    return v


def nonneg_int(s: str) -> int:
    """A whole number >= 0 (seeds)."""
    try:
        v = int(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {s!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {v}")
    return v


def positive_float(s: str) -> float:
    """A finite number > 0 (durations)."""
    v = _float(s)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {s}")
    return v


def float_in(lo: float, hi: float, what: str = "a number"):
    """A finite number in [lo, hi)."""
    def parse(s: str) -> float:
        v = _float(s)
        if not lo <= v < hi:
            raise argparse.ArgumentTypeError(f"expected {what} in [{lo:g}, {hi:g}), got {v}")
        return v
    return parse
