"""Shared fixtures of the bench tests: short copies of the two cheapest scenarios (3 s instead of 35 s)."""
from __future__ import annotations

import re

import pytest

from bigcbf.scenario import scenario_files

#: The cheapest shipped scenarios (open floor / corridor, one pedestrian each), cut to a few seconds.
SHORT = ("single_person_crossing", "corridor_meeting")
SHORT_LIMIT_S = 3.0


@pytest.fixture(scope="session")
def short_scenarios(tmp_path_factory) -> list[str]:
    """Paths of the short scenario files (same content as the shipped ones except time_limit_s)."""
    d = tmp_path_factory.mktemp("short_scenarios")
    paths = []
    for name in SHORT:
        text = scenario_files()[name].read_text()
        text, n = re.subn(r"(?m)^time_limit_s = .*$", f"time_limit_s = {SHORT_LIMIT_S}", text)
        assert n == 1
        p = d / f"{name}.toml"
        p.write_text(text)
        paths.append(str(p))
    return paths
