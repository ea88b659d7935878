"""The calibration report of a differential robot's log (tests/data/turtlebot3.bag, no vy): every panel of every
figure shows data (the unidentified vy has none, and is said in a line instead), and the index page lists the
figures and says what tau95, e_exec and e_ZOH are, with the numbers."""
from pathlib import Path

import pytest

from twin.calibrate import calibrate_series, read_log
from twin.report import figures, write_report

TURTLEBOT = Path(__file__).resolve().parents[1] / "data/turtlebot3.bag"


@pytest.fixture(scope="module")
def tb3():
    data = read_log(TURTLEBOT)
    return calibrate_series(data), data.cmd


def _has_data(ax) -> bool:
    return bool(ax.lines or ax.collections or ax.patches)


def test_no_empty_panel_and_vy_said(tb3):
    import matplotlib.pyplot as plt
    cal, cmd = tb3
    figs, left_out = figures(cal, cmd.t, cmd.u)
    try:
        panels = {name: [_has_data(ax) for ax in fig.axes] for name, (fig, _) in figs.items()}
        # vx and wz identified: two response panels; two correlation curves + the perception latency (no clean
        # steps: no edge histograms); the speed residual + two axes; the wheel limit
        assert panels == {"command_response.png": [True] * 2, "delay.png": [True] * 3, "residuals.png": [True] * 3,
                          "limits.png": [True]}
        for name in ("command_response.png", "delay.png", "residuals.png"):
            assert "vy: not identified (no lateral command)" in figs[name][1]
        assert not any("vy" in ax.get_ylabel() or "vy" in ax.get_title() for fig, _ in figs.values()
                       for ax in fig.axes)
        assert any("no clean command steps" in x for x in left_out)
    finally:
        for fig, _ in figs.values():
            plt.close(fig)


def test_index_page(tb3, tmp_path):
    cal, cmd = tb3
    files = write_report(cal, tmp_path / "rep", cmd.t, cmd.u)
    names = sorted(p.name for p in (tmp_path / "rep").iterdir())
    assert names == ["calibration.json", "command_response.png", "delay.png", "index.md", "limits.png",
                     "residuals.png"] and {p.name for p in files} == set(names)
    text = (tmp_path / "rep" / "index.md").read_text()
    for name in set(names) - {"index.md"}:
        assert f"]({name})" in text                           # every file linked
    assert f"| tau95 | {cal.delay.tau95_s:.3f} | s |" in text
    assert f"| e_ZOH | {cal.e_zoh_m:.4f} | m |" in text and "| e_exec(u) |" in text
    assert "eq:uncertainty_margin" in text and "eq:execution" in text
    assert "vy: not identified (no lateral command)" in text
