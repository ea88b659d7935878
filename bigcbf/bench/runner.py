"""A bench: plan the episodes, skip those already in the database, run the rest on an engine, write the reports.

Episodes are submitted seed by seed (all scenarios and methods of seed 0 first, then seed 1, ...), so an
interrupted bench holds complete paired sets for its first seeds.
"""
from __future__ import annotations

import fcntl
import os
import socket
import sys
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

from ..errors import UserError
from . import engines, report
from .store import ResultStore
from .tasks import EpisodeTask, params_key, params_toml, run_episode, scenario_key

DB_NAME = "results.sqlite"
OUTPUTS = ("results.sqlite", "episodes.csv", "summary.json", "summary.md") + report.FIGURES


@dataclass(frozen=True)
class BenchConfig:
    """What to run and where. ``scenarios`` are names from scenarios/ or paths to .toml files."""
    out: Path
    methods: tuple[str, ...]
    scenarios: tuple[str, ...]
    seeds: tuple[int, ...]
    workers: int | None = None            # local: default os.cpu_count(); ray: default all CPUs of the cluster
    engine: str = "local"
    ray_address: str | None = None
    config: object = None                 # RunConfig (bigcbf.config; default: RunConfig(), i.e. Table I with the
    #                                       twin-calibrated profile of the simulated X3, and every other default)
    perception: str = "lidar"
    #: (scenario as given in ``scenarios``, split, family) for the scenarios of a suite with splits/families;
    #: the reports give success per family and split for them
    labels: tuple[tuple[str, str, str], ...] = ()
    suite: str | None = None              # the suite the scenarios come from (reports compare with its paper table)
    #: ``--variant`` texts, e.g. ("route=off,on", "cbf_velocity_rows=off,on") (bigcbf.bench.variants): every method
    #: runs under every combination of the values, each combination's configuration in its episodes' key
    variants: tuple[str, ...] = ()


@dataclass
class BenchOutcome:
    total: int                            # episodes in the bench
    already_done: int                     # found finished in the database
    ran: int                              # run now (ok or error)
    errors: int                           # error rows among the bench's episodes at the end
    wall_time_s: float
    summary: dict = field(repr=False, default_factory=dict)

    @property
    def episodes_per_min(self) -> float:
        return 60.0 * self.ran / self.wall_time_s if self.wall_time_s > 0 else 0.0


def plan(config: BenchConfig) -> tuple[list[EpisodeTask], list[str], list[str]]:
    """The bench's tasks (seed-major), and its methods and scenario names in report order.

    Checks everything a user can get wrong before any episode starts: unknown method or scenario, a scenario file
    that does not load, two files with the same scenario name, seeds, workers. Each scenario's world is drawn and
    checked for every seed when there are at most ``CHECK_ALL_SEEDS`` seeds, else for a sample of that size (the
    first half of it, the last seed, and the rest spread evenly), so that planning stays fast; a draw that fails
    for another seed is recorded as that episode's error row when it runs (and the bench exits with status 1).

    Length: the checks run in the order their errors are reported, all before any episode starts (the docstring lists
    them); then the tasks from the checked values.
    """
    from ..config import RunConfig
    from ..control.methods import make_planner, resolve_method
    from ..episode import PERCEPTION_MODES
    from ..scenario import base_profile_text, load_scenario, resolve_path

    if not config.methods:
        raise UserError("no methods given")
    if not config.scenarios:
        raise UserError("no scenarios given")
    if not config.seeds:
        raise UserError("no seeds given")
    for what, items in (("method", config.methods), ("scenario", config.scenarios), ("seed", config.seeds)):
        dup = sorted({str(x) for x in items if list(items).count(x) > 1})
        if dup:
            raise UserError(f"{what} listed more than once: {', '.join(dup)}")
    if any(int(s) < 0 for s in config.seeds):
        raise UserError("seeds must be >= 0")
    if config.workers is not None and config.workers < 1:
        raise UserError(f"--workers must be >= 1, got {config.workers}")
    if config.engine not in engines.ENGINES:
        raise UserError(f"unknown engine {config.engine!r}; known: {', '.join(engines.ENGINES)}")
    if config.perception not in PERCEPTION_MODES:
        raise UserError(f"unknown perception {config.perception!r}; known: {', '.join(PERCEPTION_MODES)}")
    run_config = config.config if config.config is not None else RunConfig()
    arms = _variant_configs(config, run_config)
    if isinstance(run_config, RunConfig):
        for m in config.methods:         # as `bigcbf run` does: a factory that gives no planner is refused now,
            make_planner(m, run_config.stack, run_config.method_params(m))   # not in every worker's episode
    else:
        for m in config.methods:
            resolve_method(m)

    scen: dict[str, tuple[str, str, str]] = {}     # name -> (key, text, base robot profile's text)
    for s in config.scenarios:
        path = resolve_path(s)
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise UserError(f"cannot read the scenario file ({exc})", file=str(path)) from None
        _, profile_text = base_profile_text(path)
        name = None
        for seed in seed_sample(config.seeds):     # the draws must be valid before we start (see above)
            name = load_scenario(path, seed, robot_profile_text=profile_text).name
        if name in scen:
            raise UserError(f"two scenarios are named {name!r}; a bench needs distinct names", file=str(path))
        scen[name] = (scenario_key(text, profile_text), text, profile_text)
    methods, names = report.default_order(config.methods, scen)
    tasks = [EpisodeTask(scenario=n, scenario_sha=scen[n][0], scenario_toml=scen[n][1], method=m, seed=int(seed),
                         params_hash=phash, params_toml=ptoml, perception=config.perception,
                         robot_profile_toml=scen[n][2], variant=combo)
             for seed in config.seeds for n in names for m in methods for combo, ptoml, phash in arms]
    return tasks, methods, names


