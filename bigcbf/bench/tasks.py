"""What a bench worker runs: one episode from plain, picklable arguments, returned as a result row.

A task carries the scenario file's *text* and the run configuration's TOML *text* (not paths or objects), so
that it pickles for the process pool and for Ray, and a worker on another machine needs only the installed package
(and, for a user's method given as ``package.module:Class``, that module importable by the same name). The worker
never touches the database: it returns a row (a plain dict) and the parent writes it.

Keys: an episode is identified by (scenario, method, seed, params_hash, scenario_sha). ``params_hash`` covers
the whole run configuration (:mod:`bigcbf.config`: the stack, perception, pedestrian and every method's
parameters, defaults filled in) and the perception mode, ``scenario_sha`` the scenario file's content *and* the
content of the base robot profile it starts from (``bigcbf/profiles/x3_sim.toml`` unless the file names another),
so changing any of them gives new rows instead of mixing results of different settings. The task carries the
profile's text too, so a worker runs the robot the key names.

This module imports nothing heavy at import time (the spawned workers import it first and set their threading
environment before numpy is loaded).
"""
from __future__ import annotations

import hashlib
import json
import os
import socket
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

#: Bump when the meaning of a row changes (part of params_hash, so old rows are not mixed with new ones).
#: 2: the hashed text is the whole run configuration, no longer the stack parameters alone.
HASH_VERSION = "bigcbf-bench-2"


@dataclass(frozen=True)
class EpisodeTask:
    """One episode to run, in plain data."""
    scenario: str            # scenario name (the file's ``name``, or its stem)
    scenario_sha: str        # scenario_key(scenario file's text, its base robot profile's text)
    scenario_toml: str       # the scenario file's text
    method: str
    seed: int
    params_hash: str         # params_key(params_toml, perception)
    params_toml: str         # the RunConfig as TOML (bigcbf.config.config_toml)
    perception: str = "lidar"
    robot_profile_toml: str | None = None   # the base robot profile's text (None: read the file it names)
    #: the bench's variant combination, ((axis, value), ...) (bigcbf.bench.variants; () without --variant): a label
    #: for the reports, not part of the key (its configuration is, through params_hash)
    variant: tuple[tuple[str, str], ...] = ()

    @property
    def key(self) -> tuple[str, str, int, str, str]:
        return (self.scenario, self.method, self.seed, self.params_hash, self.scenario_sha)


def params_toml(config) -> str:
    """The TOML text of a run configuration (a RunConfig, or StackParams meaning the default configuration with
    these stack parameters): every table and key, deterministic (:func:`bigcbf.config.config_toml`)."""
    from ..config import RunConfig, config_toml
    from ..params.stack import StackParams

    if isinstance(config, StackParams):
        config = RunConfig(stack=config)
    return config_toml(config)


def params_key(toml_text: str, perception: str) -> str:
    """Stable hash of the run configuration and the perception mode: sha256 over a versioned, canonical text
    (hex, 16)."""
    h = hashlib.sha256()
    h.update(f"{HASH_VERSION}\nperception = {perception!r}\n".encode())
    h.update(toml_text.encode())
    return h.hexdigest()[:16]


def scenario_key(scenario_text: str, robot_profile_text: str) -> str:
    """The scenario part of an episode's key: sha256 over the scenario file's text and its base robot profile's
    text (hex, 16), so editing the default robot profile gives new episodes."""
    return text_sha(f"{scenario_text}\0robot profile\0{robot_profile_text}")


def text_sha(text: str) -> str:
    """sha256 of a text (hex, 16 digits)."""
    return hashlib.sha256(text.encode()).hexdigest()[:16]


# --- the worker side -------------------------------------------------------------------------------------------

_PARAMS_CACHE: dict[str, Any] = {}


def _config(task: EpisodeTask):
    """The task's RunConfig (parsed once per worker and configuration)."""
    c = _PARAMS_CACHE.get(task.params_hash)
    if c is None:
        from ..config import config_from_toml
        c = config_from_toml(task.params_toml, file=f"<run config {task.params_hash}>")
        _PARAMS_CACHE[task.params_hash] = c
    return c


def _scenario(task: EpisodeTask):
    """The task's scenario drawn for its seed, parsed from the text the task carries. No file is written: a path
    made from a file's content (the scenario's name) could point anywhere (``name = "../../x"``). A file without
    ``name`` is named after its file, which the worker does not have: the task's name (the one the bench planned
    with) stands in for it."""
    from ..params.toml_io import parse_toml
    from ..scenario import scenario_from_dict

    label = f"<bench scenario {task.scenario_sha}>"     # names the text in error messages; never opened
    raw = parse_toml(task.scenario_toml, label)
    raw.setdefault("name", task.scenario)
    return scenario_from_dict(raw, Path(label), task.seed, robot_profile_text=task.robot_profile_toml)


def _json_safe(metrics: dict) -> dict:
    """Metrics as JSON gives them back (tuples -> lists, numpy scalars -> Python numbers); inf/nan are kept (the
    store writes them as JSON Infinity/NaN; summary.json turns them into null)."""
    def default(o):
        if hasattr(o, "item"):
            return o.item()
        if hasattr(o, "tolist"):
            return o.tolist()
        raise TypeError(f"not JSON-serializable: {type(o).__name__}")
    text = json.dumps(metrics, default=default)
    return json.loads(text)


