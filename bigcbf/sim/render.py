"""Offscreen rendering (MUJOCO_GL=egl, set by ``bigcbf/__init__``), scene decorations and H.264 video.

Frames come from ``mujoco.Renderer``; extra geoms (LiDAR hits, inflated obstacle circles, paths) are added to
its scene before rendering; text overlays are drawn with OpenCV; videos are written as H.264 (yuv420p) MP4 with
the ffmpeg that imageio-ffmpeg ships, so they play in a browser.
"""
from __future__ import annotations

import contextlib
import os
import signal
import threading
from pathlib import Path
from typing import Callable, Iterable, Iterator

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


def add_arrow(scn, start_xy, end_xy, z: float = 0.05, width: float = 0.03, rgba=(0.1, 0.4, 1.0, 0.9)) -> None:
    """An arrow on the floor plane from ``start_xy`` to ``end_xy`` (e.g. an obstacle's velocity over 1 s)."""
    a, b = np.array([start_xy[0], start_xy[1], z], float), np.array([end_xy[0], end_xy[1], z], float)
    if np.linalg.norm(b - a) < 1e-3 or scn.ngeom >= scn.maxgeom:
        return
    g = scn.geoms[scn.ngeom]
    mujoco.mjv_initGeom(g, mujoco.mjtGeom.mjGEOM_ARROW, np.zeros(3), np.zeros(3), np.eye(3).ravel(),
                        np.asarray(rgba, np.float32))
    mujoco.mjv_connector(g, mujoco.mjtGeom.mjGEOM_ARROW, width, a, b)
    scn.ngeom += 1


def add_disc(scn, center_xy, radius: float, z: float = 0.01, rgba=(0.95, 0.95, 0.95, 0.9)) -> None:
    """A flat filled disc (e.g. the robot's icon in the top view)."""
    _add(scn, mujoco.mjtGeom.mjGEOM_CYLINDER, (radius, 0.002, 0), (center_xy[0], center_xy[1], z), np.eye(3), rgba)


def meters_per_pixel(model: mujoco.MjModel, camera: str, height: int) -> float | None:
    """The scale of an orthographic camera (its fovy is the visible height in metres); None for a perspective one."""
    cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
    if model.cam_projection[cam] != mujoco.mjtProjection.mjPROJ_ORTHOGRAPHIC:
        return None
    return float(model.cam_fovy[cam]) / height


