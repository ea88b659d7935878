"""bigcbf replay: drive the MuJoCo model with a log's commands and compare with its odometry."""
from __future__ import annotations

from pathlib import Path

from .argtypes import float_in, path_arg

#: the documented range of --window [s] (twin.replay.MIN_WINDOW_S, MAX_WINDOW_S; tests/test_param_ranges.py checks
#: that they agree: the CLI does not import the twin just to build its parser)
MIN_WINDOW_S, MAX_WINDOW_S = 0.1, 3600.0

HELP = ("replay a log's commands through the MuJoCo model (nominal vs calibrated, optionally fitted or model-fitted on a "
        "held-out split); errors, video")


def add_arguments(p):
    p.add_argument("log", type=path_arg, metavar="LOG", help="ROS 1 bag, ROS 2 bag folder or MCAP file")
    p.add_argument("--profile", type=path_arg, default=None, metavar="PROFILE.toml",
                   help="uncertainty profile whose execution model (A, d) is replayed (default: calibrate the log)")
    p.add_argument("--video", type=path_arg, default=None, metavar="PATH.mp4",
                   help="top view with the logged and simulated paths (H.264 MP4)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--fit", action="store_true",
                   help="also fit the model's latency, gains and floor friction to the log (slow: ~40 replays)")
    p.add_argument("--window", type=float_in(MIN_WINDOW_S, MAX_WINDOW_S, "a window in seconds"), default=5.0,
                   metavar="S", help=f"pose-drift window in seconds (5; in [{MIN_WINDOW_S:g}, {MAX_WINDOW_S:g}))")
    p.add_argument("--cmd-topic", default=None, help="command topic (default: found by type)")
    p.add_argument("--odom-topic", default=None, help="odometry topic (default: found by type)")
    p.add_argument("--model", action="store_true",
                   help="also fit the MuJoCo model behind the command layer (mujoco.sysid, as bigcbf calibrate "
                        "--model) on the first part of the log and score every model on the rest (--holdout)")
    p.add_argument("--robot", type=path_arg, default=None, metavar="DIR",
                   help="also replay a fitted robot folder (bigcbf calibrate --model DIR) behind its command layer")
    p.add_argument("--holdout", type=float_in(0.0, 0.9, "a fraction of the log"), default=None, metavar="F",
                   help="score on the last fraction F of the log and calibrate (and fit) on the rest (default 0.4 "
                        "with --model, else 0: the whole log)")
    p.add_argument("--save-robot-profile", type=path_arg, default=None, metavar="PATH.toml",
                   help="write the calibrated (or fitted) simulator robot profile (for bigcbf record calibration)")


def run(args) -> int:
    from ..errors import UserError
    from ..outputs import check_distinct, check_output_file, strict_json
    from ..params.toml_io import save

    check_distinct({"log": args.log, "--profile": args.profile},
                   {"--video": args.video, "--save-robot-profile": args.save_robot_profile})
    for path, what in ((args.video, "video"), (args.save_robot_profile, "robot profile")):
        if path is not None:                 # before the replay: a path that cannot be written fails now
            check_output_file(path, what)
    from twin.replay import ReplayOptions, replay_log

    if args.robot is not None:
        from ..robots import folder
        folder(str(args.robot))              # not a robot folder: one line saying what one holds
    if args.model:
        from twin.model_fit import require_sysid
        require_sysid()                      # before the work: mujoco.sysid missing is one line
    holdout = args.holdout if args.holdout is not None else (0.4 if args.model else 0.0)
    res = replay_log(args.log, args.profile, opt=ReplayOptions(window_s=args.window, fit=args.fit, model=args.model,
                                                               holdout=holdout),
                     video=args.video, cmd_topic=args.cmd_topic, odom_topic=args.odom_topic, robot_dir=args.robot)
    best = res.runs.get("fitted", res.runs.get("calibrated"))
    if args.save_robot_profile is not None:
        if best is None:
            raise UserError("no calibrated model to save: the log could not be calibrated (see the notes with "
                            "--json)", file=str(args.log))
        save(best.profile, args.save_robot_profile,
             header=f"Simulator robot profile ({best.name}) that replays {args.log}; from `bigcbf replay`.")
    if args.json:
        print(strict_json(res.to_json()))
        return 0
    print_result(res, args, best, holdout)
    for path in (args.video, args.save_robot_profile):
        if path is not None:
            print(f"wrote {path}")
    return 0


def print_result(res, args, best, holdout: float) -> None:
    """The replay's table, the identified axes, the best profile, the model fit and the notes."""
    print(f"replay of {args.log}: velocity RMSE (vx m/s, vy m/s, wz rad/s) and pose drift over {args.window:g} s "
          f"windows, simulated odometry vs logged"
          + ("" if res.scored_from is None else
             f"; scored on the held-out last {holdout:.0%} (from {res.scored_from - res.runs['nominal'].t[0]:.1f} s), "
             "calibrated on the rest"))
    print(f"{'model':<11} {'rmse vx':>8} {'rmse vy':>8} {'rmse wz':>8} {'drift mean':>11} {'drift max':>10} "
          f"{'yaw mean':>9} {'final err':>10}")
    for name in ("nominal", "calibrated", "fitted", "model"):
        r = res.runs.get(name)
        if r is None:
            if name == "calibrated":
                print(f"{name:<11} {'n/a':>8}   (the log could not be calibrated: see the notes)")
            continue
        print(f"{name:<11} {r.rmse[0]:8.4f} {r.rmse[1]:8.4f} {r.rmse[2]:8.4f} {r.drift_mean_m:10.3f}m "
              f"{r.drift_max_m:9.3f}m {r.yaw_drift_mean_rad:8.3f}r {r.final_error_m:9.3f}m")
    if res.identified is not None:
        print("identified axes: " + ", ".join(a for a, x in zip(("vx", "vy", "wz"), res.identified) if x)
              + ("; calibrated worse than nominal on: " + ", ".join(res.worse_axes) if res.worse_axes else
                 "; calibrated no worse than nominal on any of them"))
    if best is not None:
        p = best.profile
        lim = []
        if p.wheel_speed_max_mps is not None:
            lim.append(f"wheel speed {p.wheel_speed_max_mps:.3f} m/s"
                       + (f" (yaw lever {p.wheel_yaw_lever_m:.3f} m)" if p.wheel_yaw_lever_m is not None else ""))
        if p.wheel_accel_max_mps2 is not None:
            lim.append(f"wheel acceleration {p.wheel_accel_max_mps2:.2f} m/s^2")
        print(f"{best.name} profile: latency {p.latency_s:.3f} s, gain diag "
              f"{', '.join(f'{p.gain[j][j]:.3f}' for j in range(3))}, bias {', '.join(f'{x:+.3f}' for x in p.bias)}"
              + (f", floor friction {p.floor_friction:.3f}" if p.floor_friction is not None else "")
              + (", " + ", ".join(lim) if lim else ""))
    if res.model_fit is not None:
        print("\n".join(res.model_fit.summary_lines()))
    for n in res.notes:
        print(f"note: {n}")
