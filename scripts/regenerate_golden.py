#!/usr/bin/env python3
"""Regenerate tests/golden/episodes.json ON PURPOSE, after a deliberate change of the physics or the stack.

    .venv/bin/python scripts/regenerate_golden.py

The regression test (tests/test_episode.py) runs these episodes and compares every deterministic metric with the
stored values; a difference means behaviour changed. Review the diff of the JSON before committing it.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bigcbf.episode import DETERMINISTIC_KEYS, Episode  # noqa: E402
from bigcbf.params.stack import SIMULATION  # noqa: E402
from bigcbf.scenario import load_scenario  # noqa: E402

#: (scenario, method, seed): short episodes that still exercise perception, planning, the CBF and pedestrians
GOLDEN_EPISODES = [("required_sidestepping", "big-cbf", 0), ("single_person_crossing", "cbf-only", 1)]
GOLDEN_FILE = ROOT / "tests" / "golden" / "episodes.json"


def golden_metrics(scenario: str, method: str, seed: int) -> dict:
    res = Episode(load_scenario(scenario, seed), method, seed, SIMULATION).run().metrics()
    return {k: res[k] for k in DETERMINISTIC_KEYS}


def main() -> None:
    out = {f"{s}/{m}/{seed}": golden_metrics(s, m, seed) for s, m, seed in GOLDEN_EPISODES}
    GOLDEN_FILE.parent.mkdir(parents=True, exist_ok=True)
    GOLDEN_FILE.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    print(f"wrote {GOLDEN_FILE}")


if __name__ == "__main__":
    main()
