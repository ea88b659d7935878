"""Speed of whole episodes (figures for ``bigcbf perf``): simulated seconds per wall second, perception on."""
from __future__ import annotations

from .episode import Episode
from .params.stack import SIMULATION
from .scenario import load_scenario


def bench(quick: bool = False) -> dict:
    sc = load_scenario("single_person_crossing" if quick else "mixed_dense_traffic", 0)
    res = Episode(sc, "big-cbf", 0, SIMULATION, perception="lidar").run()
    return {"episode_realtime_factor": round(res.sim_time_s / res.wall_time_s, 2),
            "episode_scenario": sc.name,
            "episode_sim_time_s": res.sim_time_s}
