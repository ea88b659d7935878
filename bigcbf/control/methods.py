"""The method registry and how a method name becomes a planner; every method's u_in goes through the same CbfFilter.

A method is a *factory*: ``factory(params: StackParams) -> Planner``, or, when the factory has a ``params_type``
attribute (a frozen dataclass of the method's own parameters, e.g. ``DwaPlanner.params_type = DwaParams``),
``factory(params, method_params)``. A planner class is its own factory. A method name is one of:

1. a name registered in :data:`METHODS` (the eight of the paper: ``big-cbf``, ``dwa``, ...);
2. the name of an entry point in the group ``bigcbf.methods`` of an installed distribution, whose value is
   ``package.module:factory`` (``[project.entry-points."bigcbf.methods"] my-planner = "my_pkg.planners:MyPlanner"``);
3. ``package.module:factory`` itself, imported by that name (the module must be importable: installed, or on
   ``PYTHONPATH``; bench workers import it by the same name).

A name registered twice, or an entry point named like a registered method, is an error. Every mistake (unknown
name, a module that cannot be imported, an attribute that is missing or not a planner factory) is a UserError.
"""
from __future__ import annotations

import dataclasses
import importlib
import inspect
import time
from functools import lru_cache
from typing import Any, Callable

import numpy as np

from ..errors import UserError
from ..params.stack import StackParams
from ..registry import Registry, check_protocol_factory
from ..types import Obstacles, RobotState
from .behaviors import behavior_command
from .big_cbf import BigCbfPlanner, BigCbfPlusPlanner
from .planner import PlanInfo, Planner, clip_command, fail_safe

METHODS: Registry[Callable[[StackParams], Planner]] = Registry("method")


class CbfOnlyPlanner:
    """CBF-only: the GOAL feedback policy (eq:goal_basis (9), eq:behavior_subgoals (10), eq:behavior_feedback (11)
    with b = GOAL) straight into the common CBF filter."""

    name = "cbf-only"

    def __init__(self, params: StackParams):
        self.params = params

    def reset(self, seed: int) -> None:
        """Stateless and deterministic: nothing to reset."""

    @fail_safe
    def plan(self, t: float, state: RobotState, obstacles: Obstacles, goal) -> tuple[np.ndarray, PlanInfo]:
        t0 = time.perf_counter()
        u = clip_command(behavior_command("GOAL", state, obstacles, np.asarray(goal, float).reshape(2), self.params),
                         self.params)
        return u, PlanInfo(mode="GOAL", planned=True, planner_ms=(time.perf_counter() - t0) * 1e3, path=None)


class DpcbfPlanner(CbfOnlyPlanner):
    """DPCBF: CBF-only's GOAL command through the common filter with the velocity-aware barrier on
    (``StackParams.cbf_velocity_rows``: a collision-cone row per moving obstacle, ``bigcbf.control.velocity_barrier``;
    docs/fidelity.md, "The velocity-aware barrier"). The episode builds its filter from ``filter_params``."""

    name = "dpcbf"

    def __init__(self, params: StackParams):
        super().__init__(params)
        self.filter_params = dataclasses.replace(params, cbf_velocity_rows=True)


def filter_params(planner, params: StackParams) -> StackParams:
    """The parameters of the common filter for ``planner``: its ``filter_params`` when it has them (a method that
    is defined by a filter switch, e.g. ``dpcbf``), else the episode's."""
    own = getattr(planner, "filter_params", None)
    return own if isinstance(own, StackParams) else params


METHODS.register("big-cbf", lambda params: BigCbfPlanner(params, shared=True))
METHODS.register("big-cbf-noshared", lambda params: BigCbfPlanner(params, shared=False))
METHODS.register("big-cbf-plus", BigCbfPlusPlanner)      # our rules beyond the paper, each a switch (PlusRules)
METHODS.register("cbf-only", CbfOnlyPlanner)
METHODS.register("dpcbf", DpcbfPlanner)

from . import baselines as _baselines  # noqa: E402  (the five comparison methods register themselves here)

_baselines.register(METHODS)


#: the entry-point group through which installed distributions add methods
ENTRY_POINT_GROUP = "bigcbf.methods"


