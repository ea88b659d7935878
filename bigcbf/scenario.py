"""Scenario files (scenarios/*.toml): loading, validation, and the paired world a seed draws.

A scenario file holds the robot's start and goal, the time limit, walls, static obstacles, pedestrians, floor
patches, robot-profile overrides and a description of the design. The robot is a registered robot folder
(``model = "NAME"`` in ``[robot]``, ``bigcbf/robots.py``; default ``rosmaster_x3``), and its imperfections and
sensors are its default profile: for the X3 ``bigcbf/profiles/x3_sim.toml`` (latency, execution gain and bias,
residuals, lateral slip, LiDAR, encoder and gyro noise) unless the file names another base profile with
``robot_profile_base`` (a shipped profile's name, e.g. ``x3_hardware``, or a TOML path relative to the scenario
file); its ``[robot_profile]`` table overrides keys of that base (nested tables such as ``[robot_profile.lidar]`` key by key). Any number in the file may instead be a
random range that each seed draws from:

    speed_mps = { uniform = [0.8, 1.3] }      # uniform in [lo, hi]
    start_time_s = { choice = [0.0, 1.5] }    # one of the values

Draws are made in the file's order from a generator seeded by (seed, scenario name) only, so every method sees the
same world for the same seed ("paired" episodes). ``draws_as = "NAME"`` seeds them with another name instead: a
variant of a scene (the ``faults`` bench suite's files) then draws the same worlds as the scene, provided its
ranges come in the same order. Unknown keys and bad values raise UserError naming the file and the field (e.g.
``pedestrians[1].speed_mps``).

Faults (every one off by default; keys, units and ranges in ``bigcbf/params/faults.py``): robot and sensor faults
in the robot profile's ``[faults]``, ``[lidar]``, ``[odometry]`` and ``[imu]`` tables (a scenario sets them in
``[robot_profile.faults]`` etc.), and per pedestrian sudden stops and turns::

    [[pedestrians]]
    ...
    stop = { times_s = [4.0], duration_s = 2.0 }          # and/or rate_per_s: random stops, Poisson
    turn = { rate_per_s = 0.1, duration_s = 1.5, angle_deg = 180.0 }   # 180: turns back; random_side = true

Limits (documented caps, so that no file can hang or crash the simulator): ``time_limit_s`` <= 600 s; every
coordinate within +-1000 m (``WORLD_LIMIT_M``) and ``extent_m`` in (0, 1000]; sizes > 0 and at most 1000 m;
obstacle heights in [0.1, 100] m (``MIN_OBSTACLE_HEIGHT_M``: a lower one would pass under the robot's bumper);
at most 200 pedestrians, 1000 walls, boxes and cylinders together, 100 floor patches and 1000 waypoints per
pedestrian. A ``uniform`` range takes finite bounds whose difference is finite.

Geometry is checked when a seed's world is drawn (``check_geometry``): the robot's collision outline (0.30 x 0.20
m, see ``sim/truth.py``) at the start pose must be clear of every wall, box, cylinder and pedestrian (pedestrians
where they stand at t = 0), and the robot must fit somewhere in the goal region (within 0.15 m of the goal, the
Table I goal tolerance) clear of walls, boxes and cylinders, at some heading; pedestrians' paths may cross the
goal. Errors name the field and the obstacle (e.g. ``robot.start`` overlaps ``walls[2]``).
"""
from __future__ import annotations

import math
import re
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from . import PROFILES, SCENARIOS, robots
from .errors import FieldError, UserError
from .params.checks import REQUIRED, check_field_ranges, ranged
from .params.faults import EventSchedule, PedestrianTurn
from .params.robot import RobotProfile, merge_tables
from .params.toml_io import from_dict, load_toml, parse_toml
from .sim.scene import Box, Cylinder, FloorPatch, PedestrianBody, SceneSpec, Wall
from .sim.truth import MIN_OBSTACLE_HEIGHT_M

