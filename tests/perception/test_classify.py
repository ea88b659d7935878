"""Static/dynamic hysteresis: thresholds, dwell counts, counter resets (hand-made sequences)."""
import numpy as np
import pytest

from bigcbf.params.perception import PerceptionParams
from bigcbf.perception.classify import hysteresis_step, speed_sigma

P = PerceptionParams(v_dynamic_mps=0.3, v_static_mps=0.15, n_dynamic=3, n_static=5, dynamic_sigma=1.0)


def _run(speeds, static=True, sigma=0.0, params=P):
    """Feed a speed sequence to one track; return its class after each update."""
    st, nd, ns = np.array([static]), np.array([0]), np.array([0])
    out = []
    for v in speeds:
        st, nd, ns = hysteresis_step(st, nd, ns, np.array([v]), np.array([sigma]), params)
        out.append(bool(st[0]))
    return out


def test_becomes_dynamic_after_n_dynamic_fast_updates():
    assert _run([0.5, 0.5, 0.5]) == [True, True, False]


def test_a_speed_inside_the_band_resets_the_dynamic_counter():
    # 0.2 m/s is between v_static and v_dynamic: the count restarts
    assert _run([0.5, 0.5, 0.2, 0.5, 0.5, 0.5]) == [True, True, True, True, True, False]


def test_becomes_static_after_n_static_slow_updates_and_band_holds():
    assert _run([0.1] * 5, static=False) == [False] * 4 + [True]
    assert _run([0.1] * 4 + [0.2] + [0.1] * 5, static=False) == [False] * 9 + [True]
    assert _run([0.2] * 20, static=False) == [False] * 20          # inside the band: stays dynamic
    assert _run([0.2] * 20, static=True) == [True] * 20            # ... or static


def test_uncertain_speed_does_not_count():
    # 0.5 m/s with a speed std of 0.6 m/s (a young track) is not evidence of motion (dynamic_sigma = 1)
    assert _run([0.5] * 10, sigma=0.6) == [True] * 10
    assert _run([0.5] * 3, sigma=0.4) == [True, True, False]


def test_vectorised_over_tracks():
    st, nd, ns = np.array([True, True, False]), np.array([2, 0, 4]), np.array([0, 0, 4])
    st, nd, ns = hysteresis_step(st, nd, ns, np.array([1.0, 1.0, 0.0]), np.zeros(3), P)
    assert st.tolist() == [False, True, True] and nd.tolist() == [0, 1, 0] and ns.tolist() == [0, 0, 0]


def test_speed_sigma_hand_values():
    # v = (3, 4): u = (0.6, 0.8); Pv = [[1, 0], [0, 4]]: u^T Pv u = 0.36 + 2.56 = 2.92
    s = speed_sigma(np.array([[3.0, 4.0], [0.0, 0.0]]), np.array([[[1.0, 0.0], [0.0, 4.0]]] * 2))
    assert s[0] == pytest.approx(np.sqrt(2.92))
    assert s[1] == pytest.approx(2.0)            # zero speed: sqrt(lambda_max) = sqrt(4)
