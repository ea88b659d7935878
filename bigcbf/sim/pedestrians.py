"""Pedestrians: waypoint walkers with social-force interaction (Helbing & Molnar 1995; Helbing et al. 2000).

Each pedestrian i walks its polyline of waypoints at its preferred speed v0_i, starting at its start time
(before that it stands at its first waypoint). Its acceleration is

    a_i = (v0_i e_i - v_i) / tau  +  sum_j A exp((r_i + r_j - d_ij) / B) n_ij w(phi_ij)  +  [robot term]

with e_i the unit vector to the next waypoint, n_ij the unit vector from j to i, d_ij the centre distance, and
w(phi) = lambda + (1 - lambda) (1 + cos phi) / 2 the anisotropy that lets people react mostly to what is ahead of
them. "Reactive" pedestrians also treat the robot (radius r_R, true position) as such a neighbour, with its own
strength A_robot; non-reactive ones ignore it (they model people who do not see the robot). Speeds are capped at
1.3 v0. Integrated by semi-implicit Euler (stepped at 50 Hz); positions drive MuJoCo mocap bodies
(:class:`WorldPedestrians` wires them into a SimWorld).

Faults (the scenario's ``stop`` and ``turn`` keys of a pedestrian, ``bigcbf/params/faults.py``): during a stop event
a walking pedestrian's preferred velocity is zero (it comes to a halt within about tau, as a person does, and the
social forces still act on it); during a turn event its preferred direction is the direction it was heading for
when the event began, rotated by ``angle_deg`` (each turn's side at random with ``random_side``), then it heads
for its waypoint again. A stop overrides a turn. Each pedestrian's stops, turn times and turn sides draw from their
own random streams (seeded by the episode seed, the pedestrian's index and the kind), so no fault changes
another's draws, and with none set nothing is drawn.
"""
from __future__ import annotations

import math

import mujoco
import numpy as np

from ..control.jit import kernel
from ..params.faults import EventSchedule, PedestrianTurn
from ..params.pedestrians import SocialForceParams     # robot-side parameters (config reads them without sim)
from .faults import EventProcess

#: first element of the spawn key of the pedestrians' fault streams (SimWorld's streams have keys (k,))
FAULT_STREAM_KEY = 1000


