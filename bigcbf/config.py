"""One typed configuration of a run: the stack, the perception, the pedestrians and each method's own parameters.

``bigcbf run/bench --config RUN.toml`` reads it; every table and key is optional (missing ones keep their
defaults, or the ``base`` given to :func:`load_run_config`)::

    [stack]                 # StackParams (bigcbf/params/stack.py), BIG-CBF's and the filter's parameters: Table I
                            # with the twin-calibrated profile of the simulated X3 unless given
    alpha_per_s = 1.5
    [stack.uncertainty]
    kappa_img = 1.0

    [perception]            # PerceptionParams (bigcbf/params/perception.py): clustering, tracking
    gate_chi2 = 9.21

    [pedestrians]           # SocialForceParams (bigcbf/sim/pedestrians.py): the walkers' social-force model
    A_robot_mps2 = 1.0

    [methods.dwa]           # a method's own parameters (its params_type): apf, backup-cbf, dwa, mppi, pl-cbf,
    n_xy = 9                # or a user method with a params_type, e.g. [methods."my_pkg.planners:MyPlanner"]

    [route]                 # RouteParams (bigcbf/control/route.py): the route layer under EVERY method (a map from
    enabled = true          # the robot's scans, an A* path, its look-ahead point as the method's goal); off by
    lookahead_m = 1.5       # default (the paper's set-up); ``bigcbf run/bench --route on`` sets enabled

BIG-CBF, BIG-CBF-NoShared and CBF-only have no table of their own: their parameters are the stack's. A method's
``[methods.NAME.stack]`` table (any method, e.g. ``[methods.big-cbf.stack]``) lays stack keys over ``[stack]`` for
that method's episodes only (its planner and its filter), so one file can hold each method's tuned stack keys
(``bigcbf tune``, docs/tuning.md); :meth:`RunConfig.stack_for` gives the result. Unknown
tables and keys, values of the wrong type or out of range are a UserError naming the file and the field
(``methods.dwa.n_xy``). The LiDAR and the robot profile are not part of this file (the scenario file holds the
robot profile).

The bench hashes the whole configuration (:func:`config_toml`: every table with every key, defaults filled in)
into each episode's key, so two files that mean the same thing give the same key, and changing any parameter
gives new rows. The ``[route]`` table is part of that text only when it differs from the default (the route layer
off, every default), so the keys of the paper's set-up do not change with it.
"""
from __future__ import annotations

import copy
import dataclasses
import functools
try:
    import tomllib
except ModuleNotFoundError:      # Python 3.10: tomli is the same parser (bigcbf/params/toml_io.py)
    import tomli as tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .control.methods import METHODS, method_params_type
from .control.route import RouteParams
from .errors import UserError
from .params.perception import PerceptionParams
from .params.stack import StackParams, default_stack_params
from .params.toml_io import from_dict, load_toml, to_dict
from .params.pedestrians import SocialForceParams

TABLES = ("stack", "perception", "pedestrians", "methods", "route")


@dataclass(frozen=True)
class RunConfig:
    """Everything of a run that is not the scenario, the method's name, the seed or the LiDAR.

    ``RunConfig()`` is the one default: ``bigcbf run``/``bench``/``demo``, :func:`bigcbf.run_episode`, the Gymnasium
    environment and a bare ``Episode(scenario, method, seed)`` all build their episode from it
    (:meth:`bigcbf.episode.Episode.from_config`), so a scenario, method and seed give one result through every door
    (tests/test_one_config.py)."""

    #: default: Table I with the stack profile the twin calibrated for the simulated X3 (bigcbf profile simulate)
    stack: StackParams = field(default_factory=default_stack_params)
    perception: PerceptionParams = PerceptionParams()
    pedestrians: SocialForceParams = SocialForceParams()
    #: method name -> its parameters (an instance of the method's ``params_type``); methods not listed use
    #: their defaults. Default: the shipped tuned configuration's, when one is shipped (:data:`TUNED_PATH`)
    methods: dict[str, Any] = field(default_factory=lambda: dict(shipped_tuned()[0]))
    #: the route layer (bigcbf/control/route.py) under every method; off by default (the paper's set-up)
    route: RouteParams = RouteParams()
    #: method name -> its stack keys over ``stack`` (a partial StackParams table, ``[methods.NAME.stack]``)
    #: (default: the shipped tuned configuration's, when one is shipped)
    method_stacks: dict[str, dict] = field(default_factory=lambda: copy.deepcopy(shipped_tuned()[1]))

    def stack_for(self, method: str | None) -> StackParams:
        """The stack parameters of ``method``'s episodes: ``stack`` with its ``[methods.NAME.stack]`` keys."""
        over = self.method_stacks.get(method) if method is not None else None
        return self.stack if not over else from_dict(StackParams, _merge(to_dict(self.stack), over),
                                                     prefix=f"methods.{method}.stack")

    def method_params(self, method: str) -> Any:
        """The parameters of ``method`` (None for a method without a ``params_type``)."""
        ptype = method_params_type(method)
        if ptype is None:
            return None
        return self.methods.get(method, ptype())

    def replace(self, **changes) -> "RunConfig":
        return dataclasses.replace(self, **changes)


#: the shipped tuned run configuration (``bigcbf tune --write-shipped``; docs/tuning.md): when the file exists, its
#: ``[methods.NAME]`` tables (each method's chosen configuration, the grid's hash and the commit in its first lines)
#: are the defaults of ``RunConfig()``, i.e. of every front door; :func:`untuned` is the configuration without them
TUNED_PATH = Path(__file__).resolve().parent / "params" / "tuning" / "tuned.toml"


