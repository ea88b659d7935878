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
#: every tuned method at its authors' defaults (configuration 0), as a run configuration (:func:`defaults_toml`)
DEFAULTS = TUNING_DIR / "defaults.toml"
#: what --write-shipped writes (the shipped tuned run configuration and the search's results)
SHIPPED = {"tuned.toml": TUNING_DIR / "tuned.toml", "tuning.csv": TUNING_DIR / "results.csv",
           "tuning.json": TUNING_DIR / "results.json", "tuning.md": TUNING_DIR / "results.md"}
OUTPUTS = ("results.sqlite", "tuning.csv", "tuning.json", "tuning.md", "tuned.toml", "defaults.toml")
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
    rng = _need(raw, "range", list, file, where)
    if len(rng) != 2 or any(isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                            for v in rng) or not rng[0] < rng[1]:
        raise UserError("expected [low, high], two finite numbers with low < high", file=file,
                        field=f"{where}.range")
    lo, hi = float(rng[0]), float(rng[1])
    if not isinstance(raw.get("integer", False), bool):
        raise UserError("expected true or false", file=file, field=f"{where}.integer")
    scale = raw.get("scale", "linear")
    if scale not in SCALES or (scale == "log" and lo <= 0):
        raise UserError(f"scale is one of {', '.join(SCALES)} (log needs a range above 0), got {scale!r}", file=file,
                        field=f"{where}.scale")
    default = _need(raw, "default", (int, float), file, where)
    return Param(name, str(raw.get("unit", "-")), default, lo, hi, scale, raw.get("integer", False),
                 _need(raw, "source", str, file, where))


def _method_grid(name: str, raw, n: int, file: str) -> MethodGrid:
    from ..control.methods import METHODS
    where = f"methods.{name}"
    if name not in METHODS:
        raise UserError(f"not a registered method (known: {', '.join(METHODS.names())})", file=file, field=where)
    if not isinstance(raw, dict):
        raise UserError(f"expected a table, got {raw!r}"[:120], file=file, field=where)
    shared = raw.get("shared_by", [])
    if not isinstance(shared, list) or not all(isinstance(m, str) and m in METHODS and m != name for m in shared):
        raise UserError(f"expected a list of other registered methods, got {shared!r}"[:120], file=file,
                        field=f"{where}.shared_by")
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
    return MethodGrid(name, params, tuple(configs), tuple(shared))


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
        known = worlds.FAMILIES.get(fam).splits.get("dev") if isinstance(fam, str) and fam in worlds.FAMILIES \
            else None
        if known is None:
            raise UserError(f"not a world family with a dev split: {fam!r}"[:120], file=file, field="subset.families")
        bad = [s for s in seeds if isinstance(s, bool) or not isinstance(s, int) or s not in known][:5]
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
    from ..config import untuned
    base = untuned()
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
    """The run configuration of ``mg``'s configuration ``index`` (over ``base``, default the untuned defaults:
    :func:`bigcbf.config.untuned`), for the method and the methods that share its choice."""
    from ..config import run_config_from_dict, untuned
    base = untuned() if base is None else base
    table = method_table(mg, index)
    shared = {m: {"stack": table["stack"]} for m in mg.shared_by if "stack" in table}
    return run_config_from_dict({"methods": {mg.method: table, **shared}}, file=str(grid.path), base=base)


# --- the run -----------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Arm:
    """One (method, configuration) of the search and its episodes."""
    method: str
    index: int
    params_hash: str
    params_toml: str
    tasks: tuple


def dev_worlds(grid: Grid, out: Path, families=None, world_seeds=None, time_limit_s: float | None = None) -> list[Path]:
    """Write the subset's worlds into ``out/worlds/dev/`` (as the generated suite does) and return their paths, seed
    by seed over the families. ``time_limit_s`` (tests, smoke runs): each world's time limit replaced by it, the
    file then named ``..._tl<S>.toml`` (a different scenario, with a different key)."""
    from .. import worlds
    from ..params.toml_io import parse_toml
    import tomli_w

    families = list(grid.families if families is None else families)
    seeds = list(grid.world_seeds if world_seeds is None else world_seeds)
    for fam in families:
        if fam not in grid.families:
            raise UserError(f"family {fam!r} is not in the tuning subset ({', '.join(grid.families)})")
    for s in seeds:
        if s not in grid.world_seeds:
            raise UserError(f"world seed {s} is not in the tuning subset ({grid.world_seeds})")
    paths = []
    for s in seeds:
        for fam in families:
            w = worlds.generate(fam, s)
            if time_limit_s is None:
                p = out / "worlds" / grid.split / f"{w.name}.toml"
                worlds.write(w, p)
            else:
                data = parse_toml(w.toml, w.name)
                data.update(time_limit_s=float(time_limit_s), name=f"{w.name}_tl{time_limit_s:g}")
                p = out / "worlds" / grid.split / f"{data['name']}.toml"
                p.parent.mkdir(parents=True, exist_ok=True)
                p.write_text(tomli_w.dumps(data))
            paths.append(p)
    return paths


