"""Variant axes of a bench: switches of the ONE common filter and layers around a method that ``bigcbf bench
--variant NAME=V1,V2`` compares, every method under every combination of the values given, on the same seeds.

Each axis names where it lives in the run configuration (:mod:`bigcbf.config`) and its allowed values; a value
sets that field of the bench's configuration (over ``--config`` / ``--profile``), so a combination's episodes
carry its configuration in their key's ``params_hash``. A combination equal to the bench's configuration without
variants (e.g. ``route=off`` with the default configuration) has the same key as a bench without ``--variant``:
an earlier result folder resumes and only the other combinations run.

A stack axis sets its key for every method, over a method's own ``[methods.NAME.stack]`` key too; a method that is
defined by a switch keeps it under every value (``dpcbf``: the velocity rows always on).

The axes register in :data:`VARIANT_AXES` (``VARIANT_AXES.add(VariantAxis(...))``). Rows of the reports are labelled
``method [axis=value, ...]`` (:func:`arm_label`); the first value given of each axis is the one the others are
compared with, paired on the same scenes and seeds (``bigcbf.bench.report``).
"""
from __future__ import annotations

import dataclasses
import itertools
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

from ..errors import UserError
from ..registry import Registry

#: one combination: ((axis, value), ...) in the order the axes were given
Combination = tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class VariantAxis:
    """A switch the bench compares: its name on the command line, where it lives in a run configuration, its
    allowed values (in the order shown) and how a value changes a configuration."""

    name: str
    path: str                                  # e.g. "[route] enabled"
    values: tuple[str, ...]
    apply: Callable[[object, str], object]     # (RunConfig, value) -> RunConfig
    description: str = ""


VARIANT_AXES: Registry[VariantAxis] = Registry("variant axis")


def _stack(field: str, convert: Callable[[str], object]) -> Callable[[object, str], object]:
    """A ``[stack]`` key for every method: also over a method's own ``[methods.NAME.stack]`` key of that name."""
    def apply(config, value: str):
        v = convert(value)
        own = getattr(config, "method_stacks", {})
        stacks = {m: ({**over, field: v} if field in over else over) for m, over in own.items()}
        changes = {"stack": dataclasses.replace(config.stack, **{field: v})}
        if stacks != own:
            changes["method_stacks"] = stacks
        return config.replace(**changes)
    return apply


def _route(config, value: str):
    return config.replace(route=dataclasses.replace(config.route, enabled=value == "on"))


#: the value ``route_progress=on`` gives ``[route] progress_time_s`` (bigcbf/control/route.py, step 5): chosen on the
#: dev split (route on, big-cbf-plus, Backup-CBF, CBF-only, 720 episodes): 5 s gained 1 world, 3 s gained 4, none
#: lost either way. Nav2's own default, 10 s, is more than the generated worlds' time limits leave beyond the path at
#: 0.5 m/s (8 s), and the way round has to fit in that too. Measured in docs/fidelity.md ("The route layer's
#: progress check").
ROUTE_PROGRESS_ON_S = 3.0
#: and ``[route] wait_range_m``: no stall while a moving track is this near (a wait for people is not a stall)
ROUTE_PROGRESS_WAIT_M = 2.0


def _route_progress(config, value: str):
    on = value == "on"
    return config.replace(route=dataclasses.replace(
        config.route, progress_time_s=ROUTE_PROGRESS_ON_S if on else 0.0,
        wait_range_m=ROUTE_PROGRESS_WAIT_M if on else 0.0))


def _last_resorts() -> tuple[str, ...]:
    from ..params.stack import LAST_RESORTS
    return tuple(LAST_RESORTS)


VARIANT_AXES.add(VariantAxis(
    "route", "[route] enabled", ("off", "on"), _route,
    "the route layer under every method (bigcbf/control/route.py); off: the paper's set-up"))
VARIANT_AXES.add(VariantAxis(
    "route_progress", "[route] progress_time_s", ("off", "on"), _route_progress,
    f"the route layer's progress check (a stall of {ROUTE_PROGRESS_ON_S:g} s makes the path ahead costly); off: none"))
