"""bigcbf perf gives every timing also in physics steps of the same run, and the methods side by side (issue 26)."""
import json

import pytest

from bigcbf.cli import main
from bigcbf.cli.perf import SIDE_BY_SIDE, step_ratios
from bigcbf.control.methods import METHODS


def test_step_ratios_of_every_ms_figure():
    out = step_ratios({"a_ms": 0.5, "b_p95_ms": 2.0, "c_s": 3.0, "d_ms": float("nan"), "e_ms": "x"}, 100.0)
    assert out == {"a_steps": 5.0, "b_p95_steps": 20.0}


def test_perf_perception_in_steps_of_its_own_run(capsys):
    assert main(["perf", "--json", "--quick", "--only", "bigcbf.perception.perf"]) == 0
    out = json.loads(capsys.readouterr().out)
    step = out["physics_step_us"]                     # measured in this run although sim.perf was left out
    assert step > 0
    assert out["perception_steps"] == pytest.approx(1e3 * out["perception_ms"] / step, rel=1e-3)
    assert out["by_method"]["big-cbf"] == {"perception_steps": out["perception_steps"]}
    plus = out["by_method"]["big-cbf-plus"]
    assert set(SIDE_BY_SIDE) == {"big-cbf", "big-cbf-plus"}
    if "big-cbf-plus" not in METHODS:
        assert plus == "not available: method 'big-cbf-plus' is not registered"


def test_perf_table_names_the_side_by_side_figures(capsys):
    assert main(["perf", "--quick", "--only", "bigcbf.sim.perf"]) == 0
    text = capsys.readouterr().out
    assert "lidar_scan_steps" in text and "physics_step_us" in text
    assert "by_method.big-cbf-plus" in text
