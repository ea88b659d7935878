"""What a calibration log can tell of the model behind the command layer (issue 27): per fitted parameter, how far a
change of it moves the model's expected response, against the noise a fit must see that change through.

    .venv/bin/python scripts/twin_identifiability.py [--duration 40] [--seed 7] [--members 8] [--bin 0.5]
        [--rel 0.1] [--hidden wheel_kv=1.5 wheel_damping=0.1 floor_friction=0.6 base_mass=4.5] [--latency 0.05]
        [--json out.json]

A hidden X3 (``--hidden``; latency ``--latency``, no other imperfection) drives the calibration program
(``twin.record.record_calibration``, seed ``--seed``). Its log is binned as ``bigcbf calibrate --model`` bins it
(``twin.model_fit.problem``, ``--bin`` seconds), behind the command layer calibrated on the same log
(``twin.model_fit.log_front``, as the fit sees it; ``--exact-front``: the hidden one itself). The simulated
Mecanum contact is chaotic in yaw: one rollout is one draw of where each roller meets the floor. The model's
expected response is the mean of ``--members`` rollouts whose wheels start turned by random angles
(``twin.model_fit.ensemble_bins``). Per channel (vx, vy, wz, imu wz), the RMS over the bins of:

- ``log``: the log minus the expected response at the truth: what a fit against this one log sees as noise;
- ``null``: two expected responses at the truth from independent wheel angles: the ensemble's own sampling noise;
- per parameter, ``effect``: the expected response with that parameter times (1 + rel), minus the one at the truth
  (the same wheel angles).

and ``z`` = effect x sqrt(bins / block) / log, the effect against the log's noise over the drive's independent
4-s blocks (the bootstrap's block, ``ModelFitOptions.block_s``). A parameter is **resolved at rel** when, in some
channel, its effect is at least twice the null and its z at least 2: a fit of this log could then tell the truth
from a value rel away. Not resolved means the log cannot place it within rel, whatever the fit.
"""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from bigcbf.params.robot import RobotProfile
from twin.calibrate import CalibrationOptions, read_log
from twin.model_fit import (PARAMS_NAMES, ModelFitOptions, _imu, coordinates, ensemble_bins, front_of, log_front,
                            model_with, parameters, problem, write_robot_folder)
from twin.record import record_calibration
from twin.replay import _checked

ROBOT = "rosmaster_x3"
HIDDEN = {"wheel_kv": 1.5, "wheel_damping": 0.1, "floor_friction": 0.6, "base_mass": 4.5}


def rms(a: np.ndarray) -> np.ndarray:
    """Per channel (last axis), the root mean square over the bins."""
    return np.sqrt(np.mean(np.asarray(a, float) ** 2, axis=0))


def measure(hidden: dict, latency_s: float, duration: float, seed: int, members: int, bin_s: float, rel: float,
            tmp: Path, exact_front: bool = False) -> dict:
    """The table of the module docstring for one hidden model and its drive (``exact_front``: behind the hidden
    command layer itself instead of the one calibrated on the log)."""
    front = RobotProfile(latency_s=latency_s)
    write_robot_folder(model_with(ROBOT, hidden, front), tmp / "hidden")
    log = tmp / "drive.mcap"
    record_calibration(front, log, seed=seed, duration_s=duration, robot=str(tmp / "hidden"))
    raw = read_log(log, use_scan=False)
    if exact_front:
        data = _checked(raw, CalibrationOptions())[0]
        layer, imu = front_of(front), _imu(raw, float(data.cmd.t[0]))
    else:
        data, layer, imu, _ = log_front(raw, ROBOT)
    opt = ModelFitOptions(bin_s=bin_s)
    pb = problem(data, layer, ROBOT, opt, imu=imu)
    params = parameters(ROBOT)
    names = params.keys()
    kv_nominal = float(np.exp(params.as_nominal_vector()[0]))
    rng = np.random.default_rng(seed)
    angles = rng.uniform(0.0, 2 * np.pi, (members, 4))
    other = rng.uniform(0.0, 2 * np.pi, (members, 4))

    def expected(values: dict, at: np.ndarray) -> np.ndarray:
        params.update_from_vector(coordinates(names, [values[n] for n in names], kv_nominal))
        return ensemble_bins(pb, params, at).mean(axis=0)

    truth = expected(hidden, angles)
    n_bins = len(truth)
    log_noise = rms(pb.measured - truth)
    null = rms(truth - expected(hidden, other))
    independent = max(n_bins * bin_s / opt.block_s, 1.0)
    out = {"hidden": hidden, "latency_s": latency_s, "front_latency_s": layer.latency_s, "duration_s": duration,
           "seed": seed, "members": members,
           "bin_s": bin_s, "rel": rel, "bins": n_bins, "channels": pb.channels,
           "log": log_noise.tolist(), "null": null.tolist(), "params": {}}
    for n in names:
        changed = dict(hidden, **{n: hidden[n] * (1 + rel)})
        effect = rms(expected(changed, angles) - truth)
        z = effect * np.sqrt(independent) / np.maximum(log_noise, 1e-12)
        resolved = bool(np.any((effect >= 2 * null) & (z >= 2)))
        out["params"][n] = {"effect": effect.tolist(), "z": z.tolist(), "resolved": resolved}
    return out


def print_table(res: dict) -> None:
    ch = res["channels"]
    print(f"hidden {res['hidden']}, latency {res['latency_s']} s (in front: {res['front_latency_s']:.3f} s); "
          f"{res['duration_s']:g}-s drive (seed {res['seed']}), "
          f"{res['bins']} bins of {res['bin_s']} s, {res['members']} members; each parameter x {1 + res['rel']:g}")
    print(f"{'':16s}" + "".join(f"{c:>22s}" for c in ch))
    print(f"{'log noise':16s}" + "".join(f"{v:22.4f}" for v in res["log"]))
    print(f"{'null':16s}" + "".join(f"{v:22.4f}" for v in res["null"]))
    for n, p in res["params"].items():
        cells = "".join(f"{e:14.4f} (z {z:4.1f})" for e, z in zip(p["effect"], p["z"]))
        print(f"{n:16s}" + cells + ("   resolved" if p["resolved"] else "   NOT resolved"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--members", type=int, default=8)
    ap.add_argument("--bin", type=float, default=0.5)
    ap.add_argument("--rel", type=float, default=0.1)
    ap.add_argument("--latency", type=float, default=0.05)
    ap.add_argument("--hidden", nargs="*", default=[], metavar="NAME=VALUE",
                    help=f"hidden model values over {HIDDEN}; names: {', '.join(PARAMS_NAMES)}")
    ap.add_argument("--exact-front", action="store_true",
                    help="behind the hidden command layer itself (default: the one calibrated on the log, as "
                         "`bigcbf calibrate --model` fits)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args()
    hidden = dict(HIDDEN)
    for item in args.hidden:
        name, _, value = item.partition("=")
        if name not in HIDDEN:
            ap.error(f"--hidden: unknown parameter {name!r}; known: {', '.join(PARAMS_NAMES)}")
        hidden[name] = float(value)
    with tempfile.TemporaryDirectory(prefix="bigcbf-identifiability-") as tmp:
        res = measure(hidden, args.latency, args.duration, args.seed, args.members, args.bin, args.rel, Path(tmp),
                      args.exact_front)
    print_table(res)
    if args.json is not None:
        args.json.write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
