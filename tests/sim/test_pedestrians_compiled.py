"""The pedestrians' compiled social-force step (sim/pedestrians.py ``_social_step``) gives the numpy reference's
numbers bit for bit: crowds of one to six, with and without the robot, walkers starting late, looping and stopping
at their last waypoint, running into each other and into the robot."""
from __future__ import annotations

import numpy as np
import pytest

from bigcbf.sim.pedestrians import Pedestrians, SocialForceParams


def _twins(k: int, seed: int, params: SocialForceParams):
    rng = np.random.default_rng(seed)
    args = ([rng.uniform(-2, 2, (int(rng.integers(2, 5)), 2)) for _ in range(k)], rng.uniform(0.6, 1.5, k),
            rng.uniform(0, 1.0, k), rng.uniform(0.15, 0.35, k), rng.random(k) < 0.5, rng.random(k) < 0.7)
    return Pedestrians(*args, params=params, seed=seed), Pedestrians(*args, params=params, seed=seed), rng


@pytest.mark.parametrize("k", [1, 2, 3, 6])
@pytest.mark.parametrize("with_robot", [True, False])
def test_compiled_step_is_the_reference(k, with_robot):
    for seed, params in ((k, SocialForceParams()), (10 + k, SocialForceParams(A_mps2=6.0, B_m=0.5, anisotropy=0.1,
                                                                                  A_robot_mps2=4.0))):
        a, b, rng = _twins(k, seed, params)
        robot = np.zeros(2)
        for n in range(600):
            t = 0.02 * n
            robot += rng.normal(0, 0.02, 2)
            xy = tuple(robot) if with_robot else None
            a.step(t, 0.02, robot_xy=xy)
            b.step_reference(t, 0.02, robot_xy=xy)
            assert np.array_equal(a.v, b.v) and np.array_equal(a.p, b.p), (k, seed, n)
            assert np.array_equal(a.target, b.target) and np.array_equal(a.done, b.done)
        assert np.any(a.v != 0)


def test_no_pedestrians_is_a_no_op():
    p = Pedestrians([], [], [], [], [], [])
    p.step(0.0, 0.02, robot_xy=(0.0, 0.0))
    assert p.p.shape == (0, 2)
