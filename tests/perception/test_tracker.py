"""The tracker on hand-made cluster centres: assignment, gates, birth, confirmation, deletion, capacity."""
import numpy as np
import pytest

from bigcbf.params.perception import PerceptionParams
from bigcbf.perception.tracker import Tracker

ORIGIN = np.zeros(2)


def _tracker(**kw):
    return Tracker(PerceptionParams(**kw))


def test_assignment_minimises_total_distance():
    tr = _tracker(gate_min_m=0.5, gate_max_m=1.0, confirm_hits=1)
    tr.step(0.0, np.array([[0.0, 0.0], [0.6, 0.0]]), np.array([0.2, 0.2]), ORIGIN)
    assert tr.ids.tolist() == [0, 1]
    # both clusters are inside both gates (0.35 and 0.25 from each track); the pairing with the least total
    # distance is track 0 -> (0.25, 0) [0.25 m] and track 1 -> (0.35, 0) [0.25 m]; the swap costs 0.35 + 0.35
    rows, cols = tr.associate(np.array([[0.35, 0.0], [0.25, 0.0]]), np.array([0.2, 0.2]))
    assert dict(zip(rows.tolist(), cols.tolist())) == {0: 1, 1: 0}


def test_gates():
    tr = _tracker(confirm_hits=1)
    tr.step(0.0, np.array([[1.0, 0.0]]), np.array([0.25]), ORIGIN)
    z = np.array([[1.2, 0.0], [2.5, 0.0], [1.1, 0.0]])
    r = np.array([0.25, 0.25, 0.6])
    # 1.2: within gate_min_m; 2.5: beyond gate_max_m; 1.1 with radius 0.6: radius differs by > gate_radius_m
    for k, expect in ((0, True), (1, False), (2, False)):
        rows, _ = tr.associate(z[k:k + 1], r[k:k + 1])
        assert (len(rows) == 1) == expect


def test_birth_confirmation_and_deletion():
    p = PerceptionParams(confirm_hits=3, tentative_max_misses=1, coast_s=0.3)
    tr = Tracker(p)
    z, r = np.array([[2.0, 0.0]]), np.array([0.2])
    for k in range(3):
        tr.step(0.1 * k, z, r, ORIGIN)
        assert tr.confirmed.tolist() == [k == 2]
    assert len(tr.obstacles(ORIGIN)) == 1
    for t in (0.3, 0.4, 0.5):                    # coasting: kept while t - last_hit <= coast_s
        tr.step(t, np.zeros((0, 2)), np.zeros(0), ORIGIN)
        assert len(tr) == 1
    tr.step(0.6, np.zeros((0, 2)), np.zeros(0), ORIGIN)
    assert len(tr) == 0
    # a tentative track dies after tentative_max_misses + 1 misses
    tr.step(1.0, z, r, ORIGIN)
    tr.step(1.1, np.zeros((0, 2)), np.zeros(0), ORIGIN)
    assert len(tr) == 1
    tr.step(1.2, np.zeros((0, 2)), np.zeros(0), ORIGIN)
    assert len(tr) == 0


def test_no_birth_inside_a_known_object_and_rejected_reported():
    tr = _tracker(confirm_hits=1)
    tr.step(0.0, np.array([[2.0, 0.0]]), np.array([0.3]), ORIGIN)
    # next scan: the object's cluster plus a merged blob centred inside it with a much larger radius
    rej = tr.step(0.1, np.array([[2.0, 0.0], [2.1, 0.0]]), np.array([0.3, 0.7]), ORIGIN)
    assert len(tr) == 1 and rej.tolist() == [1]


def test_capacity_keeps_the_nearest():
    tr = _tracker(max_candidates=3, max_tracks=2, confirm_hits=1)
    z = np.array([[5.0, 0.0], [1.0, 0.0], [3.0, 0.0], [2.0, 0.0], [4.0, 0.0]])
    tr.step(0.0, z, np.full(5, 0.2), ORIGIN)
    assert sorted(tr.x[:, 0].tolist()) == [1.0, 2.0, 3.0]
    obs = tr.obstacles(ORIGIN)
    assert obs.p[:, 0].tolist() == [1.0, 2.0]
    assert obs.cov.shape == (2, 2, 2) and np.all(obs.r == pytest.approx(0.2))
