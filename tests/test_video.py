"""Video overlays: the projection that places labels agrees with the renderer, and a frame shows what the legend
names (the robot's trail, BIG-CBF's imagined paths with the selected one, the legend band), behavior labels
that name what the cyan path is, a progress line on a terminal."""
import io

import numpy as np
import pytest

from bigcbf.episode import Episode
from bigcbf.params.stack import SIMULATION
from bigcbf.scenario import load_scenario
from bigcbf.sim.render import Renderer, add_points, project
from bigcbf.sim.scene import SceneSpec
from bigcbf.sim.world import SimWorld
from bigcbf.video import TOP_VIEW_Z, Overlay


@pytest.mark.parametrize("camera", ["top", "track"])
def test_projection_puts_a_point_where_the_renderer_draws_it(camera):
    world = SimWorld(SceneSpec(extent=3.0))
    point = np.array([1.2, -0.7, 0.3])
    with Renderer(world.model, 320, 240) as r:
        frame = r.render(world.data, camera,
                         decorate=lambda scn: add_points(scn, point[None, :2], z=point[2], radius=0.06,
                                                         rgba=(1.0, 0.0, 1.0, 1.0)))
    magenta = (frame[..., 0] > 200) & (frame[..., 1] < 60) & (frame[..., 2] > 200)
    assert magenta.sum() > 4
    v, u = np.nonzero(magenta)
    uv, front = project(world.model, world.data, camera, point[None], 320, 240)
    assert front[0] and np.hypot(u.mean() - uv[0, 0], v.mean() - uv[0, 1]) < 2.0


def _magenta(frame):       # the trail (TRAIL_RGBA under the scene's lighting)
    f = frame.astype(int)
    return int(((f[..., 0] > 150) & (f[..., 2] > 120) & (f[..., 0] - f[..., 1] > 60)).sum())


def _cyan(frame):          # the selected path (SELECTED_RGBA under the scene's lighting)
    f = frame.astype(int)
    return int(((f[..., 1] > 170) & (f[..., 2] > 170) & (f[..., 0] < 130)).sum())


def test_a_frame_shows_the_trail_the_imagined_paths_and_the_legend():
    ep = Episode(load_scenario("required_sidestepping", 0), "big-cbf", 0, SIMULATION, time_limit_s=4.0)
    frames = {}
    with Renderer(ep.world.model, 640, 480) as r:
        overlay = Overlay(ep, r, "top")

        def observe(rec):
            overlay.observe(rec)
            if len(overlay.trail) in (1, 19) and len(overlay.trail) not in frames:
                frames[len(overlay.trail)] = overlay.frame(rec)

        ep.observers.append(observe)
        ep.run()
    first, later = frames[1], frames[19]
    assert first.shape[1] == 640 and first.shape[0] > 480 and first.shape[0] % 16 == 0     # the legend band
    band = later[480:]
    assert band.std() > 10 and _magenta(band) > 10 and _cyan(band) > 10       # the legend's swatches and text
    scene_first, scene_later = first[:480], later[:480]
    assert _magenta(scene_later) > _magenta(scene_first) + 20                 # the trail grew
    assert _cyan(scene_later) > 20                                            # the selected imagined path
    img = ep.planner.last_imagination
    assert img is not None and int(img.available.sum()) >= 5                   # the six behaviors' paths drawn


@pytest.mark.parametrize("camera", ["top", "track"])
def test_lidar_hits_are_red_dots_where_they_are(camera):
    """The top view draws the hits on the image (cheaper than a sphere each), the track view in the scene: either
    way a red dot at each hit's place."""
    ep = Episode(load_scenario("required_sidestepping", 0), "big-cbf", 0, SIMULATION, time_limit_s=4.0)
    ep.begin()
    for _ in range(20):
        ep.act()
    with Renderer(ep.world.model, 640, 480) as r:
        overlay = Overlay(ep, r, camera)
        rec = ep.act()
        frame = overlay.frame(rec)[:480].astype(int)
        hits = overlay._lidar_hits(rec)
        z = TOP_VIEW_Z + 0.19 if camera == "top" else 0.19
        uv, front = project(ep.world.model, ep.world.data, camera, np.column_stack([hits, np.full(len(hits), z)]),
                            640, 480)
    inside = front & (uv[:, 0] >= 0) & (uv[:, 0] < 640) & (uv[:, 1] >= 0) & (uv[:, 1] < 480)
    assert len(hits) > 50 and inside.sum() > 30
    red = (frame[..., 0] > 120) & (frame[..., 1] < 90) & (frame[..., 2] < 90)
    near = [red[max(int(round(y)) - 1, 0):int(round(y)) + 2, max(int(round(x)) - 1, 0):int(round(x)) + 2].any()
            for x, y in uv[inside]]
    assert np.mean(near) > 0.75          # (the track view: a few behind the robot or the box)


def _box_pixels(frame, box):
    x0, y0, x1, y1 = box
    return frame[max(y0, 0):y1, max(x0, 0):x1].astype(int)


