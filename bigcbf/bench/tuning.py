"""Equal-budget tuning (issue 24, item 4): every method gets the same search, once, on one fixed dev subset.

The protocol is a file, decided before any run and committed first: ``bigcbf/params/tuning/grid.toml``. It holds

- ``[protocol]``: the budget (8 configurations per method), the design's seed, the episode seed and the selection rule;
- ``[subset]``: the worlds, a rule over the generated suite's DEV split (the first 6 dev world seeds of every family),
  never the paper's nine scenes and never a test split;
- ``[methods.NAME]``: each method's tunable parameters (``params``: name, unit, default, range, scale, source) and its
  8 configurations (``configs``, one row per configuration in the order of ``params``): row 0 is the authors'
  defaults (for ``big-cbf``: the project's documented choice where the paper is silent), rows 1-7 a Latin hypercube
  (:func:`design`, seeded by the protocol's seed and the method's name, rounded to 3 significant digits) written
  out in full, so the file is the design. ``shared_by`` names methods that take this method's choice
  (``big-cbf-noshared`` takes ``big-cbf``'s: the ablation differs only in its margin).

A parameter name says where it lives in a run configuration (:mod:`bigcbf.config`): ``stack.KEY`` (or
``stack.uncertainty.KEY``) is a stack key of this method's episodes only (``[methods.NAME.stack]``), ``method.KEY`` a
key of the method's own parameters (``[methods.NAME]``).

:func:`run_tuning` runs every (method, configuration, world) through the bench's machinery (the episode tasks of
:mod:`.tasks`, the engines, the result store: parallel and resumable, one ``results.sqlite``), then writes
``tuning.csv`` and ``tuning.json`` (each configuration's success with its Wilson interval, at-fault collisions and
mean time to goal; the chosen one per method) and ``tuned.toml``, the chosen configurations as a run configuration
that ``bigcbf run/bench --config`` read. :func:`write_shipped` copies them to ``bigcbf/params/tuning/`` after a
complete run of the whole protocol (docs/tuning.md).

Selection (the file's ``[protocol] selection``, fixed before any run): most successes over the subset; ties by fewer
at-fault collisions; then by the lower mean time to goal over the successful episodes; then the lower configuration
index (the defaults win an exact tie).
"""
from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import json
import math
import subprocess
import sys
import time
import zlib
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from ..errors import UserError

TUNING_DIR = Path(__file__).resolve().parent.parent / "params" / "tuning"
GRID = TUNING_DIR / "grid.toml"
#: what --write-shipped writes (the shipped tuned run configuration and the search's results)
SHIPPED = {"tuned.toml": TUNING_DIR / "tuned.toml", "tuning.csv": TUNING_DIR / "results.csv",
           "tuning.json": TUNING_DIR / "results.json"}
OUTPUTS = ("results.sqlite", "tuning.csv", "tuning.json", "tuned.toml")
#: the budget of the protocol: configurations per method, the defaults among them
BUDGET = 8
SCALES = ("linear", "log")
SIGNIFICANT = 3


@dataclass(frozen=True)
class Param:
    name: str            # "stack.alpha_per_s", "stack.uncertainty.q_sigma_m2_per_s" or "method.w_heading"
    unit: str
    default: float
    lo: float
    hi: float
    scale: str           # linear or log
    integer: bool
    source: str


@dataclass(frozen=True)
class MethodGrid:
    method: str
    params: tuple[Param, ...]
    configs: tuple[tuple, ...]
    shared_by: tuple[str, ...] = ()

    def values(self, index: int) -> dict[str, float]:
        return dict(zip((p.name for p in self.params), self.configs[index]))


@dataclass(frozen=True)
class Grid:
    path: Path
    sha: str                  # sha256 of the file's bytes (hex, 16)
    design_seed: int
    episode_seed: int
    selection: str
    split: str
    families: tuple[str, ...]
    world_seeds: tuple[int, ...]
    methods: dict[str, MethodGrid]


# --- the design --------------------------------------------------------------------------------------------------

def _round(x: float, integer: bool) -> float | int:
    if integer:
        return int(round(x))
    if x == 0:
        return 0.0
    return float(f"{x:.{SIGNIFICANT}g}")


