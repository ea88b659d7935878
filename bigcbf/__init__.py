"""bigcbf: BIG-CBF navigation for a Mecanum robot in MuJoCo, with a digital twin.

Layers (a lower layer never imports a higher one; see docs/architecture.md):
cli > api > bench > episode > sim > {perception, control} > {params, types}.

The public Python API (:mod:`bigcbf.api`) is available from the package itself, loaded on first use so that
``import bigcbf.control`` on a robot does not pull in the simulator::

    import bigcbf
    result = bigcbf.run_episode("required_sidestepping", "big-cbf", seed=0)
"""
import os
from pathlib import Path

# Offscreen rendering without a display (must be set before mujoco is imported anywhere).
os.environ.setdefault("MUJOCO_GL", "egl")

__version__ = "0.1.0"

#: The package's own data (shipped in the wheel): the MJCF robot model, the scenario files and the
#: robot and stack profiles. The repository's
#: top-level ``assets`` and ``scenarios`` are symbolic links to these folders.
PACKAGE = Path(__file__).resolve().parent
ASSETS = PACKAGE / "assets"
SCENARIOS = PACKAGE / "scenarios"
#: Robot profiles (hardware imperfections and sensor models) shipped with the package, and the stack's
#: uncertainty profiles calibrated from them by the twin (``bigcbf profile simulate``).
PROFILES = PACKAGE / "profiles"
#: Default folder for videos: ``renders/`` of the current directory.
RENDERS = Path("renders")

#: name -> module of the public API, imported on first access (PEP 562)
_API = {"run_episode": "api", "run_bench": "api", "bench_config": "api", "load_config": "api",
        "load_scenario": "api", "scenarios": "api", "methods": "api", "RunConfig": "config",
        "load_run_config": "config", "EpisodeResult": "episode", "Episode": "episode", "StepRecord": "episode",
        "BenchOutcome": "bench.runner", "UserError": "errors"}


def __getattr__(name: str):
    mod = _API.get(name)
    if mod is None:
        raise AttributeError(f"module 'bigcbf' has no attribute {name!r}")
    import importlib
    return getattr(importlib.import_module(f"{__name__}.{mod}"), name)


def __dir__():
    return sorted(set(globals()) | set(_API))