class Pedestrians:
    """Vectorised state of K pedestrians. ``paths[k]`` is a (n_k, 2) array of waypoints."""

    def __init__(self, paths, speeds, start_times, radii, loop, reactive,
                 params: SocialForceParams = SocialForceParams(), robot_radius: float = 0.15,
                 stops: list[EventSchedule] | None = None, turns: list[PedestrianTurn] | None = None,
                 seed: int = 0):
        """``stops``, ``turns``: each pedestrian's fault schedules (None: none); ``seed``: the episode's seed, for
        their random streams (module docstring)."""
        self.paths = [np.asarray(p, float).reshape(-1, 2) for p in paths]
        self.k = len(self.paths)
        self.v0 = np.asarray(speeds, float)
        self.t0 = np.asarray(start_times, float)
        self.r = np.asarray(radii, float)
        self.loop = np.asarray(loop, bool)
        self.reactive = np.asarray(reactive, bool)
        self.params = params
        self.robot_radius = robot_radius
        self._A: tuple[np.ndarray, np.ndarray] | None = None      # (:meth:`_strengths`)
        self._xy: list[list[list[float]]] | None = None           # the waypoints as floats (:meth:`_desired`)
        self.p = np.array([p[0] for p in self.paths]).reshape(-1, 2)
        self.v = np.zeros((self.k, 2))
        self.target = np.ones(self.k, int)
        self.done = np.zeros(self.k, bool)
        self._stops: list[EventProcess | None] = [None] * self.k
        self._turns: list[EventProcess | None] = [None] * self.k
        self._turn_spec = list(turns) if turns is not None else [None] * self.k
        self._turn_key: list[float | None] = [None] * self.k
        self._turn_dir = np.zeros((self.k, 2))
        self._side_rng: list[np.random.Generator | None] = [None] * self.k

        def stream(i: int, kind: int) -> np.random.Generator:
            return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(FAULT_STREAM_KEY, i, kind)))

        for i in range(self.k):
            if stops is not None and stops[i].enabled:
                self._stops[i] = EventProcess(stops[i], stream(i, 0))
            if turns is not None and turns[i].enabled:
                self._turns[i] = EventProcess(turns[i], stream(i, 1))
                if turns[i].random_side:
                    self._side_rng[i] = stream(i, 2)
        self.faulty = any(x is not None for x in self._stops + self._turns)

    def _desired(self, t: float) -> np.ndarray:
        """(k, 2) the preferred velocities v0_i e_i at t (advancing the waypoints reached). In plain floats: the
        numpy form's operations on two-vectors (|d| = sqrt(dx dx + dy dy), as numpy's 2-norm computes it), the
        same bits at a fraction of the cost."""
        e = np.zeros((self.k, 2))
        tol = self.params.waypoint_tol_m
        if self._xy is None:
            self._xy = [p.tolist() for p in self.paths]
        for i, (px, py) in enumerate(self.p.tolist()):
            if t < self.t0[i] or self.done[i]:
                continue
            path = self._xy[i]
            tx, ty = path[self.target[i]]
            dx, dy = tx - px, ty - py
            if math.sqrt(dx * dx + dy * dy) < tol:
                if self.target[i] + 1 < len(path):
                    self.target[i] += 1
                elif self.loop[i]:
                    self.target[i] = 0
                else:
                    self.done[i] = True
                    continue
                tx, ty = path[self.target[i]]
                dx, dy = tx - px, ty - py
            n = max(math.sqrt(dx * dx + dy * dy), 1e-9)
            e[i] = (dx / n, dy / n)
            if self.faulty:
                e[i] = self._faulted(i, t, e[i])
        return e * self.v0[:, None]

    def stopped(self, i: int, t: float) -> bool:
        """Whether pedestrian i is in a stop event at t."""
        return self._stops[i] is not None and self._stops[i].active(t)

    def turning(self, i: int, t: float) -> bool:
        """Whether pedestrian i is in a turn event at t."""
        return self._turns[i] is not None and self._turns[i].active(t)

    def _faulted(self, i: int, t: float, e: np.ndarray) -> np.ndarray:
        """The preferred direction of walking pedestrian i under its stop and turn faults (module docstring)."""
        if self.stopped(i, t):
            return np.zeros(2)
        turns = self._turns[i]
        start = None if turns is None else turns.event_at(t)
        if start is None:
            return e
        if self._turn_key[i] != start:          # a new turn: rotate the heading it had when it began
            spec = self._turn_spec[i]
            a = np.radians(spec.angle_deg)
            if self._side_rng[i] is not None and self._side_rng[i].random() < 0.5:
                a = -a
            c, s = np.cos(a), np.sin(a)
            self._turn_dir[i] = (c * e[0] - s * e[1], s * e[0] + c * e[1])
            self._turn_key[i] = start
        return self._turn_dir[i].copy()

    def _repulsion(self, q: np.ndarray, rq: np.ndarray, A: np.ndarray) -> np.ndarray:
        """Sum over neighbours at q (m,2) with radii rq and strengths A (k, m) of the anisotropic exponential
        (compiled: ``_repulsion_exponents`` and ``_repulsion_sum``; the exponential itself is numpy's, whose bits
        differ from the C library's that compiled code calls, so the forces are the same bits as the numpy
        reference ``repulsion_reference``)."""
        pr = self.params
        q = np.ascontiguousarray(q, dtype=float)
        rq = np.ascontiguousarray(rq, dtype=float)
        if A.shape != (self.k, len(q)) or not A.flags.c_contiguous or A.dtype != float:
            A = np.ascontiguousarray(np.broadcast_to(A, (self.k, len(q))), dtype=float)
        e = np.exp(_repulsion_exponents(self.p, self.r, q, rq, float(pr.B_m)))
        return _repulsion_sum(self.p, self.v, q, A, e, float(pr.anisotropy))

    def _strengths(self) -> tuple[np.ndarray, np.ndarray]:
        """The interaction strengths (k, k) between pedestrians (A, 0 on the diagonal) and (k, 1) from the robot
        (A_robot for the reactive ones), built once (they are constants of the model)."""
        if self._A is None:
            pr = self.params
            A = np.full((self.k, self.k), pr.A_mps2)
            np.fill_diagonal(A, 0.0)
            self._A = (A, np.ascontiguousarray(np.where(self.reactive, pr.A_robot_mps2, 0.0)[:, None]))
        return self._A

    def repulsion_reference(self, q: np.ndarray, rq: np.ndarray, A: np.ndarray) -> np.ndarray:
        """:meth:`_repulsion` in numpy (the reference its compiled form is checked against, bit for bit)."""
        pr = self.params
        diff = self.p[:, None, :] - q[None, :, :]                       # (k, m, 2) from neighbour to i
        dist = np.linalg.norm(diff, axis=2)
        n = diff / np.maximum(dist, 1e-9)[..., None]
        mag = A * np.exp((self.r[:, None] + rq[None, :] - dist) / pr.B_m)
        speed = np.linalg.norm(self.v, axis=1, keepdims=True)
        heading = self.v / np.maximum(speed, 1e-9)
        cos_phi = -np.einsum("kd,kmd->km", heading, n)                  # neighbour ahead -> cos_phi = 1
        w = pr.anisotropy + (1 - pr.anisotropy) * (1 + cos_phi) / 2
        w = np.where(speed > 1e-6, w, 1.0)
        return np.sum((mag * w)[..., None] * n, axis=1)

    def step(self, t: float, dt: float, robot_xy=None) -> None:
        """One semi-implicit Euler step of dt from t (module docstring): :meth:`step_reference`'s numbers, bit
        for bit, with the forces, the integration and the speed cap in one compiled kernel (``_social_step``);
        the exponentials stay numpy's (see :meth:`_repulsion`)."""
        if self.k == 0:
            return
        pr = self.params
        active = (t >= self.t0) & ~self.done
        desired = self._desired(t)
        A_peds, A_robot = self._strengths()
        B = float(pr.B_m)
        e_peds = np.exp(_repulsion_exponents(self.p, self.r, self.p, self.r, B)) if self.k > 1 else _NONE
        if robot_xy is not None:
            q = np.array(robot_xy, float).reshape(1, 2)
            e_robot = np.exp(_repulsion_exponents(self.p, self.r, q, np.array([self.robot_radius]), B))
        else:
            q, e_robot = _NONE, _NONE
        self.v, self.p = _social_step(desired, self.v, self.p, float(pr.tau_s), A_peds, e_peds, q, A_robot, e_robot,
                                      float(dt), float(pr.max_speed_factor), self.v0, active, self.done,
                                      float(pr.anisotropy))

    def step_reference(self, t: float, dt: float, robot_xy=None) -> None:
        """:meth:`step` in numpy (the reference the compiled step is checked against, bit for bit)."""
        if self.k == 0:
            return
        pr = self.params
        active = (t >= self.t0) & ~self.done
        a = (self._desired(t) - self.v) / pr.tau_s
        A_peds, A_robot = self._strengths()
        if self.k > 1:
            a += self._repulsion(self.p, self.r, A_peds)
        if robot_xy is not None:
            a += self._repulsion(np.asarray(robot_xy, float).reshape(1, 2), np.array([self.robot_radius]), A_robot)
        v = self.v + dt * a
        vmax = pr.max_speed_factor * self.v0
        s = np.linalg.norm(v, axis=1)
        v *= np.minimum(1.0, vmax / np.maximum(s, 1e-9))[:, None]
        # before the start time a pedestrian stands; after its last waypoint it slows to a stop
        v[~active & ~self.done] = 0.0
        self.v = v
        self.p = self.p + dt * v


