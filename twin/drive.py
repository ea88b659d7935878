"""The calibration drive: a command program of steps, ramps and sweeps of vx, vy, wz and their combinations.

The program is a sequence of ~35-s cycles (the last one cut at the requested duration), each made of

- steps on one axis at a time (one level per axis and cycle, 100 %, 50 %, 75 % of its limit in turn, held
  0.8-1.2 s, back to rest in between), which give clean command edges for the delay distribution and the gains;
- random combined steps: all three axes change together to random levels within the limits (||u_xy|| up to the
  translational limit, so some combinations reach the wheels' limit and saturate), held 0.8-1.2 s;
- corner steps: 90 % of the ||u_xy|| limit on a diagonal, with and without 90 % of the wz limit, nearly the
  largest wheel speeds the stack can ask for (a wheel-speed limit below them is met, with two mixes of yaw and
  translation, which tell the limit from its yaw lever arm), held 2-2.5 s and followed by 1 s at rest (long enough
  for a robot whose wheels accelerate at 0.8 m/s^2 to reach its limit and stay there);
- ramps (triangles) of each axis to its limit and back;
- a chirp sweep of each axis (0.2 -> 1.5 Hz), which exercises the response at frequencies where the delay
  matters.

Every movement is followed by its mirror image (the same command with the opposite sign), so the robot returns
near where it started. A movement and its mirror form a *segment*. Open loop (:func:`calibration_program`) that is
all; a real robot (or a simulated one with a bias, a latency, wheel limits) does not retrace its path exactly, and
the errors add up over the drive. The recorder therefore runs the program closed loop
(:class:`CalibrationDrive`): between segments, when the odometry puts the robot more than ``recentre_m`` from
where it started, a proportional controller on the odometry position drives it back (body-frame commands of at
most ``recentre_speed_mps``, until within ``recentre_tol_m`` or ``recentre_timeout_s``), as an operator would. Those
commands are logged like any other. Commands are issued at the control rate (T_C = 50 ms).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DriveLimits:
    """Speed limits of the drive: the stack's (v_max_mps, v_side_mps, the actuator box's wz)."""
    vx_mps: float = 0.8
    vy_mps: float = 0.55
    wz_rps: float = 1.0
    v_xy_mps: float = 0.8        # limit on ||(vx, vy)||


LEVELS = (1.0, 0.5, 0.75)


def _steps_one_axis(rng, lim, dt, cycle):
    """One segment per axis: +level, rest, -level, rest."""
    out = []
    for j, top in enumerate(lim[:3]):
        frac = LEVELS[(cycle + j) % len(LEVELS)]
        hold = rng.uniform(0.8, 1.2)
        u = np.zeros(3)
        u[j] = frac * top
        seg = []
        for sign in (1, -1):
            seg.append(np.tile(sign * u, (int(round(hold / dt)), 1)))
            seg.append(np.zeros((int(round(0.5 / dt)), 3)))
        out.append(seg)
    return out


def _random_combined(rng, lim, dt, n):
    """n segments: a random combination of the three axes and its mirror."""
    out = []
    for _ in range(n):
        u = rng.uniform(-1, 1, 3) * np.asarray(lim[:3])
        nxy = np.hypot(u[0], u[1])
        if nxy > lim[3]:
            u[:2] *= lim[3] / nxy
        hold = rng.uniform(0.8, 1.2)
        out.append([np.tile(sign * u, (int(round(hold / dt)), 1)) for sign in (1, -1)])
    return out


def _corners(rng, lim, dt, n=2):
    """n segments near the corners of the command box: 90 % of the ||u_xy|| limit on a diagonal and of the wz limit
    (random signs; every other one without yaw), and the mirror: nearly the largest wheel speeds the stack can ask
    for, so that a wheel-speed limit is met, with and without yaw, which tells the limit from its yaw lever arm
    (90 %: the simulated robot's own wheels top out at 1.275 m/s, just below the corner itself)."""
    out = []
    for i in range(n):
        sx, sy, sw = rng.choice([-1.0, 1.0], 3)
        sw *= i % 2                    # every other one without yaw: two mixes of yaw and translation at the limit
        u = 0.9 * np.array([sx * lim[3] / np.sqrt(2), sy * lim[3] / np.sqrt(2), sw * lim[2]])
        u[0] = np.clip(u[0], -lim[0], lim[0])
        u[1] = np.clip(u[1], -lim[1], lim[1])
        hold = rng.uniform(2.0, 2.5)
        seg = []
        for sign in (1, -1):
            seg.append(np.tile(sign * u, (int(round(hold / dt)), 1)))
            seg.append(np.zeros((int(round(1.0 / dt)), 3)))
        out.append(seg)
    return out


def _ramps(lim, dt, duration=0.8):
    out = []
    n = int(round(duration / dt))
    tri = np.concatenate([np.linspace(0, 1, n, endpoint=False), np.linspace(1, 0, n, endpoint=False)])
    for j, top in enumerate(lim[:3]):
        seg = []
        for sign in (1, -1):
            u = np.zeros((len(tri), 3))
            u[:, j] = sign * top * tri
            seg.append(u)
        out.append(seg)
    return out


def _chirps(lim, dt, duration=1.5, f0=0.2, f1=1.5):
    out = []
    t = np.arange(int(round(duration / dt))) * dt
    phase = 2 * np.pi * (f0 * t + 0.5 * (f1 - f0) / duration * t ** 2)
    for j, top in enumerate(lim[:3]):
        seg = []
        for sign in (1, -1):
            u = np.zeros((len(t), 3))
            u[:, j] = sign * 0.6 * top * np.sin(phase)
            seg.append(u)
        out.append(seg)
    return out


def segments(limits: DriveLimits = DriveLimits(), seed: int = 0, dt: float = 0.05):
    """The program's segments, without end: each a list of command blocks (n, 3) at period dt (module
    docstring). Deterministic for a seed."""
    rng = np.random.default_rng(seed)
    lim = (limits.vx_mps, limits.vy_mps, limits.wz_rps, limits.v_xy_mps)
    cycle = 0
    while True:
        parts = [_steps_one_axis(rng, lim, dt, cycle), _random_combined(rng, lim, dt, 4), _corners(rng, lim, dt),
                 _ramps(lim, dt), _chirps(lim, dt)]
        cycle += 1
        for part in parts:
            yield from part


def calibration_program(duration_s: float = 60.0, limits: DriveLimits = DriveLimits(), seed: int = 0,
                        dt: float = 0.05, rest_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The open-loop program: command times t (N,) [s] from 0 and body twists u (N, 3): rest, then the segments
    of the module docstring back to back, the last 0.5 s at rest. Deterministic for a seed. ``duration_s``
    includes the initial rest."""
    if duration_s <= rest_s:
        raise ValueError(f"duration_s must exceed the initial rest of {rest_s} s")
    n_total = int(round(duration_s / dt))
    blocks = [np.zeros((int(round(rest_s / dt)), 3))]
    n = len(blocks[0])
    for seg in segments(limits, seed, dt):
        if n >= n_total:
            break
        blocks += seg
        n += sum(len(b) for b in seg)
    u = np.concatenate(blocks)[:n_total]
    u[-int(round(0.5 / dt)):] = 0.0            # end at rest
    return dt * np.arange(n_total), u


class CalibrationDrive:
    """The program run closed loop (module docstring): ``command(t, pose)`` gives the command to send at time t
    (every ``dt``) from the robot's odometry pose (x, y, theta); the start is the pose at the first call."""

    def __init__(self, duration_s: float, limits: DriveLimits = DriveLimits(), seed: int = 0, dt: float = 0.05,
                 rest_s: float = 1.0, recentre_m: float = 0.3, recentre_tol_m: float = 0.08,
                 recentre_speed_mps: float = 0.3, recentre_gain_per_s: float = 0.8, recentre_timeout_s: float = 8.0):
        if duration_s <= rest_s:
            raise ValueError(f"duration_s must exceed the initial rest of {rest_s} s")
        self.duration_s, self.dt = duration_s, dt
        self.recentre_m, self.tol, self.speed = recentre_m, recentre_tol_m, recentre_speed_mps
        self.gain, self.timeout = recentre_gain_per_s, recentre_timeout_s
        self._segments = segments(limits, seed, dt)
        self._queue: list[np.ndarray] = [np.zeros((int(round(rest_s / dt)), 3))]
        self._k = 0                       # row in the first queued block
        self._start = None
        self._recentring_since = None
        self.recentrings = 0              # how many times the drive went back to the start

    def _distance(self, pose) -> float:
        return float(np.hypot(pose[0] - self._start[0], pose[1] - self._start[1]))

    def command(self, t: float, pose) -> np.ndarray:
        if self._start is None:
            self._start = (float(pose[0]), float(pose[1]))
        if t >= self.duration_s - 0.5 - 1e-9:                  # end at rest
            return np.zeros(3)
        if self._recentring_since is not None:
            dist = self._distance(pose)
            if dist > self.tol and t - self._recentring_since < self.timeout:
                # proportional to the offset in the world frame, rotated into the body frame
                ex, ey = self._start[0] - pose[0], self._start[1] - pose[1]
                scale = min(self.gain, self.speed / max(dist, 1e-9))
                c, s = np.cos(pose[2]), np.sin(pose[2])
                return np.array([scale * (c * ex + s * ey), scale * (-s * ex + c * ey), 0.0])
            self._recentring_since = None
            self._queue = [np.zeros((int(round(0.5 / self.dt)), 3))]          # settle before the next segment
            self._k = 0
        while self._queue and self._k >= len(self._queue[0]):
            self._queue.pop(0)
            self._k = 0
        if not self._queue:
            if self._distance(pose) > self.recentre_m:
                self._recentring_since = t
                self.recentrings += 1
                return self.command(t, pose)
            self._queue = list(next(self._segments))
            self._k = 0
        u = self._queue[0][self._k]
        self._k += 1
        return u.copy()