def project(model: mujoco.MjModel, data: mujoco.MjData, camera: str, points: np.ndarray, width: int,
            height: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (N, 2) (u right, v down) of world points (N, 3) in a camera's image, and which of them
    lie in front of the camera (N,). The pinhole (or orthographic) model of MuJoCo's camera: axes from
    ``data.cam_xmat`` (x right, y up, looking along -z), vertical field of view ``fovy``."""
    cam = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
    R = data.cam_xmat[cam].reshape(3, 3)
    d = (np.asarray(points, float).reshape(-1, 3) - data.cam_xpos[cam]) @ R      # camera-frame coordinates
    if model.cam_projection[cam] == mujoco.mjtProjection.mjPROJ_ORTHOGRAPHIC:
        scale = height / float(model.cam_fovy[cam])
        uv = np.stack([width / 2 + scale * d[:, 0], height / 2 - scale * d[:, 1]], 1)
        return uv, np.ones(len(d), bool)
    f = 0.5 * height / np.tan(np.deg2rad(float(model.cam_fovy[cam])) / 2)
    depth = -d[:, 2]
    front = depth > 1e-6
    z = np.where(front, depth, 1.0)
    uv = np.stack([width / 2 + f * d[:, 0] / z, height / 2 - f * d[:, 1] / z], 1)
    return uv, front


def label_box(shape, text: str, uv, scale: float = 0.42) -> tuple[int, int, int, int]:
    """The box (x0, y0, x1, y1) in pixels that :func:`put_label` fills for ``text`` at ``uv`` in a frame of
    ``shape`` (the text's lower-left corner at ``uv``, clipped to the frame)."""
    h, w = shape[:2]
    (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)
    x = int(np.clip(uv[0], 2, w - tw - 4))
    y = int(np.clip(uv[1], th + 4, h - 4))
    return x - 2, y - th - 3, x + tw + 2, y + 3


def draw_dots(frame: np.ndarray, uv: np.ndarray, radius_px: float, rgb) -> None:
    """Filled anti-aliased dots at pixels ``uv`` (N, 2), drawn on the image: in an orthographic top view, overlays
    above everything else cost this instead of a lit sphere each (12 x 8 triangles in the software renderer)."""
    shift = 4                                  # sub-pixel centres (cv2 fixed point)
    r = int(round(radius_px * (1 << shift)))
    for u, v in np.asarray(uv, float).reshape(-1, 2):
        cv2.circle(frame, (int(round(u * (1 << shift))), int(round(v * (1 << shift)))), r, rgb, -1, cv2.LINE_AA,
                   shift)


def boxes_overlap(a, b, gap: int = 0) -> bool:
    """Two boxes (x0, y0, x1, y1) overlap, or come closer than ``gap`` pixels."""
    return a[0] < b[2] + gap and b[0] < a[2] + gap and a[1] < b[3] + gap and b[1] < a[3] + gap


def put_label(frame: np.ndarray, text: str, uv, scale: float = 0.42, color=(255, 255, 255)) -> tuple:
    """A short text (e.g. a track id) with its lower-left corner at pixel ``uv``, on a dark box; clipped to the
    frame. Returns the box it filled (:func:`label_box`)."""
    box = label_box(frame.shape, text, uv, scale)
    cv2.rectangle(frame, box[:2], box[2:], (20, 20, 20), -1)
    cv2.putText(frame, text, (box[0] + 2, box[3] - 3), cv2.FONT_HERSHEY_SIMPLEX, scale, color, 1, cv2.LINE_AA)
    return box


def draw_legend(frame: np.ndarray, items: Iterable[tuple[str, tuple, str]], corner: str = "bottom-right",
                scale: float = 0.38) -> np.ndarray:
    """A legend box: one line per (label, rgba in [0, 1], kind), kind "line", "dot", "ring" or "arrow"."""
    items = list(items)
    if not items:
        return frame
    h, w = frame.shape[:2]
    sizes = [cv2.getTextSize(lab, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0] for lab, _, _ in items]
    line_h = max(s[1] for s in sizes) + 8
    box_w = 34 + max(s[0] for s in sizes) + 8
    box_h = line_h * len(items) + 8
    x0 = w - box_w - 8 if corner.endswith("right") else 8
    y0 = h - box_h - 14 if corner.startswith("bottom") else 8
    overlay = frame.copy()
    cv2.rectangle(overlay, (x0, y0), (x0 + box_w, y0 + box_h), (20, 20, 20), -1)
    cv2.addWeighted(overlay, 0.75, frame, 0.25, 0, dst=frame)
    for k, (label, rgba, kind) in enumerate(items):
        yc = y0 + 4 + line_h * k + line_h // 2
        _swatch(frame, kind, x0 + 6, yc, tuple(int(255 * c) for c in rgba[:3]))
        cv2.putText(frame, label, (x0 + 34, yc + sizes[k][1] // 2), cv2.FONT_HERSHEY_SIMPLEX, scale,
                    (235, 235, 235), 1, cv2.LINE_AA)
    return frame


def _swatch(img: np.ndarray, kind: str, x: int, yc: int, col) -> None:
    if kind == "dot":
        cv2.circle(img, (x + 10, yc), 4, col, -1, cv2.LINE_AA)
    elif kind == "ring":
        cv2.circle(img, (x + 10, yc), 7, col, 1, cv2.LINE_AA)
    elif kind == "arrow":
        cv2.arrowedLine(img, (x, yc), (x + 22, yc), col, 2, cv2.LINE_AA, tipLength=0.4)
    elif kind == "disc":
        cv2.circle(img, (x + 10, yc), 6, col, -1, cv2.LINE_AA)
    else:
        cv2.line(img, (x, yc), (x + 22, yc), col, 3 if kind == "thick" else 1, cv2.LINE_AA)


def _legend_rows(labels: list[str], width: int, scale: float) -> tuple[list, list, int]:
    """The legend's layout: (rows of (item index, x), text sizes, row height) for items flowing left to right."""
    sizes = [cv2.getTextSize(lab, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0] for lab in labels]
    row_h = max((s[1] for s in sizes), default=10) + 10
    rows, x = [[]], 8
    for k, (tw, _) in enumerate(sizes):
        item_w = 30 + tw + 16
        if x + item_w > width and rows[-1]:
            rows.append([])
            x = 8
        rows[-1].append((k, x))
        x += item_w
    return rows, sizes, row_h


def with_legend_strip(frame: np.ndarray, items: Iterable[tuple[str, tuple, str]], scale: float = 0.4,
                      multiple: int = 16, reserve: Iterable[str] = ()) -> np.ndarray:
    """The frame with a legend band below it (so the legend never hides the scene): the items (label, rgba in
    [0, 1], kind as in :func:`draw_legend`) flow left to right in rows; the band's height makes the frame's height
    a multiple of ``multiple`` (H.264 macroblocks). ``reserve``: labels whose layout the band must also have room
    for, so that every frame of a video has one size whichever items a frame shows (a video's frames must)."""
    items = list(items)
    h, w = frame.shape[:2]
    rows, sizes, row_h = _legend_rows([lab for lab, _, _ in items], w, scale)
    reserve = list(reserve)
    n_rows = len(rows)
    if reserve:
        r_rows, _, r_row_h = _legend_rows(reserve, w, scale)
        n_rows, row_h = max(n_rows, len(r_rows)), max(row_h, r_row_h)
    band_h = n_rows * row_h + 8
    band_h += (-(h + band_h)) % multiple
    band = np.full((band_h, w, 3), 24, np.uint8)
    for r, row in enumerate(rows):
        yc = 4 + r * row_h + row_h // 2
        for k, x0 in row:
            label, rgba, kind = items[k]
            _swatch(band, kind, x0, yc, tuple(int(255 * c) for c in rgba[:3]))
            cv2.putText(band, label, (x0 + 30, yc + sizes[k][1] // 2), cv2.FONT_HERSHEY_SIMPLEX, scale,
                        (235, 235, 235), 1, cv2.LINE_AA)
    return np.vstack([frame, band])


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
    and ffmpeg's reason; if ffmpeg's exit is not clean when ``close`` finishes the file (a disk that fills while
    it writes the last frames or the index), ``close`` raises that UserError and deletes the unfinished file.
    Interrupted (Ctrl-C, or SIGTERM under the command line's handler: a KeyboardInterrupt), :meth:`finish_partial`
    (what the ``with`` block does then) keeps the frames written so far as ``X.partial.mp4``, a video that plays."""

    def __init__(self, path: str | Path, fps: float = 20.0):
        import imageio_ffmpeg
        self.path = Path(path)
        self.fps = fps
        self._ffmpeg = imageio_ffmpeg
        self._gen = None
        self._file = None
        self._proc = None          # ffmpeg's process (imageio-ffmpeg does not check its exit status: we do)
        self.frames = 0

    #: x264's preset: "veryfast" takes half the encoder's CPU time of the default ("medium") for a file of the
    #: same size at this quality (CRF 15) on episode videos (measured: 1.55 -> 0.80 s for 262 frames of 640 x 544)
    PRESET = "veryfast"

    def write(self, frame: np.ndarray) -> None:
        from ..outputs import AtomicFile
        frame = np.ascontiguousarray(frame, dtype=np.uint8)
        try:
            with _whole_frame():                 # Ctrl-C waits for the frame: ffmpeg stays alive for a partial video
                if self._gen is None:
                    self._file = AtomicFile(self.path, "video")
                    h, w = frame.shape[:2]
                    self._gen = self._ffmpeg.write_frames(str(self._file.tmp), (w, h), fps=self.fps, codec="libx264",
                                                          pix_fmt_out="yuv420p", quality=7, macro_block_size=16,
                                                          output_params=["-preset", self.PRESET,
                                                                         "-movflags", "+faststart"])
                    self._gen.send(None)
                    self._proc = _ffmpeg_process(self._gen)
                self._gen.send(frame)
                self.frames += 1
        except OSError as exc:                   # BrokenPipeError included: ffmpeg has exited
            self.abort()
            raise _ffmpeg_error(self.path, exc) from None

    def partial_path(self) -> Path:
        """Where :meth:`finish_partial` keeps an interrupted video: X.mp4 -> X.partial.mp4, beside the video."""
        folder = self._file.target.parent if self._file is not None else self.path.parent
        return folder / f"{self.path.stem}.partial{self.path.suffix}"

    def finish_partial(self) -> Path | None:
        """Finish an interrupted video with the frames written so far (a file that plays) and keep it as
        ``X.partial.mp4`` beside ``X.mp4`` (an older one there is replaced); ``path`` is left as it was and no
        temporary file remains. Returns the partial video's path, or None when there is nothing to keep (no frame
        written, the video already closed or dropped, ffmpeg gone: then the unfinished file is deleted). Another
        Ctrl-C meanwhile waits until the file is finished (as a frame write does)."""
        if self._file is None:
            return None
        target = self.partial_path()
        gen, self._gen = self._gen, None
        f, self._file = self._file, None
        proc, self._proc = self._proc, None
        kept = False
        try:
            with _whole_frame():
                if gen is not None and self.frames > 0:
                    gen.close()                  # ffmpeg encodes what it has and writes the index
                    if _exit_status(proc) == 0:  # not killed (by an interrupt inside its generator) nor failed
                        os.replace(f.tmp, target)
                        kept = True
        except (OSError, RuntimeError):          # ffmpeg gone, a full disk: nothing to keep (the interrupt matters)
            pass
        finally:
            if not kept:
                f.discard()
        return target if kept else None

    def close(self) -> None:
        """Finish the video and move it to ``path``."""
        if self._gen is not None:
            gen, self._gen = self._gen, None
            try:
                gen.close()
            except (OSError, RuntimeError) as exc:
                self.abort()
                raise _ffmpeg_error(self.path, exc) from None
            status = _exit_status(self._proc)
            if status != 0:
                self.abort()
                from ..errors import UserError
                raise UserError(f"cannot write the video ({_exit_reason(status)})", file=str(self.path))
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
        self._proc = None
        if self._file is not None:
            f, self._file = self._file, None
            f.discard()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc):
        if exc_type is None:
            self.close()
        elif issubclass(exc_type, KeyboardInterrupt):
            self.finish_partial()
        else:
            self.abort()


def _ffmpeg_process(gen):
    """The ffmpeg process behind an imageio-ffmpeg ``write_frames`` generator once it has started (its local ``p``),
    or None when the generator is not imageio-ffmpeg's (then only the pipe's errors are seen)."""
    frame = getattr(gen, "gi_frame", None)
    proc = frame.f_locals.get("p") if frame is not None else None
    return proc if hasattr(proc, "poll") and hasattr(proc, "wait") else None


def _exit_status(proc) -> int:
    """ffmpeg's exit status after ``write_frames`` was closed (it waited for ffmpeg, or killed it); 0 without a
    process to ask."""
    if proc is None:
        return 0
    try:
        status = proc.wait(timeout=30.0)
    except Exception:  # noqa: BLE001 - a process that does not end is not a clean exit
        proc.kill()
        return -9
    return int(status)


def _exit_reason(status: int) -> str:
    """ffmpeg's exit status in words: it exits with AVERROR(errno) = -errno, i.e. 256 - errno (228: no space left on
    the device); a negative status is the signal that killed it (SIGXFSZ: a file size limit)."""
    import signal
    if status < 0:
        try:
            name = signal.strsignal(-status) or f"signal {-status}"
        except ValueError:
            name = f"signal {-status}"
        return f"ffmpeg was stopped: {name}"
    if 128 < status < 256:
        return f"ffmpeg failed: {os.strerror(256 - status)}"
    return f"ffmpeg failed with exit status {status}"


@contextlib.contextmanager
def _whole_frame() -> Iterator[None]:
    """A section that an interrupt does not cut: Ctrl-C (and SIGTERM under the command line's handler) inside it
    raises KeyboardInterrupt when it ends (:data:`bigcbf.logio.interrupts.critical`). A KeyboardInterrupt inside
    imageio-ffmpeg's generator would kill ffmpeg and lose the video; where Python's default SIGINT handler is in
    place (the Python API), the command line's handlers (:func:`~bigcbf.logio.interrupts.interrupts_as_keyboard_
    interrupt`) are installed for the section."""
    from ..logio.interrupts import critical, interrupts_as_keyboard_interrupt
    plain = (threading.current_thread() is threading.main_thread()
             and signal.getsignal(signal.SIGINT) is signal.default_int_handler)
    with interrupts_as_keyboard_interrupt() if plain else contextlib.nullcontext():
        with critical:
            yield


def _ffmpeg_error(path: Path, exc: BaseException):
    """A UserError with ffmpeg's own last line of explanation (imageio-ffmpeg puts its stderr in the message)."""
    from ..errors import UserError
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    reason = lines[-1] if lines else type(exc).__name__
    if isinstance(exc, BrokenPipeError) or "FFMPEG STDERR" in reason:
        reason = "ffmpeg stopped"
    return UserError(f"cannot write the video ({reason})", file=str(path))
