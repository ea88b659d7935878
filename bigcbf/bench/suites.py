"""Benchmark suites: named sets of scenarios that ``bigcbf bench --suite NAME`` runs.

A suite lists its scenarios (names of the shipped scenario files or paths to TOML files), how many seeds it runs
by default, and optionally the stack parameters it is meant for (e.g. a hardware preset). Suites that generate
their worlds write them as ordinary scenario TOML files into the bench's output directory, so every world can be
inspected and rerun with ``bigcbf run FILE``. No code path of the stack knows which suite or scene it runs.

Suites register in ``SUITES`` by name (a duplicate name is an error).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..registry import Registry


@dataclass(frozen=True)
class SuiteEntry:
    """One scenario of a suite: a shipped scenario's name or a TOML path, and (generated suites) its split and
    family, used to report dev and test splits and success per family separately (the faults suite: the fault is
    the family and its level the split)."""

    scenario: str
    split: str = ""
    family: str = ""


@dataclass(frozen=True)
class Suite:
    name: str
    description: str
    #: the suite's scenarios, given the bench's output directory (generated suites write their files there);
    #: a suite with splits takes the split to select as a second argument (None: every split)
    entries: Callable[..., list[SuiteEntry]]
    default_seeds: int = 50
    #: the stack parameters the suite is meant for (None: the default profile); ``--profile`` overrides it
    params: Callable[[], object] | None = None
    #: the splits its entries belong to (``bigcbf bench --split NAME`` runs one); () for a suite without splits
    splits: tuple[str, ...] = ()


SUITES: Registry[Suite] = Registry("suite")


def _paper(out: Path) -> list[SuiteEntry]:
    from .paper import SCENARIO_ORDER
    return [SuiteEntry(name) for name in SCENARIO_ORDER]


SUITES.register("paper", Suite("paper", "the paper's nine simulation scenarios (Sec. IV, Table II)", _paper))


def _generated(out: Path, split: str | None = None) -> list[SuiteEntry]:
    from ..worlds import suite_worlds
    return [SuiteEntry(str(path), sp, family)
            for path, sp, family in suite_worlds(out, None if split is None else [split])]


SUITES.register("generated", Suite(
    "generated", "procedural worlds (bigcbf/worlds.py): 6 families x (30 dev + 30 test) worlds, written to "
    "DIR/worlds/, one seed each", _generated, default_seeds=1, splits=("dev", "test")))


def _hardware(out: Path) -> list[SuiteEntry]:
    from .paper import HARDWARE_SCENARIO_ORDER
    return [SuiteEntry(name) for name in HARDWARE_SCENARIO_ORDER]


def _hardware_params():
    """The paper's physical preset (Sec. V: r_R 0.15 m, d0 0.05 m, beta 1, e_ZOH 0.0716 m, kappa_exec 1, kappa_img
    0.8 in dynamic scenes) overlaid with the tau95 and execution model the twin calibrated for the real X3-class
    robot profile (bigcbf/profiles/stack/x3_hardware.toml)."""
    from ..params.stack import PHYSICAL, default_stack_params
    return default_stack_params("x3_hardware", base=PHYSICAL)


SUITES.register("hardware", Suite(
    "hardware", "the paper's three hardware scenes (Sec. V, Table III) at a lab's scale, with the physical preset "
    "and a real X3-class robot profile", _hardware, default_seeds=20, params=_hardware_params))


def _faults(out: Path, split: str | None = None) -> list[SuiteEntry]:
    from .faults import _suite_entries
    return _suite_entries(out, split)


SUITES.register("faults", Suite(
    "faults", "every method under LiDAR noise, scan dropout, a blanked sector, latency spikes, odometry drift, "
    "pedestrians that stop or turn (bigcbf/bench/faults.py), mild and severe, on shipped scenes where each matters, "
    "beside the same scenes without the fault; files written to DIR/faults/", _faults, default_seeds=5,
    splits=("none", "mild", "severe")))
