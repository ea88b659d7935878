#!/usr/bin/env python3
"""Writes rosmaster_x3.xml and scene.xml (run from anywhere: ``python bigcbf/assets/rosmaster_x3/generate.py``).

The Mecanum wheels have N passive rollers each; writing 48 roller bodies by hand invites mistakes, so the MJCF
is generated from the few dimensions below (their sources are in README.md beside this file). The generated files
are committed; ``tests/test_robot_folder.py`` checks that this script reproduces them byte for byte, and
``tests/test_robot.py`` pins the model's sizes (nq, nv, nu), so a change here is deliberate.

Other Mecanum bases reuse this generator with their own dimensions (``MecanumBase``): a robot folder's
``generate.py`` imports ``MecanumBase`` and ``write`` from here and passes its own (``assets/mecanum_large``).
The MJCF is the one source of the robot's kinematics for the simulator (``bigcbf/robots.py`` reads the wheel
radius, wheel positions, roller angles, footprint, sensor sites and wheel actuators from the compiled model); the
per-axis effective scales, measured on the model, are its ``<custom><numeric name="effective_scale">``.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class MecanumBase:
    """The dimensions of a four-wheel Mecanum base in the "X" roller arrangement (m, kg, rad/s, N m)."""
    name: str                     # model name, the MJCF file's stem and the robot's default class
    half_wheelbase: float         # wheel axles at x = +-half_wheelbase
    half_track: float             # wheel planes at y = +-half_track
    wheel_radius: float           # outer envelope radius of the rollers (the rolling radius)
    wheel_width: float
    n_rollers: int
    roller_radius: float
    roller_half_len: float        # half-length of the capsule's cylinder; see README (ripple)
    chassis_half: tuple[float, float, float]   # the chassis plate between the wheels
    chassis_z: float              # centre of the plate above the axle plane
    chassis_mass: float
    bumper_half: tuple[float, float, float]    # collision-only box around chassis and wheels (massless)
    bumper_z: float
    battery_half: tuple[float, float, float]
    battery_z: float
    battery_mass: float
    lidar_pos: tuple[float, float, float]      # the LiDAR's optical centre in base_link (above the axle plane)
    lidar_size: tuple[float, float]            # its housing (cylinder radius, half-height)
    lidar_mass: float
    imu_pos: tuple[float, float, float]
    hub_mass: float
    roller_mass: float
    wheel_max_speed: float        # rad/s
    wheel_max_torque: float       # N m at the wheel
    wheel_kv: float               # velocity-servo gain, N m per rad/s of speed error
    wheel_damping: float
    wheel_armature: float
    footprint_radius: float       # the display disc of the site "footprint" (the stack's r_R; not a collision)
    effective_scale: tuple[float, float, float]   # achieved / ideal twist per axis, measured on the model
    chassis_rgba: str = "0.10 0.55 0.25 1"
    extent: float = 1.0           # scene.xml's <statistic extent>


# --- the Rosmaster X3's dimensions (m, kg); sources in README.md --------------------------------------------------
X3 = MecanumBase(
    name="rosmaster_x3",
    half_wheelbase=0.080,         # wheelbase 0.160
    half_track=0.0845,            # track 0.169
    wheel_radius=0.0425,          # axle height 0.0426 in Yahboom's URDF
    wheel_width=0.030,
    n_rollers=12,
    roller_radius=0.0100,
    roller_half_len=0.0125,
    chassis_half=(0.150, 0.062, 0.025),   # 0.30 x 0.124 x 0.05 plate between the wheels; with wheels 0.30 x 0.20
    chassis_z=0.060,              # bottom ~0.035 m above the floor
    chassis_mass=3.60,
    # collision-only box around chassis and wheels (what an obstacle touches first): 0.30 x 0.20 m, from 1.3 cm to
    # 8.3 cm above the floor (the wheels' top)
    bumper_half=(0.150, 0.100, 0.035),
    bumper_z=-0.0005,
    battery_half=(0.06, 0.04, 0.012),
    battery_z=0.023,
    battery_mass=0.35,            # low, central (part of the ~4.6 kg total)
    # URDF laser_joint: 0.0435 m ahead of base_link; 0.1915 m above the floor (0.0815 + 0.11), i.e. 0.149 m above
    # the axle plane. bigcbf.params.perception.X3_LASER_MOUNT (the perception's default mounting) equals it
    # (tests/test_lidar.py)
    lidar_pos=(0.0435, 0.0, 0.149),
    lidar_size=(0.035, 0.02),
    lidar_mass=0.17,
    imu_pos=(-0.06, 0.01, 0.07),  # URDF base_imu
    hub_mass=0.060,
    roller_mass=0.005,
    wheel_max_speed=30.0,         # about 290 rpm at the wheel: 520-class gear motor
    wheel_max_torque=1.0,
    wheel_kv=3.0,                 # stiff geared motor + PID
    wheel_damping=0.002,
    wheel_armature=0.0005,
    footprint_radius=0.15,        # r_R of the paper (Sec. V)
    effective_scale=(0.991, 0.962, 0.998),   # tests/test_robot.py
)


def f(*xs: float) -> str:
    return " ".join(f"{x:.6g}" for x in xs)


def wheels(b: MecanumBase) -> list[tuple[str, float, float, int, float]]:
    """(name, x, y, sigma, phase). sigma = +1/-1 sets the roller handedness so that the inverse kinematics is the
    "X" arrangement documented in bigcbf/sim/kinematics.py. phase shifts a wheel's rollers by that fraction of the
    roller pitch: with every wheel in phase, the roller-contact ripple of the four wheels adds up to a yaw moment
    (X3: 0.11 rad of heading drift after 3 s straight at 0.5 m/s); the diagonal half-pitch offsets below cancel
    most of it (0.02 rad)."""
    lx, ly = b.half_wheelbase, b.half_track
    return [("fl", +lx, +ly, +1, 0.0), ("fr", +lx, -ly, -1, 0.5), ("rl", -lx, +ly, -1, 0.5), ("rr", -lx, -ly, +1, 0.0)]


def roller_bodies(b: MecanumBase, sigma: int, phase: float = 0.0) -> str:
    rc = b.wheel_radius - b.roller_radius
    out = []
    for k in range(b.n_rollers):
        phi = 2 * math.pi * (k + phase) / b.n_rollers
        c = (rc * math.sin(phi), 0.0, rc * math.cos(phi))
        t = (math.cos(phi), 0.0, -math.sin(phi))          # tangent of the rim, direction of increasing phi
        e = [(0.0 + sigma * t[0]) / math.sqrt(2), 1 / math.sqrt(2), sigma * t[2] / math.sqrt(2)]
        out.append(
            f'        <body name="{{w}}_roller{k}" pos="{f(*c)}">\n'
            f'          <joint name="{{w}}_roller{k}" class="roller" axis="{f(*e)}"/>\n'
            f'          <geom class="roller" fromto="{f(*(-b.roller_half_len * x for x in e))} '
            f'{f(*(b.roller_half_len * x for x in e))}"/>\n'
            f'        </body>')
    return "\n".join(out)


def wheel(b: MecanumBase, name: str, x: float, y: float, sigma: int, phase: float = 0.0) -> str:
    rollers = roller_bodies(b, sigma, phase).replace("{w}", name)
    return f"""      <body name="{name}_wheel" pos="{f(x, y, 0)}">
        <joint name="{name}_wheel" class="wheel"/>
        <geom class="hub" name="{name}_hub"/>
        <geom class="hub_visual"/>
{rollers}
      </body>"""


def robot_xml(b: MecanumBase) -> str:
    """The robot's MJCF text.

    Length: the MJCF file's text as one f-string template; the length is the document's, and splitting it would scatter
    one file."""
    ws = wheels(b)
    body = "\n".join(wheel(b, *w) for w in ws)
    actuators = "\n".join(f'    <velocity name="{w[0]}_wheel" joint="{w[0]}_wheel" class="wheel"/>' for w in ws)
    sensors = "\n".join(f'    <jointvel name="{w[0]}_wheel_vel" joint="{w[0]}_wheel"/>' for w in ws)
    cx, cy, cz = b.chassis_half
    R, rr, W = b.wheel_radius, b.roller_radius, b.wheel_width
    lp = b.lidar_pos
    return f"""<!-- GENERATED by generate.py beside this file; edit the dimensions there, not here. -->
