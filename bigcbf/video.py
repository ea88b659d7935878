"""Episode videos: an observer that renders each control step with overlays, and side-by-side composition.

Overlays drawn into the scene: LiDAR hits (red dots, placed with the robot's true pose), tracked obstacles with
their inflated radius D_i^exec (amber rings; wall points as small amber dots), the goal (green disc, in the
scene), the selected behavior's imagined path (cyan). Text: time, method, behavior mode, speed, whether the
CBF is active. H.264 MP4 via bigcbf.sim.render.VideoWriter.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from .episode import Episode, StepRecord
from .sim.render import Renderer, VideoWriter, add_points, add_polyline, add_ring, put_text

CBF_ACTIVE_RGB = (255, 90, 60)


class EpisodeVideo:
    """Attach to an Episode: ``with EpisodeVideo(ep, path) as v: ep.run()``."""

    def __init__(self, episode: Episode, path: str | Path, camera: str = "top", width: int = 640,
                 height: int = 480, every: int = 1, title: str | None = None):
        self.ep = episode
        self.camera = camera
        self.every = max(1, every)
        self.title = title or episode.method
        self.renderer = Renderer(episode.world.model, width, height)
        fps = 1.0 / (episode.params.T_C_s * self.every)
        self.writer = VideoWriter(path, fps=fps)
        self._n = 0
        episode.observers.append(self)

    def __call__(self, rec: StepRecord) -> None:
        self._n += 1
        if (self._n - 1) % self.every:
            return
        ts = rec.true_state

        def decorate(scn):
            if rec.scan is not None:
                r = np.asarray(rec.scan.ranges, float)
                ok = np.isfinite(r)
                a = rec.scan.angles[ok]
                lx, ly = 0.0435, 0.0
                c, s = np.cos(ts.theta), np.sin(ts.theta)
                ox, oy = ts.px + c * lx - s * ly, ts.py + s * lx + c * ly
                pts = np.stack([ox + r[ok] * np.cos(ts.theta + a), oy + r[ok] * np.sin(ts.theta + a)], 1)
                add_points(scn, pts[::2], z=0.19, radius=0.025)
            obs = rec.obstacles
            D = rec.D if rec.D is not None and len(rec.D) == len(obs) else None
            finite = np.isfinite(obs.p).all(axis=1) & np.isfinite(obs.r)     # a perception fault draws nothing
            for i in range(len(obs)):
                if obs.ids[i] >= 0 and finite[i]:
                    rad = float(D[i]) if D is not None and D[i] > 0 else float(obs.r[i])
                    add_ring(scn, obs.p[i], rad, z=0.012, rgba=(1.0, 0.75, 0.0, 0.9))
                    add_ring(scn, obs.p[i], float(obs.r[i]), z=0.012, rgba=(1.0, 1.0, 1.0, 0.6), segments=20)
            walls = obs.p[(obs.ids < 0) & finite]
            if len(walls):
                add_points(scn, walls, z=0.05, radius=0.04, rgba=(1.0, 0.75, 0.0, 0.9))
            if rec.path is not None and len(rec.path) > 1:
                add_polyline(scn, rec.path, z=0.03, width=0.03, rgba=(0.1, 0.95, 0.95, 0.9))
            add_ring(scn, (ts.px, ts.py), 0.15, z=0.015, rgba=(0.9, 0.9, 0.9, 0.8), segments=24)

        frame = self.renderer.render(self.ep.world.data, self.camera, decorate=decorate)
        speed = float(np.hypot(ts.vx, ts.vy))
        put_text(frame, [f"{self.title}   t = {rec.t:5.2f} s",
                         f"mode {rec.mode}   speed {speed:.2f} m/s",
                         "CBF ACTIVE" if rec.cbf_active else "CBF idle"])
        if rec.cbf_active:
            frame[-8:, :] = CBF_ACTIVE_RGB
        self.writer.write(frame)

    def close(self) -> None:
        """Finish the video (it appears at its path only now)."""
        try:
            self.writer.close()
        finally:
            self.renderer.close()

    def abort(self) -> None:
        """Drop the unfinished video (its path is left as it was)."""
        self.writer.abort()
        self.renderer.close()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        if exc_type is None:
            self.close()
        else:
            self.abort()


def side_by_side(inputs: list[str | Path], out: str | Path, fps: float) -> int:
    """Compose videos left to right (a finished one holds its last frame). Returns the frame count."""
    import imageio_ffmpeg
    readers = [imageio_ffmpeg.read_frames(str(p)) for p in inputs]
    metas = [next(r) for r in readers]
    sizes = [m["size"] for m in metas]
    last: list[np.ndarray | None] = [None] * len(readers)
    done = [False] * len(readers)
    n = 0
    with VideoWriter(out, fps=fps) as vw:
        while True:
            for i, r in enumerate(readers):
                if done[i]:
                    continue
                try:
                    w, h = sizes[i]
                    last[i] = np.frombuffer(next(r), np.uint8).reshape(h, w, 3)
                except StopIteration:
                    done[i] = True
            if all(done):
                break
            h = max(s[1] for s in sizes)
            tiles = [f if f is not None else np.zeros((h, s[0], 3), np.uint8) for f, s in zip(last, sizes)]
            vw.write(np.hstack(tiles))
            n += 1
    return n
