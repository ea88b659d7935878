"""The world families' registry and what turns a family's draw into a scenario file: :func:`generate` (seeded by
the family's name and the seed), the TOML writer (:func:`toml_value`, also the faulted scenes' writer in
``bigcbf.bench.faults``), :func:`write` and the ``generated`` bench suite's worlds (:func:`suite_worlds`).

A family is a :class:`Family` registered in :data:`FAMILIES` by its own module in this package (``FAMILIES.add``);
its metadata: the name (written once, there), a one-line summary, its design, the ranges of its drawn parameters, its
builder, its place in listings and its splits (the generated suite's world seeds, by split name; the splits are
its registry tags).
"""
from __future__ import annotations

import json
import re
import textwrap
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import UserError
from ..registry import Registry
from .geometry import (CLEARANCE_M, PLAN_SPEED_MPS, ROBOT_RADIUS_M, SLACK_PER_PEDESTRIAN_S, SLACK_S, CheckResult,
                       Draft, _r, check, time_limit)

GENERATOR_VERSION = 1
MAX_ATTEMPTS = 400

#: The generated suite's splits unless a family sets its own: world seeds per split (disjoint). Tune on dev; report
#: test.
SPLITS: dict[str, range] = {"dev": range(0, 30), "test": range(1000, 1030)}


@dataclass(frozen=True)
class Family:
    name: str
    summary: str                     # one line
    design: str                      # the family's design, the start of each world's description
    ranges: tuple[str, ...]          # the drawn parameters and their ranges (for --list)
    build: Callable[[np.random.Generator], Draft]
    order: float = 100.0             # its place in listings and in the generated suite (then by name)
    #: the generated suite's world seeds of this family, by split (default: :data:`SPLITS`)
    splits: dict[str, range] = field(default_factory=lambda: dict(SPLITS))

    @property
    def tags(self) -> tuple[str, ...]:
        """Its registry tags: the names of its splits."""
        return tuple(self.splits)


#: name -> Family, in listing order (each family's module adds itself; the package imports them all)
FAMILIES: Registry[Family] = Registry("world family")


# --- generating and writing -------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class World:
    family: str
    seed: int
    name: str
    draft: Draft
    path_length_m: float
    time_limit_s: float
    attempts: int
    toml: str


def family(name: str) -> Family:
    if name not in FAMILIES:
        raise UserError(f"unknown world family {name!r}; known: {', '.join(FAMILIES)}")
    return FAMILIES[name]


def world_name(family_name: str, seed: int) -> str:
    return f"{family_name}_{int(seed):05d}"


def generate(family_name: str, seed: int) -> World:
    """The world of ``family_name`` for ``seed``: the first draw of the family's generator (seeded by the family
    name and ``seed`` only) that passes :func:`check` and its family's own requirement."""
    fam = family(family_name)
    if int(seed) < 0:
        raise UserError(f"--seed must be >= 0, got {seed}")
    rng = np.random.default_rng([int(seed), zlib.crc32(fam.name.encode()), GENERATOR_VERSION])
    reasons: dict[str, int] = {}
    for attempt in range(1, MAX_ATTEMPTS + 1):
        d = fam.build(rng)
        res = check(d)
        if res.ok:
            limit = time_limit(res.path_length_m, len(d.pedestrians))
            why = d.requirement(d, limit) if d.requirement else None
            if why is None:
                name = world_name(fam.name, seed)
                text = _toml(fam, int(seed), name, d, res, limit, attempt)
                return World(fam.name, int(seed), name, d, res.path_length_m, limit, attempt, text)
            res = CheckResult(False, why)
        reasons[res.reason] = reasons.get(res.reason, 0) + 1
    raise RuntimeError(f"{fam.name} seed {seed}: no valid world in {MAX_ATTEMPTS} draws ({reasons})")


def _extent(d: Draft) -> float:
    """Half-size of the top view (4:3 frame, orthographic height 2.1 extent) that shows the whole region."""
    xmin, xmax, ymin, ymax = d.bounds
    cx, cy = (d.start[0] + d.goal[0]) / 2, (d.start[1] + d.goal[1]) / 2
    ax = max(cx - xmin, xmax - cx) + 0.3
    ay = max(cy - ymin, ymax - cy) + 0.3
    return _r(max(ax / 1.4, ay / 1.05), 2)


