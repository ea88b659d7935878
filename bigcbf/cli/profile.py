"""bigcbf profile simulate: the stack's uncertainty profile of a simulated robot, made by the twin."""
from __future__ import annotations

import json
from pathlib import Path

from .argtypes import nonneg_int, positive_float, robot_profile_arg

HELP = ("make the stack's uncertainty profile of a simulated robot: record its calibration drive, calibrate it, "
        "write the profile run and bench use")


def add_arguments(p):
    p.add_argument("what", choices=["simulate"],
                   help="simulate: record a calibration drive of the simulated robot and calibrate it")
    p.add_argument("--robot-profile", type=robot_profile_arg, default="x3_sim", metavar="NAME|FILE",
                   help="the simulated robot: a shipped robot profile (x3_sim, the default; x3_hardware) or a TOML")
    p.add_argument("--out", type=Path, default=None, metavar="PATH.toml",
                   help="where to write (default for a shipped robot R: the package's profiles/stack/R.toml, the "
                        "file run and bench read)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="seed of the drive and of the robot's noise (0)")
    p.add_argument("--duration", type=positive_float, default=None, metavar="S",
                   help="length of the calibration drive in seconds (default 120)")
    p.add_argument("--base", choices=["simulation", "physical"], default="simulation",
                   help="the preset the profile overlays (validation only; default simulation)")
    p.add_argument("--log", type=Path, default=None, metavar="PATH.mcap", help="also keep the drive's log here")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def run(args) -> int:
    from ..errors import UserError
    from ..params.stack import PHYSICAL, SIMULATION, stack_profile_path
    from ..scenario import profile_files

    robot = args.robot_profile
    shipped = profile_files().get(robot.stem) == robot
    out = args.out
    if out is None:
        if not shipped:
            raise UserError("give --out for a robot profile that is not shipped", field="--out")
        out = stack_profile_path(robot.stem)
    duration = 120.0 if args.duration is None else args.duration
    if duration < 30.0:
        raise UserError(f"a calibration drive for a stack profile needs at least 30 s, got {duration:g}",
                        field="--duration")
    from .record import MAX_DURATION_S
    if duration > MAX_DURATION_S:           # as bigcbf record: 1e9 s ran until killed
        raise UserError(f"a calibration drive is at most {MAX_DURATION_S:g} s, got {duration:g}", field="--duration")
    from ..outputs import check_distinct, check_output_file

    check_distinct({"--robot-profile": robot}, {"--out": out, "--log": args.log})
    for path, what in ((out, "profile"), (args.log, "log")):
        if path is not None:                 # before the drive: a path that cannot be written fails now
            check_output_file(path, what)
    from twin.stackprofile import simulate_stack_profile

    res = simulate_stack_profile(robot, out, seed=args.seed, duration_s=duration,
                                 base=PHYSICAL if args.base == "physical" else SIMULATION, log=args.log)
    if args.json:
        print(json.dumps(res))
        return 0
    u = res["tables"]["uncertainty"]
    ex = u["execution"]
    diag = ", ".join(f"{ex['A'][i][i]:.3f}" for i in range(3))
    print(f"wrote {out}: tau95 {u['tau95_s']:.4f} s, A diag {diag}, "
          f"residual bound {min(ex['residual_bound_mps']):.4f}-{max(ex['residual_bound_mps']):.4f} m/s over a "
          f"{ex['residual_horizon_s']:.3f} s horizon (from {robot.name}, seed {args.seed}, {duration:g} s drive)")
    for w in res["calibration"]["warnings"]:
        print(f"note: {w}")
    return 0
