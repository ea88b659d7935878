"""The compiled social forces (issue 26) give the same bits as their numpy reference."""
import numpy as np
import pytest

from bigcbf.sim.pedestrians import Pedestrians


@pytest.mark.parametrize("k", [1, 2, 5, 9, 17])
def test_compiled_repulsion_is_the_numpy_reference_bit_for_bit(k):
    rng = np.random.default_rng(k)
    for trial in range(30):
        peds = Pedestrians([rng.uniform(-4, 4, (3, 2)) for _ in range(k)], rng.uniform(0.5, 1.5, k),
                           np.zeros(k), rng.uniform(0.15, 0.3, k), np.zeros(k, bool), np.ones(k, bool))
        peds.p = rng.uniform(-3, 3, (k, 2))
        peds.v = rng.normal(0, 0.8, (k, 2))
        peds.v[rng.random(k) < 0.2] = 0.0                       # standing: isotropic weight
        if k > 1:
            peds.p[1] = peds.p[0]                               # two at one spot: n = 0, no nan
        A = np.full((k, k), 2.0)
        np.fill_diagonal(A, 0.0)
        for q, rq, AA in ((peds.p, peds.r, A),
                          (rng.uniform(-3, 3, (1, 2)), np.array([0.15]), np.where(rng.random(k) < .5, 1.0, 0)[:, None])):
            got, ref = peds._repulsion(q, rq, AA), peds.repulsion_reference(q, rq, AA)
            assert np.all(np.isfinite(got))
            np.testing.assert_array_equal(got, ref)


def test_steps_with_the_compiled_forces_match_the_reference_walk():
    rng = np.random.default_rng(3)
    k = 12
    paths = [rng.uniform(-5, 5, (4, 2)) for _ in range(k)]
    args = (paths, rng.uniform(0.6, 1.4, k), rng.uniform(0, 1, k), np.full(k, 0.25), np.ones(k, bool),
            rng.random(k) < 0.5)
    a, b = Pedestrians(*args), Pedestrians(*args)
    b._repulsion = b.repulsion_reference
    for n in range(300):
        robot = (np.sin(0.01 * n), 0.5 * np.cos(0.02 * n))
        a.step(0.02 * n, 0.02, robot)
        b.step(0.02 * n, 0.02, robot)
    np.testing.assert_array_equal(a.p, b.p)
    np.testing.assert_array_equal(a.v, b.v)