def plan_arms(grid: Grid, out: Path, methods=None, configs=None, **world_kwargs) -> list[Arm]:
    """The search's arms: every (method, configuration) of ``methods`` (default: every method of the grid) and
    ``configs`` (indices, default all), each with its episode tasks on the subset's worlds (the bench's tasks, with
    the arm's run configuration in their key)."""
    from ..config import untuned
    from .runner import BenchConfig, plan
    from .tasks import params_key, params_toml

    methods = list(grid.methods if methods is None else methods)
    for m in methods:
        if m not in grid.methods:
            raise UserError(f"method {m!r} is not in the tuning grid (its methods: {', '.join(grid.methods)}; "
                            f"{', '.join(s for g in grid.methods.values() for s in g.shared_by)} take another's "
                            "choice)", file=str(grid.path))
    indices = list(range(BUDGET) if configs is None else configs)
    bad = [i for i in indices if not isinstance(i, int) or not 0 <= i < BUDGET]
    if bad:
        raise UserError(f"configurations are numbered 0-{BUDGET - 1}, got {bad}")
    paths = dev_worlds(grid, out, **world_kwargs)
    base, _, _ = plan(BenchConfig(out=out, methods=tuple(methods), scenarios=tuple(str(p) for p in paths),
                                  seeds=(grid.episode_seed,), config=untuned()))
    arms = []
    for m in methods:
        mine = [t for t in base if t.method == m]
        for i in indices:
            text = params_toml(run_config(grid, grid.methods[m], i))
            h = params_key(text, mine[0].perception)
            arms.append(Arm(m, i, h, text, tuple(dataclasses.replace(t, params_hash=h, params_toml=text)
                                                for t in mine)))
    return arms


def run_tuning(grid: Grid, out: str | Path, methods=None, workers: int | None = None, *, configs=None,
               progress: bool | None = None, log=None, **world_kwargs) -> dict:
    """Run (or resume) the search into ``out`` and write its outputs there (module docstring); returns the
    results (:func:`results`). ``world_kwargs``: ``families``, ``world_seeds``, ``time_limit_s`` of
    :func:`dev_worlds` (a slice of the subset, for tests and cost measurements)."""
    from tqdm import tqdm

    from . import engines
    from .runner import DB_NAME, _DirLock, _prepare_out, check_bench_out
    from .store import ResultStore
    from .tasks import run_episode

    log = log or (lambda msg: tqdm.write(msg, file=sys.stderr))
    if workers is not None and workers < 1:
        raise UserError(f"--workers must be >= 1, got {workers}")
    out = Path(out)
    check_bench_out(out)
    out = _prepare_out(out)
    arms = plan_arms(grid, out, methods, configs, **world_kwargs)
    tasks = [t for a in arms for t in a.tasks]
    lock = _DirLock(out)
    t0 = time.perf_counter()
    try:
        with ResultStore(out / DB_NAME) as store:
            for a in arms:
                store.add_params(a.params_hash, a.tasks[0].perception, a.params_toml)
            for t in {t.scenario_sha: t for t in tasks}.values():
                store.add_scenario(t.scenario_sha, t.scenario, t.scenario_toml)
            done = store.ok_keys()
            todo = [t for t in tasks if t.key not in done]
            bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), unit="ep", desc="tune", dynamic_ncols=True,
                       disable=(not sys.stderr.isatty()) if progress is None else not progress)

            def on_row(row: dict) -> None:
                store.put(row)
                bar.update(1)
                if row["status"] == "error":
                    log(f"tune: error in {row['scenario']} / {row['method']}: {row['error'].splitlines()[0]}")
            try:
                if todo:
                    engines.run("local", todo, workers, on_row, run_episode)
            finally:
                bar.close()
            rows = {(r["method"], r["params_hash"], r["scenario"]): r for r in store.rows([t.key for t in tasks])}
        res = results(grid, arms, rows, complete=configs is None and methods is None and
                      all(v is None for v in world_kwargs.values()))
        res["worlds"] = list(dict.fromkeys(t.scenario for t in tasks))
        res["time_limit_s"] = world_kwargs.get("time_limit_s")
        res["run"] = {"episodes": len(tasks), "already_done": len(tasks) - len(todo), "ran": len(todo),
                      "wall_time_s": round(time.perf_counter() - t0, 1), "workers": workers or "all cores"}
        write_outputs(out, grid, res)
    finally:
        lock.release()
    log(f"tune: {len(tasks)} episodes ({len(tasks) - len(todo)} already done); {res['run']['wall_time_s']} s; "
        f"wrote {out}")
    return res


