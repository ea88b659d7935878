"""Benchmark suites: named sets of scenarios that ``bigcbf bench --suite NAME`` runs.

A suite lists its scenarios (names of the shipped scenario files or paths to TOML files), how many seeds it runs
by default, and optionally the stack parameters it is meant for (e.g. a hardware preset). Suites that generate
their worlds write them as ordinary scenario TOML files into the bench's output directory, so every world can be
inspected and rerun with ``bigcbf run FILE``. No code path of the stack knows which suite or scene it runs.

Suites register in ``SUITES`` under their own name (``SUITES.add(Suite(name=...))``, a duplicate name is an error);
their splits are their tags. The names they are made of are written once, elsewhere, and read from there: the
world families and their splits from ``bigcbf.worlds.FAMILIES``, the faults and their levels from
``bigcbf.bench.faults.FAULTS``, the paper's scenes from ``bigcbf.bench.paper``. This module imports the faults
(and the worlds), never the report: the bench's modules import one another without a circle.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .. import worlds
from ..registry import Registry
from . import faults


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
    #: the names of the splits its entries belong to, or a function that tells them (read when asked, e.g. the
    #: splits of the world families registered now); () for a suite without splits
    split_names: tuple[str, ...] | Callable[[], tuple[str, ...]] = ()
    #: the folder of the bench's --out where ``entries`` writes the suite's scenario files ("" when it writes none):
    #: a bench --out holding only such files is still a fresh bench's (bigcbf.bench.runner.check_bench_out)
    folder: str = ""
    #: the suite's scenarios at world seeds the bench is given instead of its splits' (``bigcbf bench
    #: --world-seeds``), given the output directory and the seeds; None for a suite whose scenarios are fixed
    fresh: Callable[..., list[SuiteEntry]] | None = None

    @property
    def splits(self) -> tuple[str, ...]:
        """The splits its entries belong to (``bigcbf bench --split NAME`` runs one); () without splits."""
        return tuple(self.split_names() if callable(self.split_names) else self.split_names)

    @property
    def tags(self) -> tuple[str, ...]:
        """Its registry tags: its splits."""
        return self.splits


SUITES: Registry[Suite] = Registry("suite")


def _paper(out: Path) -> list[SuiteEntry]:
    from .paper import SCENARIO_ORDER
    return [SuiteEntry(name) for name in SCENARIO_ORDER]


SUITES.add(Suite("paper", "the paper's nine simulation scenarios (Sec. IV, Table II)", _paper))


def _generated(out: Path, split: str | None = None) -> list[SuiteEntry]:
    return [SuiteEntry(str(path), sp, family)
            for path, sp, family in worlds.suite_worlds(out, None if split is None else [split])]


def _generated_fresh(out: Path, seeds) -> list[SuiteEntry]:
    return [SuiteEntry(str(path), sp, family) for path, sp, family in worlds.fresh_worlds(out, seeds)]


SUITES.add(Suite(
    "generated", "procedural worlds (bigcbf/worlds/, one module per family): every registered family at the seeds of "
    "each of its splits, written to DIR/worlds/<split>/, one seed each (--world-seeds: at other seeds, split "
    "fresh)", _generated, default_seeds=1, split_names=worlds.split_names, folder="worlds", fresh=_generated_fresh))


def _hardware(out: Path) -> list[SuiteEntry]:
    from .paper import HARDWARE_SCENARIO_ORDER
    return [SuiteEntry(name) for name in HARDWARE_SCENARIO_ORDER]


def _hardware_params():
    """The paper's physical preset (Sec. V: r_R 0.15 m, d0 0.05 m, beta 1, e_ZOH 0.0716 m, kappa_exec 1, kappa_img
    0.8 in dynamic scenes) overlaid with the tau95 and execution model the twin calibrated for the real X3-class
    robot profile (bigcbf/profiles/stack/x3_hardware.toml)."""
    from ..params.stack import PHYSICAL, default_stack_params
    return default_stack_params("x3_hardware", base=PHYSICAL)


SUITES.add(Suite(
    "hardware", "the paper's three hardware scenes (Sec. V, Table III) at a lab's scale, with the physical preset "
    "and a real X3-class robot profile", _hardware, default_seeds=20, params=_hardware_params))


def _faults(out: Path, split: str | None = None) -> list[SuiteEntry]:
    """The shipped scenes the faults use (split and family ``none``), then every fault's variants (family: the
    fault, split: its level), written to ``out/faults/``."""
    entries = []
    if split in (None, faults.REFERENCE):
        entries += [SuiteEntry(s, faults.REFERENCE, faults.REFERENCE) for s in faults.scenes()]
    if split != faults.REFERENCE:
        entries += [SuiteEntry(str(p), level, fault)
                    for p, level, fault in faults.write_variants(out, None if split is None else [split])]
    return entries


SUITES.add(Suite(
    "faults", f"every method under each fault of bigcbf/bench/faults.py ({', '.join(faults.FAULTS)}), at each level "
    f"({', '.join(faults.LEVELS)}), on shipped scenes where each matters, beside the same scenes without the fault "
    "(split and family none); files written to DIR/faults/", _faults, default_seeds=5,
    split_names=(faults.REFERENCE, *faults.LEVELS), folder="faults"))


def _francis2023(out: Path) -> list[SuiteEntry]:
    """The 13 archetypes' files of bigcbf/scenarios/francis2023/ (family: the archetype, split: francis2023)."""
    from . import francis2023
    return [SuiteEntry(str(path), francis2023.SPLIT, name) for name, path in francis2023.files().items()]


SUITES.add(Suite(
    "francis2023", "the 13 social-navigation archetypes of Francis et al. 2023 (Fig. 7 a-f, i-o, as robot_sf maps "
    "them) at the X3's scale (bigcbf/scenarios/francis2023/), one person each, 30 paired seeds; success per "
    "archetype", _francis2023, default_seeds=30))
