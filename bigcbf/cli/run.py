"""bigcbf run: one episode of a scenario with a method and a seed."""
from __future__ import annotations

from ..limits import MAX_TIME_LIMIT_S, MIN_TIME_LIMIT_S         # --time-limit's range: a scenario file's own
from .argtypes import float_in_range, nonneg_int, path_arg, positive_float, robot_profile_arg

HELP = "run one episode (scenario name or .toml file, method, seed); print its metrics, optionally a video/log"


def add_arguments(p):
    p.add_argument("scenario", metavar="SCENARIO_OR_FILE", help="a name from 'bigcbf scenarios' or a path to a .toml")
    p.add_argument("--method", default="big-cbf", metavar="M",
                   help="planner (default big-cbf): a name from 'bigcbf methods' or package.module:Class")
    p.add_argument("--seed", type=nonneg_int, default=0, help="seed of the paired world (default 0)")
    p.add_argument("--config", type=path_arg, default=None, metavar="RUN.toml",
                   help="run configuration: [stack], [perception], [pedestrians], [methods.NAME] tables "
                        "(docs/extending.md; default: every default)")
    p.add_argument("--profile", type=path_arg, default=None, metavar="STACK.toml",
                   help="the STACK's uncertainty profile (tau95, execution model, residual bound), as 'bigcbf "
                        "calibrate' or 'bigcbf profile simulate' writes it, laid over the configuration's [stack] "
                        "(default: Table I with the profile of the simulated X3, bigcbf/profiles/stack/x3_sim.toml). "
                        "It changes what the stack assumes, not how the simulated robot behaves: that is "
                        "--robot-profile")
    p.add_argument("--robot-profile", type=robot_profile_arg, default=None, metavar="NAME|FILE",
                   help="the SIMULATED ROBOT's imperfections (latency, gain, bias, residual noise, wheel limits, "
                        "sensors, faults): a shipped robot profile (x3_sim, x3_hardware) or a robot-profile .toml; "
                        "replaces the robot profile the scenario builds on (its robot_profile_base, default x3_sim); "
                        "the scenario's own [robot_profile] keys (a slippery floor, its faults) still apply on top")
    p.add_argument("--route", choices=["on", "off"], default=None,
                   help="the route layer under the method (bigcbf/control/route.py: a map from the robot's own scans, "
                        "an A* path on it, its look-ahead point as the method's goal), as the configuration's [route] "
                        "enabled (default: the configuration's, off: the paper's set-up)")
    p.add_argument("--time-limit", type=float_in_range(MIN_TIME_LIMIT_S, MAX_TIME_LIMIT_S, "a time limit in seconds"),
                   default=None, metavar="S",
                   help=f"end the episode (a timeout) after S simulated seconds, {MIN_TIME_LIMIT_S:g} <= S <= {MAX_TIME_LIMIT_S:g} "
                        "(default: the scenario's time_limit_s)")
    p.add_argument("--perception", choices=["lidar", "truth"], default="lidar",
                   help="obstacles from the LiDAR pipeline (default) or, for debugging, from the simulator's truth")
    p.add_argument("--video", type=path_arg, default=None, help="write an H.264 MP4 of the episode")
    p.add_argument("--camera", choices=["top", "track"], default="top", help="video view (default top)")
    p.add_argument("--log", type=path_arg, default=None, help="record the episode as ROS 2 MCAP")
    p.add_argument("--live", nargs="?", type=int, const=8765, default=None, metavar="PORT",
                   help="stream the log's topics to Foxglove while the episode runs at real time (WebSocket on "
                        "127.0.0.1:PORT, default 8765; pip install 'bigcbf[live]')")
    p.add_argument("--live-wait", type=positive_float, default=None, metavar="SECONDS",
                   help="with --live: hold the start until a Foxglove client has subscribed, at most SECONDS "
                        "(then start anyway, with a note)")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def stderr_note(text: str) -> None:
    import sys
    print(f"note: {text}", file=sys.stderr)


#: remarks about the run configuration (``config_note``: the tuned defaults' provenance, a profile's unidentified
#: axis), printed by ``cli.main`` once the command has ended without an error, so that a command that fails prints
#: its one error line only
PENDING_NOTES: list[str] = []


def config_note(text: str) -> None:
    """A remark about the configuration, kept until the command ends, then printed on stderr as ``note: ...``
    unless the command failed (its error is then its only line)."""
    PENDING_NOTES.append(text)


def flush_notes(print_them: bool = True) -> None:
    if print_them:
        for text in PENDING_NOTES:
            stderr_note(text)
    PENDING_NOTES.clear()


