"""Video overlays: the projection that places labels agrees with the renderer, and a frame shows what the legend
names (the robot's trail, BIG-CBF's imagined paths with the selected one, the legend band)."""
import numpy as np
import pytest

from bigcbf.episode import Episode
from bigcbf.params.stack import SIMULATION
from bigcbf.scenario import load_scenario
from bigcbf.sim.render import Renderer, add_points, project
from bigcbf.sim.scene import SceneSpec
from bigcbf.sim.world import SimWorld
from bigcbf.video import Overlay


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
