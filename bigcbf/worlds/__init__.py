"""Procedural worlds: scenario families generated from a seed and written as ordinary scenario TOML.

``bigcbf scenarios generate FAMILY --seed N --out FILE`` writes one world; the ``generated`` bench suite
(bigcbf/bench/suites.py) writes a dev and a test split of every family into the bench's output directory. Each
file uses the schema of :mod:`bigcbf.scenario` with concrete numbers (no random ranges: the world *is* the draw),
so ``bigcbf run FILE`` replays it and a user can read and edit it. No module of the stack imports this one.

One file per family. The shared parts are two modules: :mod:`.geometry` (a world before it is written, exact
distances, the grid path search, the generation-time checks and the time limit rule, described there) and
:mod:`.generator` (the :data:`FAMILIES` registry, :func:`generate`, the TOML writer and the suite's worlds). Every
other module of this package is a family (``posts``, ``clutter``, ...; ``bigcbf scenarios generate --list`` lists
them with the ranges their parameters are drawn from): it defines its builder and registers it with
``FAMILIES.add(Family(name=..., summary=..., design=..., ranges=..., build=..., order=...))``. The package imports
every module it holds (:func:`discover`), so a new family is one new file here: the command line, the ``generated``
suite and its reports pick it up by its registration.
"""
from __future__ import annotations

import importlib
import pkgutil

from .generator import (FAMILIES, FRESH, GENERATOR_VERSION, MAX_ATTEMPTS, SPLITS, Family, World, check_fresh_seeds,
                        family, fresh_worlds, generate, parse, split_names, suite_worlds, toml_key, toml_value,
                        world_name, write)
from .geometry import (CLEARANCE_M, FOOTPRINT_M, GRID_ALLOWANCE_M, GRID_M, MIN_PASSAGE_M, NONTRIVIAL_M,
                       PED_RADIUS_M, PED_ROUTE_M, PED_START_GAP_M, PED_WALL_CLEARANCE_M, PLAN_SPEED_MPS,
                       ROBOT_RADIUS_M, SLACK_PER_PEDESTRIAN_S, SLACK_S, CheckResult, Draft, Grid, _polyline_points,
                       _primitives, check, connected, distance, distance_grid, shortest_path, smooth, time_limit,
                       widest_clearance)


def discover() -> list[str]:
    """Import every module of this package not yet imported (each family module registers its family) and put
    :data:`FAMILIES` in listing order (each family's ``order``, then its name); the names of the families."""
    for info in pkgutil.iter_modules(__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"{__name__}.{info.name}")
    FAMILIES.sort(key=lambda f: (f.order, f.name))
    return FAMILIES.names()


discover()

__all__ = ["FAMILIES", "FRESH", "GENERATOR_VERSION", "MAX_ATTEMPTS", "SPLITS", "Family", "World", "check_fresh_seeds",
           "family", "fresh_worlds", "generate", "parse", "split_names", "suite_worlds", "toml_key", "toml_value",
           "world_name", "write", "CLEARANCE_M",
           "FOOTPRINT_M", "GRID_ALLOWANCE_M", "GRID_M", "MIN_PASSAGE_M", "NONTRIVIAL_M", "PED_RADIUS_M",
           "PED_ROUTE_M", "PED_START_GAP_M", "PED_WALL_CLEARANCE_M", "PLAN_SPEED_MPS", "ROBOT_RADIUS_M",
           "SLACK_PER_PEDESTRIAN_S", "SLACK_S", "CheckResult", "Draft", "Grid", "check", "connected", "distance",
           "distance_grid", "shortest_path", "smooth", "time_limit", "widest_clearance", "discover"]
