"""Measure how well `bigcbf calibrate --model` (twin/model_fit.py, mujoco.sysid) recovers random hidden robot models.

    .venv/bin/python scripts/twin_model_recovery.py --n 20 --seed 2700 [--duration 60] [--firmware-cap]
        [--json out.json]

For each of n hidden models drawn at random (:func:`draw_model`: the X3's wheel actuator gain kv x 2^U(-1, 1), wheel
damping U(0, 0.15) N m s/rad (a steady-state wheel-speed loss of up to about 5 %), floor friction U(0.4, 1.5),
chassis mass 3.6 kg x U(0.7, 1.5); behind a command layer with latency U(0, 0.15) s) the hidden model is written as a
robot folder, the calibration drive is recorded on it, and the log is fitted as `bigcbf calibrate LOG --model`
fits it (the command layer calibrated first, then the model behind it). Per parameter it reports:

- whether the fit calls it identified (a parameter it does not identify is kept at the model's own value and is
  not counted below);
- the relative error of the estimate against the truth, and whether it is within 10 %;
- whether the interval (the fit's level, 90 %) covers the truth; over the identified cases the number covered is
  compared with the central 95 % binomial band of the level for that many cases;
- the fit's CPU time per minute of log.
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from bigcbf.params.robot import RobotProfile
from twin.calibrate import read_log
from twin.model_fit import ModelFitOptions, fit_log, model_with, write_robot_folder
from twin.record import record_calibration

ROBOT = "rosmaster_x3"


def draw_model(rng: np.random.Generator, firmware_cap: bool = False) -> tuple[dict, RobotProfile]:
    """A hidden model (parameter values) and its command layer (module docstring; ``firmware_cap``: the command
    layer also clamps the wheels' rim speed at U(0.35, 0.6) m/s, below the drive's 0.8 m/s)."""
    values = {"wheel_kv": 3.0 * 2 ** rng.uniform(-1, 1), "wheel_damping": rng.uniform(0.0, 0.15),
              "floor_friction": rng.uniform(0.4, 1.5), "base_mass": 3.6 * rng.uniform(0.7, 1.5)}
    latency = float(rng.uniform(0.0, 0.15))
    cap = float(rng.uniform(0.35, 0.6)) if firmware_cap else None
    return values, RobotProfile(latency_s=latency, wheel_speed_max_mps=cap)


def one_case(i: int, rng, seed: int, duration: float, tmp: Path, opt: ModelFitOptions,
             firmware_cap: bool = False) -> dict:
    values, front = draw_model(rng, firmware_cap)
    hidden = tmp / f"hidden{i}"
    write_robot_folder(model_with(ROBOT, values, front), hidden)
    log = tmp / f"h{i}.mcap"
    record_calibration(front, log, seed=seed + 1 + i, duration_s=duration, robot=str(hidden))
    t0 = time.process_time()
    fit = fit_log(read_log(log, use_scan=False), ROBOT, opt)
    row = {"case": i, "latency_true_s": front.latency_s, "latency_front_s": fit.front.latency_s,
           "cap_true_mps": front.wheel_speed_max_mps, "cap_front_mps": fit.front.wheel_speed_max_mps,
           "cap_note": next((n for n in fit.notes if "wheel-speed cap" in n), None),
           "cost": fit.cost, "rms_fit": [float(v) for v in fit.rms_fit],
           "cpu_s": time.process_time() - t0, "fit_cpu_s": fit.cpu_s, "log_s": fit.log_s,
           "cpu_s_per_log_minute": fit.cpu_per_log_minute, "level": fit.level, "params": {}}
    for k, n in enumerate(fit.names):
        truth, est = values[n], float(fit.value[k])
        ok = bool(fit.identified[k])
        row["params"][n] = {"truth": truth, "estimate": est, "identified": ok, "why": fit.reasons[k],
                            "interval": [float(fit.lo[k]), float(fit.hi[k])],
                            "rel_err": est / truth - 1 if ok else None,
                            "covered": bool(fit.lo[k] <= truth <= fit.hi[k]) if ok else None}
    return row


def run(n: int, seed: int, duration: float, opt: ModelFitOptions = ModelFitOptions(),
        json_path: Path | None = None, firmware_cap: bool = False) -> list[dict]:
    """The n cases (a row each, printed as it comes; with ``json_path`` the rows so far and their summary are
    written after each case, so a run cut short still leaves its numbers)."""
    rng = np.random.default_rng(seed)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bigcbf-model-recovery-") as tmp:
        for i in range(n):
            row = one_case(i, rng, seed, duration, Path(tmp), opt, firmware_cap)
            rows.append(row)
            cells = []
            for name, p in row["params"].items():
                cells.append(f"{name} {p['truth']:.3g}->" + (f"{p['estimate']:.3g} ({p['rel_err']:+.0%}, "
                                                              f"{'in' if p['covered'] else 'OUT'})"
                                                              if p["identified"] else "n.i."))
            cap = (f"cap {row['cap_true_mps'] or 0:.2f}->{row['cap_front_mps'] or 0:.2f}  "
                   if row["cap_true_mps"] or row["cap_front_mps"] or row["cap_note"] else "")
            head = f"{i:3d} latency {row['latency_true_s']:.3f}->{row['latency_front_s']:.3f} s  {cap}"
            print(head + "  ".join(cells)
                  + f"  {row['cpu_s_per_log_minute']:.0f} s CPU/log-min", flush=True)
            if json_path is not None:
                json_path.write_text(json.dumps({"rows": rows, "summary": summary(rows)}, indent=1))
    return rows


def binomial_band(n: int, level: float, conf: float = 0.95) -> tuple[int, int]:
    """The central ``conf`` range of the number of n intervals at ``level`` that cover the truth."""
    from scipy.stats import binom
    a = (1 - conf) / 2
    return int(binom.ppf(a, n, level)), int(binom.ppf(1 - a, n, level))


def summary(rows: list[dict]) -> dict:
    out = {"cases": len(rows), "cpu_s_per_log_minute": {
        "median": float(np.median([r["cpu_s_per_log_minute"] for r in rows])),
        "max": float(np.max([r["cpu_s_per_log_minute"] for r in rows]))}}
    for name in rows[0]["params"]:
        ps = [r["params"][name] for r in rows]
        ident = [p for p in ps if p["identified"]]
        errs = [abs(p["rel_err"]) for p in ident]
        band = binomial_band(len(ident), rows[0]["level"]) if ident else None
        covered = sum(p["covered"] for p in ident)
        out[name] = {"identified": len(ident), "within_10pct": sum(e <= 0.10 for e in errs),
                     "median_abs_rel_err": float(np.median(errs)) if errs else None,
                     "max_abs_rel_err": float(np.max(errs)) if errs else None,
                     "covered": covered, "binomial_band": band,
                     "coverage_in_band": None if band is None else band[0] <= covered <= band[1]}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--seed", type=int, default=2700)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--firmware-cap", action="store_true",
                    help="the hidden command layer also clamps the wheels' rim speed (draw_model)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    rows = run(args.n, args.seed, args.duration, json_path=args.json, firmware_cap=args.firmware_cap)
    for k, v in summary(rows).items():
        print(f"{k:16s} {v}")


if __name__ == "__main__":
    main()
