"""Argument types for the subcommands: a bad value is one argparse error line naming the option and the value."""
from __future__ import annotations

import argparse
import math
from pathlib import Path


def _float(s: str) -> float:
    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {s!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {s!r}")
    return v


#: seeds are 32-bit: 0 .. 4294967295 (the same range for run, demo, record and bench)
MAX_SEED = 2**32 - 1


def nonneg_int(s: str) -> int:
    """A seed: a whole number in [0, MAX_SEED]."""
    try:
        v = int(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {s[:40]!r}") from None
    if not 0 <= v <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"expected a seed in [0, {MAX_SEED}], got {s[:40]}")
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


def path_arg(s: str) -> Path:
    """A file or folder path; an empty string is refused (Path("") would silently mean the current folder)."""
    if not s.strip():
        raise argparse.ArgumentTypeError("expected a path, got an empty string")
    return Path(s)


def float_in_closed(lo: float, hi: float, what: str = "a number"):
    """A finite number in (lo, hi]."""
    def parse(s: str) -> float:
        v = _float(s)
        if not lo < v <= hi:
            raise argparse.ArgumentTypeError(f"expected {what} in ({lo:g}, {hi:g}], got {v:g}")
        return v
    return parse


def float_in_range(lo: float, hi: float, what: str = "a number"):
    """A finite number in [lo, hi]."""
    def parse(s: str) -> float:
        v = _float(s)
        if not lo <= v <= hi:
            raise argparse.ArgumentTypeError(f"expected {what} in [{lo:g}, {hi:g}], got {v:g}")
        return v
    return parse


def robot_profile_arg(s: str) -> Path:
    """A robot profile (the simulated robot's imperfections, ``bigcbf/params/robot.py``): the name of a shipped one
    (``x3_sim``, ``x3_hardware``: ``bigcbf/profiles/``) or a path to a .toml file. Returns the file; its contents
    are checked where it is loaded (errors name that file and the field). One type for every subcommand that
    takes ``--robot-profile``."""
    from ..scenario import profile_files

    shipped = profile_files()
    if s in shipped:
        return shipped[s]
    names = ", ".join(shipped)
    if not s.strip():
        raise argparse.ArgumentTypeError(f"expected a shipped robot profile ({names}) or a .toml file, got an "
                                         "empty string")
    p = Path(s)
    if p.suffix != ".toml":
        raise argparse.ArgumentTypeError(f"no shipped robot profile {s[:60]!r} (shipped: {names}) and not a "
                                         ".toml file")
    if not p.is_file():
        what = "is a folder" if p.is_dir() else "file not found"
        raise argparse.ArgumentTypeError(f"{s[:200]}: {what} (a robot profile is a shipped name, {names}, or a "
                                         ".toml file)")
    return p