@kernel
def _repulsion_exponents(p, r, q, rq, B):
    """(k, m): (r_i + r_j - d_ij) / B, d_ij = |p_i - q_j| (the exponent of the social force)."""
    k, m = p.shape[0], q.shape[0]
    out = np.empty((k, m))
    for i in range(k):
        for j in range(m):
            dx, dy = p[i, 0] - q[j, 0], p[i, 1] - q[j, 1]
            out[i, j] = (r[i] + rq[j] - np.sqrt(dx * dx + dy * dy)) / B
    return out


@kernel
def _repulsion_sum(p, v, q, A, e, lam):
    """(k, 2): sum_j A_ij e_ij w(phi_ij) n_ij, e_ij = exp(exponent) (numpy's), in numpy's order (the reference)."""
    k, m = p.shape[0], q.shape[0]
    out = np.zeros((k, 2))
    for i in range(k):
        speed = np.sqrt(v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1])
        sm = max(speed, 1e-9)
        hx, hy = v[i, 0] / sm, v[i, 1] / sm
        sx, sy = 0.0, 0.0
        for j in range(m):
            dx, dy = p[i, 0] - q[j, 0], p[i, 1] - q[j, 1]
            dm = max(np.sqrt(dx * dx + dy * dy), 1e-9)
            nx, ny = dx / dm, dy / dm
            mag = A[i, j] * e[i, j]
            w = lam + (1 - lam) * (1 + -(hx * nx + hy * ny)) / 2 if speed > 1e-6 else 1.0
            fx, fy = (mag * w) * nx, (mag * w) * ny
            if j == 0:
                sx, sy = fx, fy
            else:
                sx, sy = sx + fx, sy + fy
        out[i, 0], out[i, 1] = sx, sy
    return out


