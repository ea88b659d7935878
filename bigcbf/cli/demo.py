"""bigcbf demo: a scripted manoeuvre in an open room, rendered to renders/demo.mp4."""
from __future__ import annotations

from pathlib import Path

HELP = "drive the robot through forward, strafe, diagonal and spin segments; write renders/demo.mp4"

#: (label, body twist vx [m/s], vy [m/s], wz [rad/s], duration [s])
SEGMENTS = [
    ("forward", 0.5, 0.0, 0.0, 2.5),
    ("strafe left", 0.0, 0.4, 0.0, 2.5),
    ("diagonal", -0.3, -0.3, 0.0, 2.5),
    ("spin", 0.0, 0.0, 1.0, 2.5),
    ("arc", 0.3, 0.0, 0.6, 2.5),
]


def add_arguments(p):
    from .. import RENDERS
    p.add_argument("--video", type=Path, default=RENDERS / "demo.mp4", help="output MP4 (default renders/demo.mp4)")
    p.add_argument("--no-video", action="store_true", help="skip rendering, print the velocities only")


def run(args) -> int:
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
    finally:
        if writer is not None:
            writer.close()
        if renderer is not None:
            renderer.close()
    print(f"{'segment':<12} {'commanded (vx, vy, wz)':>26} {'achieved (vx, vy, wz)':>26}")
    for label, cmd, ach in rows:
        print(f"{label:<12} {'%+.3f %+.3f %+.3f' % cmd:>26} {'%+.3f %+.3f %+.3f' % tuple(ach):>26}")
    if writer is not None:
        print(f"wrote {args.video} ({writer.frames} frames, H.264)")
    return 0