from .limits import MAX_TIME_LIMIT_S, MIN_TIME_LIMIT_S   # noqa: E402 -- the episode's shortest and longest [s]
WORLD_LIMIT_M = 1000.0            # every coordinate and size within +-this [m]
MAX_HEIGHT_M = 100.0              # tallest obstacle [m]
MAX_PEDESTRIANS = 200
MAX_STATIC_OBSTACLES = 1000      # walls, boxes and cylinders together
MAX_FLOOR_PATCHES = 100
MAX_WAYPOINTS = 1000             # per pedestrian
GOAL_REGION_M = 0.15             # radius of the goal region the geometry check uses (Table I's eps_g)

XY = tuple[float, float]

#: a scenario's or a pedestrian's name: a letter, digit or underscore, then those, '.' or '-' (at most 100): never a
#: path separator, a space or a control character (names reach file names, MJCF bodies and XML)
NAME_RE = re.compile(r"\w[\w.-]{0,99}")


def check_name(name, what: str) -> None:
    """A FieldError ("name") unless ``name`` is a plain identifier-like string (:data:`NAME_RE`)."""
    if not isinstance(name, str) or not NAME_RE.fullmatch(name):
        shown = repr(name)[:60]
        raise FieldError("name", f"{what} name must be letters, digits, '_', '.' or '-' (starting with a letter, "
                                 f"digit or '_', at most 100; no '/', spaces or control characters), got {shown}")


def _in_world(name: str, *points) -> None:
    for xy in points:
        if max(abs(xy[0]), abs(xy[1])) > WORLD_LIMIT_M:
            raise FieldError(name, f"must lie within +-{WORLD_LIMIT_M:g} m, got {tuple(xy)}")


def _sizes(name: str, *values: float) -> None:
    if not all(0 < v <= WORLD_LIMIT_M for v in values):
        raise FieldError(name, f"must be > 0 and <= {WORLD_LIMIT_M:g} m, got {', '.join(f'{v:g}' for v in values)}")


def _height(h: float) -> None:
    if not MIN_OBSTACLE_HEIGHT_M <= h <= MAX_HEIGHT_M:
        raise FieldError("height_m", f"must be in [{MIN_OBSTACLE_HEIGHT_M:g}, {MAX_HEIGHT_M:g}] m, got {h:g} (a "
                                     "lower obstacle would pass under the robot's bumper)")


@dataclass(frozen=True)
class RobotSpec:
    start: tuple[float, float, float]        # x [m], y [m], yaw [rad] in odom
    goal: XY                                 # x, y [m]
    model: str = robots.DEFAULT_ROBOT        # the robot: a registered robot folder (bigcbf/robots.py)

    def __post_init__(self):
        try:
            robots.check_robot_name(self.model)
        except ValueError as exc:
            raise FieldError("model", str(exc)) from None
        _in_world("start", self.start[:2])
        _in_world("goal", self.goal)
        if abs(self.start[2]) > 100.0:
            raise FieldError("start", "the start yaw must be within +-100 rad")


@dataclass(frozen=True)
class WallSpec:
    start: XY
    end: XY
    thickness_m: float = ranged(0.10, 0, WORLD_LIMIT_M, lo_open=True)
    height_m: float = ranged(0.60, MIN_OBSTACLE_HEIGHT_M, MAX_HEIGHT_M)

    def __post_init__(self):
        check_field_ranges(self)
        if self.start == self.end:
            raise FieldError("end", "a wall needs distinct start and end points")
        _in_world("start", self.start)
        _in_world("end", self.end)
        _sizes("thickness_m", self.thickness_m)
        _height(self.height_m)


@dataclass(frozen=True)
class BoxSpec:
    center: XY
    half_size: XY = ranged(REQUIRED, 0, WORLD_LIMIT_M, lo_open=True)
    yaw_rad: float = ranged(0.0, -100, 100)
    height_m: float = ranged(0.60, MIN_OBSTACLE_HEIGHT_M, MAX_HEIGHT_M)

    def __post_init__(self):
        check_field_ranges(self)
        _in_world("center", self.center)
        _sizes("half_size", *self.half_size)
        _height(self.height_m)


