"""E_CBF (eq:sim_cbf_energy (27)) and the per-step metrics; the method registry, the planner protocol, robot-side
imports, perf."""
import subprocess
import sys

import numpy as np
import pytest

from bigcbf.cli.perf import BENCHES
from bigcbf.control import METHODS, CbfFilter, PlanInfo, Planner, behavior_command
from bigcbf.control.cbf import FilterInfo
from bigcbf.control.metrics import cbf_energy
from bigcbf.params import SIMULATION
from bigcbf.types import Obstacles, RobotState


def test_cbf_energy_eq_20_by_hand():
    # du = (-0.3, 0, -0.2); R_u = diag(1, 1, 0.1): 0.09 + 0.1 * 0.04 = 0.094
    assert cbf_energy([0.5, 0.1, 0.0], [0.8, 0.1, 0.2], [1.0, 1.0, 0.1]) == pytest.approx(0.094)
    # a sequence sums its steps; a full matrix R_u: du = (1, 1, 0), [[2, 1, 0], [1, 2, 0], [0, 0, 1]] -> 6
    assert cbf_energy([[0.5, 0.1, 0.0], [1.0, 1.0, 0.0]], [[0.8, 0.1, 0.2], [0.0, 0.0, 0.0]],
                      [1.0, 1.0, 0.1]) == pytest.approx(0.094 + 2.0)
    assert cbf_energy([1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [[2, 1, 0], [1, 2, 0], [0, 0, 1]]) == pytest.approx(6.0)


def test_registry_and_protocol():
    assert {"big-cbf", "big-cbf-noshared", "cbf-only"} <= set(METHODS.names())
    for name in ("big-cbf", "big-cbf-noshared", "cbf-only"):
        planner = METHODS.get(name)(SIMULATION)
        assert isinstance(planner, Planner) and planner.name == name
        planner.reset(0)
        u, info = planner.plan(0.0, RobotState(0, 0, 0), Obstacles.empty(), np.array([3.0, 0.0]))
        assert u.shape == (3,) and isinstance(info, PlanInfo)
        np.testing.assert_allclose(u, [0.8, 0.0, 0.0])          # open space: straight to the goal at 0.8 m/s
    with pytest.raises(ValueError, match="duplicate"):
        METHODS.register("big-cbf", lambda p: None)


def test_cbf_only_feeds_the_goal_policy():
    obs = Obstacles.from_lists([[1.0, 0.0]], r=0.3)
    state, goal = RobotState(0.2, 0.1, 0.3), np.array([4.0, 0.0])
    u, info = METHODS.get("cbf-only")(SIMULATION).plan(0.0, state, obs, goal)
    np.testing.assert_allclose(u, behavior_command("GOAL", state, obs, goal, SIMULATION))
    assert info.mode == "GOAL" and info.planned and info.path is None     # planned: its time counts in P95
    u_safe, finfo = CbfFilter(SIMULATION).filter(state, obs, u)
    assert finfo.active and u_safe[0] < u[0]


def test_control_runs_without_mujoco():
    code = ("import sys, bigcbf.control, bigcbf.control.perf; "
            "bad = [m for m in ('mujoco', 'dm_control') if m in sys.modules]; "
            "sys.exit(1 if bad else 0)")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test_perf_provider():
    assert "bigcbf.control.perf:bench" in BENCHES
    from bigcbf.control.perf import bench
    out = bench(quick=True)
    for key in ("imagination_p95_ms", "cbf_qp_p95_ms"):
        assert out[key] > 0
    assert out["cbf_qp_rows_mean"] == 8.0          # the benchmark does solve QPs with 8 obstacle rows


def test_margin_stats_by_hand():
    from bigcbf.control.metrics import margin_stats
    assert margin_stats([]) == (None, None)
    # 0.1 .. 1.0: mean 0.55, 90th percentile (linear interpolation) 0.1 + 0.9 * 0.9 = 0.91
    mean, p90 = margin_stats(np.arange(1, 11) / 10)
    assert mean == pytest.approx(0.55) and p90 == pytest.approx(0.91)


def test_filter_reports_kappa_exec_m_i_of_its_rows():
    from dataclasses import replace
    from bigcbf.control.uncertainty import uncertainty_radius
    params = replace(SIMULATION, uncertainty=replace(SIMULATION.uncertainty, kappa_exec=0.7))
    obs = Obstacles.from_lists([[1.0, 0.2], [-1.5, 0.5]], v=[[0.0, 0.0], [0.3, -0.2]], r=[0.2, 0.25],
                               cov=np.eye(2) * 0.01, static=[True, False])
    state, u = RobotState(0.0, 0.0, 0.3), np.array([0.5, 0.1, 0.0])
    _, info = CbfFilter(params).filter(state, obs, u)
    want = [0.7 * uncertainty_radius(0.3, u, obs.v[i], obs.cov[i], params.uncertainty) for i in range(2)]
    np.testing.assert_allclose(info.margins, want, rtol=1e-12)
