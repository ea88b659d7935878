"""bigcbf sim --ros2: the MuJoCo twin as a ROS 2 robot (bigcbf/ros2/sim_node.py, docs/ros2.md)."""
from __future__ import annotations

from ..limits import MAX_TIME_LIMIT_S, MIN_TIME_LIMIT_S
from .argtypes import float_in_range, nonneg_int, path_arg, positive_float, robot_profile_arg

HELP = "the twin as a ROS 2 robot: /scan /odom /imu /tf /clock out, /cmd_vel in, with the scene's people (--ros2)"


def add_arguments(p):
    from ..ros2.cli_common import add_dds_arguments

    p.add_argument("scenario", metavar="SCENARIO_OR_FILE", help="a name from 'bigcbf scenarios' or a path to a .toml")
    add_dds_arguments(p)
    p.add_argument("--seed", type=nonneg_int, default=0, help="seed of the paired world (default 0)")
    p.add_argument("--config", type=path_arg, default=None, metavar="RUN.toml",
                   help="run configuration ([pedestrians], [stack] for T_C and the goal region; as bigcbf run)")
    p.add_argument("--robot-profile", type=robot_profile_arg, default=None, metavar="NAME|FILE",
                   help="the simulated robot's imperfections (as bigcbf run)")
    p.add_argument("--time-limit", type=float_in_range(MIN_TIME_LIMIT_S, MAX_TIME_LIMIT_S, "a time limit in seconds"),
                   default=None, metavar="S", help="end the episode after S simulated seconds (default: the scenario's)")
    p.add_argument("--speed", type=positive_float, default=1.0,
                   help="real time only: simulated seconds per wall-clock second (default 1)")
    p.add_argument("--cmd-timeout", type=positive_float, default=0.5, metavar="S",
                   help="real time only: a /cmd_vel older than S wall-clock seconds counts as zero (default 0.5)")
    p.add_argument("--wait", type=positive_float, default=30.0, metavar="S",
                   help="--lockstep: wait at most S seconds for the filter node at the start and for each answer "
                        "(default 30)")
    p.add_argument("--json", action="store_true", help="print the episode's metrics as one JSON object")


def run(args) -> int:
    import sys

    from ..api import load_config
    from ..logio.interrupts import interrupts_as_keyboard_interrupt
    from ..outputs import strict_json
    from ..ros2.cli_common import domain_id
    from ..ros2.transport import Node, import_cyclonedds
    from .run import config_note, load_run_scenario

    import_cyclonedds()
    domain = domain_id(args)
    scenario = load_run_scenario(args.scenario, args.seed, args.robot_profile)
    config = load_config(args.config, None, notes=config_note)
    from ..ros2.sim_node import TwinEpisode, TwinNode

    ep = TwinEpisode.from_config(scenario, None, args.seed, config, time_limit_s=args.time_limit)
    node = Node("bigcbf_sim", domain, loopback=args.loopback)
    twin = TwinNode(ep, node, lockstep=args.lockstep, speed=args.speed, cmd_timeout_s=args.cmd_timeout,
                    answer_timeout_s=args.wait)
    mode = "lock-step" if args.lockstep else f"{args.speed:g} x real time"
    print(f"bigcbf sim: {scenario.name} seed {args.seed} on DDS domain {node.domain_id}"
          f"{' (loopback)' if args.loopback else ''}, {mode}", file=sys.stderr)
    try:
        with interrupts_as_keyboard_interrupt():
            res = twin.run(wait_s=args.wait)
    finally:
        node.close()
    out = res.metrics()
    if args.json:
        print(strict_json(out))
    else:
        for k in ("success", "collision", "timeout", "time_s", "min_clearance_m", "final_goal_dist_m",
                  "control_steps"):
            print(f"{k:<22} {out[k]:.4g}" if isinstance(out[k], float) else f"{k:<22} {out[k]}")
    return 0