# --- results, selection and outputs ------------------------------------------------------------------------------

def arm_stats(grid: Grid, arm: Arm, rows: dict) -> dict:
    """One configuration's figures over its episodes: success with its Wilson 95 % interval, at-fault collisions
    (every collision when the episode has no contact rating), timeouts, mean time to goal over the successes."""
    from .stats import wilson_pct

    got = [rows.get((arm.method, arm.params_hash, t.scenario)) for t in arm.tasks]
    ok = [r["metrics"] for r in got if r is not None and r["status"] == "ok"]
    n, k = len(ok), sum(bool(m["success"]) for m in ok)
    times = [float(m["time_s"]) for m in ok if m["success"]]
    return {"config": arm.index, "params": grid.methods[arm.method].values(arm.index), "episodes": len(arm.tasks),
            "ok": n, "errors": sum(1 for r in got if r is not None and r["status"] == "error"),
            "missing": sum(r is None for r in got), "successes": k,
            "success_pct": round(100.0 * k / n, 2) if n else None, "success_ci95_pct": wilson_pct(k, n),
            "at_fault_collisions": sum(bool(m.get("at_fault_collision", m["collision"])) for m in ok),
            "collisions": sum(bool(m["collision"]) for m in ok), "timeouts": sum(bool(m["timeout"]) for m in ok),
            "mean_time_to_goal_s": round(sum(times) / len(times), 3) if times else None,
            "params_hash": arm.params_hash}


def select(stats: list[dict]) -> int | None:
    """The chosen configuration by the protocol's rule (module docstring); None while any configuration has an
    episode missing or in error (the rule compares complete results only)."""
    if not stats or any(s["errors"] or s["missing"] for s in stats):
        return None
    best = min(stats, key=lambda s: (-s["successes"], s["at_fault_collisions"],
                                     math.inf if s["mean_time_to_goal_s"] is None else s["mean_time_to_goal_s"],
                                     s["config"]))
    return best["config"]


def provenance() -> dict:
    """The code behind the results: the git commit of the checkout (``+dirty`` with uncommitted changes under
    bigcbf/) when there is one, and the package's code sha (every row of the store carries it too)."""
    from .tasks import code_sha
    root = Path(__file__).resolve().parent.parent.parent
    commit = None
    try:
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                                text=True, timeout=10, check=True).stdout.strip() or None
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--", "bigcbf"],
                               capture_output=True, text=True, timeout=10, check=True).stdout.strip()
        if commit and dirty:
            commit += "+dirty"
    except (OSError, subprocess.SubprocessError):
        pass
    return {"git_commit": commit, "code_sha": code_sha(),
            "utc": datetime.now(timezone.utc).isoformat(timespec="seconds")}


def results(grid: Grid, arms: list[Arm], rows: dict, complete: bool) -> dict:
    """The search's results: per method, each configuration's figures and the chosen one."""
    methods = {}
    for m in dict.fromkeys(a.method for a in arms):
        stats = [arm_stats(grid, a, rows) for a in arms if a.method == m]
        mg = grid.methods[m]
        methods[m] = {"chosen": select(stats), "shared_by": list(mg.shared_by),
                      "params": [{"name": p.name, "unit": p.unit, "range": [p.lo, p.hi], "default": p.default}
                                 for p in mg.params], "configs": stats}
    return {"grid": str(grid.path), "grid_sha": grid.sha, "code": provenance(), "selection": grid.selection,
            "subset": {"split": grid.split, "families": list(grid.families), "world_seeds": list(grid.world_seeds),
                       "episode_seed": grid.episode_seed},
            "complete_protocol": complete, "methods": methods}


