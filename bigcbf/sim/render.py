"""Offscreen rendering (MUJOCO_GL=egl, set by ``bigcbf/__init__``), scene decorations and H.264 video.

Frames come from ``mujoco.Renderer``; extra geoms (LiDAR hits, inflated obstacle circles, paths) are added to
its scene before rendering; text overlays are drawn with OpenCV; videos are written as H.264 (yuv420p) MP4 with
the ffmpeg that imageio-ffmpeg ships, so they play in a browser.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterable

import cv2
import mujoco
import numpy as np


class Renderer:
    """An offscreen renderer for one model. Use as a context manager (or call close())."""

    #: Rendering runs on the CPU (EGL with Mesa's software rasterizer), where every triangle costs: 12 x 8
    #: tessellation for spheres and capsules (MuJoCo's default is 28 x 16), 2x multisampling (default 4) and no
    #: floor reflection (it draws the scene twice) take an episode video with its ~140 overlay geoms per frame
    #: from 7 to about 25 frames per second, and look the same at video size.
    NUMSLICES, NUMSTACKS, OFFSAMPLES = 12, 8, 2

    def __init__(self, model: mujoco.MjModel, width: int = 640, height: int = 480, shadows: bool = False):
        model.vis.global_.offwidth = max(model.vis.global_.offwidth, width)
        model.vis.global_.offheight = max(model.vis.global_.offheight, height)
        q = model.vis.quality
        q.numslices, q.numstacks = min(q.numslices, self.NUMSLICES), min(q.numstacks, self.NUMSTACKS)
        q.offsamples = min(q.offsamples, self.OFFSAMPLES)
        self.model = model
        self._r = mujoco.Renderer(model, height=height, width=width, max_geom=20000)
        self._shadows = shadows
        self.width, self.height = width, height
        self._opt = mujoco.MjvOption()
        self._opt.geomgroup[:] = (1, 1, 1, 1, 0, 0)     # the robot's visual geoms (3), not its collision geoms (4)
        self._opt.sitegroup[:] = (1, 0, 0, 0, 0, 0)

    def render(self, data: mujoco.MjData, camera: str | int = "track",
               decorate: Callable[[mujoco.MjvScene], None] | None = None) -> np.ndarray:
        """An RGB frame (H, W, 3) uint8 from the named camera; ``decorate(scene)`` may add geoms."""
        self._r.update_scene(data, camera=camera, scene_option=self._opt)
        scn = self._r.scene
        scn.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = self._shadows
        scn.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
        if decorate is not None:
            decorate(scn)
        return self._r.render().copy()

    def close(self) -> None:
        if self._r is not None:
            self._r.close()
            self._r = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _add(scn: mujoco.MjvScene, gtype, size, pos, mat, rgba) -> None:
    if scn.ngeom >= scn.maxgeom:
        return
    g = scn.geoms[scn.ngeom]
    mujoco.mjv_initGeom(g, gtype, np.asarray(size, float), np.asarray(pos, float), np.asarray(mat, float).ravel(),
                        np.asarray(rgba, np.float32))
    scn.ngeom += 1


def add_points(scn, points_xy: np.ndarray, z: float = 0.19, radius: float = 0.02, rgba=(1.0, 0.1, 0.1, 0.9)) -> None:
    """Small spheres at 2-D points (e.g. LiDAR hits)."""
    eye = np.eye(3)
    for x, y in np.asarray(points_xy).reshape(-1, 2):
        _add(scn, mujoco.mjtGeom.mjGEOM_SPHERE, (radius, 0, 0), (x, y, z), eye, rgba)


def add_polyline(scn, points_xy: np.ndarray, z: float = 0.02, width: float = 0.02, rgba=(0.1, 0.9, 0.9, 0.9)) -> None:
    """A path drawn as thin capsules between consecutive 2-D points."""
    pts = np.asarray(points_xy, float).reshape(-1, 2)
    for a, b in zip(pts[:-1], pts[1:]):
        if np.linalg.norm(b - a) < 1e-6:
            continue
        g_idx = scn.ngeom
        if g_idx >= scn.maxgeom:
            return
        g = scn.geoms[g_idx]
        mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_CAPSULE, np.zeros(3), np.zeros(3), np.eye(3).ravel(),
                            np.asarray(rgba, np.float32))
        mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_CAPSULE, width / 2, np.array([a[0], a[1], z]),
                             np.array([b[0], b[1], z]))
        scn.ngeom += 1


def add_ring(scn, center_xy, radius: float, z: float = 0.01, rgba=(1.0, 0.8, 0.0, 0.8), segments: int = 32,
             width: float = 0.015) -> None:
    """A circle on the floor (e.g. an obstacle's inflated radius D_i)."""
    a = np.linspace(0, 2 * np.pi, segments + 1)
    pts = np.stack([center_xy[0] + radius * np.cos(a), center_xy[1] + radius * np.sin(a)], axis=1)
    add_polyline(scn, pts, z=z, width=width, rgba=rgba)


def put_text(frame: np.ndarray, lines: Iterable[str], origin=(10, 24), scale: float = 0.55) -> np.ndarray:
    """Text lines in the top-left corner, white on a dark band, readable on any background."""
    y = origin[1]
    for line in lines:
        (w, h), _ = cv2.getTextSize(line, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
        cv2.rectangle(frame, (origin[0] - 4, y - h - 5), (origin[0] + w + 4, y + 6), (20, 20, 20), -1)
        cv2.putText(frame, line, (origin[0], y), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)
        y += h + 12
    return frame


class VideoWriter:
    """H.264 (yuv420p) MP4 writer; frames are RGB uint8 arrays of one size. Use as a context manager.

    The video is written to a temporary file beside ``path`` and renamed to ``path`` by ``close()`` (an
    exception inside the ``with`` block, or ``abort()``, deletes it instead: an existing file at ``path`` is
    never half-overwritten). If ffmpeg stops (a full disk, say), ``write`` raises a UserError naming the path
    and ffmpeg's reason."""

    def __init__(self, path: str | Path, fps: float = 20.0):
        import imageio_ffmpeg
        self.path = Path(path)
        self.fps = fps
        self._ffmpeg = imageio_ffmpeg
        self._gen = None
        self._file = None
        self.frames = 0

    def write(self, frame: np.ndarray) -> None:
        from ..outputs import AtomicFile
        frame = np.ascontiguousarray(frame, dtype=np.uint8)
        try:
            if self._gen is None:
                self._file = AtomicFile(self.path, "video")
                h, w = frame.shape[:2]
                self._gen = self._ffmpeg.write_frames(str(self._file.tmp), (w, h), fps=self.fps, codec="libx264",
                                                      pix_fmt_out="yuv420p", quality=7, macro_block_size=16,
                                                      output_params=["-movflags", "+faststart"])
                self._gen.send(None)
            self._gen.send(frame)
        except OSError as exc:                   # BrokenPipeError included: ffmpeg has exited
            self.abort()
            raise _ffmpeg_error(self.path, exc) from None
        self.frames += 1

    def close(self) -> None:
        """Finish the video and move it to ``path``."""
        if self._gen is not None:
            gen, self._gen = self._gen, None
            try:
                gen.close()
            except (OSError, RuntimeError) as exc:
                self.abort()
                raise _ffmpeg_error(self.path, exc) from None
        if self._file is not None:
            f, self._file = self._file, None
            f.commit()

    def abort(self) -> None:
        """Stop ffmpeg and delete the unfinished video (``path`` is left as it was)."""
        gen, self._gen = self._gen, None
        if gen is not None:
            try:
                gen.close()
            except Exception:  # noqa: BLE001 - ffmpeg may already be gone; the file is deleted either way
                pass
        if self._file is not None:
            f, self._file = self._file, None
            f.discard()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        if exc_type is None:
            self.close()
        else:
            self.abort()


def _ffmpeg_error(path: Path, exc: BaseException):
    """A UserError with ffmpeg's own last line of explanation (imageio-ffmpeg puts its stderr in the message)."""
    from ..errors import UserError
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    reason = lines[-1] if lines else type(exc).__name__
    if isinstance(exc, BrokenPipeError) or "FFMPEG STDERR" in reason:
        reason = "ffmpeg stopped"
    return UserError(f"cannot write the video ({reason})", file=str(path))
