"""Range checks for parameter dataclasses (called from their ``__post_init__``; a ValueError there becomes a
UserError naming the file and the table when the parameters come from TOML)."""
from __future__ import annotations

import math


def check_ranges(obj, *, positive=(), nonneg=(), unit=(), min_int: dict[str, int] | None = None) -> None:
    """Every named field finite and > 0 (``positive``), >= 0 (``nonneg``), in [0, 1] (``unit``); integer fields
    at least their minimum (``min_int``). Raises ValueError naming the first field that is not."""
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
