"""The one metrics accumulator (control/metrics.py EpisodeMetrics) on a constructed trace, every figure by hand;
the one percentile rule (metrics.percentile / p95)."""
import math
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from bigcbf.control.cbf import PERCEPTION_FAULT, FilterInfo
from bigcbf.control.metrics import EpisodeMetrics, p95, percentile
from bigcbf.control.planner import PlanInfo
from bigcbf.types import RobotState

GOAL = np.array([10.0, 0.0])


def _filt(active, infeasible, ms, margins, fallback=None):
    return FilterInfo(active=active, infeasible=infeasible, fallback=fallback, solve_ms=ms, n_constraints=1,
                      h_min=0.1, D=np.zeros(1), margins=np.asarray(margins, float))


def _trace() -> EpisodeMetrics:
    """Four control steps of T_C = 0.05 s, R_u = diag(1, 1, 0.1), v_freeze 0.05 m/s; scans and physics between."""
    m = EpisodeMetrics(R_u_diag=(1.0, 1.0, 0.1), v_freeze_mps=0.05, T_C_s=0.05)
    odom = RobotState(0.0, 0.0, 0.0)
    m.scan(1.0)
    # 1: GOAL, a planning cycle of 2 ms; the filter cuts vx 0.8 -> 0.5 (E = 0.09); the robot drives at 0.5 m/s
    m.control_step(0.0, odom, RobotState(0, 0, 0, 0.5, 0.0), GOAL, [0.8, 0, 0], [0.5, 0, 0],
                   PlanInfo("GOAL", True, 2.0, margins_img=np.array([0.3, 0.5])), _filt(True, False, 0.1, [0.2]))
    m.physics(25, 0.002, 1.0)
    m.scan(None)                                                     # a scan that never arrived
    # 2: GOAL, no planning cycle; nothing to filter
    m.control_step(0.05, odom, RobotState(0, 0, 0, 0.5, 0.0), GOAL, [0.5, 0, 0], [0.5, 0, 0],
                   PlanInfo("GOAL", False, 0.1), _filt(False, False, 0.05, []))
    m.physics(25, 0.002, 0.8)
    m.scan(3.0)
    # 3: YIELD; the QP was infeasible and the filter sent (0.5, 0.2, 0) for u_in = 0 (E = 0.29); true speed 0.01
    m.control_step(0.10, odom, RobotState(0, 0, 0, 0.01, 0.0), GOAL, [0, 0, 0], [0.5, 0.2, 0],
                   PlanInfo("YIELD", False, 0.1), _filt(True, True, 0.2, [0.4, 0.6]))
    m.physics(20, 0.002, 0.4)
    m.physics(5, 0.002, 0.7)
    m.scan(2.0)
    # 4: YIELD, a planning cycle of 4 ms; the filter braked on implausible estimates; the robot stands
    m.control_step(0.15, odom, RobotState(0, 0, 0, 0.0, 0.0), GOAL, [0, 0, 0], [0, 0, 0],
                   PlanInfo("YIELD", True, 4.0), _filt(False, False, 0.05, [], fallback=PERCEPTION_FAULT))
    m.physics(25, 0.002, 0.6)
    return m


def test_accumulator_on_a_constructed_trace_by_hand():
    r = _trace().results(duration_s=0.2)
    assert r["control_steps"] == 4
    assert r["e_cbf"] == pytest.approx(0.09 + 0.29) and r["e_cbf_infeasible"] == pytest.approx(0.29)
    assert r["cbf_active_ratio"] == 0.5 and r["qp_infeasible_ratio"] == 0.25
    # planning cycles only: [2, 4] -> h = 0.95: 2 + 0.95 * 2 = 3.9
    assert r["planner_p95_ms"] == pytest.approx(3.9)
    # filter: sorted [0.05, 0.05, 0.1, 0.2], h = 3 * 0.95 = 2.85: 0.1 + 0.85 * 0.1 = 0.185
    assert r["cbf_p95_ms"] == pytest.approx(0.185)
    # perception over the scans that arrived: [1, 3, 2] -> h = 1.9: 2 + 0.9 * 1 = 2.9
    assert r["perception_p95_ms"] == pytest.approx(2.9)
    assert r["missed_scans"] == 1 and r["perception_faults"] == 1
    # stopped from step 3 on: 20 + 5 + 25 physics steps of 2 ms
    assert r["stopped_time_s"] == pytest.approx(0.1)
    assert r["min_clearance_m"] == 0.4
    assert r["mode_history"] == [(0.0, "GOAL"), (0.1, "YIELD")]
    # imagination margins [0.3, 0.5]: mean 0.4, P90 0.3 + 0.9 * 0.2 = 0.48; execution [0.2, 0.4, 0.6]: mean 0.4,
    # P90 h = 1.8: 0.4 + 0.8 * 0.2 = 0.56
    assert r["m_img_mean_m"] == pytest.approx(0.4) and r["m_img_p90_m"] == pytest.approx(0.48)
    assert r["m_exec_mean_m"] == pytest.approx(0.4) and r["m_exec_p90_m"] == pytest.approx(0.56)
    # liveness (control/liveness.py): one mode change in 0.2 s = 300 per minute; GOAL and YIELD are neutral; the
    # lateral command of step 3 (0.2 m/s left of the goal direction) held one step, < 0.25 s; 0.15 s < W
    assert r["mode_switches_per_min"] == pytest.approx(300.0)
    assert r["side_reversals"] == 0 and r["lateral_reversals"] == 0 and r["no_progress_s"] == 0.0


