"""The robot registry: a robot is a folder under ``bigcbf/assets/`` (MuJoCo Menagerie's layout), registered here.

A robot folder holds ``NAME.xml`` (the robot's MJCF), ``scene.xml`` (it with a floor and a light), ``README.md``,
``LICENSE``, ``CHANGELOG.md``, the ``generate.py`` that writes the MJCF (checked byte for byte by
``tests/test_robot_folder.py``), and its robot profiles in ``profiles/`` (shipped profile names, found by
``robot_profile_base``; the Rosmaster X3's stay in ``bigcbf/profiles/``, their original place). A scenario picks a
robot with ``model = "NAME"`` in its ``[robot]`` table (default ``rosmaster_x3``).

The MJCF is the one source of the robot's kinematics: :func:`robot` compiles it and reads

- the wheels: the hinge joints driven by the model's actuators, ordered front-left, front-right, rear-left,
  rear-right by their positions in ``base_link`` (the half wheelbase and half track);
- the rolling radius: the rollers' envelope (roller centre distance from the axle + the capsule's radius);
- the Mecanum roller angles: each wheel's roller axis where it touches the floor, which must be the "X" arrangement
  at 45 degrees of ``bigcbf/sim/kinematics.py`` (anything else is refused with one line);
- the wheel speed limit: the actuators' ``ctrlrange``; the per-axis effective scales (measured on the model):
  ``<custom><numeric name="effective_scale">``;
- the collision outline (``sim/truth.outline_from_model``), the ``lidar`` and ``imu`` sites, the display disc
  ``footprint`` (the size the robot suggests for the stack's r_R; see below).

The interface a robot's MJCF provides: a body ``base_link`` with a free joint ``root``; four wheel actuators on
hinge joints of direct children of ``base_link``, whose child bodies carry one capsule roller each; sites
``lidar`` and ``imu`` on ``base_link``; sensors ``imu_gyro``, ``imu_acc``, ``imu_quat``; the contact classes of
``sim/scene.py`` (rollers 2 / 1, body 8 / 4).

r_R: the controller's footprint radius is a stack parameter (paper Table I), not the robot's: a larger robot is run
with ``--config FILE`` whose ``[stack.uncertainty]`` sets ``r_robot_m``; a robot folder may ship such a file
(``stack.toml``, e.g. ``bigcbf/assets/mecanum_large/stack.toml``), and :attr:`Robot.footprint_radius_m` is the
value it suggests (its ``footprint`` site). Nothing applies it silently.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from . import ASSETS
from .errors import UserError


@dataclass(frozen=True)
class RobotEntry:
    """A registry entry: the robot's folder under ``bigcbf/assets/`` and its default robot profile's name."""
    folder: str
    profile: str


#: name -> entry. Adding a robot: its folder, and one line here.
ROBOTS: dict[str, RobotEntry] = {
    "rosmaster_x3": RobotEntry("rosmaster_x3", profile="x3_sim"),
    "mecanum_large": RobotEntry("mecanum_large", profile="mecanum_large_sim"),
}

DEFAULT_ROBOT = "rosmaster_x3"

#: wheel order of the kinematics (bigcbf/sim/kinematics.py) and the quadrant (sign of x, sign of y) of each wheel
WHEEL_ORDER = (("fl", 1, 1), ("fr", 1, -1), ("rl", -1, 1), ("rr", -1, -1))
#: the "X" arrangement: tan of the floor-contact roller axis' angle to the rolling direction, per wheel
X_ROLLER_SLOPES = (-1.0, 1.0, 1.0, -1.0)
#: geometry read from the model is rounded to this many decimals of a metre (the generators write 6 significant
#: digits, so that e.g. the roller envelope 0.0325 + 0.01 reads 0.0425 and not 0.042499999999999996); the roller
#: slopes, from 6-digit axes turned to the floor, to 4 decimals
DECIMALS = 6


def robot_names() -> tuple[str, ...]:
    return tuple(ROBOTS)


def robot_folder_path(name) -> Path | None:
    """``name`` as a robot folder outside the registry (a path to a folder ``D`` holding ``D/<D's name>.xml`` and
    ``D/scene.xml``, as ``bigcbf calibrate --model`` writes one), or None."""
    if not isinstance(name, str) or name in ROBOTS or not name.strip():
        return None
    d = Path(name)
    return d if d.is_dir() and (d / f"{d.resolve().name}.xml").is_file() and (d / "scene.xml").is_file() else None


def check_robot_name(name) -> str:
    """``name`` if it is a registered robot or a robot folder's path, else a ValueError whose message lists the
    known ones."""
    if not isinstance(name, str) or (name not in ROBOTS and robot_folder_path(name) is None):
        shown = str(name) if len(str(name)) <= 80 else "..." + str(name)[-77:]    # a path's end says most
        raise ValueError(f"unknown robot {shown!r}; known: {', '.join(ROBOTS)} (bigcbf/robots.py), or a "
                         "robot folder's path (D/<D>.xml and D/scene.xml)")
    return name


def folder(name: str) -> Path:
    """The robot's folder (``bigcbf/assets/<folder>``, or the folder a path names); an unknown name is a
    UserError."""
    try:
        check_robot_name(name)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    return ASSETS / ROBOTS[name].folder if name in ROBOTS else robot_folder_path(name)


def scene_path(name: str) -> Path:
    """The robot's ``scene.xml`` (the robot with a floor and a light, which ``sim/scene.py`` composes scenes on)."""
    return folder(name) / "scene.xml"


