#!/usr/bin/env python3
"""Measure the choices listed in docs/fidelity.md: BIG-CBF with our choice vs an alternative, on small samples.

    .venv/bin/python scripts/fidelity_ablations.py [--seeds 5] [--workers 2] [--only NAME ...] [--json OUT]

Each row runs BIG-CBF (or the named method) on a few scenes x seeds with the default robot profile and stack
parameters ("ours") and once more with one alternative ("alt"): a parameter, or, for choices that are code, a
patch applied inside the worker for that run only (``unittest.mock.patch``). It prints one Markdown table: per row
and variant, success, collisions, mean time of the successes, E_CBF, CBF active % (pooled over steps), QP
infeasible %, the imagination's and the execution's mean margin kappa m_i. A measurement tool: nothing in bigcbf
imports it, and the stack never runs the alternatives.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

STATIC = ("required_sidestepping", "multi_static_clutter", "double_squeeze")
DYNAMIC = ("blind_corner", "crowd_crossing", "mixed_dense_traffic")
NARROW = ("corridor_meeting", "double_squeeze", "delay_and_slip")


@dataclass(frozen=True)
class Row:
    name: str
    what: str                      # the choice and the alternative, in words
    scenes: tuple[str, ...]
    alt: str                       # the alternative's key in ALTERNATIVES
    method: str = "big-cbf"
    ours: str = "ours"             # the reference's key (default: the shipped settings)


ROWS = [
    Row("pass_offset", "PASS offset from the relevant obstacle's group vs eq:behavior_subgoals (10) per obstacle",
        STATIC, "no_groups"),
    Row("side_commitment", "side commitment in the selection vs plain lowest J", STATIC + ("single_person_crossing",),
        "no_side_commitment"),
    Row("cbf_rows", "CBF rows: tracks + nearest wall point per 8 sectors vs every obstacle a row", NARROW,
        "all_rows"),
    Row("alpha_low", "alpha 1.5 1/s vs 0.75 1/s", STATIC + DYNAMIC[:1], "alpha_0.75"),
    Row("alpha_high", "alpha 1.5 1/s vs 3.0 1/s", STATIC + DYNAMIC[:1], "alpha_3"),
    Row("release_fan", "reverse-release fallback: the fan of 10 candidates vs the push alone", DYNAMIC, "push_only"),
    Row("wall_spacing", "wall points every 0.2 m vs every 0.4 m", NARROW, "wall_spacing_0.4"),
    Row("e_exec_horizon", "e_exec horizon T_C + tau95 vs T_C", STATIC + DYNAMIC[:1], "horizon_tc"),
    Row("e_zoh", "e_ZOH 0.025 m (Table I) vs the calibration's T_C v_99 = 0.040 m", STATIC + DYNAMIC[:1], "e_zoh_cal"),
    Row("stack_profile", "stack profile: Table I + the twin's calibration vs Table I alone", STATIC + DYNAMIC,
        "table_i"),
    Row("robot_profile", "robot: the x3_sim profile vs an ideal robot and sensors (stack: Table I + calibration)",
        STATIC + DYNAMIC, "ideal_robot"),
    Row("sensor_noise", "sensors: LiDAR, encoder and gyro noise vs ideal sensors (execution imperfections kept)",
        STATIC + DYNAMIC, "ideal_sensors"),
    Row("perception_cov", "covariances from the sensor model / the static filter vs the old constants (wall "
        "1e-4 m^2, static tracks the CV filter)", STATIC + DYNAMIC, "old_covariances"),
    Row("young_tracks", "static/dynamic classification from a track's second measurement vs once its velocity "
        "rests on more than 3 (classify_after_hits 1 vs 3)", STATIC + DYNAMIC, "classify_after_3"),
    Row("noshared_kappa", "NoShared (hardware preset): fixed 0.30 m vs kappa_img x 0.30 m",
        ("lab_pedestrian_crossing",), "noshared_kappa", method="big-cbf-noshared", ours="hardware"),
]


# --- the variants -------------------------------------------------------------------------------------------------

def _params(key: str):
    from bigcbf.bench.suites import SUITES
    from bigcbf.params.stack import SIMULATION, default_stack_params
    p = default_stack_params()
    u = p.uncertainty
    if key == "hardware" or key == "noshared_kappa":
        return SUITES.get("hardware").params()
    if key == "alpha_0.75":
        return replace(p, alpha_per_s=0.75)
    if key == "alpha_3":
        return replace(p, alpha_per_s=3.0)
    if key == "horizon_tc":
        return replace(p, uncertainty=replace(u, execution=replace(u.execution, residual_horizon_s=p.T_C_s)))
    if key == "e_zoh_cal":
        return replace(p, uncertainty=replace(u, e_zoh_m=0.040))
    if key == "table_i":
        return SIMULATION
    return p


@contextlib.contextmanager
def _patches(key: str):
    """Code alternatives, applied in this process for one episode."""
    from unittest import mock

    import numpy as np
    with contextlib.ExitStack() as stack:
        if key == "no_groups":
            lone = lambda p, r, params: np.arange(len(np.asarray(r))) if np.ndim(r) else np.zeros(0, int)  # noqa
            stack.enter_context(mock.patch("bigcbf.control.behaviors.obstacle_groups", lone))
            stack.enter_context(mock.patch("bigcbf.control.imagination.obstacle_groups", lone))
        elif key == "no_side_commitment":
            stack.enter_context(mock.patch("bigcbf.control.selection.BehaviorSelector._best",
                                           lambda self, img, J: img.modes[int(np.argmin(J))]))
        elif key == "all_rows":
            stack.enter_context(mock.patch("bigcbf.control.cbf.select_constraints",
                                           lambda obstacles, rows, params: np.arange(len(obstacles))))
        elif key == "push_only":
            from bigcbf.control import imagination as im
            real = im.release_candidates
            stack.enter_context(mock.patch("bigcbf.control.imagination.release_candidates",
                                           lambda *a, **k: real(*a, **k)[:1]))
        elif key == "old_covariances":
            from bigcbf.perception import pipeline, tracker

            def const_wall(points, sensor, dphi, params):
                return np.broadcast_to(1e-4 * np.eye(2), (len(points), 2, 2)).copy()
            stack.enter_context(mock.patch.object(pipeline, "wall_point_covariance", const_wall))

            def cv_reported(self, idx):
                return self.x[idx, :2].copy(), self.P[idx, :2, :2].copy()
            stack.enter_context(mock.patch.object(tracker.Tracker, "reported", cv_reported))
        elif key == "noshared_kappa":
            from bigcbf.control import imagination as im
            real_imagine = im.imagine

            def imagine(state, obstacles, goal, params, **kw):
                if not kw.get("shared", True):
                    kap = im.kappa_img(obstacles, params.uncertainty)
                    params = replace(params, noshared_margin_m=kap * params.noshared_margin_m)
                return real_imagine(state, obstacles, goal, params, **kw)
            stack.enter_context(mock.patch("bigcbf.control.big_cbf.imagine", imagine))
            stack.enter_context(mock.patch("bigcbf.control.imagination.imagine", imagine))
        yield


def _episode(task):
    variant, method, scenario, seed = task
    from bigcbf.episode import Episode
    from bigcbf.params.perception import PerceptionParams
    from bigcbf.params.robot import ImuModel, LidarModel, OdometryModel, RobotProfile
    from bigcbf.scenario import load_scenario
    sc = load_scenario(scenario, seed)
    if variant == "ideal_robot":
        sc = replace(sc, robot_profile=RobotProfile(floor_friction=sc.robot_profile.floor_friction))
    elif variant == "ideal_sensors":
        sc = replace(sc, robot_profile=replace(sc.robot_profile, lidar=LidarModel(), odometry=OdometryModel(),
                                               imu=ImuModel()))
    pp = PerceptionParams()
    if variant == "wall_spacing_0.4":
        pp = replace(pp, wall_spacing_m=0.4)
    if variant == "classify_after_3":
        pp = replace(pp, classify_after_hits=3)
    with _patches(variant):
        r = Episode(sc, method, seed, _params(variant), perception_params=pp).run()
    return variant, scenario, seed, r.metrics()


def summarize(ms: list[dict]) -> dict:
    import numpy as np
    n = len(ms)
    steps = sum(m["control_steps"] for m in ms)
    succ = [m for m in ms if m["success"]]

    def mean(k):
        v = [m[k] for m in ms if m.get(k) is not None]
        return float(np.mean(v)) if v else None
    return {"episodes": n, "success": sum(m["success"] for m in ms), "collisions": sum(m["collision"] for m in ms),
            "time_s": float(np.mean([m["time_s"] for m in succ])) if succ else None,
            "e_cbf": mean("e_cbf"),
            "active_pct": 100 * sum(m["cbf_active_ratio"] * m["control_steps"] for m in ms) / max(steps, 1),
            "infeasible_pct": 100 * sum(m["qp_infeasible_ratio"] * m["control_steps"] for m in ms) / max(steps, 1),
            "m_img": mean("m_img_mean_m"), "m_exec": mean("m_exec_mean_m"),
            "clearance_m": mean("min_clearance_m")}


def _f(v, d=2):
    return "–" if v is None else f"{v:.{d}f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", nargs="+", default=None)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    rows = [r for r in ROWS if args.only is None or r.name in args.only]
    tasks = sorted({(v, r.method, s, seed) for r in rows for v in (r.ours, r.alt) for s in r.scenes
                    for seed in range(args.seeds)})
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    results = {}
    with ProcessPoolExecutor(args.workers) as pool:
        for variant, scenario, seed, m in pool.map(_episode, tasks):
            results[(variant, m["method"], scenario, seed)] = m
    out = []
    print("| row | variant | episodes | success | collisions | time (s) | clearance (m) | E_CBF | active (%) | "
          "QP infeas. (%) | m img (m) | m exec (m) |")
    print("|:---|:---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        for v in (r.ours, r.alt):
            ms = [results[(v, r.method, s, seed)] for s in r.scenes for seed in range(args.seeds)]
            s = summarize(ms)
            out.append({"row": r.name, "variant": v, "what": r.what, "scenes": r.scenes, **s})
            print(f"| {r.name} | {v} | {s['episodes']} | {s['success']} | {s['collisions']} | {_f(s['time_s'])} | "
                  f"{_f(s['clearance_m'])} | {_f(s['e_cbf'])} | {_f(s['active_pct'])} | {_f(s['infeasible_pct'])} | "
                  f"{_f(s['m_img'], 3)} | {_f(s['m_exec'], 3)} |", flush=True)
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
