"""Scenes: the robot's MJCF composed with a scenario's geometry by dm_control.mjcf.

Two contact layers (see the robot's MJCF): the ground (floor, floor patches: contype 1 / conaffinity 2) touches
only the robot's rollers; obstacles, walls and pedestrians (contype 4 / conaffinity 8) touch only the robot's
body (chassis, LiDAR, bumper). World geoms never touch each other. Filtering the rollers out of the obstacle layer
keeps MuJoCo's collision pass from testing 48 rollers against every wall (it cost half of each physics step in
walled scenes). Geom groups: 0 floor and floor patches, 1 walls and static obstacles, 2 pedestrians, 3-4 the
robot. The LiDAR sees groups 1-2 only.
"""
from __future__ import annotations

import copy
from collections import OrderedDict
from dataclasses import dataclass, field

import mujoco
import numpy as np
from dm_control import mjcf

from .. import robots

#: the default robot's folder and files (``bigcbf/robots.py``: every robot is a folder; ``SceneSpec.robot`` picks one)
ROBOT_DIR = robots.folder(robots.DEFAULT_ROBOT)
ROBOT_XML = ROBOT_DIR / f"{robots.DEFAULT_ROBOT}.xml"
SCENE_XML = ROBOT_DIR / "scene.xml"

WALL_RGBA = (0.72, 0.70, 0.66, 1.0)
OBSTACLE_RGBA = (0.80, 0.45, 0.20, 1.0)
PEDESTRIAN_RGBA = (0.25, 0.40, 0.85, 1.0)


@dataclass(frozen=True)
class Wall:
    """A straight wall segment from (x0, y0) to (x1, y1)."""
    x0: float
    y0: float
    x1: float
    y1: float
    thickness: float = 0.10
    height: float = 0.60


@dataclass(frozen=True)
class Box:
    x: float
    y: float
    half_x: float
    half_y: float
    yaw: float = 0.0
    height: float = 0.60


@dataclass(frozen=True)
class Cylinder:
    x: float
    y: float
    radius: float
    height: float = 0.60


@dataclass(frozen=True)
class PedestrianBody:
    """A mocap capsule; its motion is set each physics step by the scenario's pedestrian model."""
    name: str
    radius: float = 0.25
    height: float = 1.70
    x: float = 0.0
    y: float = 0.0


@dataclass(frozen=True)
class FloorPatch:
    """A floor region with its own sliding friction (e.g. a slippery patch)."""
    x: float
    y: float
    half_x: float
    half_y: float
    friction: float
    rgba: tuple[float, float, float, float] = (0.30, 0.50, 0.62, 1.0)


@dataclass(frozen=True)
class SceneSpec:
    walls: tuple[Wall, ...] = ()
    boxes: tuple[Box, ...] = ()
    cylinders: tuple[Cylinder, ...] = ()
    pedestrians: tuple[PedestrianBody, ...] = ()
    floor_patches: tuple[FloorPatch, ...] = ()
    floor_friction: float | None = None
    goal: tuple[float, float] | None = None
    robot_start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    extent: float = 6.0
    extras: dict = field(default_factory=dict, compare=False)
    robot: str = robots.DEFAULT_ROBOT      # the registered robot (bigcbf/robots.py) the scene is composed on

    def __post_init__(self):
        robots.folder(self.robot)          # an unknown robot: one UserError listing the known ones


GROUND_CONTACT = dict(contype=1, conaffinity=2)      # touches the robot's rollers
OBSTACLE_CONTACT = dict(contype=4, conaffinity=8)    # touches the robot's body


def _world_geom(parent, ground: bool = False, **kw):
    for k, v in (GROUND_CONTACT if ground else OBSTACLE_CONTACT).items():
        kw.setdefault(k, v)
    return parent.add("geom", **kw)