def test_accumulator_liveness_goes_through_it():
    """The liveness metrics are the LivenessRecorder's over the steps given to the accumulator: a command weaving
    left (0.3 m/s) for 6 steps then right for 6 is one lateral reversal; PASS-L then PASS-R one side reversal; and
    standing still 2.5 s far from the goal stalls from the first window on (2.5 s)."""
    m = EpisodeMetrics(R_u_diag=(1.0, 1.0, 1.0), v_freeze_mps=0.05, T_C_s=0.05)
    odom = RobotState(0.0, 0.0, 0.0)
    for k in range(51):
        left = k < 6
        u = [0.0, 0.3 if left else -0.3, 0.0] if k < 12 else [0.0, 0.0, 0.0]
        m.control_step(0.05 * k, odom, RobotState(0, 0, 0), GOAL, u, u,
                       PlanInfo("PASS-L" if left else "PASS-R", False, 0.0), _filt(False, False, 0.0, []))
    r = m.results(duration_s=2.55)
    assert r["lateral_reversals"] == 1 and r["side_reversals"] == 1
    assert r["mode_switches_per_min"] == pytest.approx(60.0 / 2.55)
    assert r["no_progress_s"] == pytest.approx(2.5)
    assert r["planner_p95_ms"] == 0.0                 # no planning cycle: the P95 rule's empty case


def test_accumulator_empty_and_episode_fields():
    from bigcbf.episode import EpisodeResult
    r = EpisodeMetrics(R_u_diag=(1.0, 1.0, 0.1), v_freeze_mps=0.05, T_C_s=0.05).results(0.0)
    assert r["control_steps"] == 0 and r["e_cbf"] == 0.0 and r["cbf_active_ratio"] == 0.0
    assert r["min_clearance_m"] == math.inf and r["mode_history"] == []
    assert (r["m_img_mean_m"], r["m_exec_p90_m"]) == (None, None)
    assert r["planner_p95_ms"] == r["cbf_p95_ms"] == r["perception_p95_ms"] == 0.0
    # every key is an EpisodeResult field (the episode adds only outcome, times, names and warnings)
    assert set(r) <= {f.name for f in fields(EpisodeResult)}


def test_p95_rule_by_hand():
    assert p95([]) == 0.0 and percentile([], 50) == 0.0
    assert p95([7.0]) == 7.0
    # 1..20: h = 19 * 0.95 = 18.05 -> x_19 + 0.05 (x_20 - x_19) = 19.05
    assert p95(np.arange(1, 21)) == pytest.approx(19.05)
    # order and shape do not matter (pooled): 4 samples [0, 10, 20, 30], h = 2.85 -> 20 + 0.85 * 10 = 28.5
    assert p95([[30.0, 0.0], [20.0, 10.0]]) == pytest.approx(28.5)
    assert percentile([0.0, 10.0, 20.0, 30.0], 50) == pytest.approx(15.0)
    assert isinstance(p95([1, 2, 3]), float)


def test_one_percentile_rule_in_the_package():
    """Every P95 (and the margins' P90) of bigcbf goes through metrics.percentile: no other percentile call."""
    root = Path(__file__).resolve().parents[2] / "bigcbf"
    offenders = [str(f.relative_to(root)) for f in root.rglob("*.py")
                 if f.name != "metrics.py" and any(s in f.read_text() for s in ("np.percentile(", "np.quantile(",
                                                                              "np.nanpercentile("))]
    assert offenders == []
