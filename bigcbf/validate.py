"""Checks of the values a user hands to bigcbf, shared by the Python API (:mod:`bigcbf.api`), the Gymnasium
environment (:mod:`bigcbf.gym_env`) and, through them, the command line: one rule per value, and each mistake one
:class:`bigcbf.errors.UserError` naming the field.

- a seed: a whole number in [0, 4294967295], checked by the parser of ``bigcbf run --seed``
  (:func:`bigcbf.cli.argtypes.nonneg_int`);
- an episode's time limit: the rule of a scenario file's ``time_limit_s`` (the file loader's number check, then
  ``Scenario``'s range, (0, 600] s), with the same words;
- a bench's seeds (a count in [1, 10000] or at most 10000 seeds) and workers (local: 1 to 4 per core; Ray: 1 to
  10000): the bounds of ``bigcbf bench`` (:mod:`bigcbf.cli.bench`);
- a choice among names, a list of names, a path, a callable.
"""
from __future__ import annotations

import itertools
import numbers
import os
from pathlib import Path

from .errors import UserError


def _short(value, n: int = 60) -> str:
    r = repr(value)
    return r if len(r) <= n else r[:n] + "..."


def is_whole(value) -> bool:
    """A Python or NumPy integer (not a bool)."""
    import numpy as np
    return isinstance(value, (numbers.Integral, np.integer)) and not isinstance(value, (bool, np.bool_))


def check_seed(seed, field: str = "seed") -> int:
    """A seed as ``bigcbf run --seed`` takes it: a whole number in [0, MAX_SEED] (``cli.argtypes.nonneg_int``)."""
    import argparse

    from .cli.argtypes import nonneg_int

    try:                                   # repr of a non-integer (1.5, '3', None) is never a whole number to int()
        return nonneg_int(str(int(seed)) if is_whole(seed) else repr(seed))
    except argparse.ArgumentTypeError as exc:
        raise UserError(str(exc), field=field) from None


def check_time_limit(time_limit_s, scenario) -> float:
    """An episode's time limit for ``scenario`` (a :class:`bigcbf.scenario.Scenario`), checked as the scenario file's
    ``time_limit_s`` is (the loader's number check, then ``Scenario``'s: in (0, 600] s), with the same words."""
    from dataclasses import replace

    import numpy as np

    from .errors import FieldError
    from .params.toml_io import _convert

    if isinstance(time_limit_s, (np.integer, np.floating)):
        time_limit_s = time_limit_s.item()
    v = _convert(float, time_limit_s, None, "time_limit_s")     # a finite number, as from_dict converts the file's
    try:
        return replace(scenario, time_limit_s=v).time_limit_s
    except FieldError as exc:
        raise UserError(str(exc), field=exc.field) from None


def check_int(value, field: str, lo: int, hi: int | None = None) -> int:
    """A whole number in [lo, hi]."""
    if not is_whole(value):
        raise UserError(f"expected a whole number, got {_short(value)}", field=field)
    v = int(value)
    if v < lo:
        raise UserError(f"must be >= {lo}, got {v}", field=field)
    if hi is not None and v > hi:
        raise UserError(f"must be <= {hi}, got {v}", field=field)
    return v


def check_seeds(seeds, field: str = "seeds") -> tuple[int, ...]:
    """A bench's seeds: a count N (seeds 0..N-1, 1 <= N <= MAX_SEEDS) or the seeds themselves (at most MAX_SEEDS,
    each a seed as :func:`check_seed` takes it)."""
    from collections.abc import Iterable

    from .cli.bench import MAX_SEEDS

    if is_whole(seeds):
        return tuple(range(check_int(seeds, field, 1, MAX_SEEDS)))
    if isinstance(seeds, (str, bytes)) or not isinstance(seeds, Iterable):
        raise UserError(f"expected a count of seeds or a list of seeds, got {_short(seeds)}", field=field)
    items = list(itertools.islice(seeds, MAX_SEEDS + 1))     # (an endless iterator is refused, not run forever)
    if not items:
        raise UserError("no seeds given", field=field)
    if len(items) > MAX_SEEDS:
        raise UserError(f"at most {MAX_SEEDS} seeds in one bench", field=field)
    return tuple(check_seed(s, field) for s in items)


def check_workers(workers, engine: str = "local") -> int | None:
    """A bench's worker count (None: the engine's default): 1 to MAX_WORKERS_PER_CORE per core on the local engine,
    1 to MAX_RAY_WORKERS on Ray, as ``bigcbf bench --workers``."""
    from .cli.bench import MAX_RAY_WORKERS, MAX_WORKERS_PER_CORE

    if workers is None:
        return None
    hi = MAX_WORKERS_PER_CORE * (os.cpu_count() or 1) if engine == "local" else MAX_RAY_WORKERS
    return check_int(workers, "workers", 1, hi)


def check_choice(value, choices, field: str) -> str:
    """One of the strings ``choices``."""
    if not isinstance(value, str) or value not in choices:
        raise UserError(f"must be one of {', '.join(choices)}, got {_short(value)}", field=field)
    return value


def check_names(items, field: str, what: str) -> tuple[str, ...] | None:
    """A non-empty list of names or paths (``what``: e.g. ``methods``); None stays None (the default). A single
    string is refused (it would be taken letter by letter)."""
    from collections.abc import Iterable

    if items is None:
        return None
    if isinstance(items, (str, bytes, os.PathLike)) or not isinstance(items, Iterable):
        raise UserError(f"expected a list of {what}, got {_short(items)}", field=field)
    out = tuple(items)
    if not out:
        raise UserError(f"no {what} given", field=field)
    for x in out:
        if not isinstance(x, (str, os.PathLike)) or not os.fspath(x).strip():
            raise UserError(f"expected {what} as non-empty strings, got {_short(x)}", field=field)
    return tuple(os.fspath(x) for x in out)


def check_path(value, field: str, what: str = "a path", optional: bool = True) -> Path | None:
    """A file or folder path (a str or os.PathLike, not empty: ``Path("")`` would silently mean the current
    folder); None when ``optional``."""
    if value is None and optional:
        return None
    if not isinstance(value, (str, os.PathLike)):
        raise UserError(f"expected {what}, got {_short(value)}", field=field)
    s = os.fspath(value)
    if not isinstance(s, str) or not s.strip():
        raise UserError(f"expected {what}, got an empty string", field=field)
    return Path(s)


def check_callable(value, field: str, optional: bool = True):
    """A callable (None when ``optional``)."""
    if value is None and optional:
        return None
    if not callable(value):
        raise UserError(f"expected a function, got {_short(value)}", field=field)
    return value
