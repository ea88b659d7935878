"""StackParams: Table I defaults, the Sec. V preset, TOML round trips, errors naming the file and the key."""
import dataclasses

import pytest

from bigcbf.errors import UserError
from bigcbf.params import (PHYSICAL, SIMULATION, ExecutionModel, StackParams, UncertaintyParams, load_stack_params,
                           save_stack_params)


def test_table_one_defaults():
    p = SIMULATION
    assert (p.T_B_s, p.T_C_s, p.N, p.dt_s) == (0.5, 0.05, 15, 0.1)
    assert (p.eps_g_m, p.v_freeze_mps, p.eps_h_m2) == (0.15, 0.05, 0.10)
    u = p.uncertainty
    assert (u.r_robot_m, u.d0_m, u.tau95_s, u.beta, u.e_zoh_m, u.kappa_img, u.kappa_exec) == \
        (0.15, 0.10, 0.10, 2.0, 0.025, 1.0, 1.0)
    assert p.weights == (1.0, 1.5, 3.0, 0.5, 0.05)
    assert (p.v_max_mps, p.v_side_mps, p.noshared_margin_m) == (0.8, 0.55, 0.30)
    assert p == StackParams()


def test_physical_preset():
    u = PHYSICAL.uncertainty
    assert (u.r_robot_m, u.d0_m, u.beta, u.e_zoh_m, u.kappa_img, u.kappa_exec) == (0.15, 0.05, 1.0, 0.0716, 0.8, 1.0)
    assert u.kappa_img_static == 1.0
    assert PHYSICAL.T_B_s == SIMULATION.T_B_s and PHYSICAL.weights == SIMULATION.weights


@pytest.mark.parametrize("params", [SIMULATION, PHYSICAL, dataclasses.replace(
    SIMULATION, N=10, u_min=(-0.5, -0.4, -1.0), uncertainty=UncertaintyParams(
        tau95_s=0.13, execution=ExecutionModel(A=((0.9, 0.05, 0.0), (0.0, 0.85, 0.0), (0.0, 0.0, 0.97)),
                                               d=(0.01, -0.02, 0.003), residual_speed_mps=(0.0, 0.3, 0.8),
                                               residual_bound_mps=(0.01, 0.02, 0.05), residual_horizon_s=0.2,
                                               residual_coverage=0.99, identified=(True, True, False))))])
def test_round_trip(tmp_path, params):
    f = tmp_path / "stack.toml"
    save_stack_params(params, f, header="written by a test")
    assert load_stack_params(f) == params
    assert f.read_text().startswith("# written by a test")


def test_uncertainty_profile_round_trip(tmp_path):
    """A calibrated profile holds only [uncertainty] and [uncertainty.execution]; `bigcbf run --profile` loads it."""
    f = tmp_path / "profile.toml"
    f.write_text("[uncertainty]\ntau95_s = 0.12\ne_zoh_m = 0.03\n\n[uncertainty.execution]\n"
                 "A = [[0.92, 0.0, 0.0], [0.0, 0.88, 0.0], [0.0, 0.0, 0.97]]\nd = [0.01, 0.0, 0.0]\n"
                 "residual_speed_mps = [0.0, 0.4, 0.8]\nresidual_bound_mps = [0.02, 0.03, 0.05]\n")
    p = load_stack_params(f)
    assert p.uncertainty.tau95_s == 0.12 and p.uncertainty.execution.A[1][1] == 0.88
    assert p.uncertainty.beta == 2.0 and p.N == 15             # everything else: the defaults
    on_physical = load_stack_params(f, base=PHYSICAL)          # overlay on the Sec. V preset
    assert on_physical.uncertainty.beta == 1.0 and on_physical.uncertainty.d0_m == 0.05
    assert on_physical.uncertainty.tau95_s == 0.12 and on_physical.uncertainty.execution.d == (0.01, 0.0, 0.0)
    save_stack_params(on_physical, tmp_path / "again.toml")
    assert load_stack_params(tmp_path / "again.toml") == on_physical


@pytest.mark.parametrize("text, field, words", [
    ("T_B = 0.5", "T_B", "unknown key"),
    ("[uncertainty]\ntau = 0.1", "uncertainty.tau", "unknown key"),
    ("[uncertainty.execution]\nbias = [0, 0, 0]", "uncertainty.execution.bias", "unknown key"),
    ("N = 1.5", "N", "expected an integer"),
    ("dt_s = 'fast'", "dt_s", "expected a number"),
    ("u_max = [0.8, 0.8]", "u_max", "3 values"),
    ("[uncertainty.execution]\nresidual_speed_mps = [0.0, 0.8, 0.4]\nresidual_bound_mps = [0.1, 0.1, 0.1]",
     "uncertainty.execution.residual_speed_mps", "strictly increasing"),
    ("[uncertainty.execution]\nresidual_speed_mps = [0.1, 0.8]", "uncertainty.execution.residual_speed_mps",
     "start at 0"),
    ("[uncertainty]\nbeta = -1.0", "uncertainty.beta", "beta must be >= 0 (range [0, 10]), got -1"),
    ("u_min = [0.1, -0.8, -1.0]", "u_min", "every element of u_min must be in [-10, 0], got 0.1"),
    ("N = 0", "N", "N must be >= 1 (range [1, 500]), got 0"),
    ("T_C_s = 0.0001", "T_C_s", "T_C_s must be >= 0.002 (range [0.002, 1]), got 0.0001"),
    ("alpha_per_s = 1e300", "alpha_per_s", "within +-1e+09"),
])
def test_bad_files_name_file_and_key(tmp_path, text, field, words):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(UserError) as err:
        load_stack_params(f)
    msg = str(err.value)
    assert str(f) in msg and words in msg
    if field:
        assert f"'{field}'" in msg


def test_missing_file():
    with pytest.raises(UserError, match="file not found"):
        load_stack_params("/nonexistent/stack.toml")