def design(params, n: int, seed: int, method: str) -> list[tuple]:
    """``n`` configurations of ``params`` as a Latin hypercube: each parameter's range cut into n equal strata (in
    log space for ``log``), one point per stratum at a uniform place in it, the strata of the parameters paired by
    independent permutations; numpy's PCG64 seeded by (seed, crc32(method)); values rounded to 3 significant
    digits (integers to the nearest)."""
    rng = np.random.default_rng([int(seed), zlib.crc32(method.encode())])
    cols = []
    for p in params:
        u = (rng.permutation(n) + rng.random(n)) / n
        if p.scale == "log":
            x = np.exp(np.log(p.lo) + u * (np.log(p.hi) - np.log(p.lo)))
        else:
            x = p.lo + u * (p.hi - p.lo)
        cols.append([_round(min(max(float(v), p.lo), p.hi), p.integer) for v in x])
    return [tuple(c[i] for c in cols) for i in range(n)]


# --- the grid file -----------------------------------------------------------------------------------------------

def _need(table: dict, key: str, types, file: str, where: str):
    if key not in table:
        raise UserError("missing key", file=file, field=f"{where}.{key}" if where else key)
    value = table[key]
    if isinstance(value, bool) and bool not in (types if isinstance(types, tuple) else (types,)) or \
            not isinstance(value, types):
        raise UserError(f"expected {getattr(types, '__name__', types)}, got {value!r}"[:120], file=file,
                        field=f"{where}.{key}" if where else key)
    return value


def _param(raw, file: str, where: str) -> Param:
    if not isinstance(raw, dict):
        raise UserError(f"expected a table, got {raw!r}"[:120], file=file, field=where)
    name = _need(raw, "name", str, file, where)
    if not (name.startswith("stack.") or name.startswith("method.")):
        raise UserError(f"a parameter is stack.KEY or method.KEY, got {name!r}", file=file, field=f"{where}.name")
    lo, hi = (float(v) for v in _need(raw, "range", list, file, where)[:2]) if len(raw.get("range", [])) == 2 \
        else (None, None)
    if lo is None or not lo < hi:
        raise UserError("expected [low, high] with low < high", file=file, field=f"{where}.range")
    scale = raw.get("scale", "linear")
    if scale not in SCALES or (scale == "log" and lo <= 0):
        raise UserError(f"scale is one of {', '.join(SCALES)} (log needs a range above 0), got {scale!r}", file=file,
                        field=f"{where}.scale")
    default = _need(raw, "default", (int, float), file, where)
    return Param(name, str(raw.get("unit", "-")), default, lo, hi, scale, bool(raw.get("integer", False)),
                 _need(raw, "source", str, file, where))


def _method_grid(name: str, raw, n: int, file: str) -> MethodGrid:
    from ..control.methods import METHODS
    where = f"methods.{name}"
    if name not in METHODS:
        raise UserError(f"not a registered method (known: {', '.join(METHODS.names())})", file=file, field=where)
    params = tuple(_param(p, file, f"{where}.params[{j}]") for j, p in enumerate(_need(raw, "params", list, file,
                                                                                          where)))
    rows = _need(raw, "configs", list, file, where)
    if len(rows) != n:
        raise UserError(f"{len(rows)} configurations, the protocol gives every method {n}", file=file,
                        field=f"{where}.configs")
    configs = []
    for i, row in enumerate(rows):
        at = f"{where}.configs[{i}]"
        if not isinstance(row, list) or len(row) != len(params):
            raise UserError(f"expected {len(params)} values (one per parameter)", file=file, field=at)
        for p, v in zip(params, row):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not p.lo <= v <= p.hi or \
                    (p.integer and not isinstance(v, int)):
                raise UserError(f"{p.name} = {v!r} is outside its range [{p.lo:g}, {p.hi:g}]"
                                f"{' (an integer)' if p.integer else ''}", file=file, field=at)
        configs.append(tuple(row))
    if configs and configs[0] != tuple(p.default for p in params):
        raise UserError("configuration 0 must be the defaults (each parameter's default)", file=file,
                        field=f"{where}.configs[0]")
    if len(set(configs)) != len(configs):
        raise UserError("two configurations are the same", file=file, field=f"{where}.configs")
    shared = tuple(raw.get("shared_by", ()))
    return MethodGrid(name, params, tuple(configs), shared)


