"""Episode videos: an observer that renders each control step with overlays, and side-by-side composition.

What a frame shows (the legend in a band below the scene names each item present):

- the robot: in the top view a white disc with its heading (drawn at least 9 pixels in radius, so it is seen in a
  whole-scene view) and its footprint r_R; in the track view the model itself and its footprint;
- its trail (the true path so far, magenta);
- LiDAR hits (red dots, placed with the robot's true pose);
- tracked obstacles: their inflated radius D_i^exec of eq:shared_barrier (20) (amber rings), their estimated body radius
  (thin white), their track id (``#id``) and their velocity over 1 s (blue arrows, dynamic tracks); wall points
  as small amber dots;
- BIG-CBF's imagination (eq:behavior_rollout (12)): the six behaviors' imagined paths of the latest selection (grey
  when accepted by eq:behavior_acceptance (22), red when rejected) and the path the robot follows thick cyan (the
  selected behavior's, or the fallback's release path), for other methods the path the method reports (cyan). The cyan
  path's end is labelled with the step's behavior mode in cyan; in the track view the other behaviors' ends are labelled
  with their own modes in grey, each only where it does not cover a label already drawn (the top view is crowded: the
  cyan one only). ``Overlay.last_labels`` lists what the latest frame labelled, and where;
- the goal (green disc, in the scene).

Text: method, time, behavior mode, speed, whether the CBF is active (and a red bar at the bottom while it is).
H.264 MP4 via bigcbf.sim.render.VideoWriter; on a terminal a progress line on stderr (bigcbf.progress). An
interrupted video (Ctrl-C; SIGTERM under the command line's handler) is kept as ``X.partial.mp4``
(:meth:`EpisodeVideo.finish_partial`).
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .episode import Episode, StepRecord
from .sim.render import (Renderer, VideoWriter, add_arrow, add_disc, add_points, add_polyline, add_ring, boxes_overlap,
                         draw_dots, draw_legend, label_box, meters_per_pixel, project, put_label, put_text,
                         with_legend_strip)

CBF_ACTIVE_RGB = (255, 90, 60)

#: overlay colours (RGBA in [0, 1]), shared by the scene and the legend
LIDAR_RGBA = (1.0, 0.15, 0.15, 0.9)
D_RING_RGBA = (1.0, 0.75, 0.0, 0.9)
BODY_RING_RGBA = (1.0, 1.0, 1.0, 0.6)
WALL_POINT_RGBA = (1.0, 0.75, 0.0, 0.9)
VELOCITY_RGBA = (0.25, 0.55, 1.0, 0.95)
SELECTED_RGBA = (0.1, 0.95, 0.95, 0.95)
ACCEPTED_RGBA = (0.85, 0.85, 0.85, 0.6)
REJECTED_RGBA = (0.95, 0.35, 0.35, 0.6)
TRAIL_RGBA = (1.0, 0.4, 0.85, 0.9)
ROBOT_RGBA = (0.97, 0.97, 0.97, 0.95)
HEADING_RGBA = (0.1, 0.1, 0.1, 1.0)
GOAL_RGBA = (0.1, 0.9, 0.2, 0.8)
#: label text colours (RGB): the followed path's behavior, the other imagined behaviors, track ids
SELECTED_TEXT_RGB = (60, 240, 240)
IMAGINED_TEXT_RGB = (200, 200, 200)
TRACK_TEXT_RGB = (255, 200, 60)
BEHAVIOR_LABEL_SCALE = 0.36

#: overlays above everything in the top view (pedestrians are 1.7 m tall); at their own height in the track view
TOP_VIEW_Z = 1.75
#: the robot's radius in the top view at least this many pixels
ROBOT_ICON_PX = 9.0
#: the trail keeps one point per this many control steps (0.2 s at T_C = 50 ms)
TRAIL_EVERY = 4


class Label(NamedTuple):
    """A text a frame shows next to something in the scene: ``kind`` "selected" (the cyan path's end: the step's
    mode), "imagined" (another behavior's imagined path end) or "track" (a track id); ``uv`` the pixel it labels,
    ``box`` (x0, y0, x1, y1) the pixels its dark box covers."""
    text: str
    kind: str
    uv: tuple[float, float]
    box: tuple[int, int, int, int]


class Overlay:
    """Draws one control step of an episode into a frame of one camera: the scene overlays, track ids, the legend
    and the text. Shared by :class:`EpisodeVideo` and the Gymnasium environment's ``render()``."""

    def __init__(self, episode: Episode, renderer: Renderer, camera: str = "top", title: str | None = None,
                 legend: str = "strip"):
        self.ep, self.renderer, self.camera = episode, renderer, camera
        self.legend_style = legend      # "strip": a band below the frame; "box": inside it, lower right; "none"
        self.title = title or episode.method or "external"
        self.mpp = meters_per_pixel(episode.world.model, camera, renderer.height)   # None: perspective (track)
        self.trail: list[tuple[float, float]] = []
        self.last_labels: list[Label] = []      # what the latest frame labelled (tests, tools)
        self._n = 0
        laser = getattr(getattr(episode.perception, "params", None), "laser_x_m", 0.0)
        self.laser_xy = (float(laser), float(getattr(episode.perception.params, "laser_y_m", 0.0)))

    def observe(self, rec: StepRecord) -> None:
        """Remember the robot's true position (the trail); call at every control step."""
        if self._n % TRAIL_EVERY == 0 or not self.trail:
            self.trail.append((rec.true_state.px, rec.true_state.py))
        self._n += 1

    def _w(self, pixels: float, metres: float) -> float:
        """A line width: ``pixels`` wide in the top view (at least ``metres``), ``metres`` in the track view."""
        return metres if self.mpp is None else max(metres, pixels * self.mpp)

    def _lidar_hits(self, rec: StepRecord) -> np.ndarray | None:
        """Every other LiDAR hit of the step's scan in the world (N, 2), placed with the robot's true pose."""
        if rec.scan is None:
            return None
        ts = rec.true_state
        r = np.asarray(rec.scan.ranges, float)
        ok = np.isfinite(r)
        a = rec.scan.angles[ok]
        lx, ly = self.laser_xy
        c, s = np.cos(ts.theta), np.sin(ts.theta)
        ox, oy = ts.px + c * lx - s * ly, ts.py + s * lx + c * ly
        return np.stack([ox + r[ok] * np.cos(ts.theta + a), oy + r[ok] * np.sin(ts.theta + a)], 1)[::2]

    def _imagination(self):
        img = getattr(self.ep.planner, "last_imagination", None)
        return img if img is not None and getattr(img, "p", None) is not None else None

    def frame(self, rec: StepRecord) -> np.ndarray:
        """The RGB frame of ``rec`` (H, W, 3) uint8.

        Length: the decorate callback draws the 3-D overlays inside the render call and closes over this frame's locals;
        the image overlays after it are drawn in order, later ones on top."""
        ts, top = rec.true_state, self.mpp is not None
        z0 = TOP_VIEW_Z if top else 0.0
        obs = rec.obstacles
        D = rec.D if rec.D is not None and len(rec.D) == len(obs) else None
        img = self._imagination()
        r_robot = self.ep.params.uncertainty.r_robot_m
        trail = self.trail + [(ts.px, ts.py)]
        hits = self._lidar_hits(rec)

        def decorate(scn):
            if len(trail) > 1:
                add_polyline(scn, np.array(trail), z=z0 + 0.02, width=self._w(2.0, 0.02), rgba=TRAIL_RGBA)
            if hits is not None and not top:
                add_points(scn, hits, z=z0 + 0.19, radius=self._w(2.2, 0.025), rgba=LIDAR_RGBA)
            for i in range(len(obs)):
                if obs.ids[i] < 0:
                    continue
                rad = float(D[i]) if D is not None else float(obs.r[i])
                add_ring(scn, obs.p[i], rad, z=z0 + 0.012, rgba=D_RING_RGBA, width=self._w(1.5, 0.015))
                add_ring(scn, obs.p[i], float(obs.r[i]), z=z0 + 0.012, rgba=BODY_RING_RGBA, segments=20,
                         width=self._w(1.0, 0.01))
                v = obs.v[i]
                if not obs.static[i] and np.hypot(*v) > 0.05:
                    add_arrow(scn, obs.p[i], obs.p[i] + v, z=z0 + 0.05, width=self._w(2.5, 0.03), rgba=VELOCITY_RGBA)
            walls = obs.p[obs.ids < 0]
            if len(walls):
                add_points(scn, walls, z=z0 + 0.05, radius=self._w(2.0, 0.04), rgba=WALL_POINT_RGBA)
            if img is not None:
                for b, mode in enumerate(img.modes):
                    if not img.available[b]:
                        continue
                    add_polyline(scn, img.p[b], z=z0 + 0.025, width=self._w(1.5, 0.015),
                                 rgba=ACCEPTED_RGBA if img.accepted[b] else REJECTED_RGBA)
            if rec.path is not None and len(rec.path) > 1:
                add_polyline(scn, rec.path, z=z0 + 0.03, width=self._w(3.5, 0.035), rgba=SELECTED_RGBA)
            if top:
                rad = max(r_robot, ROBOT_ICON_PX * self.mpp)
                add_disc(scn, (ts.px, ts.py), rad, z=z0 + 0.04, rgba=ROBOT_RGBA)
                tip = (ts.px + 1.1 * rad * np.cos(ts.theta), ts.py + 1.1 * rad * np.sin(ts.theta))
                add_arrow(scn, (ts.px, ts.py), tip, z=z0 + 0.05, width=self._w(2.5, 0.02), rgba=HEADING_RGBA)
            add_ring(scn, (ts.px, ts.py), r_robot, z=z0 + 0.045, rgba=(0.3, 0.3, 0.3, 0.9) if top else BODY_RING_RGBA,
                     segments=24, width=self._w(1.0, 0.012))

        data = self.ep.world.data
        frame = self.renderer.render(data, self.camera, decorate=decorate)
        model, W, H = self.ep.world.model, self.renderer.width, self.renderer.height
        if hits is not None and top:     # above every other overlay: drawn on the image (a third of the GL cost)
            uv, _ = project(model, data, self.camera, np.column_stack([hits, np.full(len(hits), z0 + 0.19)]), W, H)
            draw_dots(frame, uv, max(2.2, 0.025 / self.mpp), tuple(int(255 * c) for c in LIDAR_RGBA[:3]))
        self.last_labels = labels = []
        # track ids next to the tracks
        tracked = np.flatnonzero(obs.ids >= 0)
        if len(tracked):
            p = obs.p[tracked]
            pts = np.column_stack([p, np.full(len(p), z0 + 0.1 if top else 1.0)])
            uv, front = project(model, data, self.camera, pts, W, H)
            for k, i in enumerate(tracked):
                if front[k]:
                    text = f"#{int(obs.ids[i])}"
                    box = put_label(frame, text, uv[k] + (7, -7), color=TRACK_TEXT_RGB)
                    labels.append(Label(text, "track", (float(uv[k][0]), float(uv[k][1])), box))
        self._behavior_labels(frame, rec, img, z0, top, labels)
        speed = float(np.hypot(ts.vx, ts.vy))
        put_text(frame, [f"{self.title}   t = {rec.t:5.2f} s",
                         f"mode {rec.mode}   speed {speed:.2f} m/s",
                         "CBF ACTIVE" if rec.cbf_active else "CBF idle"])
        if rec.cbf_active:
            frame[-8:, :] = CBF_ACTIVE_RGB
        items = self.legend(img is not None, rec.path is not None)
        if self.legend_style == "strip":     # room for the largest legend: every frame of a video has one size
            every = [lab for lab, _, _ in self.legend(True, False)] + [lab for lab, _, _ in self.legend(False, True)
                                                                        if lab not in {"goal", "robot, trail"}]
            return with_legend_strip(frame, items, reserve=list(dict.fromkeys(every)))
        if self.legend_style == "box":
            draw_legend(frame, items)
        return frame

    def _behavior_labels(self, frame, rec: StepRecord, img, z0: float, top: bool, labels: list[Label]) -> None:
        """The cyan path's end labelled with the step's mode (the behavior the robot follows); in the track view
        the other imagined paths' ends with their own modes in grey, skipped where one would cover a behavior
        label already drawn. (The imagination is up to T_B old and its paths of different behaviors may end at one
        point: a label taken from it for the cyan path could name another behavior.)"""
        model, data, W, H = self.ep.world.model, self.ep.world.data, self.renderer.width, self.renderer.height
        drawn = []
        if rec.path is not None and len(rec.path) > 1:
            end = np.array([[rec.path[-1][0], rec.path[-1][1], z0 + 0.03]])
            uv, front = project(model, data, self.camera, end, W, H)
            if front[0]:
                box = put_label(frame, rec.mode, uv[0] + (4, 4), scale=BEHAVIOR_LABEL_SCALE, color=SELECTED_TEXT_RGB)
                drawn.append(Label(rec.mode, "selected", (float(uv[0][0]), float(uv[0][1])), box))
        if img is not None and not top:
            ends = np.array([[img.p[b][-1][0], img.p[b][-1][1], z0 + 0.03] for b in range(len(img.modes))])
            uv, front = project(model, data, self.camera, ends, W, H)
            for b, mode in enumerate(img.modes):
                if mode == rec.mode or not img.available[b] or not front[b]:
                    continue
                box = label_box(frame.shape, mode, uv[b] + (4, 4), BEHAVIOR_LABEL_SCALE)
                if any(boxes_overlap(box, d.box, gap=1) for d in drawn):
                    continue
                put_label(frame, mode, uv[b] + (4, 4), scale=BEHAVIOR_LABEL_SCALE, color=IMAGINED_TEXT_RGB)
                drawn.append(Label(mode, "imagined", (float(uv[b][0]), float(uv[b][1])), box))
        labels.extend(drawn)

    def legend(self, imagination: bool, path: bool) -> list[tuple[str, tuple, str]]:
        items = [("robot, trail", TRAIL_RGBA, "line"), ("LiDAR hits", LIDAR_RGBA, "dot"),
                 ("track #id: D_i (eq:shared_barrier (20))", D_RING_RGBA, "ring"),
                 ("velocity (1 s)", VELOCITY_RGBA, "arrow"),
                 ("wall points", WALL_POINT_RGBA, "dot")]
        if imagination:
            items += [("imagined: selected", SELECTED_RGBA, "thick"),
                      ("accepted (eq:behavior_acceptance (22))", ACCEPTED_RGBA, "line"),
                      ("rejected", REJECTED_RGBA, "line")]
        elif path:
            items += [("planned path", SELECTED_RGBA, "thick")]
        return items + [("goal", GOAL_RGBA, "disc")]


class EpisodeVideo:
    """Attach to an Episode: ``with EpisodeVideo(ep, path) as v: ep.run()``.

    ``progress``: a progress line on stderr (:class:`bigcbf.progress.EpisodeProgress`: simulated time, frames,
    wall time); None shows it only when stderr is a terminal. Interrupted (a KeyboardInterrupt: Ctrl-C, or
    SIGTERM under the command line's handler), the ``with`` block, or :meth:`abort` called while the interrupt is
    handled, keeps the frames so far as ``X.partial.mp4`` (:meth:`finish_partial`) and appends its path to the
    exception's ``partial_videos`` list, so that the command line can say where it is."""

    def __init__(self, episode: Episode, path: str | Path, camera: str = "top", width: int = 640,
                 height: int = 480, every: int = 1, title: str | None = None, progress: bool | None = None):
        from .progress import EpisodeProgress
        self.ep = episode
        self.every = max(1, every)
        self.renderer = Renderer(episode.world.model, width, height)
        self.overlay = Overlay(episode, self.renderer, camera, title)
        fps = 1.0 / (episode.params.T_C_s * self.every)
        self.writer = VideoWriter(path, fps=fps)
        self.progress = EpisodeProgress(episode.time_limit_s, f"video {Path(path).name}",
                                        frames=lambda: self.writer.frames, enabled=progress)
        self._n = 0
        episode.observers.append(self)

    def __call__(self, rec: StepRecord) -> None:
        self.overlay.observe(rec)
        self._n += 1
        if (self._n - 1) % self.every == 0:
            self.writer.write(self.overlay.frame(rec))
        self.progress(rec)

    def close(self) -> None:
        """Finish the video (it appears at its path only now)."""
        self.progress.update(float(self.ep.world.t), "encoding")      # the episode's end (after its last step)
        try:
            self.writer.close()
        finally:
            self.renderer.close()
            self.progress.close()

    def finish_partial(self) -> Path | None:
        """Keep the frames written so far as ``X.partial.mp4`` beside ``X.mp4`` (a video that plays; ``X.mp4`` is
        left as it was, no temporary file remains): its path, or None without a frame to keep."""
        try:
            kept = self.writer.finish_partial()
        finally:
            self.renderer.close()
        self.progress.close(f"interrupted, kept {kept.name}" if kept is not None else "interrupted")
        return kept

    def abort(self) -> None:
        """Drop the unfinished video (its path is left as it was); while a KeyboardInterrupt is handled, keep it
        instead (class docstring)."""
        exc = sys.exc_info()[1]
        if isinstance(exc, KeyboardInterrupt):
            self._keep_partial(exc)
            return
        self.writer.abort()
        self.renderer.close()
        self.progress.close("dropped")

    def _keep_partial(self, exc: KeyboardInterrupt) -> None:
        path = self.finish_partial()
        if path is not None:
            if not isinstance(getattr(exc, "partial_videos", None), list):
                exc.partial_videos = []
            exc.partial_videos.append(path)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        elif isinstance(exc, KeyboardInterrupt):
            self._keep_partial(exc)
        else:
            self.abort()


def _pad_to(frame: np.ndarray, height: int) -> np.ndarray:
    """``frame`` with dark rows added below it up to ``height`` (tiles of a side-by-side video differ in height)."""
    if frame.shape[0] >= height:
        return frame
    return np.vstack([frame, np.full((height - frame.shape[0], *frame.shape[1:]), 24, np.uint8)])


def side_by_side(inputs: list[str | Path], out: str | Path, fps: float) -> int:
    """Compose videos left to right (a finished one holds its last frame; a shorter tile is padded below to the
    tallest one's height). Returns the frame count."""
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
            tiles = [_pad_to(f if f is not None else np.zeros((h, s[0], 3), np.uint8), h) for f, s in zip(last, sizes)]
            vw.write(np.hstack(tiles))
            n += 1
    return n