def _variant_configs(config: BenchConfig, run_config) -> list[tuple[tuple, str, str]]:
    """(combination, configuration TOML, params_hash) of each combination of the bench's variant axes, in order;
    one with the combination () without ``variants`` (the bench's configuration as given: today's keys)."""
    from ..config import RunConfig
    from ..params.stack import StackParams
    from .variants import apply_combination, combination_label, combinations, parse_variants

    axes = parse_variants(config.variants or None, "variants")
    if not axes:
        ptoml = params_toml(run_config)
        return [((), ptoml, params_key(ptoml, config.perception))]
    if isinstance(run_config, StackParams):      # the same TOML text, so the same key (params_toml)
        run_config = RunConfig(stack=run_config)
    if not isinstance(run_config, RunConfig):
        raise UserError(f"--variant needs a run configuration (a RunConfig), got {type(run_config).__name__}")
    out, seen = [], {}
    for combo in combinations(axes):
        ptoml = params_toml(apply_combination(run_config, combo))
        phash = params_key(ptoml, config.perception)
        if phash in seen:                        # cannot happen with distinct values; a guard for new axes
            raise UserError(f"--variant: {combination_label(combo)} and {combination_label(seen[phash])} give the "
                            "same run configuration")
        seen[phash] = combo
        out.append((combo, ptoml, phash))
    return out


#: plan() draws every seed's world of each scenario up to this many seeds, a sample of this size beyond
CHECK_ALL_SEEDS = 200


def seed_sample(seeds, size: int = CHECK_ALL_SEEDS) -> list[int]:
    """All of ``seeds`` if there are at most ``size``, else the first size // 2, the last one and the rest spread
    evenly over the list (in the list's order, no duplicates)."""
    seeds = list(seeds)
    if len(seeds) <= size:
        return seeds
    head = size // 2
    spread = [head + round(j * (len(seeds) - 1 - head) / (size - head - 1)) for j in range(size - head)]
    return [seeds[i] for i in sorted(set(range(head)) | set(spread))]


def _variant_info(tasks) -> dict | None:
    """The reports' view of a bench's variants: {"axes": [(axis, [values])], "combinations": [combo],
    "by_hash": {params_hash: combo}}; None without variants."""
    by_hash = {t.params_hash: t.variant for t in tasks}
    combos = list(dict.fromkeys(by_hash.values()))
    if combos == [()]:
        return None
    axes = [(a, list(dict.fromkeys(c[i][1] for c in combos))) for i, (a, _) in enumerate(combos[0])]
    return {"axes": axes, "combinations": combos, "by_hash": by_hash}


def _groups(config: BenchConfig) -> dict[str, dict[str, str]] | None:
    """Scenario name -> {"split", "family"} from the config's labels (None without labels)."""
    if not config.labels:
        return None
    from ..scenario import load_scenario, resolve_path
    return {load_scenario(resolve_path(s), config.seeds[0]).name: {"split": split, "family": family}
            for s, split, family in config.labels}