def toml_key(k: str) -> str:
    """A TOML key: bare when it can be, else quoted."""
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def toml_value(v) -> str:
    """One inline TOML value of the scenario files' schema: bool, number, string, (nested) array, inline table (the
    generated worlds here; the faulted scenes of ``bigcbf.bench.faults``)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)          # a JSON string is a valid TOML basic string
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{toml_key(k)} = {toml_value(x)}" for k, x in v.items()) + " }"
    raise TypeError(f"cannot write {type(v).__name__} to a scenario file")


_value = toml_value


def _toml(fam: Family, seed: int, name: str, d: Draft, res: CheckResult, limit: float, attempts: int) -> str:
    params = "; ".join(f"{k}: {v}" for k, v in d.params.items())
    n_p = len(d.pedestrians)
    paragraphs = [
        f"Procedural world of the {fam.name} family ({fam.summary}), seed {seed}. {fam.design}",
        f"This world: {params}.",
        f"Generated by `bigcbf scenarios generate {fam.name} --seed {seed}` (generator version {GENERATOR_VERSION}, "
        f"draw {attempts}). Checked at generation: a path of {res.path_length_m:.2f} m keeps a {ROBOT_RADIUS_M:.2f} m "
        f"robot {CLEARANCE_M:.2f} m clear of all static geometry, also with every pedestrian standing where it "
        f"waits and where it stops; the narrowest passage on the widest route is {res.passage_m:.2f} m wide. Time limit: {res.path_length_m:.2f} m / {PLAN_SPEED_MPS} m/s + {SLACK_S:.0f} s + "
        f"{SLACK_PER_PEDESTRIAN_S} s x {n_p} pedestrian{'s' if n_p != 1 else ''}, rounded up: {limit:.0f} s."]
    description = "\n\n".join("\n".join(textwrap.wrap(p, 116)) for p in paragraphs)
    lines = [f"# {name}: generated by `bigcbf scenarios generate {fam.name} --seed {seed}` "
             f"(bigcbf world generator version {GENERATOR_VERSION}); run it with `bigcbf run FILE`.",
             f"name = {_value(name)}", 'description = """', description, '"""',
             f"time_limit_s = {_value(limit)}", f"extent_m = {_value(_extent(d))}", "", "[robot]",
             f"start = {_value([_r(v, 4) for v in d.start])}", f"goal = {_value(list(d.goal))}"]
    for key in ("walls", "boxes", "cylinders", "pedestrians"):
        for item in getattr(d, key):
            lines += ["", f"[[{key}]]"] + [f"{k} = {_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


def parse(text: str, file: str = "<generated>"):
    """The Scenario a generated TOML text describes (as load_scenario reads it, seed 0)."""
    from ..scenario import parse_scenario
    return parse_scenario(text, file, 0)


def write(world: World, path: Path) -> bool:
    """Write the world's TOML to ``path`` unless it already holds exactly that text; True if written."""
    path = Path(path)
    try:
        if path.read_text() == world.toml:
            return False
    except (OSError, UnicodeDecodeError):
        pass
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(world.toml)
    return True


#: The generated suite's splits: world seeds per family (disjoint). Tune on dev; report test.

def split_names() -> tuple[str, ...]:
    """The generated suite's splits: every split some family has, in the order the families name them."""
    out: list[str] = []
    for fam in FAMILIES.values():
        out += [s for s in fam.splits if s not in out]
    return tuple(out)


def suite_worlds(out: Path, splits=None) -> list[tuple[Path, str, str]]:
    """Write the generated suite's worlds into ``out/worlds/<split>/`` (only files whose text changed) and
    return (path, split, family) in an interleaved order (seed by seed, every family that has the split), so that
    a bench that is stopped part-way has covered all families evenly."""
    entries = []
    for split in (splits or split_names()):
        entries += _write_interleaved(out, split, {name: list(fam.splits.get(split, ()))
                                                   for name, fam in FAMILIES.items()})
    return entries


def _write_interleaved(out: Path, split: str, seeds: dict[str, list[int]]) -> list[tuple[Path, str, str]]:
    """Write each family's worlds at its seeds into ``out/worlds/<split>/``, seed by seed across the families."""
    out = Path(out)
    entries = []
    for k in range(max(map(len, seeds.values()), default=0)):
        for fam in FAMILIES:
            if k < len(seeds[fam]):
                w = generate(fam, seeds[fam][k])
                p = out / "worlds" / split / f"{w.name}.toml"
                write(w, p)
                entries.append((p, split, fam))
    return entries


#: The split label of worlds drawn at seeds a bench is given (``bigcbf bench --world-seeds``): seeds of no family's
#: splits, so worlds nobody tuned on or reported before.
FRESH = "fresh"


def check_fresh_seeds(seeds) -> None:
    """Refuse world seeds that are seeds of a registered family's split (a UserError naming the first one): fresh
    worlds are the ones nobody tuned on or looked at; the splits' worlds are run with ``--split``."""
    taken = set(seeds)
    for name, fam in FAMILIES.items():
        for split, rng in fam.splits.items():
            hit = sorted(taken.intersection(rng))
            if hit:
                raise UserError(f"world seed {hit[0]} is a seed of the {split} split of the family {name} (seeds "
                                f"{rng.start}-{rng.stop - 1}); fresh worlds need other seeds, or run that split "
                                f"with --split {split}", field="world_seeds")


def fresh_worlds(out: Path, seeds) -> list[tuple[Path, str, str]]:
    """Every registered family's worlds at ``seeds`` (checked by :func:`check_fresh_seeds`), written into
    ``out/worlds/fresh/`` as :func:`suite_worlds` writes a split's, with the split label :data:`FRESH`."""
    seeds = list(seeds)
    check_fresh_seeds(seeds)
    return _write_interleaved(out, FRESH, {name: seeds for name in FAMILIES})
