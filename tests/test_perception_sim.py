"""Perception on the simulated LiDAR (MuJoCo ray casting), against the simulator's ground truth."""
import mujoco
import numpy as np

from bigcbf.perception.pipeline import Perception
from bigcbf.sim.lidar import LidarConfig
from bigcbf.sim.scene import Box, PedestrianBody, SceneSpec
from bigcbf.sim.world import SimWorld


def _track_near(obs, xy):
    tracks = [i for i in range(len(obs)) if obs.ids[i] >= 0]
    if not tracks:
        return None
    return min(tracks, key=lambda i: np.linalg.norm(obs.p[i] - xy))


def test_pedestrian_crossing_at_1mps_is_tracked(capsys):
    """A pedestrian walks at 1.0 m/s across the LiDAR 2 m ahead: velocity within 0.15 m/s after 1 s."""
    world = SimWorld(SceneSpec(pedestrians=(PedestrianBody("p", radius=0.25, x=2.0, y=-2.0),)),
                     lidar=LidarConfig(range_noise_std_m=0.01), seed=1)
    mid = world.model.body_mocapid[mujoco.mj_name2id(world.model, mujoco.mjtObj.mjOBJ_BODY, "ped_p")]
    perception = Perception()
    v_true = np.array([0.0, 1.0])
    errs, vel_err_after_1s = [], []
    for k in range(40):                        # 4 s of scans at 10 Hz
        t = 0.1 * k
        truth = np.array([2.0, -2.0]) + v_true * t
        world.data.mocap_pos[mid, :2] = truth
        world.step(50)
        obs = perception.update(world.scan(), (0.0, 0.0, 0.0))
        i = _track_near(obs, truth)
        if i is None:
            continue
        errs.append(np.linalg.norm(obs.p[i] - truth))
        if t >= 1.0:
            vel_err_after_1s.append(np.linalg.norm(obs.v[i] - v_true))
            assert not obs.static[i]
    rmse = float(np.sqrt(np.mean(np.square(errs))))
    with capsys.disabled():
        print(f"\n  pedestrian 1.0 m/s: position RMSE {rmse:.3f} m, max velocity error after 1 s "
              f"{max(vel_err_after_1s):.4f} m/s (mean {np.mean(vel_err_after_1s):.4f})")
    assert len(vel_err_after_1s) >= 25
    assert max(vel_err_after_1s) < 0.15
    assert rmse < 0.10


def test_static_box_is_static_points_on_its_surface():
    """A 0.4 m square box while the robot drives past and stops: it is tracked (one static track all along, so a
    box that started moving would be followed) and reported by wall points on its surface, never as its
    circumscribed circle (``Tracker.report``: a static track that is not round)."""
    world = SimWorld(SceneSpec(boxes=(Box(1.5, 0.8, 0.2, 0.2),)))
    perception = Perception()
    ids = set()
    for k in range(50):
        world.command((0.2, 0.0, 0.0) if k < 25 else (0.0, 0.0, 0.0))   # the robot moves, then stops
        world.step(50)
        o = world.odom()
        obs = perception.update(world.scan(), (o.px, o.py, o.theta))
        assert np.all(obs.ids < 0), f"a circle at t = {0.1 * (k + 1):.1f} s"
        # distance of each wall point from the box's surface (axis-aligned, half sides 0.2 m)
        q = np.abs(obs.p - (1.5, 0.8)) - 0.2
        off = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
        assert np.sum(np.abs(off) < 0.03) >= 2, f"box not represented at t = {0.1 * (k + 1):.1f} s"
        T = perception.tracker
        assert T.static.all()
        ids |= set(T.ids[T.confirmed].tolist())
    assert len(ids) == 1
