#!/usr/bin/env python3
"""Regenerate tests/golden/episodes.json ON PURPOSE, after a deliberate change of the physics or the stack.

    .venv/bin/python scripts/regenerate_golden.py

The regression test (tests/test_episode.py) runs these episodes and compares them with the stored values; a
difference means behaviour changed. Review the diff of the JSON before committing it.

On one machine a run is bit-for-bit the same run after run (the test runs each episode twice and checks it).
Across machines it is not: another CPU's SIMD kernels (numpy, MuJoCo, and proxsuite, which loads its AVX-512,
AVX2 or plain build by the CPU) change last bits, and the closed loop grows them. Even on one machine two
processes can differ: the same QP inputs, byte for byte, given to two proxsuite solver objects with the same history
gave solutions differing in the last bits (its AVX-512 kernels depend on where its internal buffers fall in
memory), and blind_corner/apf/0 changed with the length of an unrelated environment variable. So the golden values
are compared on what is robust, with tolerances from a measured spread (``TOLERANCES``):

- the outcome (success, collision, timeout) and the number of perception faults exactly;
- the behavior-mode sequence exactly, its switch times within one selection period;
- the first ``TRACE_S`` seconds (every ``TRACE_EVERY``-th control step's u_in, u_safe and true pose), second by
  second within 3 times the measured growth of a perturbation (``TRACE_ATOL``);
- the real-valued metrics within 3 times the largest difference measured (``TOLERANCES``);
- final_goal_dist_m of a successful episode on what it means: the robot ended inside the goal region (within
  eps_g of the goal, plus 3 times the largest odometry error measured, since success is judged on odometry); its
  value moves chaotically within the region (single_person_crossing/cbf-only/1: 0.0815 m where the earlier golden
  values were made, 0.0751 m here).

The measurement (scripts/measure_spread.py, 2026-11-24, this 2-core AMD EPYC VM): 3 scenario/method pairs x seeds
0-5 = 18 episodes, each run as is, with its initial pose moved by +-1e-12 and by +-1e-9 (m in x and y, rad in yaw;
12 runs: 1e-12 is a last bit of a coordinate, 1e-9 stands for what a machine's different last bits accumulate over
many steps), and in a fresh process with OMP/OPENBLAS/MKL_NUM_THREADS=1. The core type cannot be changed on one
machine: the perturbed runs stand in for it.
- Robust (outcome and mode sequence unchanged by all 13 variants): 15 of 18. Not: required_sidestepping/big-cbf/0
  (the earlier golden episode: x + 1e-12 flips the mode chosen after REVERSE at 8.0 s, GOAL or PASS-R),
  required_sidestepping/big-cbf/5 (yaw +-1e-9 changes the mode sequence), blind_corner/apf/1 (yaw - 1e-12: a
  success becomes a timeout). The golden episodes are robust ones, and stayed within every tolerance under 15
  further random kicks of up to 3e-9 on all three coordinates and with environments of other sizes;
  required_sidestepping/big-cbf/2 and /4 did not (the mode chosen after a REVERSE is a near-tie there too).
- Largest difference from the unperturbed run over the 15 robust episodes -> tolerance (3 x):
      time_s, sim_time_s   0.45 s (blind_corner/apf/0)                         -> 1.35 s
      control_steps        9                                                   -> 27
      cbf_active_ratio     0.0084 (single_person_crossing/cbf-only/1)          -> 0.025
      qp_infeasible_ratio  0.0041 (blind_corner/apf/0)                         -> 0.0125
      e_cbf                8.5 % (9.3 of 108.8, single_person_crossing/cbf-only/1) -> 25.5 % (+ 0.001)
      min_clearance_m      0.019 m (blind_corner/apf/0)                        -> 0.057 m
      stopped_time_s       0.05 s (blind_corner/apf/3)                         -> 0.15 s
      mode switch times    0                                                   -> one selection period, 0.5 s
      final_goal_dist_m    0.105 m; successful runs ended at most 0.182 m from the goal (eps_g 0.15 m + 0.032 m
                           of odometry error)                                  -> inside eps_g + 0.2 m (x3_sim's odometry error: see
                           ODOMETRY_ALLOWANCE_M)
      trace, per second    [0,1) 1.6e-9, [1,2) 3.5e-9, [2,3) 2.3e-8, [3,4) 2.2e-4, [4] 7.9e-4
                           (required_sidestepping/big-cbf/1 from 2 s on)       -> 3 x each, at least 1e-7
  The 1e-12 runs alone moved the metrics about 10 to 1000 times less (e_cbf 1.5 %, time 0.15 s, trace 1e-10).
- Re-measured after the exact QP solver (bigcbf.control.smallqp) replaced proxsuite and the perception changes of
  issue 13 (scripts/measure_spread.py --seeds 0 1 2 3, 2026-11-24): the fresh one-thread process now gives
  bit-identical runs for all 12 episodes, blind_corner/apf/0 included (the solver has no alignment-dependent
  kernels); the perturbations move the golden episodes themselves (required_sidestepping/big-cbf/3,
  single_person_crossing/cbf-only/1, blind_corner/apf/3) by at most: cbf_active_ratio 0.0159, control_steps 6,
  qp_infeasible_ratio 0.0078, e_cbf 3.59 of 81.4 (4.4 %; 0.016 absolute on a near-zero e_cbf), min_clearance_m
  0.0137 m, time_s 0.3 s; the trace 1.5e-9, 7.8e-8, 4.2e-6, 9.1e-3 and 2.0e-2 in seconds 0-4 (the BIG-CBF
  episode grows fastest). Each tolerance is the larger of the earlier one and 3 x this (cbf_active_ratio 0.048,
  qp_infeasible_ratio 0.0234, e_cbf 0.048 absolute, the trace 1.3e-5, 0.027 and 0.06 in seconds 2-4). Over
  all 12 episodes the spread is wider (blind_corner/apf/1: time 2.85 s, e_cbf 16.8 of 28): an episode's
  spread depends on how close its own decisions are, so the tolerances follow the episodes the test runs.
- After the behaviors' change of the relevant obstacle and PASS's forward distance (2026-11-24, later), the BIG-CBF
  golden episode required_sidestepping/big-cbf/3 stopped being robust: after SIDE-L, GOAL and PASS-L (which
  without a relevant obstacle also heads for the goal) are a near-tie, and y + 1e-12 picked the other one (so did
  seeds 0, 1, 2, 4 and 5 of that scene). single_person_crossing/big-cbf/1 (GOAL, SIDE-L, YIELD, PASS-R, with a
  walker) replaced it: its outcome, modes, trace and metrics stayed within every tolerance above under x, y and
  yaw +-1e-12 and +-1e-9 (12 runs, compared with ``differences`` below).
- The one-thread process gave bit-identical runs for 17 of 18 episodes; blind_corner/apf/0 differed, which is the
  process effect above (it differs as much with an unrelated environment variable), not the thread count.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bigcbf.episode import DETERMINISTIC_KEYS, Episode  # noqa: E402
from bigcbf.params.stack import SIMULATION  # noqa: E402
from bigcbf.scenario import load_scenario  # noqa: E402

#: (scenario, method, seed): short episodes that exercise perception, planning (BIG-CBF's mode switching, a
#: baseline), the CBF, walls and pedestrians, and whose outcome and mode sequence the measurement found robust
GOLDEN_EPISODES = [("single_person_crossing", "big-cbf", 1), ("single_person_crossing", "cbf-only", 1),
                   ("blind_corner", "apf", 3)]
GOLDEN_FILE = ROOT / "tests" / "golden" / "episodes.json"
TRACE_S = 4.0
TRACE_EVERY = 5          # control steps between trace samples (0.25 s)
#: the trace's tolerance by whole second of its time: 3 x the largest measured difference (module docstring), at
#: least 1e-7 (the earlier golden values' first 4 s matched to 1e-7 on the machine where their metrics did not)
TRACE_ATOL = {0: 1e-7, 1: 1e-7, 2: 1.3e-5, 3: 0.027, 4: 0.06}

#: metric -> (absolute tolerance, relative tolerance): 3 x the largest difference measured over the robust
#: episodes (module docstring)
TOLERANCES = {
    "time_s": (1.35, 0.0),
    "sim_time_s": (1.35, 0.0),
    "control_steps": (27, 0.0),
    "cbf_active_ratio": (0.048, 0.0),
    "qp_infeasible_ratio": (0.0234, 0.0),
    "e_cbf": (0.048, 0.255),
    "min_clearance_m": (0.057, 0.0),
    "stopped_time_s": (0.15, 0.0),
    "final_goal_dist_m": (0.31, 0.0),        # used only when the golden episode did not succeed
}
#: allowance over eps_g for the true final distance of a successful episode: success is judged on odometry, and
#: the x3_sim profile's odometry (encoder quantization, wheel-speed noise, a wheel-radius error, a gyro bias) ends
#: up to 0.164 m off: the largest true final distance over 345 successful episodes of the nine scenes (BIG-CBF
#: and BIG-CBF-NoShared, seeds 0-19) was 0.314 m with eps_g 0.15 m (0.1 m was measured with exact odometry)
ODOMETRY_ALLOWANCE_M = 0.2


def golden_run(scenario: str, method: str, seed: int, perturb=(0.0, 0.0, 0.0)) -> dict:
    """{"metrics": the deterministic metrics of the whole episode, "trace": [[t, u_in(3), u_safe(3), x, y, theta],
    ...] every TRACE_EVERY control steps up to TRACE_S}. ``perturb`` (dx, dy, dyaw) moves the initial pose
    (scripts/measure_spread.py)."""
    ep = Episode(load_scenario(scenario, seed), method, seed, SIMULATION)
    if any(perturb):
        x, y, yaw = ep.scenario.robot.start
        ep.world.reset_pose(x + perturb[0], y + perturb[1], yaw + perturb[2])
    trace: list = []
    count = [0]

    def observe(rec) -> None:
        if rec.t <= TRACE_S + 1e-9 and count[0] % TRACE_EVERY == 0:
            ts = rec.true_state
            trace.append([round(rec.t, 6), *map(float, rec.u_in), *map(float, rec.u_safe), ts.px, ts.py, ts.theta])
        count[0] += 1

    ep.observers.append(observe)
    res = ep.run().metrics()
    return {"metrics": {k: res[k] for k in DETERMINISTIC_KEYS}, "trace": trace}


def differences(got: dict, golden: dict) -> list[str]:
    """What differs beyond the tolerances between two golden_run results (module docstring); [] when they agree."""
    out = []
    g, w = got["metrics"], golden["metrics"]
    for k in ("success", "collision", "timeout", "perception_faults"):
        if g[k] != w[k]:
            out.append(f"{k}: {g[k]} vs golden {w[k]}")
    modes_g, modes_w = [m for _, m in g["mode_history"]], [m for _, m in w["mode_history"]]
    if modes_g != modes_w:
        out.append(f"mode sequence {modes_g} vs golden {modes_w}")
    elif any(abs(a[0] - b[0]) > SIMULATION.T_B_s + 1e-6 for a, b in zip(g["mode_history"], w["mode_history"])):
        out.append(f"mode switch times {g['mode_history']} vs golden {w['mode_history']}")
    if len(got["trace"]) != len(golden["trace"]):
        out.append(f"trace length {len(got['trace'])} vs golden {len(golden['trace'])}")
    else:
        for ra, rb in zip(got["trace"], golden["trace"]):
            worst, atol = max(abs(a - b) for a, b in zip(ra, rb)), TRACE_ATOL[int(rb[0])]
            if worst > atol:
                out.append(f"trace at t = {rb[0]:g} s differs by {worst:.3g} > {atol:g}")
                break
    for k, (atol, rtol) in TOLERANCES.items():
        if k == "final_goal_dist_m" and w["success"]:
            limit = SIMULATION.eps_g_m + ODOMETRY_ALLOWANCE_M
            if not (g[k] <= limit and w[k] <= limit):
                out.append(f"{k}: {g[k]:.4f} m, golden {w[k]:.4f} m: not both inside the goal region (<= {limit:g})")
            continue
        a, b = g[k], w[k]
        if a is None or b is None:
            if a != b:
                out.append(f"{k}: {a} vs golden {b}")
        elif abs(a - b) > atol + rtol * abs(b):
            out.append(f"{k}: {a:.6g} vs golden {b:.6g} (tolerance {atol:g} + {rtol:g} x golden)")
    return out


def main() -> None:
    out = {f"{s}/{m}/{seed}": golden_run(s, m, seed) for s, m, seed in GOLDEN_EPISODES}
    GOLDEN_FILE.parent.mkdir(parents=True, exist_ok=True)
    GOLDEN_FILE.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    print(f"wrote {GOLDEN_FILE}")


if __name__ == "__main__":
    main()
