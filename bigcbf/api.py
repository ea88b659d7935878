"""The public Python API: what the command line does, in a few lines of Python, with typed results.

    import bigcbf

    res = bigcbf.run_episode("required_sidestepping", "big-cbf", seed=0)        # -> EpisodeResult
    print(res.success, res.time_s, res.e_cbf)

    out = bigcbf.run_bench("results/", methods=["cbf-only", "big-cbf"], seeds=range(3), workers=2)
    print(out.summary["methods"]["big-cbf"]["success_pct"])                      # -> BenchOutcome

Every function calls the same code as its subcommand (``bigcbf run``, ``bigcbf bench``); mistakes in the
arguments or files raise :class:`bigcbf.errors.UserError` with the one-line message the command prints.

Calibration and replay live in the ``twin`` package's API (``twin.calibrate_log(log) -> twin.Calibration``,
``twin.replay_log(log, profile) -> twin.ReplayResult``, see ``twin/__init__.py``), not here: ``twin`` builds on
``bigcbf``, and no module of ``bigcbf`` but its command line imports ``twin``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterable, Sequence

from .config import RunConfig, load_run_config
from .errors import UserError

__all__ = ["RunConfig", "load_config", "run_episode", "run_bench", "bench_config", "scenarios", "methods",
           "load_scenario"]


def load_config(config: str | Path | RunConfig | None = None, profile: str | Path | None = None, *,
                base: RunConfig | None = None, notes: Callable[[str], None] | None = None) -> RunConfig:
    """The run configuration: ``base`` (default: every default, Table I), overlaid with a ``--config`` TOML file
    (or taken as given when ``config`` is a RunConfig), then with a ``--profile`` stack-parameter TOML (a
    calibrated uncertainty profile from ``bigcbf calibrate``) over its ``stack``.

    ``notes(text)`` receives remarks about the profile (an axis the calibration did not identify); default:
    none are reported."""
    from .params.stack import load_stack_params

    if isinstance(config, RunConfig):
        cfg = config
    elif config is not None:
        cfg = load_run_config(config, base=base)
    else:
        cfg = base or RunConfig()
    if profile is not None:
        stack = load_stack_params(profile, base=cfg.stack)
        missing = [a for a, ok in zip(("vx", "vy"), stack.uncertainty.execution.identified[:2]) if not ok]
        if missing and notes is not None:
            notes(f"{profile}: {', '.join(missing)} not identified by the calibration; its execution model and "
                  "residual bound are the nominal ones, not measured")
        cfg = cfg.replace(stack=stack)
    return cfg


def load_scenario(scenario, seed: int = 0):
    """A scenario (a name from :func:`scenarios`, a path to a TOML file, or a Scenario) drawn for ``seed``."""
    from .scenario import Scenario
    from .scenario import load_scenario as _load

    if isinstance(scenario, Scenario):
        return scenario
    return _load(scenario, seed)


def run_episode(scenario, method: str = "big-cbf", seed: int = 0, *, config: str | Path | RunConfig | None = None,
                profile: str | Path | None = None, perception: str = "lidar", time_limit_s: float | None = None,
                video: str | Path | None = None, camera: str = "top", log: str | Path | None = None,
                live=None, observers: Iterable[Callable] = ()):
    """Run one episode and return its :class:`bigcbf.episode.EpisodeResult` (``.metrics()`` gives a dict).

    ``scenario``: a name (``bigcbf scenarios``), a scenario TOML path, or a Scenario. ``method``: a registered
    method, an entry point of ``bigcbf.methods`` or ``package.module:Class``. ``config``/``profile``: see
    :func:`load_config`. ``video``: an H.264 MP4 (``camera`` top or track); ``log``: a ROS 2 MCAP; ``live``: a
    :class:`bigcbf.logio.live.LiveWriter` to stream the log's topics to Foxglove (paced at real time).
    ``observers``: callables that receive every control step's :class:`bigcbf.episode.StepRecord`.
    """
    from .control.methods import resolve_method
    from .episode import PERCEPTION_MODES, Episode

    if perception not in PERCEPTION_MODES:
        raise UserError(f"perception must be one of {', '.join(PERCEPTION_MODES)}, got {perception!r}")
    sc = load_scenario(scenario, seed)
    resolve_method(method)
    cfg = load_config(config, profile)
    from .outputs import check_output_file
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
                 notes: Callable[[str], None] | None = None):
    """The :class:`bigcbf.bench.runner.BenchConfig` that :func:`run_bench` runs (what ``bigcbf bench`` builds from
    its options). ``seeds``: a count N (seeds 0..N-1) or the seeds themselves; default the suite's count.
    ``methods``: default every registered method. ``scenarios``: default the suite's (``split``: only that split
    of a suite that has splits, e.g. generated's dev or test). The run configuration is the suite's stack
    parameters (if it has them), then ``config``, then ``profile`` (see :func:`load_config`)."""
    import os

    from .bench.engines import ENGINES, ray_available
    from .bench.paper import METHOD_ORDER, ordered
    from .bench.runner import BenchConfig
    from .bench.suites import SUITES
    from .control.methods import METHODS, resolve_method

    if engine not in ENGINES:
        raise UserError(f"--engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    if ray_address is not None and engine != "ray":
        raise UserError("--ray-address needs --engine ray")
    if engine == "ray" and not ray_available():
        raise UserError("--engine ray needs Ray, which is not installed: pip install 'bigcbf[ray]'")
    if perception not in ("lidar", "truth"):
        raise UserError(f"--perception must be lidar or truth, got {perception!r}")
    s = SUITES.get(suite)
    if seeds is None:
        seeds = s.default_seeds
    seed_list = tuple(range(seeds)) if isinstance(seeds, int) else tuple(int(x) for x in seeds)
    if workers is None and engine == "local":
        workers = os.cpu_count() or 1
    method_list = tuple(methods) if methods else tuple(ordered(METHODS.names(), METHOD_ORDER))
    for m in method_list:
        resolve_method(m)
    out = Path(out)
    if split is not None:
        if not s.splits:
            raise UserError(f"suite {suite!r} has no splits (--split is for suites such as generated)")
        if split not in s.splits:
            raise UserError(f"suite {suite!r} has no split {split!r}; known: {', '.join(s.splits)}")
        if scenarios:
            raise UserError("--split selects among the suite's scenarios; drop it when giving --scenarios")
    entries = s.entries(out, split) if s.splits else s.entries(out)
    if scenarios:
        scenario_list = tuple(str(x) for x in scenarios)
        # scenarios given by path that are files of the suite keep their split and family in the reports
        known = {Path(e.scenario).resolve(): e for e in entries if e.split or e.family}
        labels = tuple((x, known[Path(x).resolve()].split, known[Path(x).resolve()].family) for x in scenario_list
                       if Path(x).resolve() in known)
    else:
        scenario_list = tuple(str(e.scenario) for e in entries)
        labels = tuple((str(e.scenario), e.split, e.family) for e in entries if e.split or e.family)
    base = RunConfig(stack=s.params()) if s.params is not None else None
    cfg = load_config(config, profile, base=base, notes=notes)
    return BenchConfig(out=out, methods=method_list, scenarios=scenario_list, seeds=seed_list, workers=workers,
                       engine=engine, ray_address=ray_address, config=cfg, perception=perception, labels=labels,
                       suite=None if scenarios else s.name)


def run_bench(out: str | Path, *, progress: bool | None = False, report_only: bool = False, **kwargs):
    """Run (or resume) a bench into ``out`` and return its :class:`bigcbf.bench.runner.BenchOutcome` (counts, wall
    time, and ``summary``: the content of summary.json). ``kwargs``: as for :func:`bench_config`."""
    from .bench.runner import run_bench as _run

    return _run(bench_config(out, **kwargs), progress=progress, report_only=report_only)


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