@pytest.mark.parametrize("camera", ["track", "top"])
def test_the_cyan_path_is_labelled_with_the_steps_mode(camera):
    """Found at 8.6 s of required_sidestepping (seed 0, the former big-cbf, the obstacle then on the goal line): the
    robot followed GOAL, and the latest imagination's PASS-R path ended where GOAL's did: the track view labelled the
    cyan path PASS-R. At 3, 6 and 8.6 s the label at the cyan path's end is the step's mode, drawn in cyan, and no
    other label covers it (whatever the modes are: the scene and big-cbf have changed since)."""
    from bigcbf.api import load_config       # as `bigcbf run` (the default configuration)
    ep = Episode.from_config(load_scenario("required_sidestepping", 0), "big-cbf", 0, load_config(None, None),
                             time_limit_s=8.7)
    checked = []
    with Renderer(ep.world.model, 640, 480) as r:
        overlay = Overlay(ep, r, camera)

        def observe(rec):
            overlay.observe(rec)
            if not any(abs(rec.t - t) < 0.026 for t in (3.0, 6.0, 8.6)) or rec.path is None:
                return
            frame = overlay.frame(rec)[:480]
            selected = [lab for lab in overlay.last_labels if lab.kind == "selected"]
            assert [lab.text for lab in selected] == [rec.mode]
            lab = selected[0]
            end = np.array([[*rec.path[-1], (TOP_VIEW_Z if camera == "top" else 0.0) + 0.03]])
            uv, front = project(ep.world.model, ep.world.data, camera, end, 640, 480)
            assert front[0] and np.hypot(*(uv[0] - lab.uv)) < 1.5       # placed at the cyan path's own end
            u, v = int(lab.uv[0]), int(lab.uv[1])
            assert _cyan(frame[max(v - 12, 0):v + 12, max(u - 12, 0):u + 12]) > 3   # the cyan path is there
            px = _box_pixels(frame, lab.box)
            text_cyan = (px[..., 1] > 150) & (px[..., 2] > 150) & (px[..., 0] < 150)
            r, g, b = px[..., 0], px[..., 1], px[..., 2]
            text_grey = (r > 110) & (np.abs(r - g) < 25) & (np.abs(g - b) < 25)
            assert text_cyan.sum() > 15 and text_grey.sum() < 3              # drawn in cyan, nothing written over it
            for other in overlay.last_labels:
                if other.kind == "imagined":
                    assert other.text != rec.mode
                    x0, y0, x1, y1 = other.box
                    assert x1 <= lab.box[0] or lab.box[2] <= x0 or y1 <= lab.box[1] or lab.box[3] <= y0
            if camera == "top":
                assert not any(other.kind == "imagined" for other in overlay.last_labels)
            checked.append((round(rec.t, 2), rec.mode))

        ep.observers.append(observe)
        ep.run()
    assert [t for t, _ in checked] == [3.0, 6.0, 8.6]


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_a_video_shows_its_progress_on_a_terminal_only(tmp_path, monkeypatch):
    from bigcbf.video import EpisodeVideo
    shown = {}
    for name, stream in (("tty", _Terminal()), ("log", io.StringIO())):
        monkeypatch.setattr("sys.stderr", stream)
        ep = Episode(load_scenario("required_sidestepping", 0), "big-cbf", 0, SIMULATION, time_limit_s=1.0)
        with EpisodeVideo(ep, tmp_path / f"{name}.mp4", width=160, height=120):
            ep.run()
        shown[name] = stream.getvalue()
    assert shown["log"] == ""                            # nothing in logs or CI
    lines = shown["tty"].split("\r")
    assert len(lines) > 3 and shown["tty"].endswith("\n") and shown["tty"].count("\n") == 1
    assert "video tty.mp4" in lines[-1] and "100%" in lines[-1] and "1.0/1.0 s simulated, 20 frames" in lines[-1]
    assert any("encoding" in line for line in lines)


def _frames(path):
    import imageio_ffmpeg
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    return meta, sum(1 for _ in reader)


def test_ctrl_c_keeps_a_partial_video_that_plays(tmp_path):
    """`bigcbf run --video X.mp4` interrupted (SIGINT, as Ctrl-C sends it) keeps the frames so far as
    X.partial.mp4, leaves X.mp4 as it was and no temporary file."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    out = tmp_path / "x.mp4"
    out.write_bytes(b"an earlier video")
    exe = Path(sys.executable).with_name("bigcbf")
    env = dict(os.environ, MUJOCO_GL="egl")
    # a child of a background job inherits an ignored SIGINT; a terminal's foreground process has the default
    proc = subprocess.Popen([str(exe), "run", "required_sidestepping", "--video", str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:      # frames being written: 1 s more
            if any(p.stat().st_size > 50_000 for p in tmp_path.glob(".x.*")):
                break
            time.sleep(0.1)
        time.sleep(1.0)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert out.read_bytes() == b"an earlier video"
    partial = tmp_path / "x.partial.mp4"
    meta, n = _frames(partial)
    assert meta["codec"].startswith("h264") and n > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.mp4", "x.partial.mp4"]
