"""Issue 26: compiled pieces of the control side against their references: the obstacle groups' connected
components (behaviors._components: scipy's labels and dtype), the usability check of the inputs (faults._usable)."""
import numpy as np
from scipy.sparse.csgraph import connected_components

from bigcbf.control.behaviors import _components, obstacle_groups
from bigcbf.params import SIMULATION


def test_components_are_scipys_connected_components():
    rng = np.random.default_rng(0)
    for _ in range(500):
        M = int(rng.integers(2, 60))
        p = rng.uniform(0, rng.uniform(0.5, 20), (M, 2))
        adj = np.hypot(*(p[:, None, :] - p[None, :, :]).transpose(2, 0, 1)) < rng.uniform(0.1, 3)
        want = connected_components(adj, directed=False)[1]
        got = np.empty(M, np.int32)
        _components(adj, got)
        assert np.array_equal(got, want) and got.dtype == want.dtype


def test_groups_by_hand():
    """Three posts 0.5 m apart in a row (gaps 0.3 m: the footprint, 2 (r_R + d0) + 0.1, cannot pass) and one 3 m
    away: two groups, labelled in the order of their first member."""
    p = [[5.0, 0.0], [0.0, 0.0], [0.5, 0.0], [1.0, 0.0]]
    assert obstacle_groups(p, [0.1] * 4, SIMULATION).tolist() == [0, 1, 1, 1]


def _plainly_usable_numpy(p, v, cov, r):
    """faults._plainly_usable as of a086be6 (numpy), the reference."""
    import math
    from bigcbf.control.faults import MAX_COVARIANCE_M2, MAX_POSITION_M, MAX_RADIUS_M, MAX_SPEED_MPS
    with np.errstate(over="ignore", invalid="ignore"):
        if (np.isfinite(p).all() and np.isfinite(v).all() and np.isfinite(cov).all() and np.isfinite(r).all()
                and np.abs(p).max() <= MAX_POSITION_M and np.abs(v).max() <= MAX_SPEED_MPS / math.sqrt(2)
                and r.min() >= 0 and r.max() <= MAX_RADIUS_M):
            c01, c10 = cov[:, 0, 1], cov[:, 1, 0]
            a, c = cov[:, 0, 0], cov[:, 1, 1]
            if (np.array_equal(c01, c10) and (a >= 0).all() and (c >= 0).all() and (a * c >= c01 * c01).all()
                    and (a + c).max() <= MAX_COVARIANCE_M2):
                return True
    return False


def test_compiled_usability_check_is_the_numpy_check():
    """faults._plainly_usable (compiled: faults._usable) against its numpy form on good inputs and on inputs with
    one number spoiled (NaN, inf, huge, negative radius, asymmetric or indefinite covariance, at the bounds)."""
    from bigcbf.control.faults import (MAX_COVARIANCE_M2, MAX_POSITION_M, MAX_RADIUS_M, MAX_SPEED_MPS,
                                       _plainly_usable)
    rng = np.random.default_rng(2)
    spoil = [np.nan, np.inf, -np.inf, 1e300, -1.0, MAX_POSITION_M, MAX_POSITION_M * 1.0000001, MAX_RADIUS_M,
             MAX_SPEED_MPS / np.sqrt(2), MAX_COVARIANCE_M2, 0.0, -0.0, 1e-300]
    seen = set()
    for trial in range(3000):
        M = int(rng.integers(1, 6))
        p, v = rng.normal(0, 3, (M, 2)), rng.normal(0, 0.5, (M, 2))
        a = rng.normal(size=(M, 2, 2)) * 0.1
        cov, r = a @ a.transpose(0, 2, 1), rng.uniform(0, 0.5, M)
        arr = [p, v, cov, r][trial % 4]
        if trial % 5:
            arr.flat[rng.integers(arr.size)] = spoil[trial % len(spoil)]
        want = _plainly_usable_numpy(p, v, cov, r)
        assert _plainly_usable(p, v, cov, r) == want
        seen.add(want)
    assert seen == {True, False}
