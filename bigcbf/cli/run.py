"""bigcbf run: one episode of a scenario with a method and a seed."""
from __future__ import annotations


from .argtypes import nonneg_int, path_arg

HELP = "run one episode (scenario name or .toml file, method, seed); print its metrics, optionally a video/log"


def add_arguments(p):
    p.add_argument("scenario", metavar="SCENARIO_OR_FILE", help="a name from 'bigcbf scenarios' or a path to a .toml")
    p.add_argument("--method", default="big-cbf", metavar="M",
                   help="planner (default big-cbf): a name from 'bigcbf methods' or package.module:Class")
    p.add_argument("--seed", type=nonneg_int, default=0, help="seed of the paired world (default 0)")
    p.add_argument("--config", type=path_arg, default=None, metavar="RUN.toml",
                   help="run configuration: [stack], [perception], [pedestrians], [methods.NAME] tables "
                        "(docs/extending.md; default: every default)")
    p.add_argument("--profile", type=path_arg, default=None,
                   help="stack parameters / calibrated uncertainty profile TOML over the configuration's [stack] "
                        "(default: Table I with the twin-calibrated profile of the simulated X3, "
                        "bigcbf/profiles/stack/x3_sim.toml)")
    p.add_argument("--perception", choices=["lidar", "truth"], default="lidar",
                   help="obstacles from the LiDAR pipeline (default) or, for debugging, from the simulator's truth")
    p.add_argument("--video", type=path_arg, default=None, help="write an H.264 MP4 of the episode")
    p.add_argument("--camera", choices=["top", "track"], default="top", help="video view (default top)")
    p.add_argument("--log", type=path_arg, default=None, help="record the episode as ROS 2 MCAP")
    p.add_argument("--live", nargs="?", type=int, const=8765, default=None, metavar="PORT",
                   help="stream the log's topics to Foxglove while the episode runs at real time (WebSocket on "
                        "127.0.0.1:PORT, default 8765; pip install 'bigcbf[live]')")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def stderr_note(text: str) -> None:
    import sys
    print(f"note: {text}", file=sys.stderr)


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


def run(args) -> int:
    from ..api import load_config, run_episode
    from ..outputs import strict_json

    config = load_config(args.config, args.profile, notes=stderr_note)
    live = None
    if args.live is not None:
        live = start_live(args.live)
    try:
        res = run_episode(args.scenario, args.method, args.seed, config=config, perception=args.perception,
                          video=args.video, camera=args.camera, log=args.log, live=live)
    finally:
        if live is not None:
            live.close()
    out = res.metrics()
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