def load_grid(path: str | Path = GRID) -> Grid:
    """The tuning protocol of ``path`` (default: the shipped grid), checked: every mistake is a UserError naming the
    file and the field. Each configuration is also checked as a run configuration (:func:`run_config`): a value
    outside its field's documented range, a key the method does not have, or defaults that are not the code's
    defaults are errors."""
    from .. import worlds
    from ..params.toml_io import load_toml

    path = Path(path)
    data = load_toml(path)
    file = str(path)
    proto = _need(data, "protocol", dict, file, "")
    n = _need(proto, "configs_per_method", int, file, "protocol")
    if n != BUDGET:
        raise UserError(f"the protocol gives every method {BUDGET} configurations, got {n}", file=file,
                        field="protocol.configs_per_method")
    sub = _need(data, "subset", dict, file, "")
    split = _need(sub, "split", str, file, "subset")
    if split != "dev":
        raise UserError(f"tuning uses the dev split only, got {split!r}", file=file, field="subset.split")
    fams = tuple(_need(sub, "families", list, file, "subset"))
    seeds = tuple(_need(sub, "world_seeds", list, file, "subset"))
    for fam in fams:
        known = worlds.FAMILIES.get(fam).splits["dev"] if fam in worlds.FAMILIES else None
        if known is None:
            raise UserError(f"unknown world family {fam!r}", file=file, field="subset.families")
        bad = [s for s in seeds if not isinstance(s, int) or s not in known]
        if bad:
            raise UserError(f"world seeds {bad} are not in {fam}'s dev split ({known.start}-{known.stop - 1})",
                            file=file, field="subset.world_seeds")
    methods = {name: _method_grid(name, raw, n, file) for name, raw in _need(data, "methods", dict, file, "").items()}
    grid = Grid(path, hashlib.sha256(path.read_bytes()).hexdigest()[:16], _need(proto, "design_seed", int, file,
                                                                                   "protocol"),
                _need(proto, "episode_seed", int, file, "protocol"), _need(proto, "selection", str, file, "protocol"),
                split, fams, seeds, methods)
    for mg in methods.values():
        _check_defaults(grid, mg)
    return grid


def _check_defaults(grid: Grid, mg: MethodGrid) -> None:
    """Every configuration loads as a run configuration, and configuration 0 is the code's defaults."""
    from ..config import RunConfig
    base = RunConfig()
    for i in range(len(mg.configs)):
        rc = run_config(grid, mg, i)
        if i == 0:
            for p in mg.params:
                code = _code_value(base, mg.method, p.name)
                if not math.isclose(code, p.default, rel_tol=1e-12, abs_tol=1e-12):
                    raise UserError(f"default {p.default!r} of {p.name} is not the code's default {code!r}",
                                    file=str(grid.path), field=f"methods.{mg.method}.params")
        for m in (mg.method, *mg.shared_by):
            rc.stack_for(m)


def _code_value(config, method: str, name: str) -> float:
    table, _, key = name.partition(".")
    obj = config.stack_for(method) if table == "stack" else config.method_params(method)
    for part in key.split("."):
        obj = getattr(obj, part)
    return obj


def method_table(mg: MethodGrid, index: int) -> dict:
    """The ``[methods.NAME]`` table of configuration ``index``: its own keys, and its stack keys under ``stack``."""
    table: dict = {}
    for name, v in mg.values(index).items():
        kind, _, key = name.partition(".")
        node = table.setdefault("stack", {}) if kind == "stack" else table
        *parents, leaf = key.split(".")
        for part in parents:
            node = node.setdefault(part, {})
        node[leaf] = v
    return table


def run_config(grid: Grid, mg: MethodGrid, index: int, base=None):
    """The run configuration of ``mg``'s configuration ``index`` (over ``base``, default RunConfig()), for the
    method and the methods that share its choice."""
    from ..config import run_config_from_dict
    table = method_table(mg, index)
    shared = {m: {"stack": table["stack"]} for m in mg.shared_by if "stack" in table}
    return run_config_from_dict({"methods": {mg.method: table, **shared}}, file=str(grid.path), base=base)
