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


def _count_frames(path):
    import imageio_ffmpeg
    reader = imageio_ffmpeg.read_frames(str(path))
    next(reader)
    return sum(1 for _ in reader)


def test_an_interrupted_video_is_kept_as_a_partial_one(tmp_path):
    import pytest
    path = tmp_path / "v.mp4"
    path.write_bytes(b"keep me")
    with pytest.raises(KeyboardInterrupt):
        with VideoWriter(path, fps=10) as vw:
            for k in range(7):
                vw.write(np.full((64, 96, 3), 30 * k, np.uint8))
            raise KeyboardInterrupt
    assert path.read_bytes() == b"keep me"                     # never in the final file's place
    assert _count_frames(tmp_path / "v.partial.mp4") == 7      # a video that plays, every frame written
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.mp4", "v.partial.mp4"]
    # nothing written, or another error than an interrupt: nothing kept, no temporary file
    empty = VideoWriter(tmp_path / "e.mp4")
    assert empty.finish_partial() is None
    with pytest.raises(RuntimeError):
        with VideoWriter(tmp_path / "f.mp4") as vw:
            vw.write(np.zeros((64, 96, 3), np.uint8))
            raise RuntimeError("boom")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.mp4", "v.partial.mp4"]


def test_an_interrupt_waits_for_the_frame_being_written():
    """Ctrl-C inside imageio-ffmpeg's generator kills ffmpeg (the video is lost): a frame write is a section
    that a SIGINT ends only when it is done, with Python's default handler in place too."""
    import os
    import signal
    import time

    import pytest

    from bigcbf.sim.render import _whole_frame
    before = signal.signal(signal.SIGINT, signal.default_int_handler)      # as in a terminal (a test worker may
    try:                                                                   # ignore SIGINT)
        done = []
        with pytest.raises(KeyboardInterrupt):
            with _whole_frame():
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.05)                 # the handler runs in here
                done.append("frame written")
        assert done == ["frame written"]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, before)
