"""SimWorld: the MuJoCo physics of one scene with the robot's firmware, odometry, IMU and LiDAR.

    world = SimWorld(open_room(), profile=RobotProfile(), seed=0)
    world.command((0.5, 0.0, 0.0))     # body twist issued now, through the imperfection layer
    world.advance(1.0)                 # physics at the model timestep (2 ms)
    world.odom(), world.true_state(), world.imu(), world.scan()   # scan(): None when a fault loses it
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import mujoco
import numpy as np

from ..params.robot import RobotProfile
from ..robots import robot as registered_robot
from ..types import LaserScan, RobotState
from .faults import LidarFaults
from .firmware import Encoders, Gyro, ImperfectionLayer, WheelOdometry
from .kinematics import MecanumKinematics
from .lidar import Lidar, LidarConfig
from .scene import SceneSpec, cached_model, open_room

#: the default robot's wheels (fl, fr, rl, rr); a SimWorld takes its robot's from ``bigcbf.robots`` (``world.robot``)
WHEELS = ("fl", "fr", "rl", "rr")


def _yaw(quat_wxyz) -> float:
    w, x, y, z = quat_wxyz
    return float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


@dataclass
class PhysicsLog:
    """The physics blocks of a run as stepped (:meth:`SimWorld.record_blocks`): the simulation state before the
    first (``mj_getState`` with mjSTATE_INTEGRATION, the solver's warm start included, so that a replay is the run
    to the bit) and, per block, its steps, wheel targets and mocap positions (the only inputs the world writes
    between blocks)."""

    state0: np.ndarray | None
    blocks: list

    def add(self, m: mujoco.MjModel, d: mujoco.MjData, nb: int) -> None:
        if self.state0 is None:
            spec = mujoco.mjtState.mjSTATE_INTEGRATION
            self.state0 = np.empty(mujoco.mj_stateSize(m, spec))
            mujoco.mj_getState(m, d, self.state0, spec)
        self.blocks.append((int(nb), d.ctrl.copy(), d.mocap_pos.copy()))


class SimWorld:
    """One episode's physics. Deterministic for a given scene, profile, seed and command sequence."""

    #: the random streams, one per noise source and fault (SeedSequence children keep their index: adding a source at
    #: the end changes none of the others)
    STREAMS = ("residual", "lidar", "latency_jitter", "slip", "gyro_noise", "gyro_bias", "scan_dropout",
               "latency_spikes", "wheel_noise")

    def __init__(self, scene: SceneSpec | None = None, profile: RobotProfile = RobotProfile(), seed: int = 0,
                 lidar: LidarConfig | None = None, kinematics: MecanumKinematics | None = None,
                 model: mujoco.MjModel | None = None):
        """``lidar``: the LiDAR's configuration; None takes the robot profile's LiDAR model. The robot is the
        scene's (``SceneSpec.robot``, a folder of ``bigcbf/robots.py``): its MJCF gives the model, the wheel
        actuators and ``kinematics`` (None: the robot's, read from its MJCF)."""
        self.scene = scene or open_room()
        #: the robot as its MJCF describes it (bigcbf.robots.Robot): wheels, kinematics, outline, sensor mounts
        self.robot = registered_robot(self.scene.robot)
        if kinematics is None:
            kinematics = self.robot.kinematics
        if profile.floor_friction is not None:
            from dataclasses import replace
            self.scene = replace(self.scene, floor_friction=profile.floor_friction)
        self.model = model if model is not None else cached_model(self.scene)
        self.data = mujoco.MjData(self.model)
        self.profile = profile
        self.kin = kinematics
        # independent random streams, so that e.g. LiDAR noise does not change the execution residuals
        rng = dict(zip(self.STREAMS, (np.random.default_rng(s)
                                      for s in np.random.SeedSequence(seed).spawn(len(self.STREAMS)))))
        self.imperfection = ImperfectionLayer(profile, rng["residual"], rng["latency_jitter"], rng["slip"],
                                              kinematics.half_wheelbase_m + kinematics.half_track_m,
                                              rng_spikes=rng["latency_spikes"])
        if lidar is None:
            lidar = LidarConfig.from_model(profile.lidar)
        self.lidar = Lidar(self.model, lidar, rng["lidar"])
        f = profile.faults
        self.lidar_faults = (LidarFaults(f.scan_dropout, f.blanked_sectors_deg, rng["scan_dropout"],
                                         self.lidar.angles) if f.scan_dropout.enabled or f.blanked_sectors_deg
                             else None)
        self.encoders = Encoders(profile.odometry, rng=rng["wheel_noise"])
        self.gyro = Gyro(profile.imu, rng["gyro_noise"], rng["gyro_bias"])
        m = self.model
        self._act = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in self.robot.actuators])
        self._wheel_dof = np.array([m.jnt_dofadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j)]
                                    for j in self.robot.wheels])
        self._base = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "base_link")
        root = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "root")
        self._qadr, self._vadr = m.jnt_qposadr[root], m.jnt_dofadr[root]
        self._imu_gyro = m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, "imu_gyro")]
        self._imu_acc = m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, "imu_acc")]
        self._imu_quat = m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, "imu_quat")]
        self._hooks: list[Callable[["SimWorld"], None]] = []
        #: the physics blocks as stepped, for ``bigcbf perf``'s replay (``record_blocks``); None: not recorded
        self.block_log: PhysicsLog | None = None
        self._ctrl_for, self._ctrl = None, np.zeros(4)
        self.odometry = WheelOdometry(kinematics)
        self.reset_pose(*self.scene.robot_start)
        self.data.ctrl[self._act] = self._ctrl

    # --- time ----------------------------------------------------------------------------------------------
    @property
    def t(self) -> float:
        return float(self.data.time)

    @property
    def dt(self) -> float:
        return float(self.model.opt.timestep)

    def record_blocks(self) -> "PhysicsLog":
        """From now on, log every physics block as it is stepped (its wheel targets, the pedestrians' mocap
        positions, its number of steps) and the state before the first: ``sim.perf.replay_realtime_factor`` steps
        exactly this physics again without the stack (``bigcbf perf``'s floor of the same run)."""
        self.block_log = PhysicsLog(state0=None, blocks=[])
        return self.block_log

    def add_pre_step(self, hook: Callable[["SimWorld"], None]) -> None:
        """Call ``hook(world)`` before every block of physics steps (pedestrian motion, ...; see ``step``)."""
        self._hooks.append(hook)

    # --- commands and stepping -------------------------------------------------------------------------------
    def command(self, u) -> float:
        """Issue body twist u = (vx, vy, wz) now; returns when the wheels receive it (after the latency)."""
        u = np.asarray(u, float)
        if u.shape != (3,) or not np.all(np.isfinite(u)):
            raise ValueError(f"a command is a finite body twist (vx, vy, wz), got {u!r}")
        return self.imperfection.submit(self.t, u)

    #: physics steps per block (10 ms): the firmware side (hooks, odometry) runs once per block, MuJoCo steps the
    #: block in C. A block also ends when a queued command reaches the wheels, so command timing stays exact
    #: to the physics step; the wheel odometry integrates at 100 Hz (trapezoidal in the wheel speeds), as a
    #: robot's firmware does.
    BLOCK_STEPS = 5

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps."""
        m, d = self.model, self.data
        dt = m.opt.timestep
        imp = self.imperfection
        while n > 0:
            for hook in self._hooks:
                hook(self)
            t = d.time
            twist = imp.at(t)
            nb = min(n, self.BLOCK_STEPS)
            nxt = imp.next_apply_time()
            if nxt is not None:                        # stop the block where the next command takes effect
                nb = max(1, min(nb, math.ceil((nxt - t) / dt - 1e-9)))
            if imp.limiter is not None:                # the firmware's wheel limits (robot profile): their mean
                lim = imp.limiter.update(t, twist, nb * dt)         # over the block
                if self._ctrl_for is None or not np.array_equal(lim, self._ctrl_for):
                    self._ctrl_for, self._ctrl = lim.copy(), self.kin.inverse(lim)
                    d.ctrl[self._act] = self._ctrl
            elif twist is not self._ctrl_for:          # wheel targets change only with the executed twist
                self._ctrl_for, self._ctrl = twist, self.kin.inverse(twist)
                d.ctrl[self._act] = self._ctrl
            w0, g0 = d.qvel[self._wheel_dof], float(d.sensordata[self._imu_gyro + 2])     # (an index copy)
            if self.block_log is not None:
                self.block_log.add(m, d, nb)
            try:
                mujoco.mj_step(m, d, nb)
            except mujoco.FatalError as exc:           # the scene asks more of the simulator than it can hold
                from ..errors import UserError
                raise UserError(f"MuJoCo stopped at t = {d.time:.3f} s: {str(exc).splitlines()[0]} ({d.ncon} "
                                "contacts): the scene has more overlapping geometry than the simulator's memory "
                                "holds; use fewer or non-overlapping floor patches and obstacles") from None
            w1 = d.qvel[self._wheel_dof]
            w_mean = self.encoders.increment(0.5 * (w0 + w1), nb * dt)
            gyro = self.gyro.measure(0.5 * (g0 + float(d.sensordata[self._imu_gyro + 2])), nb * dt)
            self.odometry.update(w_mean, nb * dt, gyro, measured=self.encoders.speed(w1))
            n -= nb

    def advance(self, duration_s: float) -> None:
        self.step(max(0, int(round(duration_s / self.dt))))

    # --- state ---------------------------------------------------------------------------------------------
    def reset_pose(self, x: float, y: float, theta: float) -> None:
        """Put the robot at rest at (x, y, theta) on the floor; odometry restarts there."""
        d, q = self.data, self._qadr
        d.qpos[q:q + 3] = (x, y, self.model.qpos0[q + 2])
        d.qpos[q + 3:q + 7] = (np.cos(theta / 2), 0.0, 0.0, np.sin(theta / 2))
        d.qvel[:] = 0.0
        mujoco.mj_forward(self.model, d)
        self.odometry.reset(x, y, theta)

    def odom(self) -> RobotState:
        """Odometry: body velocity from the wheel speeds, heading from the IMU gyro (see WheelOdometry)."""
        return self.odometry.state()

    def true_state(self, snapshot: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> RobotState:
        """Ground truth from the simulator: pose in the world (= odom at start), body twist; of the moment a
        ``snapshot()`` was taken when one is given (the same numbers ``true_state()`` gave then)."""
        d, q, v = self.data, self._qadr, self._vadr
        xmat, qpos, qvel = (d.xmat[self._base], d.qpos, d.qvel) if snapshot is None else snapshot
        R = xmat.reshape(3, 3)
        vb = R.T @ qvel[v:v + 3]
        wb = R.T @ qvel[v + 3:v + 6]
        return RobotState(float(qpos[q]), float(qpos[q + 1]), _yaw(qpos[q + 3:q + 7]),
                          float(vb[0]), float(vb[1]), float(wb[2]))

    def snapshot(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What ``true_state`` reads now, copied (a few microseconds: the episode keeps one per physics block and
        turns it into a state only when a contact needs it)."""
        d = self.data
        return d.xmat[self._base].copy(), d.qpos.copy(), d.qvel.copy()

    def pose(self) -> tuple[float, float, float]:
        """The true planar pose (x [m], y [m], yaw [rad]) in the world (cheaper than ``true_state``)."""
        d, q = self.data, self._qadr
        return float(d.qpos[q]), float(d.qpos[q + 1]), _yaw(d.qpos[q + 3:q + 7])

    def reading_intervals(self) -> tuple[float, float]:
        """(wheels, gyro): the averaging intervals [s] of the current odometry twist (the encoders' speed window)
        and gyro reading (the last block); 0 before the first. The logs' covariances depend on them
        (``bigcbf.logio.covariance``)."""
        return float(self.encoders.speed_interval_s), float(self.gyro.last_dt)

    def wheel_speeds(self) -> np.ndarray:
        return self.data.qvel[self._wheel_dof].copy()

    def imu(self) -> dict:
        s = self.data.sensordata
        gyro = s[self._imu_gyro:self._imu_gyro + 3].copy()
        gyro[2] += self.gyro.bias + self.gyro.last_noise       # the yaw axis as the gyro model reads it
        return {"orientation": tuple(s[self._imu_quat:self._imu_quat + 4]),
                "angular_velocity": tuple(gyro),
                "linear_acceleration": tuple(s[self._imu_acc:self._imu_acc + 3])}

    #: the sensor frames the stack's messages use (REP 105 names) and the model's sites that carry them
    SENSOR_FRAMES = {"laser": "lidar", "imu_link": "imu"}

    def sensor_frames(self) -> dict[str, tuple[float, float, float, float]]:
        """Pose of each sensor frame in ``base_link`` as (x, y, z, yaw) [m, rad], from the model's sites. ``base_link``
        is the robot's frame on the floor (planar odometry puts it at z = 0), so z is the height above the floor
        with the robot at rest."""
        m = self.model
        base_z = float(m.qpos0[self._qadr + 2])            # the body's rest height above the floor
        out = {}
        for frame, site in self.SENSOR_FRAMES.items():
            k = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, site)
            if k < 0 or m.site_bodyid[k] != self._base:
                raise ValueError(f"the model has no site {site!r} on base_link for the {frame} frame")
            x, y, z = (float(v) for v in m.site_pos[k])
            out[frame] = (x, y, z + base_z, _yaw(m.site_quat[k]))
        return out

    def robot_description(self) -> str:
        """The robot model's text (its MJCF, the file the robot's scene.xml includes)."""
        return self.robot.xml.read_text()

    def scan(self) -> LaserScan | None:
        """The LiDAR scan now; None when the robot profile's scan dropout loses it (``[faults.scan_dropout]``);
        blanked sectors (``faults.blanked_sectors_deg``) read inf. With scan dropout on, a lost scan still
        draws its range noise, so the scans that arrive are those of the same episode without the fault."""
        scan = self.lidar.scan(self.data, self.t)
        lf = self.lidar_faults
        if lf is None:
            return scan
        if lf.dropped(self.t):
            return None
        return lf.apply(scan)

    def warnings(self) -> dict[str, int]:
        """MuJoCo warnings raised so far (name -> count), empty when none."""
        return {mujoco.mjtWarning(i).name: int(w.number) for i, w in enumerate(self.data.warning) if w.number}
