"""The saturating execution model (twin.limits): the wheel geometry by hand, the static fit on synthetic samples."""
import numpy as np
import pytest

from twin.limits import fit_static, rim_demand, rim_matrix, saturate


def test_rim_demand_and_saturation_by_hand():
    # lever 0.1645 m: (0.6, 0, 1.0) asks rims (0.4355, 0.7645, 0.4355, 0.7645) -> the fastest 0.7645 m/s; a
    # 0.4 m/s limit scales the twist by 0.4 / 0.7645 (as the simulator's firmware does)
    np.testing.assert_allclose(rim_matrix(0.1645) @ [0.6, 0.0, 1.0], [0.4355, 0.7645, 0.4355, 0.7645])
    assert rim_demand(np.array([[0.6, 0.0, 1.0]]), 0.1645)[0] == pytest.approx(0.7645)
    np.testing.assert_allclose(saturate(np.array([[0.6, 0.0, 1.0]]), 0.4, 0.1645)[0],
                               np.array([0.6, 0.0, 1.0]) * 0.4 / 0.7645)
    np.testing.assert_allclose(saturate(np.array([[0.2, 0.1, 0.5]]), 0.4, 0.1645)[0], [0.2, 0.1, 0.5])
    assert saturate(np.array([[2.0, 0.0, 0.0]]), None, 0.1)[0, 0] == 2.0


def _static_samples(rng, n=3000, v_max=None, lever=0.12):
    A = np.array([[0.9, 0.02, 0.0], [0.0, 0.85, 0.0], [0.03, 0.0, 0.95]])
    d = np.array([0.02, 0.0, -0.03])
    u = rng.uniform([-0.8, -0.55, -1.0], [0.8, 0.55, 1.0], (n, 3))
    v = saturate(u @ A.T + d, v_max, lever) + rng.normal(0, [0.01, 0.01, 0.03], (n, 3))
    return u, v, A, d


def test_static_fit_finds_the_limit_and_the_gains_below_it():
    rng = np.random.default_rng(0)
    u, v, A, d = _static_samples(rng, v_max=0.5)
    st = fit_static(u, v, np.ones(3, bool))
    assert st.v_max == pytest.approx(0.5, rel=0.03)
    assert st.lever_identified and st.lever_m == pytest.approx(0.12, abs=0.03)
    np.testing.assert_allclose(st.A, A, atol=0.02)
    np.testing.assert_allclose(st.d, d, atol=0.01)
    # the linear fit across the limit reads the gains low: what the summary warns about
    assert np.all(np.diag(st.A_linear) < np.diag(A) - 0.1)
    assert st.n_saturated > 100 and st.cost_saturating < 0.5 * st.cost_linear


def test_static_fit_claims_no_limit_on_a_linear_robot():
    rng = np.random.default_rng(1)
    u, v, A, d = _static_samples(rng, v_max=None)
    st = fit_static(u, v, np.ones(3, bool))
    assert st.v_max is None and st.n_saturated == 0
    np.testing.assert_allclose(st.A, A, atol=0.02)


def test_differential_drive_limit_without_vy():
    """A differential drive (vy never commanded): its two wheels vx -+ k wz; the lever is identified from the
    combinations of vx and wz."""
    rng = np.random.default_rng(2)
    n = 3000
    u = np.column_stack([rng.uniform(-0.5, 0.5, n), np.zeros(n), rng.uniform(-2.0, 2.0, n)])
    v = saturate(u, 0.3, 0.08) + rng.normal(0, [0.005, 0.0, 0.02], (n, 3))
    v[:, 1] = 0.0
    st = fit_static(u, v, np.array([True, False, True]))
    assert st.v_max == pytest.approx(0.3, rel=0.05) and st.lever_m == pytest.approx(0.08, abs=0.02)
    np.testing.assert_allclose(np.diag(st.A)[[0, 2]], [1.0, 1.0], atol=0.03)