@dataclass(frozen=True)
class CylinderSpec:
    center: XY
    radius_m: float = ranged(REQUIRED, 0, WORLD_LIMIT_M, lo_open=True)
    height_m: float = ranged(0.60, MIN_OBSTACLE_HEIGHT_M, MAX_HEIGHT_M)

    def __post_init__(self):
        check_field_ranges(self)
        _in_world("center", self.center)
        _sizes("radius_m", self.radius_m)
        _height(self.height_m)


@dataclass(frozen=True)
class PedestrianSpec:
    name: str
    waypoints: tuple[XY, ...]                # the path, from its first point
    speed_mps: float = ranged(REQUIRED, 0, 3, lo_open=True)
    start_time_s: float = ranged(0.0, 0, MAX_TIME_LIMIT_S)  # stands at the first waypoint until then
    radius_m: float = ranged(0.25, 0.1, 0.6)
    loop: bool = False                       # back to the first waypoint after the last (else stop there)
    reactive: bool = True                    # avoids the robot (social force); False: ignores it
    stop: EventSchedule = EventSchedule()   # sudden stops (bigcbf/params/faults.py); none by default
    turn: PedestrianTurn = PedestrianTurn()  # sudden turns / reversals; none by default

    def __post_init__(self):
        check_name(self.name, "a pedestrian's")
        check_field_ranges(self)
        if not 2 <= len(self.waypoints) <= MAX_WAYPOINTS:
            raise FieldError("waypoints", f"a pedestrian needs at least 2 waypoints (at most {MAX_WAYPOINTS})")
        _in_world("waypoints", *self.waypoints)
        if not (0 < self.speed_mps <= 3.0):
            raise FieldError("speed_mps", "must be in (0, 3] m/s")
        if not (0.1 <= self.radius_m <= 0.6):
            raise FieldError("radius_m", "must be in [0.1, 0.6] m")
        if self.start_time_s < 0:
            raise FieldError("start_time_s", "must be >= 0")


@dataclass(frozen=True)
class FloorPatchSpec:
    center: XY
    half_size: XY = ranged(REQUIRED, 0, WORLD_LIMIT_M, lo_open=True)
    friction: float = ranged(REQUIRED, 0, 5, lo_open=True)

    def __post_init__(self):
        check_field_ranges(self)
        if not (0 < self.friction <= 5):
            raise FieldError("friction", "must be in (0, 5]")
        _in_world("center", self.center)
        _sizes("half_size", *self.half_size)