def start_live(port: int):
    """A LiveWriter on 127.0.0.1:port, announced on stderr; UserError without foxglove-sdk or with a busy port."""
    import sys

    from ..errors import UserError
    try:
        from ..logio.live import LiveWriter
        import foxglove  # noqa: F401
    except ImportError:
        raise UserError("--live needs foxglove-sdk, which is not installed: pip install 'bigcbf[live]'") from None
    if not 0 <= port < 65536:
        raise UserError(f"--live: a port is in [0, 65535], got {port}")
    try:
        live = LiveWriter(port=port)
    except Exception as exc:      # the SDK raises its own error type for a port in use
        raise UserError(f"--live: cannot serve on 127.0.0.1:{port} ({exc})") from None
    print(f"streaming to Foxglove on {live.url} (open a Foxglove WebSocket connection); real time", file=sys.stderr)
    return live


def load_run_scenario(scenario, seed: int, robot_profile=None):
    """The scenario (a name or a .toml path) drawn for ``seed``; with ``robot_profile`` (a robot-profile file, as
    :func:`bigcbf.cli.argtypes.robot_profile_arg` returns it) in place of the base robot profile the scenario
    names (``robot_profile_base``): the scenario's own ``[robot_profile]`` keys are laid over it as usual. A bad
    profile is one UserError naming its file and the field."""
    from dataclasses import replace

    from ..scenario import load_scenario, robot_profile_table

    if robot_profile is None:
        return load_scenario(scenario, seed)
    robot_profile_table(robot_profile)            # checked on its own, so that an error names this file
    sc = load_scenario(scenario, seed, robot_profile_text=robot_profile.read_text())
    return replace(sc, robot_profile_base=str(robot_profile))


def with_route(config, route: str | None):
    """``config`` with its route layer switched on or off by ``--route`` (None: as the configuration says)."""
    from dataclasses import replace
    if route is None:
        return config
    return config.replace(route=replace(config.route, enabled=route == "on"))


def run(args) -> int:
    import sys

    from ..api import load_config, run_episode
    from ..errors import UserError
    from ..logio.interrupts import interrupts_as_keyboard_interrupt
    from ..outputs import check_distinct, strict_json

    if args.live_wait is not None and args.live is None:
        raise UserError("--live-wait needs --live")
    scenario = load_run_scenario(args.scenario, args.seed, args.robot_profile)
    # before any work: no output onto an input (the scenario file, a profile) or onto the other output
    check_distinct({"scenario": scenario.file, "--config": args.config, "--profile": args.profile,
                    "--robot-profile": args.robot_profile}, {"--video": args.video, "--log": args.log})
    config = with_route(load_config(args.config, args.profile, notes=config_note), args.route)
    from ..sanity import describe, sensor_check
    for line in sensor_check(scenario.scene(), scenario.robot_profile.lidar, config.stack, scenario.robot_profile)[1]:
        stderr_note(line)                            # at the start: a sensor that cannot see the scene's obstacles
    live = None
    try:
        with interrupts_as_keyboard_interrupt():     # Ctrl-C, SIGTERM: one KeyboardInterrupt, never inside a log write
            if args.live is not None:
                live = start_live(args.live)
                if args.live_wait is not None and not live.wait_for_client(args.live_wait):
                    stderr_note(f"no Foxglove client subscribed within {args.live_wait:g} s; starting without one")
            res = run_episode(scenario, args.method, args.seed, config=config, perception=args.perception,
                              time_limit_s=args.time_limit, video=args.video, camera=args.camera, log=args.log,
                              live=live)
    except KeyboardInterrupt as exc:                 # what was recorded so far: X.partial.mcap, X.partial.mp4
        for path in getattr(exc, "partial_logs", ()):
            print(f"kept the log recorded so far as {path}", file=sys.stderr)
        for path in getattr(exc, "partial_videos", ()):
            print(f"kept the video recorded so far as {path}", file=sys.stderr)
        raise
    finally:
        if live is not None:
            live.close()
    out = res.metrics()
    for line in describe({k: v for k, v in res.warnings.items() if k != "lidar_sees_obstacles_late"}):
        stderr_note(line)
    if args.json:
        print(strict_json(out))
    else:
        for k, v in out.items():
            if k == "mode_history":
                v = " ".join(f"{t:.1f}:{m}" for t, m in v)
            print(f"{k:<22} {v:.4g}" if isinstance(v, float) else f"{k:<22} {v}")
        for path in (args.video, args.log):
            if path is not None:
                print(f"wrote {path}")
    return 0
