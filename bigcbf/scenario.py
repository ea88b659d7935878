"""Scenario files (scenarios/*.toml): loading, validation, and the paired world a seed draws.

A scenario file holds the robot's start and goal, the time limit, walls, static obstacles, pedestrians, floor
patches, robot-profile overrides and a description of the design. Any number in the file may instead be a
random range that each seed draws from:

    speed_mps = { uniform = [0.8, 1.3] }      # uniform in [lo, hi]
    start_time_s = { choice = [0.0, 1.5] }    # one of the values

Draws are made in the file's order from a generator seeded by (seed, scenario name) only, so every method sees the
same world for the same seed ("paired" episodes). Unknown keys and bad values raise UserError naming the file and
the field (e.g. ``pedestrians[1].speed_mps``).
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from . import SCENARIOS
from .errors import UserError
from .params.robot import RobotProfile
from .params.toml_io import from_dict, load_toml
from .sim.scene import Box, Cylinder, FloorPatch, PedestrianBody, SceneSpec, Wall

XY = tuple[float, float]


@dataclass(frozen=True)
class RobotSpec:
    start: tuple[float, float, float]        # x [m], y [m], yaw [rad] in odom
    goal: XY                                 # x, y [m]


@dataclass(frozen=True)
class WallSpec:
    start: XY
    end: XY
    thickness_m: float = 0.10
    height_m: float = 0.60

    def __post_init__(self):
        if self.start == self.end:
            raise ValueError("a wall needs distinct start and end points")
        if self.thickness_m <= 0 or self.height_m <= 0:
            raise ValueError("thickness_m and height_m must be > 0")


@dataclass(frozen=True)
class BoxSpec:
    center: XY
    half_size: XY
    yaw_rad: float = 0.0
    height_m: float = 0.60

    def __post_init__(self):
        if min(self.half_size) <= 0 or self.height_m <= 0:
            raise ValueError("half_size and height_m must be > 0")


@dataclass(frozen=True)
class CylinderSpec:
    center: XY
    radius_m: float
    height_m: float = 0.60

    def __post_init__(self):
        if self.radius_m <= 0 or self.height_m <= 0:
            raise ValueError("radius_m and height_m must be > 0")


@dataclass(frozen=True)
class PedestrianSpec:
    name: str
    waypoints: tuple[XY, ...]                # the path, from its first point
    speed_mps: float
    start_time_s: float = 0.0                # stands at the first waypoint until then
    radius_m: float = 0.25
    loop: bool = False                       # back to the first waypoint after the last (else stop there)
    reactive: bool = True                    # avoids the robot (social force); False: ignores it

    def __post_init__(self):
        if len(self.waypoints) < 2:
            raise ValueError("a pedestrian needs at least 2 waypoints")
        if not (0 < self.speed_mps <= 3.0):
            raise ValueError("speed_mps must be in (0, 3]")
        if not (0.1 <= self.radius_m <= 0.6):
            raise ValueError("radius_m must be in [0.1, 0.6]")
        if self.start_time_s < 0:
            raise ValueError("start_time_s must be >= 0")


@dataclass(frozen=True)
class FloorPatchSpec:
    center: XY
    half_size: XY
    friction: float

    def __post_init__(self):
        if min(self.half_size) <= 0 or not (0 < self.friction <= 5):
            raise ValueError("half_size must be > 0 and friction in (0, 5]")


@dataclass(frozen=True)
class Scenario:
    """One scenario as drawn for one seed (the file's ranges resolved)."""
    name: str
    description: str
    time_limit_s: float
    robot: RobotSpec
    extent_m: float = 6.0                    # half-size of the area shown in videos (m)
    walls: tuple[WallSpec, ...] = ()
    boxes: tuple[BoxSpec, ...] = ()
    cylinders: tuple[CylinderSpec, ...] = ()
    pedestrians: tuple[PedestrianSpec, ...] = ()
    floor_patches: tuple[FloorPatchSpec, ...] = ()
    robot_profile: RobotProfile = RobotProfile()
    dynamic: bool = False                    # informational: has moving people (set from pedestrians)
    file: str = field(default="", compare=False)
    seed: int = 0

    def __post_init__(self):
        if self.time_limit_s <= 0:
            raise ValueError("time_limit_s must be > 0")
        names = [p.name for p in self.pedestrians]
        if len(set(names)) != len(names):
            raise ValueError("pedestrian names must be unique")

    @property
    def goal(self) -> np.ndarray:
        return np.array(self.robot.goal, float)

    def scene(self) -> SceneSpec:
        """The MuJoCo scene geometry (pedestrians as mocap capsules at their first waypoint)."""
        return SceneSpec(
            walls=tuple(Wall(*w.start, *w.end, w.thickness_m, w.height_m) for w in self.walls),
            boxes=tuple(Box(*b.center, *b.half_size, b.yaw_rad, b.height_m) for b in self.boxes),
            cylinders=tuple(Cylinder(*c.center, c.radius_m, c.height_m) for c in self.cylinders),
            pedestrians=tuple(PedestrianBody(p.name, p.radius_m, 1.7, *p.waypoints[0]) for p in self.pedestrians),
            floor_patches=tuple(FloorPatch(*f.center, *f.half_size, f.friction) for f in self.floor_patches),
            goal=self.robot.goal, robot_start=self.robot.start, extent=self.extent_m)


# --- random ranges -----------------------------------------------------------------------------------------------

def _resolve(node, rng: np.random.Generator, file: str, path: str):
    """Replace every {uniform = [lo, hi]} / {choice = [...]} table by a draw, in document order."""
    if isinstance(node, dict):
        keys = set(node)
        if keys and keys <= {"uniform", "choice"}:
            if len(keys) != 1:
                raise UserError("a random range has exactly one of 'uniform' or 'choice'", file=file, field=path)
            if "uniform" in node:
                lo_hi = node["uniform"]
                if (not isinstance(lo_hi, list) or len(lo_hi) != 2
                        or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in lo_hi)
                        or lo_hi[0] > lo_hi[1]):
                    raise UserError("'uniform' takes [lo, hi] with lo <= hi", file=file, field=path)
                return float(rng.uniform(lo_hi[0], lo_hi[1]))
            options = node["choice"]
            if not isinstance(options, list) or not options:
                raise UserError("'choice' takes a non-empty array", file=file, field=path)
            return _resolve(options[int(rng.integers(len(options)))], rng, file, path)
        return {k: _resolve(v, rng, file, f"{path}.{k}" if path else k) for k, v in node.items()}
    if isinstance(node, list):
        return [_resolve(v, rng, file, f"{path}[{i}]") for i, v in enumerate(node)]
    return node


