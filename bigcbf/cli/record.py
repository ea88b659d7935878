"""bigcbf record: record a calibration drive in the simulator as a robot log (ROS 2 MCAP)."""
from __future__ import annotations

from .argtypes import nonneg_int, path_arg, positive_float, robot_profile_arg

#: the longest calibration drive (1 h of simulated driving, ~7 min of computing, ~200 MB of MCAP)
MAX_DURATION_S = 3600.0

HELP = "record a calibration drive (steps, ramps, sweeps) of a simulated robot with a given profile as ROS 2 MCAP"


def add_arguments(p):
    p.add_argument("what", choices=["calibration"], help="what to record (calibration: the calibration drive)")
    p.add_argument("--robot-profile", type=robot_profile_arg, required=True, metavar="NAME|FILE",
                   help="the simulated robot: a shipped robot profile (x3_sim, x3_hardware) or a .toml of its "
                        "imperfections (latency_s, latency_jitter_s, gain, bias, residual_max, "
                        "residual_hold_s, floor_friction, wheel_speed_max_mps, wheel_accel_max_mps2, "
                        "wheel_yaw_lever_m); an empty file is the ideal robot")
    p.add_argument("--out", type=path_arg, required=True, metavar="PATH.mcap", help="the log to write")
    p.add_argument("--seed", type=nonneg_int, default=0, help="seed of the drive program and of the imperfections")
    p.add_argument("--duration", type=positive_float, default=120.0, metavar="S",
                   help="length of the drive in seconds (default 120; 5 to 3600)")
    p.add_argument("--json", action="store_true", help="print a JSON summary")


def run(args) -> int:
    from ..errors import UserError
    from ..params.robot import RobotProfile
    from ..params.toml_io import load

    from ..outputs import check_distinct, check_output_file, strict_json

    profile = load(RobotProfile, args.robot_profile)
    if args.duration < 5.0:
        raise UserError(f"a calibration drive needs at least 5 s, got {args.duration}", field="--duration")
    if args.duration > MAX_DURATION_S:
        raise UserError(f"a calibration drive is at most {MAX_DURATION_S:g} s, got {args.duration:g}",
                        field="--duration")
    check_distinct({"--robot-profile": args.robot_profile}, {"--out": args.out})
    check_output_file(args.out, "log")
    from twin.record import record_calibration

    summary = record_calibration(profile, args.out, seed=args.seed, duration_s=args.duration)
    if args.json:
        print(strict_json(summary))
    else:
        n = sum(summary["messages"].values())
        print(f"wrote {args.out}: {args.duration:g} s calibration drive, {n} messages "
              f"({', '.join(f'{k} {v}' for k, v in summary['messages'].items())}); back to the start "
              f"{summary['recentrings']} times, at most {summary['max_distance_m']:.2f} m from it")
    return 0