def entry_points() -> dict[str, Any]:
    """The installed ``bigcbf.methods`` entry points by name (not loaded). A name that a registered method or
    another entry point already uses is a UserError (names are unique, as in every registry)."""
    from importlib.metadata import entry_points as _eps

    out: dict[str, Any] = {}
    for ep in _eps(group=ENTRY_POINT_GROUP):
        if ep.name in METHODS:
            raise UserError(f"entry point {ep.name!r} = {ep.value!r} ({ENTRY_POINT_GROUP}) has the name of a "
                            "built-in method; rename it")
        if ep.name in out and out[ep.name].value != ep.value:
            raise UserError(f"two {ENTRY_POINT_GROUP} entry points are named {ep.name!r}: {out[ep.name].value!r} "
                            f"and {ep.value!r}")
        out[ep.name] = ep
    return out


def method_names() -> list[str]:
    """Every method a name can select without a module path: the registered ones, then the entry points."""
    return METHODS.names() + sorted(entry_points())


def _import_factory(spec: str, what: str) -> Callable:
    mod_name, _, attr = spec.partition(":")
    if not mod_name or not attr:
        raise UserError(f"{what}: expected package.module:factory, got {spec!r}")
    try:
        mod = importlib.import_module(mod_name)
    except ImportError as exc:
        raise UserError(f"{what}: cannot import {mod_name!r} ({exc}); is it installed or on PYTHONPATH?") from None
    obj: Any = mod
    for part in attr.split("."):
        if not hasattr(obj, part):
            raise UserError(f"{what}: module {mod_name!r} has no attribute {attr!r}")
        obj = getattr(obj, part)
    name = "it" if repr(spec) in what else repr(spec)
    check_protocol_factory(obj, ("reset", "plan"), "planner", what, name)
    return obj


@lru_cache(maxsize=None)
def _resolve(name: str) -> Callable:
    if name in METHODS:
        return METHODS.get(name)
    eps = entry_points()
    if name in eps:
        return _import_factory(eps[name].value, f"method {name!r} (entry point {ENTRY_POINT_GROUP})")
    if ":" in name:
        return _import_factory(name, f"method {name!r}")
    raise UserError(f"unknown method {name!r}; known: {', '.join(method_names())} "
                    "(or give package.module:Class)")


def resolve_method(name: str) -> Callable:
    """The factory of method ``name`` (rules in the module docstring); UserError when there is none."""
    if not isinstance(name, str) or not name:
        raise UserError(f"a method name is a non-empty string, got {name!r}")
    return _resolve(name)


def method_params_type(name: str) -> type | None:
    """The dataclass of method ``name``'s own parameters, or None when it has none."""
    return getattr(resolve_method(name), "params_type", None)


def _call_factory(name: str, factory: Callable, args: tuple):
    """``factory(*args)``; a user's factory (not a registered method) that cannot be called so, or that raises,
    is a UserError naming the method, not a traceback from inside the episode. A registered method's exception
    is a bug of ours and propagates."""
    if name in METHODS:
        return factory(*args)
    try:
        inspect.signature(factory).bind(*args)
    except TypeError as exc:
        call = "factory(params, method_params)" if len(args) == 2 else "factory(params)"
        raise UserError(f"method {name!r}: its factory cannot be called as {call} ({exc})") from None
    except ValueError:               # no signature to inspect (a builtin): let the call decide
        pass
    try:
        return factory(*args)
    except Exception as exc:         # noqa: BLE001 - the user's code, reported in one line
        raise UserError(f"method {name!r}: its factory raised {type(exc).__name__}: {str(exc)[:200]}") from None


def make_planner(name: str, params: StackParams, method_params: Any = None) -> Planner:
    """A new planner of method ``name`` with the stack parameters and (methods with a ``params_type``) its own
    parameters (default: the dataclass's defaults). The result must implement the Planner protocol."""
    factory = resolve_method(name)
    ptype = getattr(factory, "params_type", None)
    if ptype is None:
        if method_params is not None:
            raise UserError(f"method {name!r} takes no parameters of its own (its factory has no params_type)")
        planner = _call_factory(name, factory, (params,))
    else:
        if method_params is None:
            method_params = ptype()
        elif not isinstance(method_params, ptype):
            raise TypeError(f"method {name!r} takes {ptype.__name__}, got {type(method_params).__name__}")
        planner = _call_factory(name, factory, (params, method_params))
    missing = [a for a in ("reset", "plan") if not callable(getattr(planner, a, None))]
    if missing:
        raise UserError(f"method {name!r}: {type(planner).__name__} is not a planner (no {', '.join(missing)}; "
                        "see bigcbf.control.planner.Planner)")
    return planner
