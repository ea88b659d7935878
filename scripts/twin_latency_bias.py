"""Where the command layer's latency bias comes from, without MuJoCo (issue 27, docs/twin.md).

    .venv/bin/python scripts/twin_latency_bias.py [--seeds 11 12 13] [--accel 3.0]

A synthetic robot with exactly the structure the dynamic fit assumes (twin.limits: dead time, the simulated
firmware's wheel limits (bigcbf.sim.firmware.WheelLimiter), first-order wheels with a 15 ms lag, 20-ms averaged
odometry at 50 Hz), driven by the
calibration drive's commands (twin.drive.segments, 80 s at 20 Hz) and, like the simulator's firmware
(bigcbf.sim.firmware), with the latency jitter on each command's delay and the execution residual added to the
target before the wheel limits. twin.limits.fit_dynamic and refine_dynamic (as fit_model runs them) are given the
true static part, so only the dynamics are estimated. Prints each case's half-step latency (dead time + lag ln 2) per axis and its median over the axes
against the noiseless case: a jitter J should add J/2; a residual nothing. "resid. after" adds the same residual to
the limiter's output instead of its target (a check of the mechanism: the simulated firmware adds it before).
"""
from __future__ import annotations

import argparse

import numpy as np

from bigcbf.params.robot import RobotProfile
from bigcbf.sim.firmware import WheelLimiter
from twin.drive import DriveLimits, segments
from twin.limits import DynamicProblem, StaticFit, fit_dynamic, refine_dynamic

LATENCY_S, V_MAX, LEVER_M, WHEEL_LAG_S = 0.1, 0.6, 0.1645, 0.015


def commands(seed: int, duration: float = 80.0, dt: float = 0.05):
    rows, gen = [], segments(DriveLimits(), seed, dt)
    while len(rows) * dt < duration:
        for block in next(gen):
            rows.extend(block)
    u = np.array(rows[:int(duration / dt)])
    return np.arange(len(u)) * dt, u


def respond(t_cmd, u_cmd, jitter, residual, accel, rng, h=0.001, after: bool = False):
    """The synthetic robot's averaged odometry (times, twists) for the commands. ``after``: the residual added to
    the limiter's output instead of its target (not what the simulated firmware does; the mechanism's check)."""
    n = len(t_cmd)
    apply_at = np.maximum.accumulate(t_cmd + LATENCY_S + (rng.uniform(0, jitter, n) if jitter > 0 else 0.0))
    noise = rng.uniform(-1, 1, (n, 3)) * residual
    target = u_cmd if after else u_cmd + noise                      # the residual before the limits
    tg = np.arange(0, t_cmd[-1] + 1, h)
    k = np.searchsorted(apply_at, tg, side="right") - 1
    # the simulated firmware's own wheel limits (rim-speed saturation, rim-acceleration limit)
    limiter = WheelLimiter(RobotProfile(wheel_speed_max_mps=V_MAX, wheel_accel_max_mps2=accel), LEVER_M)
    y, out = np.zeros(3), np.zeros((len(tg), 3))
    alpha = 1 - np.exp(-h / WHEEL_LAG_S)
    for i in range(len(tg)):
        lim = limiter.update(tg[i], target[k[i]] if k[i] >= 0 else np.zeros(3), h)
        if after and k[i] >= 0:
            lim = lim + noise[k[i]]
        y = y + (lim - y) * alpha
        out[i] = y
    ts = np.arange(0.02, tg[-1], 0.02)
    c = np.vstack([np.zeros(3), np.cumsum(out, axis=0)]) * h
    return ts, (c[np.searchsorted(tg, ts)] - c[np.searchsorted(tg, ts - 0.02)]) / 0.02


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[11])
    ap.add_argument("--accel", type=float, default=3.0, help="rim-acceleration limit [m/s^2] (large: none)")
    args = ap.parse_args()
    static = StaticFit(np.eye(3), np.zeros(3), V_MAX, LEVER_M, (LEVER_M, LEVER_M), True, V_MAX, 0, 0.0, 0.0,
                       np.eye(3), np.zeros(3))
    cases = {"noiseless": (0.0, 0.0, False), "jitter 0.04 s": (0.04, 0.0, False), "residual 0.04": (0.0, 0.04, False),
             "resid. after": (0.0, 0.04, True)}
    for seed in args.seeds:
        t_cmd, u_cmd = commands(seed)
        base = None
        for name, (jitter, residual, after) in cases.items():
            ts, v = respond(t_cmd, u_cmd, jitter, np.full(3, residual), args.accel, np.random.default_rng(seed),
                            after=after)
            block = np.minimum((ts / ts[-1] * 10).astype(int), 9)
            fit_args = (t_cmd, u_cmd, ts, v, np.ones(len(ts), bool), block, np.ones(3, bool), static)
            dyn = fit_dynamic(DynamicProblem(*fit_args, 0.01, 0.02))
            dyn = refine_dynamic(DynamicProblem(*fit_args, 0.0025, 0.02), dyn)      # as twin.limits.fit_model ends
            half = (dyn.latency_s + dyn.axis_lags_s * np.log(2)) * 1e3
            med = float(np.median(half))
            base = med if base is None else base
            print(f"seed {seed} accel {args.accel:g}  {name:14s} half-step {np.round(half, 1)} ms, median {med:.1f} "
                  f"({med - base:+.1f} vs noiseless; expected {jitter / 2 * 1e3:+.1f})  dead "
                  f"{np.round(dyn.latency_s * 1e3, 1)} lag {np.round(dyn.axis_lags_s * 1e3, 1)} ms", flush=True)


if __name__ == "__main__":
    main()
