"""The Mecanum robot model: compiles, runs cleanly, pinned sizes, and moves as commanded."""
from pathlib import Path

import mujoco
import numpy as np
import pytest

from bigcbf import ASSETS
from bigcbf.sim.kinematics import MecanumKinematics
from bigcbf.sim.scene import SceneSpec
from bigcbf.sim.world import SimWorld

SCENES = sorted(ASSETS.rglob("scene*.xml"))


def test_scene_files_exist():
    assert SCENES, "no scene*.xml under assets/"


@pytest.mark.parametrize("path", SCENES, ids=lambda p: str(p.relative_to(ASSETS)))
def test_scene_compiles_and_runs_without_warnings(path: Path):
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    rng = np.random.default_rng(0)
    lo, hi = m.actuator_ctrlrange[:, 0], m.actuator_ctrlrange[:, 1]
    for k in range(int(1.0 / m.opt.timestep)):
        if k % 50 == 0:                       # new wheel commands every 0.1 s, across the full range
            d.ctrl[:] = rng.uniform(lo, hi)
        mujoco.mj_step(m, d)
    assert all(w.number == 0 for w in d.warning), [(i, w.number) for i, w in enumerate(d.warning) if w.number]
    assert np.all(np.isfinite(d.qpos))


def test_model_sizes_are_pinned():
    """Catch unintended model changes: 7 (free) + 4 wheels + 48 rollers."""
    m = mujoco.MjModel.from_xml_path(str(ASSETS / "rosmaster_x3" / "scene.xml"))
    assert (m.nq, m.nv, m.nu) == (59, 58, 4)
    assert m.opt.timestep == 0.002
    total_mass = float(m.body_mass.sum())
    assert total_mass == pytest.approx(4.6, abs=0.05)


def _settled_twist(u, kin=MecanumKinematics()):
    world = SimWorld(SceneSpec(), kinematics=kin)
    world.command(u)
    world.advance(1.0)                       # settle
    samples = []
    for _ in range(100):                     # then average 1 s
        world.step(10)
        s = world.true_state()
        samples.append((s.vx, s.vy, s.wz))
    return np.mean(samples, axis=0)


@pytest.mark.parametrize("u", [(0.5, 0.0, 0.0), (0.0, 0.5, 0.0), (0.35, 0.35, 0.0), (0.0, 0.0, 1.0)],
                         ids=["forward", "lateral", "diagonal", "spin"])
def test_kinematic_fidelity_within_5_percent(u):
    u = np.array(u)
    achieved = _settled_twist(u)
    scale = np.where(np.abs(u) > 0, np.abs(u), np.linalg.norm(u))
    rel = np.abs(achieved - u) / scale
    assert np.all(rel < 0.05), f"achieved {achieved} for {u} (relative errors {rel})"


def test_effective_scale_matches_the_model():
    """The firmware's per-axis effective scales are what the model does today (within 1 %)."""
    ideal = MecanumKinematics(effective_scale=(1.0, 1.0, 1.0))
    measured = np.array([_settled_twist((0.5, 0, 0), ideal)[0] / 0.5, _settled_twist((0, 0.5, 0), ideal)[1] / 0.5,
                         _settled_twist((0, 0, 1.0), ideal)[2] / 1.0])
    np.testing.assert_allclose(measured, MecanumKinematics().effective_scale, rtol=0.01)


def test_ground_truth_and_wheel_odometry_are_kept_apart():
    world = SimWorld(SceneSpec())
    world.command((0.4, 0.2, 0.3))
    world.advance(2.0)
    odom, true = world.odom(), world.true_state()
    assert np.hypot(odom.px - true.px, odom.py - true.py) < 0.1     # close, as good odometry is
    assert (odom.px, odom.py) != (true.px, true.py)                  # but a separate estimate


@pytest.mark.parametrize("u, where", [((0.4, 0.0, 0.0), "front"), ((0.0, -0.4, 0.0), "side")])
def test_obstacles_touch_the_body_and_the_ground_touches_the_rollers(u, where):
    """Two contact layers: driving into a wall, the wall touches the body's outline (bumper, chassis, LiDAR),
    never a roller; the floor touches only rollers; GroundTruth reports the contact."""
    import mujoco
    from bigcbf.sim.scene import Wall
    from bigcbf.sim.truth import GroundTruth
    wall = Wall(0.45, -1.0, 0.45, 1.0) if where == "front" else Wall(-1.0, -0.4, 1.0, -0.4)
    world = SimWorld(SceneSpec(walls=(wall,)))
    truth = GroundTruth(world.model, world.scene)
    m, d = world.model, world.data
    name = lambda g: mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or ""
    world.command(u)
    touched = False
    for _ in range(150):
        world.step(5)
        pairs = [(name(c.geom[0]), name(c.geom[1])) for c in d.contact[:d.ncon]]
        for a, b in pairs:
            assert "floor" not in (a, b) or not ({a, b} & {"chassis", "bumper", "lidar"})
            if "wall0" in (a, b):
                assert ({a, b} - {"wall0"}) <= {"chassis", "bumper", "lidar"}, pairs
        if truth.in_contact(d):
            touched = True
            break
    assert touched
    # the outline that touched: the bumper is the robot's 0.30 x 0.20 m extent (wall faces 0.05 m thick)
    x, y = d.qpos[0], d.qpos[1]
    if where == "front":
        assert x == pytest.approx(0.45 - 0.05 - 0.15, abs=0.01)
    else:
        assert y == pytest.approx(-0.4 + 0.05 + 0.10, abs=0.01)
