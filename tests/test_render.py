"""Offscreen rendering and H.264 video."""
import numpy as np

from bigcbf.sim.render import Renderer, VideoWriter, add_ring, put_text
from bigcbf.sim.scene import Cylinder, SceneSpec
from bigcbf.sim.world import SimWorld


def test_frames_are_not_blank_and_show_the_robot(tmp_path):
    world = SimWorld(SceneSpec(cylinders=(Cylinder(1.0, 0.0, 0.2),), extent=2.0))
    with Renderer(world.model, 320, 240) as r:
        track = r.render(world.data, "track")
        top = r.render(world.data, "top", decorate=lambda s: add_ring(s, (1.0, 0.0), 0.5))
        # the robot's visual geoms are shown: hiding group 3 changes the image
        r._opt.geomgroup[3] = 0
        no_robot = r.render(world.data, "track")
    for f in (track, top):
        assert f.shape == (240, 320, 3) and f.dtype == np.uint8
        assert f.std() > 10                  # not a blank or single-colour frame
    assert np.abs(track.astype(int) - no_robot).sum() > 1000


def test_video_is_h264_mp4(tmp_path):
    import imageio_ffmpeg
    path = tmp_path / "v.mp4"
    with VideoWriter(path, fps=10) as vw:
        for k in range(10):
            frame = np.full((96, 128, 3), 20 * k, np.uint8)
            vw.write(put_text(frame, [f"{k}"]))
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    assert meta["codec"].startswith("h264") and "yuv420p" in meta["pix_fmt"]
    assert sum(1 for _ in reader) == 10