CSV_COLUMNS = ("method", "config", "chosen", "params", "episodes", "ok", "errors", "missing", "successes",
               "success_pct", "success_ci95_lo", "success_ci95_hi", "at_fault_collisions", "collisions", "timeouts",
               "mean_time_to_goal_s", "params_hash")


def results_csv(res: dict) -> str:
    """One line per (method, configuration)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for m, r in res["methods"].items():
        for s in r["configs"]:
            ci = s["success_ci95_pct"] or [None, None]
            w.writerow([m, s["config"], int(s["config"] == r["chosen"]),
                        "; ".join(f"{k}={v}" for k, v in s["params"].items()), s["episodes"], s["ok"], s["errors"],
                        s["missing"], s["successes"], s["success_pct"], ci[0], ci[1], s["at_fault_collisions"],
                        s["collisions"], s["timeouts"], s["mean_time_to_goal_s"], s["params_hash"]])
    return buf.getvalue()


def _line(s: dict) -> str:
    from .stats import fmt_ci
    t = "-" if s["mean_time_to_goal_s"] is None else f"{s['mean_time_to_goal_s']:.1f} s"
    return (f"success {s['successes']}/{s['ok']} = {fmt_ci(s['success_pct'], s['success_ci95_pct'])} %, at-fault "
            f"{s['at_fault_collisions']}, mean time to goal {t}")


def tuned_toml(grid: Grid, res: dict) -> str:
    """The chosen configurations as a run configuration (``[methods.NAME]`` tables, stack keys under
    ``[methods.NAME.stack]``), with its provenance in the leading comments."""
    import tomli_w
    code = res["code"]
    head = [f"Tuned run configuration, written by `bigcbf tune` (issue 24 item 4; docs/tuning.md) on {code['utc']}.",
            f"Provenance: grid {Path(res['grid']).name} sha256 {res['grid_sha']}; code git {code['git_commit']} "
            f"(code sha {code['code_sha']}).",
            f"Subset: {res['subset']['split']} split, families {', '.join(res['subset']['families'])}, world seeds "
            f"{res['subset']['world_seeds']}, episode seed {res['subset']['episode_seed']}.",
            "The whole protocol: " + ("yes." if res["complete_protocol"] else
                                      f"NO, a slice of it: worlds {', '.join(res.get('worlds', []))}, time limit "
                                      f"{res.get('time_limit_s') or 'of each world'}; not for shipping."),
            f"Selection: {res['selection']}"]
    tables: dict = {}
    for m, r in res["methods"].items():
        if r["chosen"] is None:
            head.append(f"{m}: no choice (episodes missing or in error); its defaults apply.")
            continue
        s = r["configs"][[c["config"] for c in r["configs"]].index(r["chosen"])]
        head.append(f"{m}: configuration {r['chosen']} of {BUDGET}: {_line(s)}"
                    + (f"; shared by {', '.join(r['shared_by'])}" if r["shared_by"] else ""))
        table = method_table(grid.methods[m], r["chosen"])
        tables[m] = table
        for other in r["shared_by"]:
            if "stack" in table:
                tables[other] = {"stack": table["stack"]}
    text = "".join(f"# {line}\n" for line in head)
    return text + ("\n" + tomli_w.dumps({"methods": tables}) if tables else "")


def defaults_toml(grid: Grid) -> str:
    """Every method of the grid at configuration 0, its authors' defaults, as a run configuration: with a tuned file
    shipped (the default then), ``--config`` this file to run the defaults (shipped as
    bigcbf/params/tuning/defaults.toml)."""
    import tomli_w
    tables: dict = {}
    for m, mg in grid.methods.items():
        tables[m] = method_table(mg, 0)
        for other in mg.shared_by:
            if "stack" in tables[m]:
                tables[other] = {"stack": tables[m]["stack"]}
    return (f"# The authors' defaults of every tuned method (configuration 0 of each in {grid.path.name}, sha256 "
            f"{grid.sha}),\n# as a run configuration: `bigcbf bench --config` this file to run them when a tuned "
            "configuration is shipped.\n# Written by bigcbf.bench.tuning.defaults_toml (docs/tuning.md).\n\n"
            + tomli_w.dumps({"methods": tables}))


def results_md(res: dict) -> str:
    """The search as Markdown: its provenance, then per method a table of its configurations (chosen in bold)."""
    from .stats import fmt_ci
    code = res["code"]
    lines = ["# Equal-budget tuning results", "",
             f"Grid `{Path(res['grid']).name}` sha256 `{res['grid_sha']}`, code git `{code['git_commit']}` (code sha "
             f"`{code['code_sha']}`), {code['utc']}; "
             + ("the whole protocol." if res["complete_protocol"] else
                f"a slice (worlds {', '.join(res.get('worlds', []))}), not for shipping."),
             f"Selection: {res['selection']}", ""]
    for m, r in res["methods"].items():
        names = [p["name"].split(".")[-1] for p in r["params"]]
        lines += [f"## {m}" + (f" (also {', '.join(r['shared_by'])})" if r["shared_by"] else ""), "",
                  "| config | " + " | ".join(names) + " | success % [95 % CI] | at-fault | timeouts | time to goal (s) |",
                  "|---:|" + "---:|" * len(names) + "---:|---:|---:|---:|"]
        for s in r["configs"]:
            b = "**" if s["config"] == r["chosen"] else ""
            t = "-" if s["mean_time_to_goal_s"] is None else f"{s['mean_time_to_goal_s']:.1f}"
            lines.append(f"| {b}{s['config']}{b} | " + " | ".join(str(v) for v in s["params"].values())
                         + f" | {s['successes']}/{s['ok']}: {fmt_ci(s['success_pct'], s['success_ci95_pct'])} | "
                         f"{s['at_fault_collisions']} | {s['timeouts']} | {t} |")
        lines.append("")
    return "\n".join(lines)


def write_outputs(out: Path, grid: Grid, res: dict) -> None:
    """tuning.csv, tuning.json and tuned.toml into ``out`` (atomically); tuned.toml is read back as a run
    configuration."""
    from ..config import load_run_config
    from ..outputs import strict_json, write_text
    write_text(out / "tuning.csv", results_csv(res), "tuning results")
    write_text(out / "tuning.json", strict_json(res, indent=1) + "\n", "tuning results")
    write_text(out / "tuning.md", results_md(res), "tuning results")
    write_text(out / "tuned.toml", tuned_toml(grid, res), "tuned run configuration")
    write_text(out / "defaults.toml", defaults_toml(grid), "defaults run configuration")
    load_run_config(out / "tuned.toml")


def write_shipped(out: str | Path, grid: Grid) -> list[Path]:
    """Copy a finished search's tuned.toml and results into bigcbf/params/tuning/ (tuned.toml, results.csv,
    results.json, results.md). Refused unless ``out`` holds the whole protocol of ``grid`` (every method, configuration and
    world, no time-limit change), with a choice for every method."""
    from ..outputs import write_text
    out = Path(out)
    try:
        res = json.loads((out / "tuning.json").read_text())
    except (OSError, ValueError) as exc:
        raise UserError(f"no finished search to ship ({exc})", file=str(out / "tuning.json")) from None
    if not res.get("complete_protocol"):
        raise UserError("a slice of the protocol (fewer methods, configurations or worlds): rerun `bigcbf tune` "
                        "without --methods/--configs/--families/--world-seeds/--time-limit", file=str(out))
    if res.get("grid_sha") != grid.sha:
        raise UserError(f"the search ran grid {res.get('grid_sha')}, the grid is now {grid.sha}: rerun it",
                        file=str(out))
    missing = [m for m in grid.methods if res["methods"].get(m, {}).get("chosen") is None]
    if missing:
        raise UserError(f"no choice for {', '.join(missing)} (episodes missing or in error): rerun to resume",
                        file=str(out))
    written = []
    for name, dest in SHIPPED.items():
        written.append(write_text(dest, (out / name).read_text(), "shipped tuning file"))
    return written


def table_lines(res: dict) -> list[str]:
    """A plain-text table of the search (what `bigcbf tune` prints)."""
    lines = []
    for m, r in res["methods"].items():
        for s in r["configs"]:
            mark = "*" if s["config"] == r["chosen"] else " "
            extra = f", {s['errors']} errors" if s["errors"] else ""
            extra += f", {s['missing']} not run" if s["missing"] else ""
            lines.append(f"{mark} {m:<14} {s['config']}  {_line(s)}{extra}")
    return lines