#: an empty (0, 0) array: "no such neighbours" for ``_social_step``
_NONE = np.zeros((0, 0))


@kernel
def _social_step(desired, v, p, tau, A_peds, e_peds, q, A_robot, e_robot, dt, max_factor, v0, active, done, lam):
    """(v, p) after one step (``Pedestrians.step_reference``'s operations in its order): a = (desired - v) / tau
    + the pedestrians' repulsion (``_repulsion_sum`` over the pedestrians themselves when ``e_peds`` has any) +
    the robot's (over the one row of ``q`` when ``e_robot`` has any); v + dt a capped at max_factor v0 (|v| as
    numpy's 2-norm: sqrt(vx vx + vy vy)); zero for those not active and not done; p + dt v."""
    k = p.shape[0]
    a = (desired - v) / tau
    if e_peds.shape[0] > 0:
        a = a + _repulsion_sum(p, v, p, A_peds, e_peds, lam)
    if e_robot.shape[0] > 0:
        a = a + _repulsion_sum(p, v, q, A_robot, e_robot, lam)
    v_new = v + dt * a
    for i in range(k):
        s = np.sqrt(v_new[i, 0] * v_new[i, 0] + v_new[i, 1] * v_new[i, 1])
        f = min(1.0, (max_factor * v0[i]) / max(s, 1e-9))
        v_new[i, 0] *= f
        v_new[i, 1] *= f
        if not active[i] and not done[i]:
            v_new[i, 0] = 0.0
            v_new[i, 1] = 0.0
    return v_new, p + dt * v_new


class WorldPedestrians:
    """A scenario's pedestrians walking in a SimWorld: the social-force model (:class:`Pedestrians`) stepped every
    ``PERIOD_S`` before the physics blocks (reactive pedestrians see the robot's true position), and each
    pedestrian's mocap body ``ped_<name>`` (sim/scene.py) moved to where the pedestrian is now, extrapolated at its
    velocity between social-force steps so its motion in the physics stays smooth.

    ``specs``: the scenario's pedestrian entries (``name``, ``waypoints``, ``speed_mps``, ``start_time_s``,
    ``radius_m``, ``loop``, ``reactive``, ``stop``, ``turn``); ``seed``: the episode's, for the fault streams.
    Registers itself as the world's pre-step hook and places the bodies at once.
    """

    #: the social-force model runs at 50 Hz (its relaxation time is 0.5 s)
    PERIOD_S = 0.02

    def __init__(self, world, specs, params: SocialForceParams = SocialForceParams(), robot_radius: float = 0.15,
                 seed: int = 0):
        specs = list(specs)
        self.pedestrians = Pedestrians([p.waypoints for p in specs], [p.speed_mps for p in specs],
                                 [p.start_time_s for p in specs], [p.radius_m for p in specs],
                                 [p.loop for p in specs], [p.reactive for p in specs],
                                 params=params, robot_radius=robot_radius,
                                 stops=[p.stop for p in specs], turns=[p.turn for p in specs], seed=seed)
        m = world.model
        self._world = world
        self._mocap = np.array([m.body_mocapid[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"ped_{p.name}")]
                                for p in specs], dtype=np.intp)       # (an index array, built once)
        self._t, self._next = 0.0, 0.0
        self.move(world)
        world.add_pre_step(self.move)

    def move(self, world) -> None:
        """Before each physics block: the social-force step when due, and the mocap bodies moved to where the
        pedestrians are now."""
        if not len(self._mocap):
            return
        t = world.t
        if t >= self._next - 1e-9:
            self.pedestrians.step(t, self.PERIOD_S, robot_xy=tuple(world.data.qpos[0:2]))
            self._t, self._next = t, t + self.PERIOD_S
        world.data.mocap_pos[self._mocap, :2] = self.pedestrians.p + (t - self._t) * self.pedestrians.v

    def positions(self) -> np.ndarray:
        """(K, 2) the pedestrians' centres in the physics now (their mocap bodies) [m]."""
        return self._world.data.mocap_pos[self._mocap, :2] if len(self._mocap) else np.zeros((0, 2))

    @property
    def velocities(self) -> np.ndarray:
        """(K, 2) the pedestrians' velocities [m/s]."""
        return self.pedestrians.v