def run_episode(task: EpisodeTask) -> dict:
    """Run one episode (Episode.from_config(...).run().metrics()) and return its metrics as a JSON-safe dict."""
    from ..episode import Episode

    result = Episode.from_config(_scenario(task), task.method, task.seed, _config(task),
                                 perception=task.perception).run()
    return _json_safe(result.metrics())


def estimated_cost(task: EpisodeTask, _cache: dict | None = None) -> float:
    """The episode's estimated work in cost units (:func:`bigcbf.cost.episode_cost`: its time limit, scene,
    perception and method), to hand the longest episodes out first; 0 when the task cannot even be read (its
    worker then records the error at once). ``_cache``: scenarios already drawn, by (scenario_sha, seed)."""
    from ..cost import episode_cost
    try:
        key = (task.scenario_sha, task.seed)
        sc = _cache.get(key) if _cache is not None else None
        if sc is None:
            sc = _scenario(task)
            if _cache is not None:
                _cache[key] = sc
        config = _config(task)
        return float(episode_cost(sc, task.method, config.stack, method_params=config.method_params(task.method),
                                  perception_params=config.perception, perception=task.perception).total)
    except Exception:  # noqa: BLE001 - a task that cannot be read is run (and its error recorded) by its worker
        return 0.0


def longest_first(tasks) -> list:
    """``tasks`` ordered for the pool: grouped by world (scenario_sha, seed: the same scene for every method and
    variant), the groups by their longest episode's :func:`estimated_cost`, the most work first, and within a group
    its episodes the most work first (stable: equal estimates keep their order). Longest first, so that a pool does
    not end waiting on one long episode started last; by world, so that a worker runs the methods of one world in a
    row and compiles its scene once (``bigcbf.sim.scene.cached_model``; compiling costs 0.1-0.25 s of an episode's
    ~1 s). The last groups are the ones whose longest episode is short, so the tail stays short."""
    cache: dict = {}
    costs = [estimated_cost(t, cache) for t in tasks]
    group: dict = {}
    for i, t in enumerate(tasks):
        k = (t.scenario_sha, t.seed)
        group[k] = max(group.get(k, -1.0), costs[i])
    order = sorted(range(len(tasks)), key=lambda i: (-group[(tasks[i].scenario_sha, tasks[i].seed)],
                                                     tasks[i].scenario_sha, tasks[i].seed, -costs[i]))
    return [tasks[i] for i in order]


_CODE_SHA: str | None = None


def code_sha() -> str:
    """Fingerprint of the code that runs episodes: sha256 over the bigcbf package's .py files (hex, 12).

    Not part of an episode's key (editing any file would make a resumed bench start over), but stored in every
    row; the reports warn when a bench's rows come from more than one version."""
    global _CODE_SHA
    if _CODE_SHA is None:
        root = Path(__file__).resolve().parent.parent
        h = hashlib.sha256()
        for f in sorted(root.rglob("*.py")):
            h.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
        _CODE_SHA = h.hexdigest()[:12]
    return _CODE_SHA


def guarded(fn: Callable[[EpisodeTask], dict], task: EpisodeTask) -> dict:
    """Run ``fn(task)`` and return a result row; an exception becomes a row with status "error" and its message.

    This is the function the engines send to workers (top-level, so it pickles).
    """
    t0 = time.perf_counter()
    row = dict(scenario=task.scenario, method=task.method, seed=task.seed, params_hash=task.params_hash,
               scenario_sha=task.scenario_sha, host=socket.gethostname(), pid=os.getpid(), code_sha=code_sha())
    try:
        metrics = fn(task)
    except Exception as exc:  # noqa: BLE001 - any crash of an episode is recorded, not raised
        frames = traceback.extract_tb(exc.__traceback__)
        where = f" (at {Path(frames[-1].filename).name}:{frames[-1].lineno} in {frames[-1].name})" if frames else ""
        row.update(status="error", error=f"{type(exc).__name__}: {exc}{where}", metrics=None)
    else:
        row.update(status="ok", error=None, metrics=metrics)
    row["worker_wall_s"] = time.perf_counter() - t0
    return row


def watch_parent(parent_pid: int, period_s: float = 1.0) -> None:
    """Worker initializer: exit when the parent bench process is gone (killed with SIGKILL, say), instead of
    lingering as an orphan that finishes episodes nobody will record."""
    import threading

    def watch():
        while True:
            if os.getppid() != parent_pid:
                os._exit(1)
            time.sleep(period_s)

    threading.Thread(target=watch, name="bench-parent-watch", daemon=True).start()


def error_row(task: EpisodeTask, message: str) -> dict:
    """A row for an episode whose worker died (no exception could be caught inside it)."""
    return dict(scenario=task.scenario, method=task.method, seed=task.seed, params_hash=task.params_hash,
                scenario_sha=task.scenario_sha, host=socket.gethostname(), pid=None, code_sha=None, status="error",
                error=message, metrics=None, worker_wall_s=None)
