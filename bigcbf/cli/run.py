"""bigcbf run: one episode of a scenario with a method and a seed."""
from __future__ import annotations

from pathlib import Path

from .argtypes import nonneg_int, path_arg

HELP = "run one episode (scenario name or .toml file, method, seed); print its metrics, optionally a video/log"


def add_arguments(p):
    p.add_argument("scenario", metavar="SCENARIO_OR_FILE", help="a name from 'bigcbf scenarios' or a path to a .toml")
    p.add_argument("--method", default="big-cbf", help="planner (default big-cbf); see 'bigcbf methods'")
    p.add_argument("--seed", type=nonneg_int, default=0, help="seed of the paired world (default 0)")
    p.add_argument("--profile", type=path_arg, default=None,
                   help="stack parameters / calibrated uncertainty profile TOML (default: Table I)")
    p.add_argument("--perception", choices=["lidar", "truth"], default="lidar",
                   help="obstacles from the LiDAR pipeline (default) or, for debugging, from the simulator's truth")
    p.add_argument("--video", type=path_arg, default=None, help="write an H.264 MP4 of the episode")
    p.add_argument("--camera", choices=["top", "track"], default="top", help="video view (default top)")
    p.add_argument("--log", type=path_arg, default=None, help="record the episode as ROS 2 MCAP")
    p.add_argument("--json", action="store_true", help="print one JSON object")


def load_params(path):
    """The stack parameters of ``--profile`` (Table I without one). A calibrated profile whose translational axes
    were not identified by the calibration gets a note on stderr: the behaviors command vx and vy, and for an
    unidentified axis the profile holds the nominal model, not a measurement."""
    import sys

    from ..params.stack import SIMULATION, load_stack_params
    if path is None:
        return SIMULATION
    params = load_stack_params(path)
    missing = [a for a, ok in zip(("vx", "vy", "wz"), params.uncertainty.execution.identified[:2]) if not ok]
    if missing:
        print(f"note: {path}: {', '.join(missing)} not identified by the calibration; its execution model and "
              "residual bound are the nominal ones, not measured", file=sys.stderr)
    return params


def check_output(path: Path, what: str) -> None:
    """Refuse to write where that would fail late or destroy something (see ``bigcbf.outputs``)."""
    from ..outputs import check_output_file
    check_output_file(path, what)


def run(args) -> int:
    from ..control.methods import METHODS
    from ..episode import Episode
    from ..outputs import strict_json
    from ..scenario import load_scenario

    scenario = load_scenario(args.scenario, args.seed)
    METHODS.get(args.method)
    params = load_params(args.profile)
    for path, what in ((args.video, "video"), (args.log, "log")):
        if path is not None:
            check_output(path, what)
    ep = Episode(scenario, args.method, args.seed, params, perception=args.perception)
    outputs = []
    try:
        if args.video is not None:
            from ..video import EpisodeVideo
            outputs.append(EpisodeVideo(ep, args.video, camera=args.camera))
        if args.log is not None:
            from ..logio.episode_log import EpisodeLogger
            outputs.append(EpisodeLogger(ep, args.log))
        res = ep.run()
    except BaseException:
        for o in outputs:                # an unfinished video or log is dropped; the paths stay as they were
            o.abort()
        raise
    for o in outputs:
        o.close()
    out = res.metrics()
    if args.json:
        print(strict_json(out))
    else:
        for k, v in out.items():
            if k == "mode_history":
                v = " ".join(f"{t:.1f}:{m}" for t, m in v)
            print(f"{k:<22} {v:.4g}" if isinstance(v, float) else f"{k:<22} {v}")
    if args.video is not None and not args.json:
        print(f"wrote {args.video}")
    return 0