@dataclass(frozen=True)
class Scenario:
    """One scenario as drawn for one seed (the file's ranges resolved)."""
    name: str
    description: str
    time_limit_s: float = ranged(REQUIRED, MIN_TIME_LIMIT_S, MAX_TIME_LIMIT_S)
    robot: RobotSpec
    extent_m: float = ranged(6.0, 0, WORLD_LIMIT_M, lo_open=True)  # half-size of the area shown in videos (m)
    walls: tuple[WallSpec, ...] = ()
    boxes: tuple[BoxSpec, ...] = ()
    cylinders: tuple[CylinderSpec, ...] = ()
    pedestrians: tuple[PedestrianSpec, ...] = ()
    floor_patches: tuple[FloorPatchSpec, ...] = ()
    robot_profile: RobotProfile = RobotProfile()   # the base profile with the file's overrides (set by the loader)
    dynamic: bool = False                    # informational: has moving people (set from pedestrians)
    file: str = field(default="", compare=False)
    seed: int = 0
    robot_profile_base: str = field(default="", compare=False)   # the base profile's file (set by the loader)

    def __post_init__(self):
        check_name(self.name, "a scenario's")
        check_field_ranges(self)
        if not MIN_TIME_LIMIT_S <= self.time_limit_s <= MAX_TIME_LIMIT_S:
            raise FieldError("time_limit_s", f"must be in [{MIN_TIME_LIMIT_S:g}, {MAX_TIME_LIMIT_S:g}] s, got "
                             f"{self.time_limit_s:g}")
        if not 0 < self.extent_m <= WORLD_LIMIT_M:
            raise FieldError("extent_m", f"must be in (0, {WORLD_LIMIT_M:g}] m, got {self.extent_m:g}")
        for what, items, cap in (("pedestrians", self.pedestrians, MAX_PEDESTRIANS),
                                 ("walls", self.walls + self.boxes + self.cylinders, MAX_STATIC_OBSTACLES),
                                 ("floor_patches", self.floor_patches, MAX_FLOOR_PATCHES)):
            if len(items) > cap:
                raise FieldError(what, f"at most {cap} {'walls, boxes and cylinders' if what == 'walls' else what}"
                                       f" in a scenario, got {len(items)}")
        names = [p.name for p in self.pedestrians]
        if len(set(names)) != len(names):
            raise FieldError("pedestrians", "pedestrian names must be unique")

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
            goal=self.robot.goal, robot_start=self.robot.start, extent=self.extent_m, robot=self.robot.model)


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
                        or not all(math.isfinite(x) for x in lo_hi)
                        or not math.isfinite(float(lo_hi[1]) - float(lo_hi[0])) or not lo_hi[0] <= lo_hi[1]):
                    raise UserError("'uniform' takes [lo, hi] with finite lo <= hi (and hi - lo finite), got "
                                    f"{lo_hi!r}", file=file, field=path)
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

#: the robot profile every scenario starts from unless it names another (``robot_profile_base``)
DEFAULT_ROBOT_PROFILE = "x3_sim"


def profile_files() -> dict[str, Path]:
    """The robot profiles shipped in bigcbf/profiles/ and in each robot folder's profiles/, by name (the file
    stem; bigcbf/profiles/ first)."""
    out: dict[str, Path] = {}
    for folder in (PROFILES, *robots.profile_folders()):
        for p in sorted(folder.glob("*.toml")):
            out.setdefault(p.stem, p)
    return out


def default_profile(raw: dict) -> str:
    """The base robot profile of a scenario file that names none: its robot's (``[robot] model``; an unknown
    robot falls back to the X3's, and the Scenario's validation reports the robot)."""
    model = raw["robot"].get("model") if isinstance(raw.get("robot"), dict) else None
    return robots.ROBOTS[model].profile if isinstance(model, str) and model in robots.ROBOTS \
        else DEFAULT_ROBOT_PROFILE


def robot_profile_path(ref: str, scenario_file: str | Path | None = None) -> Path:
    """A base robot profile: a shipped profile's name, or a TOML path (relative to the scenario file's folder)."""
    shipped = profile_files()
    if ref in shipped:
        return shipped[ref]
    p = Path(ref)
    if not p.is_absolute() and scenario_file is not None:
        p = Path(scenario_file).parent / p
    if p.suffix != ".toml" or not p.is_file():
        raise UserError(f"no robot profile {ref!r}: neither a shipped profile ({', '.join(shipped)}) nor a .toml "
                        "file", file=None if scenario_file is None else str(scenario_file), field="robot_profile_base")
    return p


def robot_profile_table(path: str | Path, text: str | None = None) -> dict:
    """A robot-profile file's table, validated as a RobotProfile (errors name that file and the field); ``text``
    instead of reading the file (the bench ships profiles as text)."""
    data = load_toml(path) if text is None else parse_toml(text, str(path))
    from_dict(RobotProfile, data, file=str(path))
    return data


def load_robot_profile(name_or_file: str | Path = DEFAULT_ROBOT_PROFILE) -> RobotProfile:
    """A robot profile by shipped name (``x3_sim``, ``x3_hardware``) or path."""
    path = robot_profile_path(str(name_or_file))
    return from_dict(RobotProfile, robot_profile_table(path), file=str(path))


