"""A robot is a folder (bigcbf/robots.py): its files, its generator, its kinematics read from the MJCF, and a second
robot (mecanum_large) running a shipped scenario from its own folder."""
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from bigcbf import robots
from bigcbf.config import load_run_config
from bigcbf.episode import Episode
from bigcbf.errors import UserError
from bigcbf.params.perception import X3_LASER_MOUNT, PerceptionParams
from bigcbf.params.toml_io import load_toml
from bigcbf.scenario import load_robot_profile, profile_files, resolve_path, scenario_from_dict
from bigcbf.sim.kinematics import MecanumKinematics
from bigcbf.sim.scene import SceneSpec
from bigcbf.sim.truth import robot_outline
from bigcbf.sim.world import SimWorld


def _check(script, cwd):
    """Run a generate.py with --check: compares what it would write with the files beside it, writes nothing."""
    return subprocess.run([sys.executable, str(script), "--check"], cwd=cwd, capture_output=True, text=True,
                          timeout=60)


@pytest.mark.parametrize("name", robots.robot_names())
def test_folder_has_its_files_and_the_generator_reproduces_them(name):
    d = robots.folder(name)
    for f in ("README.md", "LICENSE", "CHANGELOG.md", "generate.py", f"{name}.xml", "scene.xml"):
        assert (d / f).is_file(), f"{d}: {f} missing"
    before = {f: (d / f).read_bytes() for f in (f"{name}.xml", "scene.xml")}
    r = _check(d / "generate.py", d.parents[2])
    assert r.returncode == 0, r.stderr + r.stdout          # byte for byte what generate.py writes
    assert before == {f: (d / f).read_bytes() for f in before}
    assert robots.ROBOTS[name].profile in profile_files()        # its default profile is a shipped name
    load_robot_profile(robots.ROBOTS[name].profile)


def test_the_generator_check_notices_a_hand_edit(tmp_path):
    d = robots.folder("rosmaster_x3")
    for f in ("generate.py", "rosmaster_x3.xml", "scene.xml"):
        (tmp_path / f).write_bytes((d / f).read_bytes())
    assert _check(tmp_path / "generate.py", d.parents[2]).returncode == 0
    xml = tmp_path / "rosmaster_x3.xml"
    xml.write_text(xml.read_text().replace('mass="3.6"', 'mass="3.7"'))
    r = _check(tmp_path / "generate.py", d.parents[2])
    assert r.returncode != 0 and "rosmaster_x3.xml" in r.stderr and "scene.xml" not in r.stderr


def test_x3_kinematics_come_from_its_mjcf_unchanged():
    r = robots.robot("rosmaster_x3")
    assert r.kinematics == MecanumKinematics()           # bit for bit: the X3's results stay identical
    assert r.wheels == ("fl_wheel", "fr_wheel", "rl_wheel", "rr_wheel")
    assert r.roller_slopes == robots.X_ROLLER_SLOPES
    assert (r.outline.half_x, r.outline.half_y) == (0.15, 0.10) and robot_outline() == r.outline
    assert r.laser_mount[:2] == X3_LASER_MOUNT[:2] and r.footprint_radius_m == 0.15
    assert r.perception_params(PerceptionParams()) == PerceptionParams()
    assert r.mass_kg == pytest.approx(4.6, abs=0.05)


def test_large_robot_reads_its_own_dimensions():
    r = robots.robot("mecanum_large")
    k = r.kinematics
    assert (k.half_wheelbase_m, k.half_track_m, k.rolling_radius_m, k.max_wheel_speed_rad_s) == (0.2, 0.19, 0.075, 20.0)
    assert k.effective_scale == (0.981, 0.945, 0.995)
    assert (2 * r.outline.half_x, 2 * r.outline.half_y) == pytest.approx((0.60, 0.45))
    assert r.laser_mount == pytest.approx((0.20, 0.0, 0.2455, 0.0))
    p = r.perception_params(PerceptionParams())
    assert (p.laser_x_m, p.laser_y_m, p.laser_yaw_rad) == (0.20, 0.0, 0.0)
    mine = PerceptionParams(laser_x_m=0.19)                    # a mounting set on purpose is kept
    assert r.perception_params(mine) == mine
    assert r.mass_kg == pytest.approx(20.13, abs=0.01)
    world = SimWorld(SceneSpec(robot="mecanum_large"))
    assert world.kin == k and world.model.nu == 4 and world.robot is r
    assert world.sensor_frames()["laser"] == pytest.approx(r.laser_mount)
    assert 'model="mecanum_large"' in world.robot_description()


def _settled_twist(u, kin):
    world = SimWorld(SceneSpec(robot="mecanum_large"), kinematics=kin)
    world.command(u)
    world.advance(1.0)                       # settle
    samples = []
    for _ in range(100):                     # then average 1 s
        world.step(10)
        s = world.true_state()
        samples.append((s.vx, s.vy, s.wz))
    assert world.warnings() == {}
    return np.mean(samples, axis=0)