def profile_folders() -> list[Path]:
    """Every registered robot's ``profiles/`` folder that exists."""
    return [p for p in (folder(n) / "profiles" for n in ROBOTS) if p.is_dir()]


@dataclass(frozen=True)
class Robot:
    """A robot as its compiled MJCF describes it (see the module docstring)."""
    name: str
    folder: Path
    xml: Path                       # the robot's MJCF
    scene_xml: Path                 # scene.xml beside it
    profile: str                    # the default robot profile's name
    wheels: tuple[str, ...]         # fl, fr, rl, rr: the wheel joints
    actuators: tuple[str, ...]      # their actuators, same order
    wheel_positions: tuple[tuple[float, float], ...]   # (x, y) of each wheel in base_link [m]
    half_wheelbase_m: float
    half_track_m: float
    wheel_radius_m: float           # the rollers' envelope: the rolling radius
    roller_slopes: tuple[float, ...]   # per wheel, tan of the contact roller's axis angle to the rolling direction
    max_wheel_speed_rad_s: float
    effective_scale: tuple[float, float, float]
    outline: object                 # sim.truth.Outline: the collision outline in base_link
    laser_mount: tuple[float, float, float, float]   # the lidar site: x, y, z above the floor [m], yaw [rad]
    imu_mount: tuple[float, float, float, float]
    footprint_radius_m: float       # the display disc "footprint": the r_R the robot suggests for the stack
    mass_kg: float

    @property
    def kinematics(self):
        """The firmware's Mecanum kinematics of this robot (``bigcbf.sim.kinematics.MecanumKinematics``)."""
        from .sim.kinematics import MecanumKinematics
        return MecanumKinematics(half_wheelbase_m=self.half_wheelbase_m, half_track_m=self.half_track_m,
                                 rolling_radius_m=self.wheel_radius_m,
                                 max_wheel_speed_rad_s=self.max_wheel_speed_rad_s,
                                 effective_scale=self.effective_scale)

    def perception_params(self, params):
        """``params`` (PerceptionParams) with the laser mounting of this robot's ``lidar`` site where ``params``
        keeps the default mounting (``X3_LASER_MOUNT``); a mounting set on purpose (e.g. a miscalibration study in
        ``[perception]``) is kept."""
        from .params.perception import X3_LASER_MOUNT
        if (params.laser_x_m, params.laser_y_m, params.laser_yaw_rad) != X3_LASER_MOUNT:
            return params
        x, y, _, yaw = self.laser_mount
        return replace(params, laser_x_m=x, laser_y_m=y, laser_yaw_rad=yaw)