@functools.lru_cache(maxsize=1)
def shipped_tuned() -> tuple[dict, dict]:
    """(methods, method_stacks) of the shipped tuned configuration; empty when none is shipped. It holds
    ``[methods.NAME]`` tables only (a UserError naming the file otherwise)."""
    if not TUNED_PATH.is_file():
        return {}, {}
    data = load_toml(TUNED_PATH)
    for key in data:
        if key != "methods":
            raise UserError("a tuned configuration holds [methods.NAME] tables only", file=str(TUNED_PATH), field=key)
    cfg = run_config_from_dict(data, file=str(TUNED_PATH), base=untuned())
    return cfg.methods, cfg.method_stacks


def tuned_provenance() -> str | None:
    """The shipped tuned configuration's provenance line (grid hash and commit), None when none is shipped."""
    if not TUNED_PATH.is_file():
        return None
    for line in TUNED_PATH.read_text().splitlines():
        if line.startswith("# Provenance:"):
            return line[2:]
    return "Provenance: unknown (no provenance line)"


def untuned() -> RunConfig:
    """RunConfig() without the shipped tuned configuration: every method at its authors' (the dataclass) defaults."""
    return RunConfig(methods={}, method_stacks={})


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(base[k], v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
    return out


def run_config_from_dict(data: dict, *, file: str | None = None, base: RunConfig | None = None) -> RunConfig:
    """A RunConfig from a TOML document (``base``: where missing keys come from; default the defaults)."""
    base = base or RunConfig()
    for key, value in data.items():
        if key not in TABLES:
            raise UserError(f"unknown table (known: {', '.join(TABLES)})", file=file, field=key)
        if not isinstance(value, dict):
            raise UserError(f"expected a table, got {value!r}", file=file, field=key)
    parts: dict[str, Any] = {}
    for key, cls in (("stack", StackParams), ("perception", PerceptionParams), ("pedestrians", SocialForceParams),
                     ("route", RouteParams)):
        if key in data:
            parts[key] = from_dict(cls, _merge(to_dict(getattr(base, key)), data[key]), file=file, prefix=key)
    methods, stacks = dict(base.methods), dict(base.method_stacks)
    for name, table in data.get("methods", {}).items():
        where = f"methods.{name}"
        if not isinstance(table, dict):
            raise UserError(f"expected a table, got {table!r}", file=file, field=where)
        try:
            ptype = method_params_type(name)
        except UserError as err:
            raise UserError(err.message, file=file, field=where) from None
        if "stack" in table:
            stacks[name] = _method_stack(table["stack"], stacks.get(name, {}), parts.get("stack", base.stack),
                                         file, f"{where}.stack")
            table = {k: v for k, v in table.items() if k != "stack"}
            if not table:
                continue
        if ptype is None:
            raise UserError(f"method {name!r} has no parameters of its own (BIG-CBF's are in [stack], or in "
                            f"[methods.{name}.stack] for its episodes only)", file=file, field=where)
        start = to_dict(methods[name]) if name in methods else {}
        methods[name] = from_dict(ptype, _merge(start, table), file=file, prefix=where)
    return RunConfig(stack=parts.get("stack", base.stack), perception=parts.get("perception", base.perception),
                     pedestrians=parts.get("pedestrians", base.pedestrians), methods=methods,
                     route=parts.get("route", base.route), method_stacks=stacks)


def _method_stack(table, start: dict, stack: StackParams, file: str | None, where: str) -> dict:
    """A method's ``[methods.NAME.stack]`` table over ``start`` (its earlier one), checked as stack keys over
    ``stack`` (errors name the file and ``methods.NAME.stack.KEY``)."""
    if not isinstance(table, dict):
        raise UserError(f"expected a table of stack keys, got {table!r}", file=file, field=where)
    over = _merge(start, table)
    from_dict(StackParams, _merge(to_dict(stack), over), file=file, prefix=where)
    return over


def load_run_config(path: str | Path, base: RunConfig | None = None) -> RunConfig:
    """Read a run configuration TOML (format in the module docstring); errors name the file and the field."""
    return run_config_from_dict(load_toml(path), file=str(path), base=base)


def config_dict(config: RunConfig) -> dict:
    """The whole configuration as a TOML document: every table, every key, and a table for every registered
    method with parameters of its own (defaults filled in), plus every other method the configuration names, and
    the ``[route]`` table when it is not the default (the route layer off)."""
    methods = {}
    for name in METHODS.names():
        ptype = method_params_type(name)
        if ptype is not None:
            methods[name] = to_dict(config.methods.get(name, ptype()))
    for name, params in config.methods.items():
        methods[name] = to_dict(params)
    for name, over in config.method_stacks.items():     # only when given: the keys of other files do not change
        if over:
            methods[name] = {**methods.get(name, {}), "stack": over}
    out = {"stack": to_dict(config.stack), "perception": to_dict(config.perception),
           "pedestrians": to_dict(config.pedestrians), "methods": dict(sorted(methods.items()))}
    if config.route != RouteParams():
        out["route"] = to_dict(config.route)
    return out


def config_toml(config: RunConfig) -> str:
    """:func:`config_dict` as TOML text (deterministic: dataclass field order, methods sorted by name)."""
    import tomli_w
    return tomli_w.dumps(config_dict(config))


def config_from_toml(text: str, *, file: str = "<run config>") -> RunConfig:
    """Parse :func:`config_toml`'s text back (what a bench worker does with its task). The text is the whole
    configuration, so it is read over :func:`untuned`: a method without ``[methods.NAME.stack]`` in it has no stack
    keys of its own, and a shipped tuned file cannot add its keys to a configuration that had none (a fixed point:
    config_from_toml(config_toml(c)) == c)."""
    return run_config_from_dict(tomllib.loads(text), file=file, base=untuned())