<mujoco model="{b.name}">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="0.002" integrator="implicitfast" solver="PGS" cone="elliptic" iterations="20"/>

  <default>
    <default class="{b.name}">
      <!-- two contact layers (bigcbf/sim/scene.py gives the world's side): the rollers (contype 2 / conaffinity 1)
           touch only the ground (floor and floor patches, 1 / 2); the body (class "body": chassis, LiDAR and a
           bumper box around the wheels, 8 / 4) touches only obstacles, walls and pedestrians (4 / 8). The robot
           never touches itself. Groups 3 (visual) and 4 (collision): the LiDAR's ray groups 0-2 never see it. -->
      <geom contype="2" conaffinity="1" group="4" friction="1.0 0.005 0.0001" solref="0.004 1"/>
      <default class="body">
        <geom contype="8" conaffinity="4"/>
      </default>
      <default class="visual">
        <geom contype="0" conaffinity="0" group="3" mass="0"/>
      </default>
      <default class="wheel">
        <joint axis="0 1 0" damping="{b.wheel_damping}" armature="{b.wheel_armature}"/>
        <velocity kv="{b.wheel_kv}" ctrlrange="{-b.wheel_max_speed} {b.wheel_max_speed}"
                  forcerange="{-b.wheel_max_torque} {b.wheel_max_torque}"/>
      </default>
      <default class="hub">
        <geom type="cylinder" size="{R - 2 * rr - 0.002:.4f} {W / 2 - 0.004:.4f}"
              zaxis="0 1 0" mass="{b.hub_mass}" contype="0" conaffinity="0"/>
      </default>
      <default class="hub_visual">
        <geom type="cylinder" size="{R - rr:.4f} {W / 2 - 0.008:.4f}"
              zaxis="0 1 0" contype="0" conaffinity="0" group="3" mass="0" rgba="0.75 0.75 0.78 1"/>
      </default>
      <default class="roller">
        <joint damping="0" armature="1e-6" frictionloss="0"/>
        <geom type="capsule" size="{rr}" mass="{b.roller_mass}" rgba="0.15 0.15 0.15 1"/>
      </default>
    </default>
  </default>

  <worldbody>
    <body name="base_link" pos="0 0 {R + 0.0005:.4f}" childclass="{b.name}">
      <freejoint name="root"/>
      <geom name="chassis" class="body" type="box" size="{f(cx, cy, cz)}" pos="{f(0, 0, b.chassis_z)}"
            mass="{b.chassis_mass}"/>
      <geom name="bumper" class="body" type="box" size="{f(*b.bumper_half)}" pos="{f(0, 0, b.bumper_z)}" mass="0"/>
      <geom name="battery" type="box" size="{f(*b.battery_half)}" pos="{f(0, 0, b.battery_z)}" mass="{b.battery_mass}"
            contype="0" conaffinity="0"/>
      <geom class="visual" type="box" size="{f(cx, cy, cz)}" pos="{f(0, 0, b.chassis_z)}" rgba="{b.chassis_rgba}"/>
      <geom class="visual" type="box" size="{f(cx - 0.01, cy - 0.005, 0.003)}" pos="{f(0, 0, b.chassis_z + cz + 0.02)}"
            rgba="0.12 0.12 0.12 1"/>
      <geom name="lidar" class="body" type="cylinder" size="{f(*b.lidar_size)}" pos="{f(*lp[:2], lp[2] - 0.012)}"
            mass="{b.lidar_mass}"/>
      <geom class="visual" type="cylinder" size="{f(*b.lidar_size)}" pos="{f(*lp[:2], lp[2] - 0.012)}"
            rgba="0.2 0.2 0.25 1"/>
      <site name="imu" pos="{f(*b.imu_pos)}" size="0.01" group="3"/>
      <site name="lidar" pos="{f(*lp)}" size="0.01" group="3"/>
      <site name="footprint" type="cylinder" size="{f(b.footprint_radius)} 0.001" pos="0 0 {-R + 0.002:.4f}" \
rgba="1 1 1 0.15"
            group="3"/>
{body}
    </body>
  </worldbody>

  <actuator>
{actuators}
  </actuator>

  <sensor>
    <gyro name="imu_gyro" site="imu"/>
    <accelerometer name="imu_acc" site="imu"/>
    <framequat name="imu_quat" objtype="site" objname="imu"/>
{sensors}
  </sensor>

  <custom>
    <!-- achieved / ideal body twist per axis (vx, vy, wz), measured on this model: the firmware's inverse
         kinematics divides by it (bigcbf/sim/kinematics.py); tests/test_robot.py re-measures it -->
    <numeric name="effective_scale" data="{f(*b.effective_scale)}"/>
  </custom>
</mujoco>
"""


def scene_xml(b: MecanumBase) -> str:
    """scene.xml: the robot with a floor and a light (MuJoCo Menagerie's layout)."""
    return f"""<mujoco model="{b.name} scene">
  <include file="{b.name}.xml"/>

  <statistic center="0 0 0.1" extent="{b.extent}"/>
  <visual>
    <headlight diffuse="0.6 0.6 0.6" ambient="0.3 0.3 0.3" specular="0 0 0"/>
    <global azimuth="120" elevation="-25"/>
  </visual>
  <asset>
    <texture type="skybox" builtin="gradient" rgb1="0.3 0.5 0.7" rgb2="0 0 0" width="512" height="3072"/>
    <texture type="2d" name="groundplane" builtin="checker" mark="edge" rgb1="0.2 0.3 0.4" rgb2="0.1 0.2 0.3"
             markrgb="0.8 0.8 0.8" width="300" height="300"/>
    <material name="groundplane" texture="groundplane" texuniform="true" texrepeat="5 5" reflectance="0.1"/>
  </asset>
  <worldbody>
    <light pos="0 0 3" dir="0 0 -1" directional="true"/>
    <!-- the floor in a body of its own: MuJoCo's midphase then pairs each roller with the floor alone, not with
         every wall and obstacle that scenes add to the world body (4x cheaper collision in walled scenes) -->
    <body name="ground">
      <geom name="floor" size="0 0 0.05" type="plane" material="groundplane" contype="1" conaffinity="2" priority="1"
            friction="1.0 0.005 0.0001"/>
    </body>
  </worldbody>
</mujoco>
"""


def files(b: MecanumBase) -> dict[str, str]:
    """The generated files of a robot folder: name -> text."""
    return {f"{b.name}.xml": robot_xml(b), "scene.xml": scene_xml(b)}


def write(b: MecanumBase, folder: str | Path) -> None:
    """Write the robot's generated files into ``folder``; ``--check`` on the command line only compares."""
    check = "--check" in sys.argv[1:]
    stale = []
    for name, text in files(b).items():
        out = Path(folder) / name
        if check:
            if not out.is_file() or out.read_text() != text:
                stale.append(str(out))
        else:
            out.write_text(text)
            print(f"wrote {out}")
    if stale:
        raise SystemExit(f"out of date (run generate.py): {', '.join(stale)}")


if __name__ == "__main__":
    write(X3, Path(__file__).parent)