VARIANT_AXES.add(VariantAxis(
    "cbf_velocity_rows", "[stack] cbf_velocity_rows", ("off", "on"), _stack("cbf_velocity_rows", lambda v: v == "on"),
    "the velocity-aware barrier of the common filter (a collision-cone row per moving obstacle); off: the paper's"))
VARIANT_AXES.add(VariantAxis(
    "cbf_slowdown", "[stack] cbf_slowdown", ("off", "on"), _stack("cbf_slowdown", lambda v: v == "on"),
    "an infeasible step's margins evaluated at slower commands before the last resort; off: the paper's"))
VARIANT_AXES.add(VariantAxis(
    "cbf_last_resort", "[stack] cbf_last_resort", _last_resorts(), _stack("cbf_last_resort", str),
    "what the common filter commands when no command satisfies every row; slack: the paper's least violation"))


def _axes_line() -> str:
    return "; ".join(f"{n}={','.join(VARIANT_AXES.get(n).values)}" for n in VARIANT_AXES.names())


def parse_variants(specs: Iterable[str] | None, field: str = "--variant") -> tuple[tuple[str, tuple[str, ...]], ...]:
    """``["route=off,on", ...]`` -> ``(("route", ("off", "on")), ...)``, checked: a known axis, given once, with one
    or more distinct allowed values. A mistake is a UserError naming ``field`` (one line: the command line's
    ``--variant``, the Python API's ``variants``)."""
    if specs is None:
        return ()
    if isinstance(specs, str) or not isinstance(specs, (list, tuple)):
        raise UserError(f"expected a list of NAME=V1,V2 texts, got {specs!r}"[:160], field=field)
    out: list[tuple[str, tuple[str, ...]]] = []
    for spec in specs:
        if not isinstance(spec, str) or spec.count("=") != 1:
            raise UserError(f"expected NAME=V1,V2 (known: {_axes_line()}), got {str(spec)[:40]!r}",
                            field=field)
        name, _, text = spec.partition("=")
        name = name.strip()
        if name not in VARIANT_AXES:
            raise UserError(f"unknown axis {name[:40]!r}; known: {_axes_line()}", field=field)
        axis = VARIANT_AXES.get(name)
        values = tuple(v.strip() for v in text.split(","))
        bad = [v for v in values if v not in axis.values]
        if bad:
            raise UserError(f"{name} ({axis.path}) takes {', '.join(axis.values)}, got {bad[0][:40]!r}",
                            field=field)
        dup = sorted({v for v in values if values.count(v) > 1})
        if dup:
            raise UserError(f"{name}: value listed more than once: {', '.join(dup)}", field=field)
        if any(n == name for n, _ in out):
            raise UserError(f"axis {name} given more than once; list its values in one --variant {name}=V1,V2",
                            field=field)
        out.append((name, values))
    return tuple(out)


def combinations(axes: Sequence[tuple[str, Sequence[str]]]) -> list[Combination]:
    """Every combination of the axes' values (the last axis varying fastest); ``[()]`` without axes."""
    return [tuple(zip([n for n, _ in axes], vals)) for vals in itertools.product(*[v for _, v in axes])]


def combination_label(combo: Combination) -> str:
    """``route=on, cbf_velocity_rows=off`` ('' without axes)."""
    return ", ".join(f"{a}={v}" for a, v in combo)


def arm_label(method: str, combo: Combination) -> str:
    """A report row's name: ``dwa [route=on]``; the method alone without axes."""
    return f"{method} [{combination_label(combo)}]" if combo else method


def split_label(label: str) -> tuple[str, str]:
    """``"dwa [route=on]"`` -> ``("dwa", "route=on")``; a bare method -> ``(method, "")``."""
    if label.endswith("]") and " [" in label:
        method, _, rest = label.partition(" [")
        return method, rest[:-1]
    return label, ""


def apply_combination(config, combo: Combination):
    """``config`` (a RunConfig) with each axis of ``combo`` set to its value."""
    for name, value in combo:
        config = VARIANT_AXES.get(name).apply(config, value)
    return config


__all__ = ["VariantAxis", "VARIANT_AXES", "parse_variants", "combinations", "combination_label", "arm_label",
           "split_label", "apply_combination"]
