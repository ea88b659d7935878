"""The calibration drive: a command program of steps, ramps and sweeps of vx, vy, wz and their combinations.

The program is a sequence of ~35-s cycles (the last one cut at the requested duration), each made of

- steps on one axis at a time (one level per axis and cycle, 100 %, 50 %, 75 % of its limit in turn, held
  0.8-1.2 s, back to rest in between), which give clean command edges for the delay distribution and the gains;
- random combined steps: all three axes change together to random levels within the limits (||u_xy|| up to the
  translational limit, so some combinations reach the wheels' limit and saturate), held 0.8-1.2 s;
- ramps (triangles) of each axis to its limit and back;
- a chirp sweep of each axis (0.2 -> 1.5 Hz), which exercises the response at frequencies where the delay
  matters.

Every movement is followed by its mirror image (the same command with the opposite sign), so the robot returns
near where it started and the drive fits in a small room. Commands are issued at the control rate (T_C = 50 ms).
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
    out = []
    for j, top in enumerate(lim[:3]):
        for frac in (LEVELS[(cycle + j) % len(LEVELS)],):
            hold = rng.uniform(0.8, 1.2)
            u = np.zeros(3)
            u[j] = frac * top
            for sign in (1, -1):
                out.append(np.tile(sign * u, (int(round(hold / dt)), 1)))
                out.append(np.zeros((int(round(0.5 / dt)), 3)))
    return out


def _random_combined(rng, lim, dt, n):
    out = []
    for _ in range(n):
        u = rng.uniform(-1, 1, 3) * np.asarray(lim[:3])
        nxy = np.hypot(u[0], u[1])
        if nxy > lim[3]:
            u[:2] *= lim[3] / nxy
        hold = rng.uniform(0.8, 1.2)
        for sign in (1, -1):
            out.append(np.tile(sign * u, (int(round(hold / dt)), 1)))
    return out


def _ramps(lim, dt, duration=0.8):
    out = []
    n = int(round(duration / dt))
    tri = np.concatenate([np.linspace(0, 1, n, endpoint=False), np.linspace(1, 0, n, endpoint=False)])
    for j, top in enumerate(lim[:3]):
        for sign in (1, -1):
            u = np.zeros((len(tri), 3))
            u[:, j] = sign * top * tri
            out.append(u)
    return out


def _chirps(lim, dt, duration=1.5, f0=0.2, f1=1.5):
    out = []
    t = np.arange(int(round(duration / dt))) * dt
    phase = 2 * np.pi * (f0 * t + 0.5 * (f1 - f0) / duration * t ** 2)
    for j, top in enumerate(lim[:3]):
        for sign in (1, -1):
            u = np.zeros((len(t), 3))
            u[:, j] = sign * 0.6 * top * np.sin(phase)
            out.append(u)
    return out


def calibration_program(duration_s: float = 60.0, limits: DriveLimits = DriveLimits(), seed: int = 0,
                        dt: float = 0.05, rest_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Command times t (N,) [s] from 0 and body twists u (N, 3): rest, then cycles of the module docstring.

    Deterministic for a seed. ``duration_s`` includes the initial rest."""
    if duration_s <= rest_s:
        raise ValueError(f"duration_s must exceed the initial rest of {rest_s} s")
    rng = np.random.default_rng(seed)
    lim = (limits.vx_mps, limits.vy_mps, limits.wz_rps, limits.v_xy_mps)
    n_total = int(round(duration_s / dt))
    blocks = [np.zeros((int(round(rest_s / dt)), 3))]
    n = len(blocks[0])
    cycle = 0
    while n < n_total:
        parts = [_steps_one_axis(rng, lim, dt, cycle), _random_combined(rng, lim, dt, 4), _ramps(lim, dt),
                 _chirps(lim, dt)]
        cycle += 1
        for part in parts:
            for b in part:
                blocks.append(b)
                n += len(b)
    u = np.concatenate(blocks)[:n_total]
    u[-int(round(0.5 / dt)):] = 0.0            # end at rest
    return dt * np.arange(n_total), u
