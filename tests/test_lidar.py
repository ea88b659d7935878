"""The simulated LiDAR: ranges to known geometry, misses, self-exclusion, LaserScan shape."""
import numpy as np
import pytest

from bigcbf.params.perception import X3_LASER_MOUNT, PerceptionParams
from bigcbf.robots import robot
from bigcbf.sim.lidar import LidarConfig
from bigcbf.sim.scene import Cylinder, PedestrianBody, SceneSpec, Wall
from bigcbf.sim.world import SimWorld

LASER_X = X3_LASER_MOUNT[0]     # the laser sits 4.35 cm ahead of base_link


def test_one_laser_mount_for_model_and_perception():
    """The X3 MJCF's lidar site (the robot's mount, bigcbf/robots.py) and the perception's default mounting
    (X3_LASER_MOUNT) agree."""
    x, y, _, yaw = SimWorld(SceneSpec()).sensor_frames()["laser"]
    assert (x, y, yaw) == pytest.approx(X3_LASER_MOUNT, abs=1e-9)
    p = PerceptionParams()
    assert (p.laser_x_m, p.laser_y_m, p.laser_yaw_rad) == X3_LASER_MOUNT
    assert X3_LASER_MOUNT == (0.0435, 0.0, 0.0)        # URDF laser_joint (assets/rosmaster_x3/README.md)
    assert robot("rosmaster_x3").laser_mount == pytest.approx((*X3_LASER_MOUNT[:2], 0.192, 0.0), abs=1e-9)


def _beam(scan, angle):
    return scan.ranges[int(np.argmin(np.abs(scan.angles - angle)))]


def test_scan_shape_like_laserscan():
    s = SimWorld(SceneSpec()).scan()
    assert len(s.ranges) == 360 and s.ranges.dtype == np.float32
    assert s.angle_min == pytest.approx(-np.pi) and s.angle_increment == pytest.approx(np.pi / 180)
    assert (s.range_min, s.range_max) == (0.12, 8.0)


def test_empty_world_all_misses_and_robot_excluded():
    """Nothing but the robot and the floor: every beam reports inf (the robot's own geoms are not seen)."""
    s = SimWorld(SceneSpec()).scan()
    assert np.all(np.isinf(s.ranges))


def test_ranges_to_wall_and_cylinder_within_1cm():
    # wall face at x = 2 - 0.05 (thickness 0.1); cylinder radius 0.2 at (0, 1.5)
    world = SimWorld(SceneSpec(walls=(Wall(2, -3, 2, 3),), cylinders=(Cylinder(0.0, 1.5, 0.2),)))
    s = world.scan()
    assert _beam(s, 0.0) == pytest.approx(1.95 - LASER_X, abs=0.01)
    # beam at 30 deg hits the wall plane at (1.95 - x_l)/cos(30)
    assert _beam(s, np.pi / 6) == pytest.approx((1.95 - LASER_X) / np.cos(np.pi / 6), abs=0.01)
    # beam straight left from (x_l, 0) meets the cylinder at y = 1.5 - sqrt(0.2^2 - x_l^2)
    assert _beam(s, np.pi / 2) == pytest.approx(1.5 - np.sqrt(0.04 - LASER_X**2), abs=0.01)
    assert np.isinf(_beam(s, np.pi))         # nothing behind


def test_scan_follows_robot_yaw_and_sees_pedestrians():
    world = SimWorld(SceneSpec(pedestrians=(PedestrianBody("p", radius=0.25, x=0.0, y=2.0),),
                               robot_start=(0.0, 0.0, np.pi / 2)))
    s = world.scan()
    # facing +y: the pedestrian is dead ahead at 2 - 0.25 - x_l
    assert _beam(s, 0.0) == pytest.approx(2.0 - 0.25 - LASER_X, abs=0.01)


def test_range_noise_and_limits():
    world = SimWorld(SceneSpec(walls=(Wall(1, -3, 1, 3), Wall(-9.5, -3, -9.5, 3))),
                     lidar=LidarConfig(range_noise_std_m=0.01), seed=4)
    s = world.scan()
    front = s.ranges[np.abs(s.angles) < 0.3]
    assert np.all(np.isfinite(front)) and 0.002 < np.std(front - (0.95 - LASER_X) / np.cos(s.angles[np.abs(s.angles) < 0.3])) < 0.02
    assert np.isinf(_beam(s, np.pi))         # the far wall is beyond range_max = 8 m