class _DirLock:
    """An exclusive lock on the output directory (released by the OS if the process dies)."""

    def __init__(self, out: Path):
        self.path = out / ".bench.lock"
        try:
            self.fh = self.path.open("w")
        except OSError as exc:
            raise UserError(f"cannot write in the output directory ({exc.strerror or exc})", file=str(out)) from None
        try:
            fcntl.flock(self.fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self.fh.close()
            raise UserError("another 'bigcbf bench' is writing to this directory", file=str(out)) from None

    def release(self) -> None:
        fcntl.flock(self.fh, fcntl.LOCK_UN)
        self.fh.close()


#: what a bench leaves in --out before its database holds anything (a bench stopped at its start): not the user's
_START_REMNANTS = frozenset({".bench.lock", DB_NAME, DB_NAME + "-wal", DB_NAME + "-shm", DB_NAME + "-journal"})
def _suite_folders() -> set[str]:
    """The folders where suites write their scenario files before the bench starts (each suite's ``folder``)."""
    from .suites import SUITES
    return {SUITES.get(n).folder for n in SUITES.names()} - {""}


def _suite_folder(folder: Path) -> bool:
    """A folder a suite wrote: it holds nothing but scenario TOML files (in sub-folders too)."""
    try:
        return folder.is_dir() and all(p.is_dir() or p.suffix == ".toml" for p in folder.rglob("*"))
    except OSError:
        return False


def is_results_db(path: Path) -> bool:
    """``path`` is a bigcbf results database (an SQLite file with the store's ``meta`` table), read without changing
    it. A database that cannot be opened for another reason (a read-only folder, a lock) counts as one: the store
    opens it next and says what is wrong."""
    import sqlite3
    try:
        with open(path, "rb") as fh:
            if fh.read(16) != b"SQLite format 3\0":
                return False
    except OSError:
        return True
    try:
        con = sqlite3.connect(f"{Path(path).resolve().as_uri()}?mode=ro", uri=True, timeout=5.0)
    except sqlite3.Error:
        return True
    try:
        return con.execute("SELECT value FROM meta WHERE key = 'schema'").fetchone() is not None
    except sqlite3.OperationalError as exc:
        return "no such table" not in str(exc)
    except sqlite3.DatabaseError:
        return False
    finally:
        con.close()


def check_bench_out(out: str | Path, inputs=()) -> None:
    """Refuse, before anything is written, an ``--out`` folder a bench would spoil: it must be new, empty, or an
    earlier bench's (its results.sqlite is a bigcbf results database: the bench resumes), else a user's own
    summary.md or episodes.csv would be overwritten. ``inputs``: the bench's scenario files; the folders of --out
    that hold them are not counted (the generated and faults suites write their scenario files into
    ``out/worlds`` and ``out/faults`` before the bench starts). A file where the folder should be is left to
    :func:`_prepare_out`."""
    out = Path(out)
    if not out.is_dir():
        return
    try:
        entries = set(os.listdir(out))
    except OSError as exc:
        raise UserError(f"cannot read the output directory ({exc.strerror or exc})", file=str(out)) from None
    db = out / DB_NAME
    if DB_NAME in entries and db.is_file() and db.stat().st_size > 0:
        if is_results_db(db):
            return
        raise UserError(f"the output directory holds a {DB_NAME} that is not a bigcbf bench's; give --out a new or "
                        "empty folder", file=str(out))
    real_out = os.path.realpath(out)
    held = set()
    for p in inputs:
        rel = os.path.relpath(os.path.realpath(p), real_out)
        if not rel.startswith(os.pardir):
            held.add(rel.split(os.sep)[0])
    held |= {f for f in _suite_folders() if f in entries and _suite_folder(out / f)}
    other = sorted(entries - _START_REMNANTS - held)
    if other:
        shown = ", ".join(other[:3]) + (", ..." if len(other) > 3 else "")
        raise UserError(f"--out is neither empty nor an earlier bench's (it holds {shown} and no {DB_NAME}); a bench "
                        "writes summary.md, episodes.csv and more there: give a new or empty folder", file=str(out))


def _prepare_out(out: Path) -> Path:
    """The output directory, created and checked writable (also for --report-only: the reports are written)."""
    from ..outputs import check_output_dir
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise UserError("--out must be a directory, found a file", file=str(out))
    check_output_dir(out, "output directory")
    return out


def run_bench(config: BenchConfig, *, progress: bool | None = None, report_only: bool = False,
              episode_fn: Callable[[EpisodeTask], dict] = run_episode, log=None) -> BenchOutcome:
    """Run (or resume) a bench and write every output into ``config.out``.

    ``progress``: a tqdm bar (None: only on a terminal). ``report_only``: run nothing, rebuild the outputs from the
    database. ``episode_fn``: what a worker runs per task (tests inject failures here). ``log``: where the final
    line and error lines go (default: stderr).

    Length: the directory lock, the result database and the progress bar are held in nested with/try-finally scopes that
    the run and the report share; the on_row callback closes over them.
    """
    from tqdm import tqdm

    log = log or (lambda msg: tqdm.write(msg, file=sys.stderr))     # (above the progress bar, when there is one)
    from ..outputs import check_distinct
    from ..scenario import resolve_path

    tasks, methods, scenarios = plan(config)
    scenario_files = {f"scenario {s}": resolve_path(s) for s in config.scenarios}
    check_bench_out(config.out, scenario_files.values())
    check_distinct(scenario_files, {f"the bench's {name}": Path(config.out) / name for name in OUTPUTS})
    out = _prepare_out(config.out)
    lock = _DirLock(out)
    t0 = time.perf_counter()
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    params = {t.params_hash: t.params_toml for t in tasks}      # one per variant combination (one without)
    phash = ",".join(params)                                     # (the runs table's key of this bench)
    try:
        with ResultStore(out / DB_NAME) as store:
            for h, text in params.items():
                store.add_params(h, config.perception, text)
            for t in {t.scenario_sha: t for t in tasks}.values():
                store.add_scenario(t.scenario_sha, t.scenario, t.scenario_toml)
            done = store.ok_keys()
            todo = [] if report_only else [t for t in tasks if t.key not in done]
            already = sum(t.key in done for t in tasks)
            bar = tqdm(total=len(tasks), initial=already, unit="ep", desc="bench", dynamic_ncols=True,
                       disable=(not sys.stderr.isatty()) if progress is None else not progress, smoothing=0.05)
            ran = errors_now = 0

            def on_row(row: dict) -> None:
                nonlocal ran, errors_now
                store.put(row)
                ran += 1
                bar.update(1)
                if row["status"] == "error":
                    errors_now += 1
                    log(f"bench: error in {row['scenario']} / {row['method']} / seed {row['seed']}: "
                        f"{row['error'].splitlines()[0]}")

            completed = False
            try:
                if todo:
                    engines.run(config.engine, todo, config.workers, on_row, episode_fn, config.ray_address)
                completed = True
            finally:
                bar.close()
                wall = time.perf_counter() - t0
                if ran:
                    store.add_run(started_utc=started, params_hash=phash, engine=config.engine,
                                  workers=config.workers or "all", host=socket.gethostname(), episodes_run=ran,
                                  errors=errors_now, wall_time_s=round(wall, 2), completed=completed)
            rows = store.rows([t.key for t in tasks])
            runs = [r for r in store.runs() if set(r["params_hash"].split(",")) <= set(params)]
        info = {"suite": config.suite, "perception": config.perception, "params_hash": phash, "engine": config.engine,
                "workers": config.workers or (os.cpu_count() if config.engine == "local" else "all")}
        if runs:   # over every invocation that ran episodes of these parameters (a resumed bench has several)
            n, w = sum(r["episodes_run"] for r in runs), sum(r["wall_time_s"] for r in runs)
            info.update(runs=len(runs), wall_time_s=round(w, 1), episodes_per_min=round(60.0 * n / w, 2) if w else None)
        summary = report.write_reports(out, rows, methods, scenarios, list(config.seeds), info,
                                       groups=_groups(config), variants=_variant_info(tasks))
    finally:
        lock.release()
    outcome = BenchOutcome(total=len(tasks), already_done=already, ran=ran,
                           errors=summary["bench"]["errors"], wall_time_s=wall, summary=summary)
    missing = len(tasks) - len(rows)
    versions = summary["bench"]["code_versions"]
    if len(versions) > 1:
        log(f"bench: warning: the rows come from {len(versions)} code versions ({', '.join(versions)}); "
            "use a new --out for consistent numbers")
    log(f"bench: {len(tasks)} episodes: {already} already done, {ran} run now"
        f"{f' ({outcome.episodes_per_min:.1f} episodes/min)' if ran else ''}, {outcome.errors} errors"
        f"{f', {missing} not run' if missing else ''}; {wall:.1f} s; wrote {out}")
    return outcome


__all__ = ["BenchConfig", "BenchOutcome", "plan", "run_bench", "check_bench_out", "OUTPUTS", "DB_NAME"]
