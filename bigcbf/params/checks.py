"""Range checks for parameter dataclasses.

Two tools, one rule (a value outside its documented range is an error naming the field):

- :func:`ranged` declares a field's *documented physical range* in its metadata
  (``samples: int = ranged(512, 2, 20_000)  # sampled sequences per update [-]``); the comment on the line keeps
  the unit and what the field is (``bigcbf methods`` reads both, and shows the range). ``toml_io.from_dict`` checks
  every such field of every dataclass it loads (a UserError naming the file and the field), and the class's
  ``__post_init__`` calls :func:`check_field_ranges` so that the Python API refuses the same values (a FieldError).
- :func:`check_ranges`: the older sign checks (> 0, >= 0, [0, 1]) of some classes, called from ``__post_init__``.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from ..errors import FieldError


@dataclass(frozen=True)
class Range:
    """A closed (or half-open) interval of allowed values; for an array field, every element must lie in it."""

    lo: float
    hi: float
    lo_open: bool = False          # True: lo itself is not allowed (``(0, 10]``)
    hi_open: bool = False

    def __contains__(self, v) -> bool:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            return False
        above = v > self.lo if self.lo_open else v >= self.lo
        below = v < self.hi if self.hi_open else v <= self.hi
        return above and below

    def __str__(self) -> str:
        return f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"


#: the ``default`` of :func:`ranged` for a field the caller must give
REQUIRED: Any = dataclasses.MISSING


def ranged(default: Any, lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False, **kw):
    """A dataclass field with ``default`` whose documented range is [lo, hi] (``lo_open``/``hi_open``: excluded).
    For a tuple field the range applies to every element; None (an unset optional field) is always allowed."""
    return dataclasses.field(default=default, metadata={"range": Range(lo, hi, lo_open, hi_open)}, **kw)


def field_range(f: dataclasses.Field) -> Range | None:
    """The documented range of a dataclass field (None: none declared)."""
    return f.metadata.get("range") if f.metadata else None


def _leaves(value):
    if isinstance(value, (tuple, list)):
        for x in value:
            yield from _leaves(x)
    else:
        yield value


def range_violation(f: dataclasses.Field, value) -> str | None:
    """The message for ``value`` of field ``f`` outside its documented range (one line: the field's name, the
    bound it crosses, the range, the value), else None."""
    rng = field_range(f)
    if rng is None or value is None:
        return None
    for v in _leaves(value):
        if v in rng:
            continue
        number = isinstance(v, (int, float)) and not isinstance(v, bool)
        shown = f"{v:g}" if number else repr(v)[:40]
        what = f"every element of {f.name}" if isinstance(value, (tuple, list)) else f.name
        if number and (v < rng.lo or (rng.lo_open and v == rng.lo)):
            return f"{what} must be {'>' if rng.lo_open else '>='} {rng.lo:g} (range {rng}), got {shown}"
        return f"{what} must be in {rng}, got {shown}"
    return None


def check_field_ranges(obj) -> None:
    """FieldError naming the first field of the dataclass instance ``obj`` outside its documented range."""
    for f in dataclasses.fields(obj):
        msg = range_violation(f, getattr(obj, f.name))
        if msg is not None:
            raise FieldError(f.name, msg)


def check_ranges(obj, *, positive=(), nonneg=(), unit=(), min_int: dict[str, int] | None = None) -> None:
    """Every named field finite and > 0 (``positive``), >= 0 (``nonneg``), in [0, 1] (``unit``); integer fields
    at least their minimum (``min_int``). Raises ValueError naming the first field that is not. The documented
    ranges of the fields (:func:`ranged`) are checked first."""
    check_field_ranges(obj)
    for name in (*positive, *nonneg, *unit):
        v = getattr(obj, name)
        if not math.isfinite(v):
            raise ValueError(f"{name} must be finite, got {v}")
    for name in positive:
        if not getattr(obj, name) > 0:
            raise ValueError(f"{name} must be > 0, got {getattr(obj, name)}")
    for name in nonneg:
        if not getattr(obj, name) >= 0:
            raise ValueError(f"{name} must be >= 0, got {getattr(obj, name)}")
    for name in unit:
        if not 0 <= getattr(obj, name) <= 1:
            raise ValueError(f"{name} must be in [0, 1], got {getattr(obj, name)}")
    for name, lo in (min_int or {}).items():
        if getattr(obj, name) < lo:
            raise ValueError(f"{name} must be >= {lo}, got {getattr(obj, name)}")