def _yaw(q) -> float:
    w, x, y, z = q
    return float(math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def _bad(name: str, what: str) -> UserError:
    d = folder(name)
    return UserError(f"robot {name!r}: {what}", file=str(d / f"{name if name in ROBOTS else d.resolve().name}.xml"))


@functools.lru_cache(maxsize=None)
def robot(name: str = DEFAULT_ROBOT) -> Robot:
    """The registered robot ``name``, read from its compiled MJCF (once per process).

    Length: the model's checks in the order their errors are reported, each on the ids the earlier ones found (base and
    root, the wheels, their rollers), then the Robot built from them."""
    import mujoco

    from .sim.truth import outline_from_model
    d = folder(name)
    stem = name if name in ROBOTS else d.resolve().name
    xml = d / f"{stem}.xml"
    if not xml.is_file() or not (d / "scene.xml").is_file():
        raise UserError(f"robot {name!r}: its folder needs {stem}.xml and scene.xml", file=str(d))
    m = mujoco.MjModel.from_xml_path(str(xml))
    obj = mujoco.mjtObj
    base = mujoco.mj_name2id(m, obj.mjOBJ_BODY, "base_link")
    root = mujoco.mj_name2id(m, obj.mjOBJ_JOINT, "root")
    if base < 0 or root < 0 or m.jnt_type[root] != mujoco.mjtJoint.mjJNT_FREE or m.jnt_bodyid[root] != base:
        raise _bad(name, "needs a body 'base_link' with a free joint 'root'")
    r = lambda v: round(float(v), DECIMALS)       # noqa: E731
    wheels = {}
    for a in range(m.nu):
        j = int(m.actuator_trnid[a, 0])
        if m.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT or m.jnt_type[j] != mujoco.mjtJoint.mjJNT_HINGE:
            raise _bad(name, f"actuator {a} does not drive a hinge joint (a wheel)")
        body = int(m.jnt_bodyid[j])
        if m.body_parentid[body] != base:
            raise _bad(name, f"the wheel of actuator {a} is not a child body of base_link")
        x, y = (r(v) for v in m.body_pos[body][:2])
        key = (int(np.sign(x)), int(np.sign(y)))
        if key in wheels or 0 in key:
            raise _bad(name, "needs one wheel in each quadrant of base_link (front/rear x left/right)")
        # the rollers: child bodies of the wheel, each a capsule on a hinge
        env, slopes = [], []
        for c in range(m.nbody):
            if m.body_parentid[c] != body:
                continue
            gs = [g for g in range(m.ngeom) if m.geom_bodyid[g] == c]
            js = [k for k in range(m.njnt) if m.jnt_bodyid[k] == c]
            if len(gs) != 1 or len(js) != 1 or m.geom_type[gs[0]] != mujoco.mjtGeom.mjGEOM_CAPSULE:
                raise _bad(name, f"body {mujoco.mj_id2name(m, obj.mjOBJ_BODY, c)!r}: a roller is one capsule on "
                                 "one hinge")
            p = m.body_pos[c]
            env.append(math.hypot(p[0], p[2]) + float(m.geom_size[gs[0]][0]))
            # the roller axis in the wheel frame, turned about the axle (y) to where the roller meets the floor
            ax = m.jnt_axis[js[0]]
            phi = math.atan2(p[0], p[2])
            th = math.pi - phi
            ex = ax[0] * math.cos(th) + ax[2] * math.sin(th)
            slopes.append(ax[1] / ex if abs(ex) > 1e-9 else math.inf)
        if not env:
            raise _bad(name, f"the wheel of actuator {a} has no rollers")
        wheels[key] = (mujoco.mj_id2name(m, obj.mjOBJ_JOINT, j), mujoco.mj_id2name(m, obj.mjOBJ_ACTUATOR, a),
                       (x, y), r(np.mean(env)), round(float(np.mean(slopes)), 4), float(np.ptp(env)),
                       float(np.ptp(slopes)),
                       float(m.actuator_ctrlrange[a, 1]) if m.actuator_ctrllimited[a] else math.inf)
    if len(wheels) != 4:
        raise _bad(name, f"bigcbf's Mecanum kinematics takes four wheels, the model drives {len(wheels)}")
    ws = [wheels[(sx, sy)] for _, sx, sy in WHEEL_ORDER]
    lx, ly = abs(ws[0][2][0]), abs(ws[0][2][1])
    radii = {w[3] for w in ws}
    if any((abs(w[2][0]), abs(w[2][1])) != (lx, ly) for w in ws) or len(radii) != 1 or \
            max(w[5] for w in ws) > 1e-6 or max(w[6] for w in ws) > 1e-4:
        raise _bad(name, "the wheels must sit at (+-lx, +-ly) with one rolling radius (every roller alike)")
    slopes = tuple(w[4] for w in ws)
    if slopes != X_ROLLER_SLOPES:
        raise _bad(name, f"the rollers must be in the 'X' arrangement at 45 deg (contact-roller slopes "
                         f"{X_ROLLER_SLOPES} for fl, fr, rl, rr), got {slopes}")
    speeds = {w[7] for w in ws}
    if len(speeds) != 1 or not math.isfinite(next(iter(speeds))):
        raise _bad(name, "the four wheel actuators need one ctrlrange (the wheel speed limit)")
    k = mujoco.mj_name2id(m, obj.mjOBJ_NUMERIC, "effective_scale")
    if k < 0 or m.numeric_size[k] != 3:
        raise _bad(name, "needs <custom><numeric name=\"effective_scale\" data=\"kx ky kw\"/> (measured on the model)")
    eff = tuple(float(v) for v in m.numeric_data[m.numeric_adr[k]:m.numeric_adr[k] + 3])
    base_z = float(m.qpos0[m.jnt_qposadr[root] + 2])

    def mount(site: str) -> tuple[float, float, float, float]:
        s = mujoco.mj_name2id(m, obj.mjOBJ_SITE, site)
        if s < 0 or m.site_bodyid[s] != base:
            raise _bad(name, f"needs a site {site!r} on base_link")
        x, y, z = (float(v) for v in m.site_pos[s])
        return x, y, z + base_z, _yaw(m.site_quat[s])

    fp = mujoco.mj_name2id(m, obj.mjOBJ_SITE, "footprint")
    return Robot(name=name, folder=d, xml=xml, scene_xml=d / "scene.xml",
                 profile=ROBOTS[name].profile if name in ROBOTS else ROBOTS[DEFAULT_ROBOT].profile,
                 wheels=tuple(w[0] for w in ws), actuators=tuple(w[1] for w in ws),
                 wheel_positions=tuple(w[2] for w in ws), half_wheelbase_m=lx, half_track_m=ly,
                 wheel_radius_m=radii.pop(), roller_slopes=slopes, max_wheel_speed_rad_s=speeds.pop(),
                 effective_scale=eff, outline=outline_from_model(m), laser_mount=mount("lidar"),
                 imu_mount=mount("imu"), footprint_radius_m=float(m.site_size[fp][0]) if fp >= 0 else math.nan,
                 mass_kg=float(m.body_subtreemass[base]))
