"""bigcbf calibrate: the shared-uncertainty terms of eq:uncertainty_margin (21) (tau95, A, d, e_exec, e_ZOH) from a
robot log."""
from __future__ import annotations

from .argtypes import float_in, path_arg, positive_float

HELP = "calibrate tau95, the execution model (A, d, residual bound e_exec) and e_ZOH from a robot log"

#: the files ``--report DIR`` may write (twin/report.py's write_report; a figure with nothing to show is left out):
#: none of them may be the log or ``--out``
REPORT_FILES = ("index.md", "command_response.png", "delay.png", "residuals.png", "limits.png", "calibration.json")


def add_arguments(p):
    p.add_argument("log", type=path_arg, metavar="LOG", help="ROS 1 bag, ROS 2 bag folder or MCAP file")
    p.add_argument("--out", type=path_arg, default=None, metavar="PROFILE.toml",
                   help="write the uncertainty profile (use with bigcbf run --profile)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--report", type=path_arg, default=None, metavar="DIR", help="write plots and calibration.json here")
    p.add_argument("--cmd-topic", default=None, help="command topic (Twist/TwistStamped; default: found by type)")
    p.add_argument("--odom-topic", default=None, help="odometry topic (nav_msgs/Odometry; default: found by type)")
    p.add_argument("--scan-topic", default=None, help="laser scan topic for the perception latency (default: by type)")
    p.add_argument("--no-scan", action="store_true", help="ignore scans (tau95 = actuation delay only)")
    p.add_argument("--scan-clock", choices=["auto", "stamps", "log"], default="auto",
                   help="scan acquisition times: header stamps when on the log's clock (auto), always the header "
                        "stamps, or always the log times")
    p.add_argument("--cmd-timeout", type=positive_float, default=None, metavar="S",
                   help="the robot's command timeout, if its firmware stops when commands stop (default: none, "
                        "the last command is held)")
    p.add_argument("--coverage", type=float_in(0.5, 1.0, "a coverage"), default=0.95,
                   help="stated coverage of the residual bound (0.95)")
    p.add_argument("--model", type=path_arg, default=None, metavar="DIR",
                   help="also fit the MuJoCo model behind the command layer (wheel gain and damping, floor friction, "
                        "chassis mass; mujoco.sysid, about a minute of CPU per minute of log) and write it as the "
                        "robot folder DIR (bigcbf replay LOG --robot DIR; [robot] model = \"DIR\" in a scenario)")
    p.add_argument("--robot", default="rosmaster_x3", metavar="NAME|DIR",
                   help="with --model: the robot whose model is fitted (a registered robot or a robot folder; "
                        "default rosmaster_x3)")


def run(args) -> int:
    from dataclasses import replace

    from twin.calibrate import CalibrationOptions, calibrate_series, read_log, summary_lines, write_profile

    from ..errors import UserError
    from ..outputs import check_distinct, check_output_dir, check_output_file, strict_json
    if args.no_scan and args.scan_topic is not None:
        raise UserError("--scan-topic and --no-scan contradict each other: give one")
    report = {} if args.report is None else {f"--report's {n}": args.report / n for n in REPORT_FILES}
    check_distinct({"log": args.log}, {"--out": args.out, **report})
    if args.out is not None:                 # before the work: a path that cannot be written fails now
        check_output_file(args.out, "profile")
    if args.report is not None:
        check_output_dir(args.report, "report folder")
    if args.model is not None:
        from twin.model_fit import require_sysid

        from ..robots import folder
        require_sysid()                      # before the work: mujoco.sysid missing is one line
        folder(args.robot)                   # an unknown robot: one line naming the known ones
        check_distinct({"log": args.log}, {"--model": args.model, "--out": args.out, "--report": args.report})
        check_output_dir(args.model, "model folder")
    elif args.robot != "rosmaster_x3":
        raise UserError("--robot names the model --model fits: give --model DIR too")
    opt = CalibrationOptions()
    opt = replace(opt, residual=replace(opt.residual, coverage=args.coverage),
                  delay=replace(opt.delay, scan_clock=args.scan_clock), max_command_age_s=args.cmd_timeout)
    data = read_log(args.log, args.cmd_topic, args.odom_topic, args.scan_topic, use_scan=not args.no_scan)
    cal = calibrate_series(data, opt)
    written = []
    if args.out is not None:
        written.append(write_profile(cal, args.out))
    if args.report is not None:
        from twin.report import write_report
        written += write_report(cal, args.report, data.cmd.t, data.cmd.u)
    fit = None
    if args.model is not None:
        from twin.model_fit import fit_log, write_robot_folder
        fit = fit_log(data, args.robot, cal_opt=opt)
        written += write_robot_folder(fit, args.model)
    if args.json:
        out = cal.to_json()
        out["model"] = None if fit is None else fit.to_json()
        out["written"] = [str(p) for p in written]
        print(strict_json(out))
    else:
        print("\n".join(summary_lines(cal) + ([] if fit is None else fit.summary_lines())))
        for p in written:
            print(f"wrote {p}")
    return 0