def compose(spec: SceneSpec) -> mjcf.RootElement:
    """The MJCF scene (the robot's scene.xml: robot + floor; and the scene's geometry) as a dm_control.mjcf element
    tree."""
    root = mjcf.from_path(str(robots.scene_path(spec.robot)))
    wb = root.worldbody
    if spec.floor_friction is not None:
        root.find("geom", "floor").friction = (spec.floor_friction, 0.005, 0.0001)
    ground = root.find("body", "ground")        # the floor's own body (see scene.xml), so floor patches join it
    if spec.floor_patches:      # every roller touching overlapping patches is a contact each: room for them (the
        # arena's size changes no result; 50 overlapping patches overflowed the default 16 MB, a fuzzer's case)
        root.size.memory = f"{16 + 2 * len(spec.floor_patches)}M"
    for k, p in enumerate(spec.floor_patches):
        _world_geom(ground, ground=True, name=f"floor_patch{k}", type="box", size=(p.half_x, p.half_y, 0.0005),
                    pos=(p.x, p.y, 0.0005), friction=(p.friction, 0.005, 0.0001), priority=2, rgba=p.rgba, group=0)
    for k, w in enumerate(spec.walls):
        a, b = np.array([w.x0, w.y0]), np.array([w.x1, w.y1])
        length = float(np.linalg.norm(b - a))
        c = (a + b) / 2
        yaw = float(np.arctan2(*(b - a)[::-1]))
        _world_geom(wb, name=f"wall{k}", type="box", size=(length / 2 + w.thickness / 2, w.thickness / 2, w.height / 2),
                    pos=(c[0], c[1], w.height / 2), euler=(0, 0, yaw), rgba=WALL_RGBA, group=1)
    for k, o in enumerate(spec.boxes):
        _world_geom(wb, name=f"box{k}", type="box", size=(o.half_x, o.half_y, o.height / 2),
                    pos=(o.x, o.y, o.height / 2), euler=(0, 0, o.yaw), rgba=OBSTACLE_RGBA, group=1)
    for k, o in enumerate(spec.cylinders):
        _world_geom(wb, name=f"cylinder{k}", type="cylinder", size=(o.radius, o.height / 2),
                    pos=(o.x, o.y, o.height / 2), rgba=OBSTACLE_RGBA, group=1)
    for p in spec.pedestrians:
        body = wb.add("body", name=f"ped_{p.name}", mocap=True, pos=(p.x, p.y, 0))
        # the capsule's lower sphere is centred on the floor (its lower half is under it, where nothing collides
        # with it): at every height the robot's body and LiDAR reach, the pedestrian has its full radius, the one
        # the clearance metric uses (sim/truth.py)
        half = max((p.height - p.radius) / 2, 0.01)
        _world_geom(body, name=f"ped_{p.name}", type="capsule", size=(p.radius, half), pos=(0, 0, half),
                    rgba=PEDESTRIAN_RGBA, group=2)
    if spec.goal is not None:
        wb.add("site", name="goal", type="cylinder", size=(0.15, 0.002), pos=(*spec.goal, 0.002),
               rgba=(0.1, 0.9, 0.2, 0.6), group=0)
    # cameras: a top-down view over the scene and one that tracks the robot
    cx, cy = spec.robot_start[:2] if spec.goal is None else (np.add(spec.robot_start[:2], spec.goal) / 2)
    wb.add("camera", name="top", pos=(cx, cy, 10.0), euler=(0, 0, 0), fovy=2.1 * spec.extent)
    base = root.find("body", "base_link")
    base.add("camera", name="track", mode="track", pos=(-4.2, 0, 3.9), xyaxes=(0, -1, 0, 0.68, 0, 0.73))
    return root


def build_model(spec: SceneSpec | None = None) -> mujoco.MjModel:
    """Compile the composed scene into an MjModel (dm_control's mjcf.Physics is not used: it fails on mujoco 4)."""
    root = compose(spec or SceneSpec())
    model = mujoco.MjModel.from_xml_string(root.to_xml_string(), assets=root.get_assets())
    # dm_control's schema predates orthographic cameras: switch the top view after compiling (fovy is then the
    # visible height in metres)
    model.cam_projection[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "top")] = \
        mujoco.mjtProjection.mjPROJ_ORTHOGRAPHIC
    return model


#: compiled scenes kept per process (``cached_model``)
MODEL_CACHE_SIZE = 8
_MODEL_CACHE: OrderedDict = OrderedDict()


def _robot_files_stamp(name: str) -> tuple:
    """(path, size, mtime) of every file of the robot's folder: a robot file edited between two episodes of one
    process is compiled anew."""
    out = []
    for f in sorted(robots.folder(name).rglob("*")):
        if f.is_file():
            st = f.stat()
            out.append((str(f), st.st_size, st.st_mtime_ns))
    return tuple(out)


def cached_model(spec: SceneSpec) -> mujoco.MjModel:
    """A copy of ``build_model(spec)``, compiled once per process for the last ``MODEL_CACHE_SIZE`` scenes (issue 26:
    the bench runs every method on each world of a (scenario, seed), and a scene's compilation by dm_control.mjcf
    costs 0.1-0.3 s against under 1 ms for copying its MjModel). The key is the scene's value (``SceneSpec`` is a
    frozen dataclass: every field that ``compose`` reads) and the robot folder's files (path, size, mtime). The
    copy is a deep copy (``MjModel.__copy__``): the caller may change it without touching the cache. The same model,
    so the same episode, bit for bit (tests/sim/test_scene_cache.py)."""
    key = (spec, _robot_files_stamp(spec.robot))
    model = _MODEL_CACHE.get(key)
    if model is None:
        model = build_model(spec)
        _MODEL_CACHE[key] = model
        while len(_MODEL_CACHE) > MODEL_CACHE_SIZE:
            _MODEL_CACHE.popitem(last=False)
    else:
        _MODEL_CACHE.move_to_end(key)
    return copy.copy(model)


def open_room(extent: float = 6.0, walls: bool = True) -> SceneSpec:
    """An open square room (side 2*extent) with walls, for demos and calibration drives."""
    e = extent
    ws = (Wall(-e, -e, e, -e), Wall(e, -e, e, e), Wall(e, e, -e, e), Wall(-e, e, -e, -e)) if walls else ()
    return SceneSpec(walls=ws, extent=e)