def scenario_files(folder: str | None = None) -> dict[str, Path]:
    """The scenarios shipped in scenarios/ (the paper's nine), or in one of its sub-folders (``hardware``), by name
    (the file stem)."""
    root = SCENARIOS if folder is None else SCENARIOS / folder
    return {p.stem: p for p in sorted(root.glob("*.toml"))}


def all_scenario_files() -> dict[str, Path]:
    """Every shipped scenario, sub-folders included, by name (names are unique across folders)."""
    out = {}
    for p in sorted(SCENARIOS.rglob("*.toml")):
        out.setdefault(p.stem, p)
    return out


def resolve_path(name_or_file: str | Path) -> Path:
    """A shipped scenario's name (the nine of scenarios/ or those of its sub-folders, e.g. the hardware scenes),
    or a path to a .toml file anywhere."""
    s = str(name_or_file)
    files = all_scenario_files()
    if s in files:
        return files[s]
    p = Path(s)
    if p.suffix == ".toml" or p.exists() or "/" in s:
        if not p.is_file():
            raise UserError("scenario file not found", file=str(p))
        return p
    raise UserError(f"unknown scenario {s!r}; known: {', '.join(files)} (or give a path to a .toml file)")


def load_scenario(name_or_file: str | Path, seed: int = 0, *, robot_profile_text: str | None = None) -> Scenario:
    """Load a scenario and draw its world for ``seed``. ``robot_profile_text``: the base robot profile's TOML
    text, instead of reading the file the scenario refers to (the bench ships it with the task)."""
    path = resolve_path(name_or_file)
    return scenario_from_dict(load_toml(path), path, seed, robot_profile_text=robot_profile_text)


def parse_scenario(text: str, file: str | Path = "<text>", seed: int = 0) -> Scenario:
    """The Scenario a scenario file's TOML ``text`` describes, drawn for ``seed``, as :func:`load_scenario` reads
    it (``file`` names it in errors and locates a relative ``robot_profile_base``)."""
    return scenario_from_dict(parse_toml(text, str(file)), Path(file), seed)


def _robot_folder_near_file(raw: dict, path: Path) -> None:
    """A relative ``[robot] model`` that is not a registered robot names a robot folder relative to the scenario
    file's folder, as a relative ``robot_profile_base`` does (not to the working directory, so one file means one
    robot wherever it is run from): rewritten in ``raw`` to that path, which RobotSpec then checks (an unknown
    robot's message names the path it looked at). A bare name that is no folder beside the file is left as it is:
    a registered robot's name mistyped, which RobotSpec reports with the known names."""
    rob = raw.get("robot")
    model = rob.get("model") if isinstance(rob, dict) else None
    if not isinstance(model, str) or model in robots.ROBOTS or not model.strip() or Path(model).is_absolute():
        return
    near = path.parent / model
    if len(Path(model).parts) > 1 or model.startswith(".") or robots.robot_folder_path(str(near)) is not None:
        rob["model"] = str(near)


def scenario_from_dict(raw: dict, path: Path, seed: int = 0, *, robot_profile_text: str | None = None) -> Scenario:
    """The Scenario of a scenario file's parsed TOML ``raw`` (read from ``path``), drawn for ``seed``."""
    for reserved in ("file", "seed", "dynamic"):
        if reserved in raw:
            raise UserError("unknown key (set by the loader, not by the file)", file=str(path), field=reserved)
    name = raw.get("name", path.stem)
    if not isinstance(name, str):
        raise UserError("expected a string", file=str(path), field="name")
    try:
        check_name(name, "a scenario's")
    except FieldError as exc:
        hint = "" if "name" in raw else " (the file sets no name, so its file name is used: set name = \"...\")"
        raise UserError(f"{exc}{hint}", file=str(path), field="name") from None
    draws_as = raw.pop("draws_as", name)
    if not isinstance(draws_as, str) or not draws_as:
        raise UserError("expected a scenario name (a non-empty string)", file=str(path), field="draws_as")
    _robot_folder_near_file(raw, path)
    base_ref = raw.pop("robot_profile_base", default_profile(raw))
    if not isinstance(base_ref, str):
        raise UserError("expected a string (a shipped profile's name or a .toml path)", file=str(path),
                        field="robot_profile_base")
    base_path = robot_profile_path(base_ref, path) if robot_profile_text is None else Path(base_ref)
    base = robot_profile_table(base_path, robot_profile_text)
    data = _resolve(raw, scenario_rng(draws_as, seed), str(path), "")
    data.setdefault("name", name)
    over = data.get("robot_profile", {})
    if not isinstance(over, dict):
        raise UserError(f"expected a table, got {over!r}", file=str(path), field="robot_profile")
    data["robot_profile"] = merge_tables(base, over)
    sc = from_dict(Scenario, data, file=str(path))
    if not sc.description.strip():
        raise UserError("describe the scenario's design", file=str(path), field="description")
    check_geometry(sc, str(path))
    return replace(sc, file=str(path), seed=int(seed), dynamic=bool(sc.pedestrians),
                   robot_profile_base=str(base_path))


