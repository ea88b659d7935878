"""bigcbf filter --ros2: the stack as a ROS 2 safety filter node (bigcbf/ros2/filter_node.py, docs/ros2.md).
Robot side: imports no simulator (mujoco, dm_control, cv2)."""
from __future__ import annotations

from .argtypes import nonneg_int, path_arg, positive_float

HELP = "the stack as a ROS 2 node: /scan /odom in, /cmd_vel out (big-cbf, big-cbf-plus, or the filter alone)"

METHOD_CHOICES = ("big-cbf", "big-cbf-plus", "filter")


def add_arguments(p):
    from ..ros2.cli_common import add_dds_arguments

    add_dds_arguments(p)
    p.add_argument("--method", choices=METHOD_CHOICES, default="big-cbf",
                   help="big-cbf (default) or big-cbf-plus: the planner and the filter; filter: the common CBF filter "
                        "alone on /cmd_vel_in (a Nav2 controller upstream)")
    p.add_argument("--profile", type=path_arg, default=None, metavar="STACK.toml",
                   help="the stack's uncertainty profile, as 'bigcbf calibrate' writes it for the robot (default: "
                        "Table I with the simulated X3's profile; the method's own keys: the shipped tuned configuration's)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="seed of the planner's random draws (default 0)")
    p.add_argument("--goal", type=_goal, default=None, metavar="X,Y",
                   help="the goal in the odom frame [m] (default: from /goal_pose)")
    for name, default in (("scan", "/scan"), ("odom", "/odom"), ("cmd", "/cmd_vel"), ("cmd-in", "/cmd_vel_in"),
                          ("goal", "/goal_pose")):
        p.add_argument(f"--{name}-topic", default=default, metavar="TOPIC", help=f"(default {default})")
    p.add_argument("--stamped", action="store_true",
                   help="publish /cmd_vel as TwistStamped (Nav2's enable_stamped_cmd_vel; always with --lockstep)")
    p.add_argument("--markers", action="store_true",
                   help="also publish /tracked_obstacles and /cbf/inflated_radius markers (for Foxglove)")
    p.add_argument("--scan-timeout", type=positive_float, default=0.5, metavar="S",
                   help="watchdog: zero command when the latest scan is older than S seconds (default 0.5)")
    p.add_argument("--odom-timeout", type=positive_float, default=0.5, metavar="S",
                   help="watchdog: zero command when no /odom came for S wall-clock seconds (default 0.5)")
    p.add_argument("--overrun-ms", type=positive_float, default=None, metavar="MS",
                   help="watchdog: a step that took longer than MS (from the message in to /cmd_vel out) sends zero "
                        "instead (default: the control period T_C, 50 ms; with --lockstep none, the twin's time "
                        "waits for the answer)")
    p.add_argument("--idle-exit", type=positive_float, default=None, metavar="S",
                   help="stop when no /odom came for S seconds after the first (default: run until Ctrl-C)")
    p.add_argument("--json", action="store_true", help="at the end, print the node's summary as one JSON object")


def _goal(s: str):
    import argparse
    import math
    parts = s.split(",")
    try:
        x, y = (float(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y (two numbers), got {s!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise argparse.ArgumentTypeError(f"expected two finite numbers, got {s!r}")
    return (x, y)


def run(args) -> int:
    import sys

    from ..logio.interrupts import interrupts_as_keyboard_interrupt
    from ..outputs import strict_json
    from ..ros2.cli_common import domain_id
    from ..ros2.transport import Node, import_cyclonedds
    from ..ros2.wire import check_topic

    import_cyclonedds()
    domain = domain_id(args)                 # every option checked before the warm-up
    for opt in ("scan_topic", "odom_topic", "cmd_topic", "cmd_in_topic", "goal_topic"):
        check_topic(getattr(args, opt), "--" + opt.replace("_", "-"))
    from ..api import load_config
    from ..ros2.filter_node import FilterNode, FilterOptions
    from ..ros2.stack import SafetyStack
    from .run import config_note

    # the run configuration every front door builds (the shipped tuned defaults included): the node runs the
    # method as `bigcbf run` and the bench do
    stack = SafetyStack.from_config(args.method, load_config(None, args.profile, notes=config_note), seed=args.seed)
    warm = stack.warm_up()
    opts = FilterOptions(scan_topic=args.scan_topic, odom_topic=args.odom_topic, cmd_topic=args.cmd_topic,
                         cmd_in_topic=args.cmd_in_topic, goal_topic=args.goal_topic, goal=args.goal,
                         stamped=args.stamped, lockstep=args.lockstep, markers=args.markers,
                         scan_timeout_s=args.scan_timeout, odom_timeout_s=args.odom_timeout,
                         overrun_ms=args.overrun_ms, idle_exit_s=args.idle_exit)
    node = Node("bigcbf_filter", domain, loopback=args.loopback)
    fnode = FilterNode(node, stack, opts)
    print(f"bigcbf filter: {args.method} on DDS domain {node.domain_id}{' (loopback)' if args.loopback else ''}"
          f"{', lock-step' if args.lockstep else ''}; ready (warm-up {warm:.1f} s)", file=sys.stderr, flush=True)
    try:
        with interrupts_as_keyboard_interrupt():
            fnode.spin()
    except KeyboardInterrupt:
        pass                              # Ctrl-C / SIGTERM: the normal end of a node; the summary follows
    finally:
        node.close()
    summary = fnode.stats.summary()
    if args.json:
        print(strict_json(summary))
    else:
        for k, v in summary.items():
            print(f"{k:<22} {v}")
    return 0