@pytest.mark.parametrize("u", [(0.5, 0.0, 0.0), (0.0, 0.5, 0.0), (0.35, 0.35, 0.0), (0.0, 0.0, 1.0)],
                         ids=["forward", "lateral", "diagonal", "spin"])
def test_large_robot_achieves_the_commanded_twist(u):
    u = np.array(u)
    achieved = _settled_twist(u, robots.robot("mecanum_large").kinematics)
    scale = np.where(np.abs(u) > 0, np.abs(u), np.linalg.norm(u))
    rel = np.abs(achieved - u) / scale
    assert np.all(rel < 0.05), f"achieved {achieved} for {u} (relative errors {rel})"


def test_large_robot_effective_scale_matches_its_model():
    kin = robots.robot("mecanum_large").kinematics
    ideal = replace(kin, effective_scale=(1.0, 1.0, 1.0))
    measured = [_settled_twist((0.5, 0, 0), ideal)[0] / 0.5, _settled_twist((0, 0.5, 0), ideal)[1] / 0.5,
                _settled_twist((0, 0, 1.0), ideal)[2]]
    np.testing.assert_allclose(measured, kin.effective_scale, rtol=0.01)


def _shipped_with_robot(name, model, **robot_keys):
    path = resolve_path(name)
    raw = load_toml(path)
    raw["robot"].update(model=model, **robot_keys)
    return scenario_from_dict(raw, path, seed=0)


def test_large_robot_runs_a_shipped_scenario():
    sc = _shipped_with_robot("required_sidestepping", "mecanum_large")
    assert sc.robot_profile_base.endswith("mecanum_large/profiles/mecanum_large_sim.toml")
    assert sc.robot_profile == load_robot_profile("mecanum_large_sim")
    config = load_run_config(robots.folder("mecanum_large") / "stack.toml")     # the r_R it suggests
    assert config.stack.uncertainty.r_robot_m == robots.robot("mecanum_large").footprint_radius_m == 0.30
    ep = Episode.from_config(sc, "big-cbf", 0, config, time_limit_s=3.0)
    assert ep.world.robot.name == "mecanum_large" and ep.truth.outline == robots.robot("mecanum_large").outline
    assert ep.perception.params.laser_x_m == 0.20                 # the perception knows the robot's laser mount
    res = ep.run()
    assert not res.collision and res.min_clearance_m > 0.1
    start, pose = np.array(sc.robot.start[:2]), ep.world.pose()
    assert pose[0] - start[0] > 0.8                              # drove towards the goal (8 m ahead) for 3 s
    # the LiDAR scans from its own mount: the site in the world is the pose plus the mount
    site = ep.world.data.site_xpos[ep.world.lidar.site_id]
    c, s = np.cos(pose[2]), np.sin(pose[2])
    assert site[:2] == pytest.approx([pose[0] + 0.20 * c, pose[1] + 0.20 * s], abs=2e-3)


def test_unknown_robot_is_one_line_naming_the_field():
    with pytest.raises(UserError) as exc:
        _shipped_with_robot("required_sidestepping", "no_such_robot")
    msg = str(exc.value)
    assert "field 'robot.model'" in msg and "unknown robot 'no_such_robot'" in msg and "rosmaster_x3" in msg
    assert "\n" not in msg
    with pytest.raises(UserError, match="unknown robot 'nope'"):
        SceneSpec(robot="nope")


def test_the_large_robot_must_fit_the_scene():
    """Its 0.60 x 0.45 m outline is what the geometry check tests: a wall 0.25 m behind the start fits the X3 (0.15 m
    half length) but not it."""
    path = resolve_path("required_sidestepping")
    raw = load_toml(path)
    raw["walls"] = [{"start": [-0.30, -2.0], "end": [-0.30, 2.0]}]
    scenario_from_dict(raw, path, seed=0)
    raw["robot"]["model"] = "mecanum_large"
    with pytest.raises(UserError, match=r"robot.start.*0.60 x 0.45 m"):
        scenario_from_dict(raw, path, seed=0)


def test_a_robot_folder_without_its_effective_scale_is_refused(tmp_path, monkeypatch):
    src = robots.folder("mecanum_large")
    text = (src / "mecanum_large.xml").read_text()
    cut = text[:text.index("  <custom>")] + "</mujoco>\n"
    (tmp_path / "mecanum_large.xml").write_text(cut)
    (tmp_path / "scene.xml").write_text((src / "scene.xml").read_text())
    monkeypatch.setitem(robots.ROBOTS, "broken_base", robots.RobotEntry(str(tmp_path), "x3_sim"))
    (tmp_path / "mecanum_large.xml").rename(tmp_path / "broken_base.xml")
    with pytest.raises(UserError, match="effective_scale"):
        robots.robot("broken_base")
