"""Issue 26: the obstacle groups' connected components (behaviors._components) are scipy's, labels and dtype."""
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
