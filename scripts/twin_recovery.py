"""Measure how well `bigcbf calibrate` recovers random hidden robot profiles with wheel limits (issue 14's figures).

    .venv/bin/python scripts/twin_recovery.py --n 20 --seed 1000 [--duration 80] [--json out.json]

For each of n profiles drawn at random (``twin.record.random_profile``: latency, jitter, diagonal gains, bias, residual noise, a
wheel-speed limit and a wheel-acceleration limit, within the documented ranges of bigcbf/params/robot.py) the
calibration drive is recorded in the simulator and calibrated; the figures are compared with the profile:

- wheel-speed limit: the identified rim-speed limit against ``wheel_speed_max_mps`` (relative error);
- acceleration limit: the identified rim-acceleration limit against ``wheel_accel_max_mps2`` (relative error);
- latency: the identified latency (median over the axes) minus the model's own, against the mean latency the
  simulator applies: latency_s + U(0, latency_jitter_s) rounded up to its physics step (a command reaches the
  wheels at the first step at or after its time: ``applied_latency``; latency_s + latency_jitter_s / 2 + half a
  step on average, 1 ms on the X3's 2 ms step). The model's own is measured on a reference drive with the same wheel
  limits and a known latency of REF_LATENCY_S and nothing else (gains 1, no bias or noise), as its identified
  latency minus REF_LATENCY_S: the simulated wheels follow their targets with a ~17 ms lag, and behind an
  acceleration ramp part of that lag reads as dead time (a ramp delayed and a ramp lagged look the same); on the
  ideal profile (no limits) it reads as a lag instead. The reference's latency keeps it off the search's floor:
  with none, a dead time cannot go below 0, and behind a ramp the reference read 0 where the same limits with
  0.1 s read 0.1035 (3.5 ms of the model's own). Both differences are printed;
- gains: the diagonal of A against the profile's gains (relative error, worst axis), and against the profile's
  gains times the model's own (the reference drive's A: the simulated wheels realise 97-100 % of a target);
- interval coverage, per identified axis: the model's own part of the truth is the reference drive's estimate,
  which has an interval of its own, so the pair is checked: the difference of the two latencies (the ratio of the
  two gains, ``Calibration.gain_ci``) against the known difference (the profile's gain), with the two 90 %
  intervals' half-widths combined in quadrature (``*_covered_pair``); and, stricter, the drive's interval alone
  against the mean latency plus the reference's point estimate (the gain times the reference drive's); with the
  binomial band a 90 % interval should fall in over that many cases.

Prints one row per profile and the maximum and median of each error, and the coverages.
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.stats import binom

from bigcbf.params.robot import RobotProfile
from twin.calibrate import calibrate_log
from twin.record import random_profile, record_calibration


draw_profile = random_profile
REF_LATENCY_S = 0.1      # the reference drive's latency (docstring; a whole number of physics steps) [s]


def applied_latency(latency_s: float, jitter_s: float, dt: float) -> float:
    """The mean delay after which the simulator applies a command sent on a physics step: latency_s + U(0, jitter_s)
    rounded up to the next step (SimWorld.step ends a block where a queued command takes effect), averaged over
    the jitter (10,001 points)."""
    delay = latency_s + jitter_s * np.linspace(0.0, 1.0, 10001)
    return float(np.mean(np.ceil(delay / dt - 1e-9) * dt))


def physics_step_s() -> float:
    from bigcbf.sim.scene import open_room
    from bigcbf.sim.world import SimWorld
    return float(SimWorld(open_room()).dt)


def run(n: int, seed: int, duration: float, start: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    rows = []
    dt = physics_step_s()
    with tempfile.TemporaryDirectory(prefix="bigcbf-recovery-") as tmp:
        ideal_path = Path(tmp) / "ideal.mcap"
        record_calibration(RobotProfile(), ideal_path, seed=seed, duration_s=duration)
        ideal = calibrate_log(ideal_path)
        L0 = float(np.nanmedian(ideal.latency_s))
        for i in range(n):
            prof = draw_profile(rng)
            if i < start:                   # drawn, so that profile i is the same whatever the start
                continue
            path = Path(tmp) / f"p{i}.mcap"
            t0 = time.perf_counter()
            record_calibration(prof, path, seed=seed + 1 + i, duration_s=duration)
            cal = calibrate_log(path)
            ref_prof = RobotProfile(latency_s=REF_LATENCY_S, wheel_speed_max_mps=prof.wheel_speed_max_mps,
                                    wheel_accel_max_mps2=prof.wheel_accel_max_mps2)
            record_calibration(ref_prof, path, seed=seed + 1 + i, duration_s=duration)
            ref = calibrate_log(path)
            own = ref.latency_s - REF_LATENCY_S              # the model's own latency per axis
            L_ref = float(np.nanmedian(own))
            st, dyn = cal.model.static, cal.model.dynamic
            g = np.diag(np.asarray(prof.gain))
            lat_true = applied_latency(prof.latency_s, prof.latency_jitter_s, dt)
            row = {
                "profile": i, "latency_true_s": lat_true, "latency_s": float(np.nanmedian(cal.latency_s)) - L_ref,
                "latency_vs_ideal_s": float(np.nanmedian(cal.latency_s)) - L0,
                "v_max_true": prof.wheel_speed_max_mps, "v_max": st.v_max,
                "accel_true": prof.wheel_accel_max_mps2, "accel": dyn.accel_max,
                "gains_true": g.tolist(), "gains": np.diag(cal.fit.A).tolist(),
                "lever_m": st.lever_m, "lever_identified": st.lever_identified, "seconds": time.perf_counter() - t0}
            row["err_latency_s"] = row["latency_s"] - lat_true
            row["err_latency_vs_ideal_s"] = row["latency_vs_ideal_s"] - lat_true
            row["err_v_max"] = None if st.v_max is None else st.v_max / prof.wheel_speed_max_mps - 1
            row["err_accel"] = None if dyn.accel_max is None else dyn.accel_max / prof.wheel_accel_max_mps2 - 1
            row["err_gain"] = float(np.max(np.abs(np.diag(cal.fit.A) / g - 1)))
            ax = np.flatnonzero(cal.fit.identified)
            g_model = g * np.diag(ref.fit.A)
            row["gains_model_true"] = g_model.tolist()
            row["err_gain_model"] = float(np.max(np.abs(np.diag(cal.fit.A)[ax] / g_model[ax] - 1)))
            # the parts of each latency (dead time, first-order lag per axis), of this drive and of the reference's
            row["dead_s"], row["lag_s"] = dyn.latency_s.tolist(), dyn.axis_lags_s.tolist()
            row["ref_dead_s"] = ref.model.dynamic.latency_s.tolist()
            row["ref_lag_s"] = ref.model.dynamic.axis_lags_s.tolist()
            row["jitter_s"], row["residual_max"] = prof.latency_jitter_s, list(prof.residual_max)
            lat_ax = lat_true + own
            ci_l, ci_g = cal.latency_ci_s, cal.gain_ci
            row["latency_ci_s"], row["gain_ci"] = ci_l.tolist(), ci_g.tolist()
            row["latency_covered"] = [bool(ci_l[j, 0] <= lat_ax[j] <= ci_l[j, 1]) for j in ax
                                      if np.isfinite(ci_l[j]).all() and np.isfinite(lat_ax[j])]
            row["gain_covered"] = [bool(ci_g[j, 0] <= g_model[j] <= ci_g[j, 1]) for j in ax
                                   if np.isfinite(ci_g[j]).all()]
            # the model's own part of the truth is itself an estimate (the reference drive's, with an interval of
            # its own): the pair's difference (latency) or ratio (gain) against the known difference or ratio, the
            # two intervals' half-widths combined in quadrature
            rl, rci_l = ref.latency_s, ref.latency_ci_s
            rA, rci_g = np.diag(ref.fit.A), ref.gain_ci
            hl, hA = cal.latency_s, np.diag(cal.fit.A)
            row["ref_latency_ci_s"], row["ref_gain_ci"] = rci_l.tolist(), rci_g.tolist()
            row["latency_covered_pair"], row["gain_covered_pair"] = [], []
            for j in ax:
                if np.isfinite(ci_l[j]).all() and np.isfinite(rci_l[j]).all():
                    dl = hl[j] - rl[j]
                    lo = dl - np.hypot(hl[j] - ci_l[j, 0], rci_l[j, 1] - rl[j])
                    hi = dl + np.hypot(ci_l[j, 1] - hl[j], rl[j] - rci_l[j, 0])
                    row["latency_covered_pair"].append(bool(lo <= lat_true - REF_LATENCY_S <= hi))
                if np.isfinite(ci_g[j]).all() and np.isfinite(rci_g[j]).all() and hA[j] > 0 and rA[j] > 0:
                    ratio = hA[j] / rA[j]
                    lo = ratio * (1 - np.hypot(1 - ci_g[j, 0] / hA[j], rci_g[j, 1] / rA[j] - 1))
                    hi = ratio * (1 + np.hypot(ci_g[j, 1] / hA[j] - 1, 1 - rci_g[j, 0] / rA[j]))
                    row["gain_covered_pair"].append(bool(lo <= g[j] <= hi))
            rows.append(row)
            f = lambda x, fmt: "none" if x is None else format(x, fmt)   # noqa: E731
            print(f"{i:3d} latency {lat_true:.3f} -> {row['latency_s']:.3f} s ({row['err_latency_s'] * 1e3:+5.1f} ms; "
                  f"vs ideal {row['err_latency_vs_ideal_s'] * 1e3:+5.1f})  "
                  f"v_max {prof.wheel_speed_max_mps:.3f} -> {f(st.v_max, '.3f')} ({f(row['err_v_max'], '+.1%')})  "
                  f"accel {prof.wheel_accel_max_mps2:.2f} -> {f(dyn.accel_max, '.2f')} ({f(row['err_accel'], '+.1%')})"
                  f"  gains {row['err_gain']:.1%} (x model's {row['err_gain_model']:.1%})  "
                  f"covered latency {sum(row['latency_covered_pair'])}/{len(row['latency_covered_pair'])} "
                  f"({sum(row['latency_covered'])}) gains {sum(row['gain_covered_pair'])}/"
                  f"{len(row['gain_covered_pair'])} ({sum(row['gain_covered'])})  "
                  f"lever {st.lever_m:.3f}{'' if st.lever_identified else '?'}  {row['seconds']:.0f} s", flush=True)
    return rows


def summary(rows: list[dict]) -> dict:
    out = {}
    for key, scale in (("err_v_max", 1), ("err_accel", 1), ("err_latency_s", 1), ("err_latency_vs_ideal_s", 1),
                       ("err_gain", 1), ("err_gain_model", 1)):
        vals = [abs(r[key]) * scale for r in rows if r[key] is not None]
        missing = sum(r[key] is None for r in rows)
        out[key] = {"max": max(vals) if vals else None, "median": float(np.median(vals)) if vals else None,
                    "not_identified": missing}
    out["within_10ms_latency"] = sum(abs(r["err_latency_s"]) <= 0.010 for r in rows)
    out["within_3pct_gains"] = sum(r["err_gain"] <= 0.03 for r in rows)
    out["within_3pct_gains_model"] = sum(r["err_gain_model"] <= 0.03 for r in rows)
    for key in ("latency_covered_pair", "gain_covered_pair", "latency_covered", "gain_covered"):
        hits = [c for r in rows for c in r[key]]
        n = len(hits)
        lo, hi = binom.interval(0.95, n, 0.90) if n else (0, 0)
        out[key] = {"covered": int(sum(hits)), "cases": n, "band_90pct_level": [int(lo), int(hi)]}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--duration", type=float, default=80.0)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--start", type=int, default=0, help="run profiles start..n-1 (to split a run)")
    args = ap.parse_args()
    rows = run(args.n, args.seed, args.duration, args.start)
    s = summary(rows)
    for k, v in s.items():
        if isinstance(v, dict) and "max" in v:
            print(f"{k:24s} max {v['max']}  median {v['median']}  not identified {v['not_identified']}")
        else:
            print(f"{k:24s} {v}")
    if args.json is not None:
        args.json.write_text(json.dumps({"rows": rows, "summary": s}, indent=1))


if __name__ == "__main__":
    main()
