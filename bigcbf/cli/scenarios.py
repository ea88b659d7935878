"""bigcbf scenarios: list the scenarios with one line each."""
from __future__ import annotations

HELP = "list the benchmark scenarios (scenarios/*.toml), one line each"


def add_arguments(p):
    pass


def run(args) -> int:
    from ..scenario import describe, scenario_files

    files = scenario_files()
    width = max(map(len, files), default=0)
    for name, path in files.items():
        print(f"{name:<{width}}  {describe(path)}")
    return 0
