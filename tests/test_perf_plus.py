"""Issue 26 item 3: ``bigcbf perf`` reports big-cbf-plus (with its route layer) beside big-cbf, measured."""
import json

import pytest

from bigcbf.cli import main
from bigcbf.cli.perf import RATIO_FIGURES


def test_perf_reports_big_cbf_plus_beside_big_cbf(capsys):
    assert main(["perf", "--json", "--quick", "--only", "bigcbf.sim.perf"]) == 0
    out = json.loads(capsys.readouterr().out)
    plus = out["by_method"]["big-cbf-plus"]
    assert isinstance(plus, dict) and set(plus) == set(RATIO_FIGURES)
    for k in ("imagination_p95_steps", "perception_steps", "cbf_qp_p95_steps"):
        assert plus[k] > 0
    assert 0 < plus["episode_physics_ratio"] < 1       # the stack costs something; the physics is the floor


def test_plus_provider_runs_its_route_layer():
    from bigcbf.episode_perf import episode_figures
    from bigcbf.control.route import RouteParams
    figs = episode_figures("big-cbf-plus", quick=True, route=RouteParams(enabled=True))
    assert figs["episode_scenario"] == "single_person_crossing"
    assert figs["episode_route_tick_mean_ms"] > 0         # the route layer ran in that episode
    assert figs["episode_physics_ratio"] == pytest.approx(
        figs["episode_realtime_factor"] / figs["episode_physics_realtime_factor"], rel=0.01)
