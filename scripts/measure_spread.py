#!/usr/bin/env python3
"""Measure how far each golden metric moves under perturbations a machine change brings (issue 16, item 7).

    .venv/bin/python scripts/measure_spread.py [--seeds 0 1 2 3] [--out spread.json]

For each (scenario, method) of ``PAIRS`` and each seed, the episode runs
- as is (the reference),
- with its initial pose moved by +-1e-12 and by +-1e-9 (m in x and y, rad in yaw; twelve runs: 1e-12 is a last
  bit of a coordinate; 1e-9 stands for the differences a machine change accumulates over many steps),
- in a fresh interpreter with OMP_NUM_THREADS = OPENBLAS_NUM_THREADS = MKL_NUM_THREADS = 1 (the default here is
  the library's own choice, 2 threads on the 2-core VM).
The CPU's core type (another SIMD path in numpy, MuJoCo, proxsuite) cannot be changed on one machine; the 1e-12
runs stand in for it: a last-bit difference anywhere grows the same way. Prints, per metric, the largest
difference from the reference over the perturbed runs of each episode, and the trace's largest difference per
second; writes everything as JSON (``--out``). scripts/regenerate_golden.py's docstring records the result.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

PAIRS = [("required_sidestepping", "big-cbf"), ("single_person_crossing", "cbf-only"), ("blind_corner", "apf")]
PERTURB = {f"{axis}{sign}{size:.0e}": tuple(float(sign + "1") * size * (i == j) for j in range(3))
           for size in (1e-12, 1e-9) for i, axis in enumerate(("x", "y", "yaw")) for sign in "+-"}
THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def runs(pairs, seeds, perturb) -> dict:
    """The golden runs, as JSON gives them back (so that runs of both processes compare alike)."""
    from regenerate_golden import golden_run
    return json.loads(json.dumps({f"{s}/{m}/{seed}": golden_run(s, m, seed, perturb=perturb)
                                  for s, m in pairs for seed in seeds}))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--dump", action="store_true", help=argparse.SUPPRESS)   # the one-thread child
    a = ap.parse_args()
    if a.dump:
        print(json.dumps(runs(PAIRS, a.seeds, (0.0, 0.0, 0.0))))
        return
    env = {**os.environ, **{k: "1" for k in THREAD_ENV}}
    child = subprocess.run([sys.executable, __file__, "--dump", "--seeds", *map(str, a.seeds)], env=env,
                           capture_output=True, text=True, check=True)
    variants = {"threads=1": json.loads(child.stdout)}
    ref = runs(PAIRS, a.seeds, (0.0, 0.0, 0.0))
    for name, d in PERTURB.items():
        variants[name] = runs(PAIRS, a.seeds, d)
    report: dict = {"episodes": {}}
    for key, r in ref.items():
        ep = {"outcome": [r["metrics"][k] for k in ("success", "collision", "timeout")],
              "modes": [m for _, m in r["metrics"]["mode_history"]], "metrics": {}, "trace": {}, "variants": {}}
        for vname, v in variants.items():
            o = v[key]
            same_modes = [m for _, m in o["metrics"]["mode_history"]] == ep["modes"]
            same_outcome = [o["metrics"][k] for k in ("success", "collision", "timeout")] == ep["outcome"]
            ep["variants"][vname] = {"same_outcome": same_outcome, "same_modes": same_modes,
                                     "identical": o == r}
            for k, want in r["metrics"].items():
                got = o["metrics"][k]
                if k == "mode_history":
                    if same_modes:
                        d = max((abs(a[0] - b[0]) for a, b in zip(got, want)), default=0.0)
                        ep["metrics"]["mode_times"] = max(ep["metrics"].get("mode_times", 0.0), d)
                elif isinstance(want, (int, float)) and not isinstance(want, bool):
                    d = abs(float(got) - float(want)) if want is not None and got is not None else 0.0
                    ep["metrics"][k] = max(ep["metrics"].get(k, 0.0), d)
            for row_a, row_b in zip(o["trace"], r["trace"]):
                sec = str(int(row_b[0]))
                d = max(abs(x - y) for x, y in zip(row_a[1:], row_b[1:]))
                ep["trace"][sec] = max(ep["trace"].get(sec, 0.0), d)
        finals = [v[key]["metrics"]["final_goal_dist_m"] for v in [*variants.values(), ref]
                  if v[key]["metrics"]["success"]]
        ep["final_goal_dist_success_max"] = max(finals, default=None)
        ep["reference"] = {k: v for k, v in r["metrics"].items() if k != "mode_history"}
        report["episodes"][key] = ep
    robust = {k: e for k, e in report["episodes"].items()
              if all(v["same_outcome"] and v["same_modes"] for v in e["variants"].values())}
    spread = {}
    for e in robust.values():
        for k, d in e["metrics"].items():
            ref_v = e["reference"].get(k)
            spread[k] = max(spread.get(k, 0.0), d)
            if k == "e_cbf" and ref_v:
                spread["e_cbf_relative"] = max(spread.get("e_cbf_relative", 0.0), d / abs(ref_v))
    report["robust"] = sorted(robust)
    report["spread_over_robust"] = spread
    report["trace_spread"] = max(max(e["trace"].values()) for e in report["episodes"].values())
    report["final_goal_dist_success_max"] = max(e["final_goal_dist_success_max"] or 0.0
                                                for e in report["episodes"].values())
    text = json.dumps(report, indent=1)
    if a.out:
        a.out.write_text(text + "\n")
    keys = sorted({k for e in report["episodes"].values() for k in e["metrics"]})
    print(f"{'episode':42s} " + " ".join(f"{k[:12]:>12s}" for k in keys))
    for name, e in report["episodes"].items():
        flags = "".join("" if v["same_outcome"] and v["same_modes"] else f" [{vn}: outcome "
                        f"{'=' if v['same_outcome'] else 'CHANGED'}, modes {'=' if v['same_modes'] else 'CHANGED'}]"
                        for vn, v in e["variants"].items())
        print(f"{name:42s} " + " ".join(f"{e['metrics'].get(k, 0.0):12.3g}" for k in keys) + flags)
        print(f"{'  trace max |diff| by second':42s} " + " ".join(f"{s}s:{d:.1e}" for s, d in e["trace"].items()))
        print(f"{'  identical to the reference':42s} " + ", ".join(f"{vn} {v['identical']}"
                                                                  for vn, v in e["variants"].items()))
    print(f"robust (outcome and mode sequence unchanged by every perturbation): {len(robust)} of "
          f"{len(report['episodes'])}; not: {', '.join(sorted(set(report['episodes']) - set(robust)))}")
    print("largest spread over the robust episodes: " + ", ".join(f"{k} {v:.3g}" for k, v in sorted(spread.items())))
    print(f"trace: largest difference {report['trace_spread']:.2g}; final_goal_dist_m of successful runs: at most "
          f"{report['final_goal_dist_success_max']:.3f} m")


if __name__ == "__main__":
    main()
