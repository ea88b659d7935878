"""The public Python API: what the command line does, in a few lines of Python, with typed results.

    import bigcbf

    res = bigcbf.run_episode("required_sidestepping", "big-cbf", seed=0)        # -> EpisodeResult
    print(res.success, res.time_s, res.e_cbf)

    out = bigcbf.run_bench("results/", methods=["cbf-only", "big-cbf"], seeds=range(3), workers=2)
    print(out.summary["methods"]["big-cbf"]["success_pct"])                      # -> BenchOutcome

Every function calls the same code as its subcommand (``bigcbf run``, ``bigcbf bench``) and checks its arguments
with the same rules (:mod:`bigcbf.validate`, shared with the Gymnasium environment): every mistake in the arguments
or files raises :class:`bigcbf.errors.UserError`, one line naming the field (seeds are whole numbers in
[0, 4294967295], a time limit is in (0, 600] s, a list of methods, scenarios or seeds is not empty, ...).

:func:`run_bench` on the local engine starts worker processes that import the calling script afresh (the
``spawn`` start method), so a script calls it under ``if __name__ == "__main__":``; an unguarded call at a
script's top level is a UserError before any work.

Calibration and replay live in the ``twin`` package's API (``twin.calibrate_log(log) -> twin.Calibration``,
``twin.replay_log(log, profile) -> twin.ReplayResult``, see ``twin/__init__.py``), not here: ``twin`` builds on
``bigcbf``, and no module of ``bigcbf`` but its command line imports ``twin``.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Callable, Iterable, Sequence

from .config import RunConfig, load_run_config
from .errors import UserError
from .validate import (check_callable, check_choice, check_names, check_path, check_seed, check_seeds,
                       check_time_limit, check_workers)

#: the cameras of a video (``bigcbf run --camera``)
CAMERAS = ("top", "track")

__all__ = ["RunConfig", "load_config", "run_episode", "run_bench", "bench_config", "scenarios", "methods",
           "load_scenario"]


def load_config(config: str | Path | RunConfig | None = None, profile: str | Path | None = None, *,
                base: RunConfig | None = None, notes: Callable[[str], None] | None = None) -> RunConfig:
    """The run configuration: ``base`` (default: ``RunConfig()``, Table I with the twin-calibrated stack profile of
    the simulated X3, what every front door uses), overlaid with a ``--config`` TOML file
    (or taken as given when ``config`` is a RunConfig), then with a ``--profile`` stack-parameter TOML (a
    calibrated uncertainty profile from ``bigcbf calibrate``) over its ``stack``.

    ``notes(text)`` receives remarks about the profile (an axis the calibration did not identify) and, when a tuned
    configuration is shipped and ``base`` is not given, its provenance line; default: none are reported."""
    from .params.stack import load_stack_params

    if not isinstance(config, RunConfig):
        check_path(config, "config", "a RunConfig or the path of a run configuration TOML file")
    profile = check_path(profile, "profile", "the path of a stack parameter (profile) TOML file")
    if base is not None and not isinstance(base, RunConfig):
        raise UserError(f"expected a RunConfig or None, got {type(base).__name__}", field="base")
    check_callable(notes, "notes")
    if isinstance(config, RunConfig):
        cfg = config
    elif config is not None:
        cfg = load_run_config(config, base=base)
    else:
        cfg = base or RunConfig()
    if base is None and not isinstance(config, RunConfig) and notes is not None:
        from .config import TUNED_PATH, tuned_provenance
        prov = tuned_provenance()
        if prov is not None and config is None:    # the shipped tuned configuration is every method's default
            notes(f"method defaults: the tuned configuration {TUNED_PATH.name} ({prov}); --config "
                  f"{TUNED_PATH.parent / 'defaults.toml'} runs the authors' defaults")
        elif prov is not None:      # a --config file is read over it (docs/tuning.md)
            notes(f"{config}: read over the tuned configuration {TUNED_PATH.name} (a method key the file does not "
                  "set keeps its tuned value)")
    if profile is not None:
        stack = load_stack_params(profile, base=cfg.stack)
        missing = [a for a, ok in zip(("vx", "vy"), stack.uncertainty.execution.identified[:2]) if not ok]
        if missing and notes is not None:
            notes(f"{profile}: {', '.join(missing)} not identified by the calibration; its execution model and "
                  "residual bound are the nominal ones, not measured")
        cfg = cfg.replace(stack=stack)
    return cfg


def load_scenario(scenario, seed: int = 0):
    """A scenario (a name from :func:`scenarios`, a path to a TOML file, or a Scenario, returned as it is) drawn for
    ``seed`` (a whole number in [0, 4294967295])."""
    from .scenario import Scenario
    from .scenario import load_scenario as _load

    seed = check_seed(seed)
    if isinstance(scenario, Scenario):
        return scenario
    check_path(scenario, "scenario", "a scenario name, a scenario TOML file path or a Scenario", optional=False)
    return _load(os.fspath(scenario), seed)


def run_episode(scenario, method: str = "big-cbf", seed: int = 0, *, config: str | Path | RunConfig | None = None,
                profile: str | Path | None = None, perception: str = "lidar", time_limit_s: float | None = None,
                video: str | Path | None = None, camera: str = "top", log: str | Path | None = None,
                live=None, observers: Iterable[Callable] = ()):
    """Run one episode and return its :class:`bigcbf.episode.EpisodeResult` (``.metrics()`` gives a dict).

    ``scenario``: a name (``bigcbf scenarios``), a scenario TOML path, or a Scenario. ``method``: a registered
    method, an entry point of ``bigcbf.methods`` or ``package.module:Class``. ``config``/``profile``: see
    :func:`load_config`. ``video``: an H.264 MP4 (``camera`` top or track); ``log``: a ROS 2 MCAP; ``live``: a
    :class:`bigcbf.logio.live.LiveWriter` to stream the log's topics to Foxglove (paced at real time).
    ``observers``: callables that receive every control step's :class:`bigcbf.episode.StepRecord`. ``seed``: a
    whole number in [0, 4294967295]; ``time_limit_s``: in (0, 600] s (default: the scenario's).

    Length: the docstring is a third of it; the checks run in the order their errors are reported, before the episode,
    and the outputs share one try that aborts them all on any error.
    """
    from .control.methods import resolve_method
    from .episode import PERCEPTION_MODES, Episode

    seed = check_seed(seed)
    if perception not in PERCEPTION_MODES:
        raise UserError(f"perception must be one of {', '.join(PERCEPTION_MODES)}, got {perception!r}"[:160])
    check_choice(camera, CAMERAS, "camera")
    check_path(video, "video", "a video file path")
    check_path(log, "log", "a log file path")
    if isinstance(observers, (str, bytes)) or not isinstance(observers, Iterable):
        raise UserError(f"expected a list of functions, got {type(observers).__name__}", field="observers")
    observers = list(observers)
    for f in observers:
        check_callable(f, "observers", optional=False)
    sc = load_scenario(scenario, seed)
    if time_limit_s is not None:
        time_limit_s = check_time_limit(time_limit_s, sc)
    resolve_method(method)
    cfg = load_config(config, profile)
    from .outputs import check_distinct, check_output_file
    as_path = lambda x: x if isinstance(x, (str, Path)) else None      # noqa: E731 -- a RunConfig is no file
    check_distinct({"scenario": getattr(sc, "file", None) or None, "config": as_path(config), "profile": as_path(profile)},
                   {"video": video, "log": log})
    for path, what in ((video, "video"), (log, "log")):
        if path is not None:             # before the episode: a path that cannot be written fails now
            check_output_file(path, what)
    ep = Episode.from_config(sc, method, seed, cfg, perception=perception, time_limit_s=time_limit_s)
    ep.observers.extend(observers)
    outputs = []
    try:
        if video is not None:
            from .video import EpisodeVideo
            outputs.append(EpisodeVideo(ep, video, camera=camera))
        if log is not None:
            from .logio.episode_log import EpisodeLogger
            outputs.append(EpisodeLogger(ep, log))
        if live is not None:
            from .logio.episode_log import EpisodeLogger
            from .logio.live import RealTimePacer
            EpisodeLogger(ep, writer=live)             # the caller owns (and closes) the live writer
            ep.observers.append(RealTimePacer())
        res = ep.run()
    except BaseException:
        for o in outputs:                # an unfinished video or log is dropped; the paths stay as they were
            o.abort()
        raise
    for o in outputs:                    # written to temporary files, renamed into place here
        o.close()
    return res


def bench_config(out: str | Path, *, methods: Sequence[str] | None = None, scenarios: Sequence[str] | None = None,
                 suite: str = "paper", seeds: int | Iterable[int] | None = None, workers: int | None = None,
                 engine: str = "local", ray_address: str | None = None, config: str | Path | RunConfig | None = None,
                 profile: str | Path | None = None, perception: str = "lidar", split: str | None = None,
                 notes: Callable[[str], None] | None = None, variants: Sequence[str] | None = None,
                 world_seeds: Iterable[int] | None = None):
    """The :class:`bigcbf.bench.runner.BenchConfig` that :func:`run_bench` runs (what ``bigcbf bench`` builds from
    its options). ``seeds``: a count N (seeds 0..N-1) or the seeds themselves; default the suite's count.
    ``methods``: default every registered method. ``scenarios``: default the suite's (``split``: only that split
    of a suite that has splits, e.g. generated's dev or test). The run configuration is the suite's stack
    parameters (if it has them), then ``config``, then ``profile`` (see :func:`load_config`). ``variants``: texts
    ``NAME=V1,V2`` (``bigcbf bench --variant``, :mod:`bigcbf.bench.variants`): every method under every combination.
    ``world_seeds`` (a suite with fresh worlds, e.g. generated): its worlds at these world seeds instead of its
    splits' (split label ``fresh``; seeds of a registered split are refused), 1 to 10000 of them.

    Checked as ``bigcbf bench`` checks its options, before anything is written: ``seeds`` a count in [1, 10000]
    or 1 to 10000 seeds in [0, 4294967295]; ``methods`` and ``scenarios`` non-empty lists (None: the default);
    ``workers`` a whole number from 1 to 4 per core (local engine) or to 10000 (Ray). A mistake is a UserError
    naming the field.

    Length: the option checks in the order their errors are reported, all before the first write (check_bench_out, the
    suite's files); then the BenchConfig from the checked values."""
    from .bench.engines import ENGINES, ray_available
    from .bench.paper import METHOD_ORDER, ordered
    from .bench.runner import BenchConfig
    from .bench.suites import SUITES
    from .control.methods import METHODS, resolve_method

    out = check_path(out, "out", "an output folder path", optional=False)
    method_list = check_names(methods, "methods", "methods")
    scenario_list = check_names(scenarios, "scenarios", "scenarios")
    if engine not in ENGINES:
        raise UserError(f"--engine must be one of {', '.join(ENGINES)}, got {engine!r}"[:160])
    if ray_address is not None and (not isinstance(ray_address, str) or not ray_address.strip()):
        raise UserError(f"expected a Ray address (e.g. auto or ray://head:10001), got {ray_address!r}"[:160],
                        field="ray_address")
    if ray_address is not None and engine != "ray":
        raise UserError("--ray-address needs --engine ray")
    if engine == "ray" and not ray_available():
        raise UserError("--engine ray needs Ray, which is not installed: pip install 'bigcbf[ray]'")
    if perception not in ("lidar", "truth"):
        raise UserError(f"--perception must be lidar or truth, got {perception!r}"[:160])
    if not isinstance(suite, str):
        raise UserError(f"expected a suite name, got {suite!r}"[:160], field="suite")
    if split is not None and not isinstance(split, str):
        raise UserError(f"expected a split name, got {split!r}"[:160], field="split")
    check_callable(notes, "notes")
    from .bench.variants import parse_variants
    variant_specs = tuple(variants or ()) if parse_variants(variants, "variants") else ()
    s = SUITES.get(suite)
    seed_list = check_seeds(s.default_seeds if seeds is None else seeds)
    workers = check_workers(workers, engine)
    if workers is None and engine == "local":
        workers = os.cpu_count() or 1
    if method_list is None:
        method_list = tuple(ordered(METHODS.names(), METHOD_ORDER))
    for m in method_list:
        resolve_method(m)
    if split is not None:
        if not s.splits:
            raise UserError(f"suite {suite!r} has no splits (--split is for suites such as generated)")
        if split not in s.splits:
            raise UserError(f"suite {suite!r} has no split {split!r}; known: {', '.join(s.splits)}")
        if scenario_list:
            raise UserError("--split selects among the suite's scenarios; drop it when giving --scenarios")
    if world_seeds is not None:
        if s.fresh is None:
            raise UserError(f"suite {suite!r} has no worlds drawn by seed (--world-seeds is for suites such as "
                            "generated)", field="world_seeds")
        if split is not None or scenario_list:
            raise UserError("--world-seeds draws the suite's worlds at other seeds; drop --split and --scenarios",
                            field="world_seeds")
        world_seeds = check_seeds(world_seeds, "world_seeds")     # (s.fresh refuses split seeds before it writes)
    base = RunConfig(stack=s.params()) if s.params is not None else None
    cfg = load_config(config, profile, base=base, notes=notes)
    from .bench.runner import check_bench_out
    check_bench_out(out)              # before the suite writes its worlds there: a user's folder stays untouched
    if world_seeds is not None:
        entries = s.fresh(out, world_seeds)
    else:
        entries = s.entries(out, split) if s.splits else s.entries(out)     # (a suite may write its scenario files)
    if scenario_list:
        # scenarios given by path that are files of the suite keep their split and family in the reports
        known = {Path(e.scenario).resolve(): e for e in entries if e.split or e.family}
        labels = tuple((x, known[Path(x).resolve()].split, known[Path(x).resolve()].family) for x in scenario_list
                       if Path(x).resolve() in known)
    else:
        scenario_list = tuple(str(e.scenario) for e in entries)
        labels = tuple((str(e.scenario), e.split, e.family) for e in entries if e.split or e.family)
    return BenchConfig(out=out, methods=method_list, scenarios=scenario_list, seeds=seed_list, workers=workers,
                       engine=engine, ray_address=ray_address, config=cfg, perception=perception, labels=labels,
                       suite=None if scenarios is not None else s.name, variants=variant_specs)


#: what run_bench says when a script calls it at its top level, where every bench worker would run it again
UNGUARDED_MESSAGE = ('put the call under `if __name__ == "__main__":` (bench workers are fresh Python processes that '
                     'import your script)')


def _called_from_reimported_main() -> bool:
    """True in a worker process of the local engine that is importing the user's script (``spawn`` runs the main
    script there as ``__mp_main__``): a frame of that module's top-level code is on the stack."""
    f = sys._getframe(1)
    while f is not None:
        if f.f_code.co_name == "<module>" and f.f_globals.get("__name__") == "__mp_main__":
            return True
        f = f.f_back
    return False


def _worker_branch(test) -> bool | None:
    """What ``test`` (an ``if``'s condition) is in a worker, where the script's ``__name__`` is ``"__mp_main__"``:
    True or False when it is a comparison of ``__name__`` with a string (or not/and/or of such), None when it
    cannot be told."""
    import ast

    if isinstance(test, ast.UnaryOp) and isinstance(test.op, ast.Not):
        v = _worker_branch(test.operand)
        return None if v is None else not v
    if isinstance(test, ast.BoolOp):
        vals = [_worker_branch(v) for v in test.values]
        if isinstance(test.op, ast.And):
            return False if False in vals else (True if all(v is True for v in vals) else None)
        return True if True in vals else (False if all(v is False for v in vals) else None)
    if isinstance(test, ast.Compare) and len(test.ops) == 1:
        left, right = test.left, test.comparators[0]
        if isinstance(right, ast.Name) and right.id == "__name__":
            left, right = right, left
        if (isinstance(left, ast.Name) and left.id == "__name__" and isinstance(right, ast.Constant)
                and isinstance(right.value, str)):
            op, name = test.ops[0], "__mp_main__"
            if isinstance(op, (ast.Eq, ast.Is)):
                return name == right.value
            if isinstance(op, (ast.NotEq, ast.IsNot)):
                return name != right.value
            if isinstance(op, ast.In):
                return name in right.value
            if isinstance(op, ast.NotIn):
                return name not in right.value
    return None


def _runs_in_workers(stmts, line: int) -> bool:
    """Whether the statement of ``line`` among the module-level ``stmts`` would run again when a worker imports the
    script: not inside an ``if __name__ == "__main__":`` block (or a function or class body). An ``if`` whose
    condition cannot be told gets the benefit of the doubt (only a call known to run again is refused)."""
    import ast

    for node in stmts:
        if not node.lineno <= line <= (node.end_lineno or node.lineno):
            continue
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            return False
        if isinstance(node, ast.If):
            for branch, taken_when in ((node.body, True), (node.orelse, False)):
                if any(s.lineno <= line <= (s.end_lineno or s.lineno) for s in branch):
                    v = _worker_branch(node.test)
                    if v is None or v != taken_when:
                        return False
                    return _runs_in_workers(branch, line)
            return True                                    # in the condition itself
        inner = []                       # the statements of a for, while, with, try or match
        for name in ("body", "orelse", "finalbody", "handlers", "cases"):
            for child in getattr(node, name, None) or ():
                inner.extend(child.body if isinstance(child, (ast.ExceptHandler, ast.match_case)) else [child])
        if inner and any(s.lineno <= line <= (s.end_lineno or s.lineno) for s in inner):
            return _runs_in_workers(inner, line)
        return True
    return True


def _unguarded_call_site() -> str | None:
    """``file:line`` of the main script's top-level statement that leads to this call when a bench worker would
    run it again (it is not under ``if __name__ == "__main__":``), else None (also when that cannot be told: no
    script file, as in an interactive session, or a call from another thread)."""
    import ast

    main = sys.modules.get("__main__")
    path = getattr(main, "__file__", None)
    if not path:
        return None
    site = None
    f = sys._getframe(1)
    while f is not None:
        if f.f_globals is main.__dict__ and f.f_code.co_name == "<module>":
            site = f
        f = f.f_back
    if site is None or os.path.realpath(site.f_code.co_filename) != os.path.realpath(path):
        return None
    try:
        tree = ast.parse(Path(path).read_bytes(), path)
    except (OSError, SyntaxError, ValueError):
        return None
    line = site.f_lineno
    return f"{path}:{line}" if _runs_in_workers(tree.body, line) else None


def run_bench(out: str | Path, *, progress: bool | None = False, report_only: bool = False, **kwargs):
    """Run (or resume) a bench into ``out`` and return its :class:`bigcbf.bench.runner.BenchOutcome` (counts, wall
    time, and ``summary``: the content of summary.json). ``kwargs``: as for :func:`bench_config`.

    A script calls it under ``if __name__ == "__main__":``: the local engine's workers are fresh Python processes
    that import the script, and a call at its top level is a UserError before any work. A bench whose every
    episode failed raises a UserError naming the first error (after writing its outputs); with some failed, the
    outcome counts them (``errors``; the command line exits with status 1 in both cases)."""
    import inspect

    from .bench.runner import run_bench as _run

    if _called_from_reimported_main():     # a bench worker importing the script: it must not run a bench itself
        raise UserError(UNGUARDED_MESSAGE)
    known = [p for p in inspect.signature(bench_config).parameters if p != "out"]
    for k in kwargs:
        if k not in known:
            raise UserError(f"unknown argument; run_bench takes out, progress, report_only, {', '.join(known)}",
                            field=k)
    if progress is not None and not isinstance(progress, bool):
        raise UserError(f"expected True, False or None, got {progress!r}"[:160], field="progress")
    if not isinstance(report_only, bool):
        raise UserError(f"expected True or False, got {report_only!r}"[:160], field="report_only")
    if kwargs.get("engine", "local") == "local" and not report_only:     # (before a suite writes its files)
        site = _unguarded_call_site()
        if site is not None:
            raise UserError(f"run_bench is called at the top level of {site}: {UNGUARDED_MESSAGE}")
    config = bench_config(out, **kwargs)
    outcome = _run(config, progress=progress, report_only=report_only)
    if outcome.total and outcome.errors == outcome.total:
        first = (outcome.summary.get("error_episodes") or [{}])[0]
        where = f"{first.get('scenario')} / {first.get('method')} / seed {first.get('seed')}"
        what = str(first.get("error") or "").splitlines()[0] if first.get("error") else "unknown error"
        raise UserError(f"every one of the bench's {outcome.total} episodes failed (recorded in {config.out}); the "
                        f"first: {where}: {what}")
    return outcome


def scenarios() -> dict[str, Path]:
    """The shipped scenarios by name (their TOML files inside the package)."""
    from .scenario import scenario_files
    return scenario_files()


def methods() -> dict[str, str]:
    """Every method selectable by name: registered ones and ``bigcbf.methods`` entry points -> where each comes
    from (``built-in`` or the entry point's ``package.module:factory``)."""
    from .control.methods import METHODS, entry_points

    out = {name: "built-in" for name in METHODS.names()}
    out.update({name: ep.value for name, ep in sorted(entry_points().items())})
    return out
