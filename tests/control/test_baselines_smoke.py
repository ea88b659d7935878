"""Smoke test (issue 6): each of the five comparison methods runs one seed of every scenario end to end, for a
short simulated time (1.5 s) so that the whole sweep stays fast: no exception, finite metrics."""
import math

import pytest

from bigcbf.control.baselines import BASELINES
from bigcbf.episode import Episode
from bigcbf.scenario import load_scenario, scenario_files

SCENARIOS = sorted(scenario_files())


def test_all_nine_scenarios_present():
    assert len(SCENARIOS) == 9


@pytest.mark.parametrize("method", sorted(BASELINES))
def test_method_runs_every_scenario(method):
    for name in SCENARIOS:
        res = Episode(load_scenario(name, 0), method, 0, time_limit_s=1.5).run()
        assert res.method == method and res.scenario == name
        assert res.control_steps >= 25, (method, name)                 # it drove for the 1.5 s (30 ticks)
        assert math.isfinite(res.min_clearance_m) and math.isfinite(res.e_cbf)
        assert not res.collision, (method, name)