def scenario_rng(name: str, seed: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), zlib.crc32(name.encode())])


# --- finding and loading ----------------------------------------------------------------------------------------

def scenario_files() -> dict[str, Path]:
    """The scenarios shipped in scenarios/, by name (the file stem)."""
    return {p.stem: p for p in sorted(SCENARIOS.glob("*.toml"))}


def resolve_path(name_or_file: str | Path) -> Path:
    """A scenario name from scenarios/, or a path to a .toml file anywhere."""
    s = str(name_or_file)
    files = scenario_files()
    if s in files:
        return files[s]
    p = Path(s)
    if p.suffix == ".toml" or p.exists() or "/" in s:
        if not p.is_file():
            raise UserError("scenario file not found", file=str(p))
        return p
    raise UserError(f"unknown scenario {s!r}; known: {', '.join(files)} (or give a path to a .toml file)")


def load_scenario(name_or_file: str | Path, seed: int = 0) -> Scenario:
    """Load a scenario and draw its world for ``seed``."""
    path = resolve_path(name_or_file)
    raw = load_toml(path)
    for reserved in ("file", "seed", "dynamic"):
        if reserved in raw:
            raise UserError("unknown key (set by the loader, not by the file)", file=str(path), field=reserved)
    name = raw.get("name", path.stem)
    if not isinstance(name, str):
        raise UserError("expected a string", file=str(path), field="name")
    data = _resolve(raw, scenario_rng(name, seed), str(path), "")
    data.setdefault("name", name)
    sc = from_dict(Scenario, data, file=str(path))
    if not sc.description.strip():
        raise UserError("describe the scenario's design", file=str(path), field="description")
    return replace(sc, file=str(path), seed=int(seed), dynamic=bool(sc.pedestrians))


def describe(path: Path) -> str:
    """The first sentence of a scenario's description (for ``bigcbf scenarios``)."""
    raw = load_toml(path)
    text = " ".join(str(raw.get("description", "")).split())
    return text.split(". ")[0].rstrip(".") + "." if text else ""
