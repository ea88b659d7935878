#!/usr/bin/env python3
"""Regenerate tests/golden/episodes.json ON PURPOSE, after a deliberate change of the physics or the stack.

    .venv/bin/python scripts/regenerate_golden.py

The regression test (tests/test_episode.py) runs these episodes and compares them with the stored values; a
difference means behaviour changed. Review the diff of the JSON before committing it.

Two kinds of golden values, because the physics is chaotic: a last-bit difference (another CPU's SIMD kernels in
numpy or the QP solver) grows to millimetres over a 15 s episode. So
- ``trace``: the first ``TRACE_S`` seconds, every control step's u_in, u_safe and true pose, compared tightly;
- ``metrics``: the whole episode's metrics, discrete outcomes exactly and real numbers loosely.
On one machine both are bit-for-bit the same run after run (the test checks that too).
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
TRACE_S = 4.0
TRACE_EVERY = 5          # control steps between trace samples (0.25 s)


def golden_run(scenario: str, method: str, seed: int) -> dict:
    """{"metrics": the deterministic metrics of the whole episode, "trace": [[t, u_in(3), u_safe(3), x, y, theta],
    ...] every TRACE_EVERY control steps up to TRACE_S}."""
    ep = Episode(load_scenario(scenario, seed), method, seed, SIMULATION)
    trace: list = []
    count = [0]

    def observe(rec) -> None:
        if rec.t <= TRACE_S + 1e-9 and count[0] % TRACE_EVERY == 0:
            ts = rec.true_state
            trace.append([round(rec.t, 6), *map(float, rec.u_in), *map(float, rec.u_safe), ts.px, ts.py, ts.theta])
        count[0] += 1

    ep.observers.append(observe)
    res = ep.run().metrics()
    return {"metrics": {k: res[k] for k in DETERMINISTIC_KEYS}, "trace": trace}


def main() -> None:
    out = {f"{s}/{m}/{seed}": golden_run(s, m, seed) for s, m, seed in GOLDEN_EPISODES}
    GOLDEN_FILE.parent.mkdir(parents=True, exist_ok=True)
    GOLDEN_FILE.write_text(json.dumps(out, indent=1, sort_keys=True) + "\n")
    print(f"wrote {GOLDEN_FILE}")


if __name__ == "__main__":
    main()
