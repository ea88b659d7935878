"""bigcbf demo: required sidestepping with CBF-only and BIG-CBF on the same seed, side by side.

Each episode is built from the default run configuration, ``RunConfig()`` (Table I with the twin-calibrated stack
profile of the simulated X3), as ``bigcbf run``, ``bigcbf bench``, :func:`bigcbf.run_episode` and the Gymnasium
environment build theirs: the demo's big-cbf row is ``bigcbf run required_sidestepping --method big-cbf --seed S``.

``bigcbf demo --manoeuvre`` instead drives the bare robot through a scripted manoeuvre (forward, strafe,
diagonal, spin, arc) and prints commanded against achieved body velocities.
"""
from __future__ import annotations

from pathlib import Path

from .argtypes import nonneg_int, path_arg

HELP = ("required sidestepping, CBF-only vs BIG-CBF on one seed: renders/demo_required_sidestep.mp4 and both "
        "metric rows (--manoeuvre: the scripted robot drive)")
DEMO_SCENARIO = "required_sidestepping"
DEMO_METHODS = ("cbf-only", "big-cbf")

#: (label, body twist vx [m/s], vy [m/s], wz [rad/s], duration [s])
SEGMENTS = [
    ("forward", 0.5, 0.0, 0.0, 2.5),
    ("strafe left", 0.0, 0.4, 0.0, 2.5),
    ("diagonal", -0.3, -0.3, 0.0, 2.5),
    ("spin", 0.0, 0.0, 1.0, 2.5),
    ("arc", 0.3, 0.0, 0.6, 2.5),
]


def add_arguments(p):
    p.add_argument("--seed", type=nonneg_int, default=0, help="seed of the paired world (default 0)")
    p.add_argument("--video", type=path_arg, default=None,
                   help="output MP4 (default renders/demo_required_sidestep.mp4, or renders/demo.mp4 with --manoeuvre)")
    p.add_argument("--no-video", action="store_true", help="skip rendering, print the metrics only")
    p.add_argument("--manoeuvre", action="store_true", help="the scripted robot drive instead of the scenario")


def run(args) -> int:
    from .. import RENDERS
    from ..outputs import check_output_file
    if args.manoeuvre:
        args.video = args.video or RENDERS / "demo.mp4"
    else:
        args.video = args.video or RENDERS / "demo_required_sidestep.mp4"
    if not args.no_video:
        from ..outputs import check_distinct
        from ..scenario import resolve_path
        check_distinct({"scenario": resolve_path(DEMO_SCENARIO)}, {"--video": args.video})
        check_output_file(args.video, "video")
    return run_manoeuvre(args) if args.manoeuvre else run_sidestep(args)


def demo_episode(method: str, seed: int, config=None, **kwargs):
    """The demo's episode of ``method`` on ``seed``: DEMO_SCENARIO built from ``config`` (default ``RunConfig()``,
    the configuration every front door uses); ``kwargs`` as for :meth:`bigcbf.episode.Episode.from_config`."""
    from ..config import RunConfig
    from ..episode import Episode
    from ..scenario import load_scenario

    return Episode.from_config(load_scenario(DEMO_SCENARIO, seed), method, seed,
                               RunConfig() if config is None else config, **kwargs)


def run_sidestep(args) -> int:
    import tempfile

    from ..config import RunConfig
    from ..video import EpisodeVideo, side_by_side

    config = RunConfig()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        parts = []
        for method in DEMO_METHODS:
            ep = demo_episode(method, args.seed, config)
            if args.no_video:
                rows.append(ep.run().metrics())
                continue
            part = Path(tmp) / f"{method}.mp4"
            with EpisodeVideo(ep, part, camera="top", width=480, height=400, title=method):
                rows.append(ep.run().metrics())
            parts.append(part)
        if parts:
            n = side_by_side(parts, args.video, fps=1.0 / config.stack.T_C_s)
    keys = ["method", "success", "collision", "timeout", "time_s", "min_clearance_m", "e_cbf", "cbf_active_ratio",
            "qp_infeasible_ratio", "planner_p95_ms", "cbf_p95_ms"]
    print(f"{DEMO_SCENARIO}, seed {args.seed}")
    print("  ".join(f"{k:>15}" for k in keys))
    for r in rows:
        print("  ".join(f"{r[k]:>15.3f}" if isinstance(r[k], float) else f"{str(r[k]):>15}" for k in keys))
    if not args.no_video:
        print(f"wrote {args.video} ({n} frames, H.264)")
    return 0


def run_manoeuvre(args) -> int:
    import numpy as np

    from ..sim.render import Renderer, VideoWriter, add_polyline, put_text
    from ..sim.scene import open_room
    from ..sim.world import SimWorld

    world = SimWorld(open_room(extent=3.0), seed=0)
    fps, control_dt = 20, 0.05
    steps = int(round(control_dt / world.dt))
    trail: list[tuple[float, float]] = []
    rows = []
    renderer = None if args.no_video else Renderer(world.model, 640, 480)
    writer = None if args.no_video else VideoWriter(args.video, fps=fps)
    try:
        for label, vx, vy, wz, dur in SEGMENTS:
            achieved = []
            for k in range(int(round(dur / control_dt))):
                world.command((vx, vy, wz))
                world.step(steps)
                s = world.true_state()
                trail.append((s.px, s.py))
                if k * control_dt >= 1.0:          # after the response has settled
                    achieved.append((s.vx, s.vy, s.wz))
                if writer is not None:
                    frame = renderer.render(world.data, "track",
                                            decorate=lambda scn: add_polyline(scn, trail[::4] + trail[-1:]))
                    put_text(frame, [f"t = {world.t:5.2f} s   {label}",
                                     f"cmd  vx {vx:+.2f}  vy {vy:+.2f}  wz {wz:+.2f}",
                                     f"true vx {s.vx:+.2f}  vy {s.vy:+.2f}  wz {s.wz:+.2f}"])
                    writer.write(frame)
            rows.append((label, (vx, vy, wz), np.mean(achieved, axis=0)))
    except BaseException:
        if writer is not None:
            writer.abort()              # no half-written video; the path stays as it was
        raise
    else:
        if writer is not None:
            writer.close()
    finally:
        if renderer is not None:
            renderer.close()
    print(f"{'segment':<12} {'commanded (vx, vy, wz)':>26} {'achieved (vx, vy, wz)':>26}")
    for label, cmd, ach in rows:
        print(f"{label:<12} {'%+.3f %+.3f %+.3f' % cmd:>26} {'%+.3f %+.3f %+.3f' % tuple(ach):>26}")
    if writer is not None:
        print(f"wrote {args.video} ({writer.frames} frames, H.264)")
    return 0