def base_profile_text(name_or_file: str | Path) -> tuple[Path, str]:
    """The base robot profile a scenario file refers to: its path and text (for the bench's episode key)."""
    path = resolve_path(name_or_file)
    raw = load_toml(path)
    ref = raw.get("robot_profile_base", default_profile(raw))
    if not isinstance(ref, str):
        raise UserError("expected a string (a shipped profile's name or a .toml path)", file=str(path),
                        field="robot_profile_base")
    p = robot_profile_path(ref, path)
    try:
        return p, p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read the robot profile ({exc})", file=str(p)) from None


def check_geometry(sc: Scenario, file: str | None = None) -> None:
    """The start pose free for the robot's collision outline and a goal region it fits in (module docstring);
    a UserError naming the field (robot.start, robot.goal) and the obstacle otherwise."""
    from .sim.truth import Clearance

    scene = sc.scene()
    clear = Clearance(scene)
    x, y, yaw = sc.robot.start
    static = clear.static_distances(x, y, yaw)
    peds = np.array([p.waypoints[0] for p in sc.pedestrians], float).reshape(-1, 2)
    moving = clear.pedestrian_distances(x, y, yaw, peds)
    for dist, names in ((static, clear.names), (moving, [f"pedestrians[{k}]" for k in range(len(peds))])):
        if len(dist) and dist.min() <= 0.0:
            k = int(np.argmin(dist))
            raise UserError(f"the robot ({2 * clear.outline.half_x:.2f} x {2 * clear.outline.half_y:.2f} m at the "
                            f"start pose) overlaps {names[k]} by {-dist[k]:.3f} m; move the start or the obstacle",
                            file=file, field="robot.start")
    if not len(static):
        return
    gx, gy = sc.robot.goal
    # the robot's centre anywhere within GOAL_REGION_M of the goal (the goal, two rings), at one of 8 headings
    centres = [(gx, gy)] + [(gx + r * math.cos(a), gy + r * math.sin(a)) for r in (0.5 * GOAL_REGION_M, GOAL_REGION_M)
                            for a in np.linspace(0, 2 * math.pi, 12, endpoint=False)]
    best = -math.inf
    for cx, cy in centres:
        for heading in np.linspace(0, math.pi, 8, endpoint=False):
            d = clear.static_distances(cx, cy, heading).min()
            if d > 0:
                return
            best = max(best, d)
    k = int(np.argmin(clear.static_distances(gx, gy, yaw)))
    raise UserError(f"the robot does not fit anywhere in the goal region ({GOAL_REGION_M:g} m around the goal): "
                    f"{clear.names[k]} covers it", file=file, field="robot.goal")


def describe(path: Path) -> str:
    """The first sentence of a scenario's description (for ``bigcbf scenarios``)."""
    raw = load_toml(path)
    text = " ".join(str(raw.get("description", "")).split())
    return text.split(". ")[0].rstrip(".") + "." if text else ""
