"""Where one `bigcbf perf` episode's wall time goes (issue 26's episode budget, README "Where the episode's time goes").

    .venv/bin/python scripts/episode_budget.py [--runs 3]

The episode of `bigcbf perf` (mixed_dense_traffic, seed 0, big-cbf, LiDAR perception) is run once to warm up, then
`--runs` times: each time plainly (its wall time), its physics again bare at constant wheel targets and replayed
from its recorded blocks (`bigcbf.sim.perf`, the two references of `bigcbf perf`'s episode ratios), and once more
with each part timed in place by a wrapper: its `mj_step` calls, the LiDAR's ray casting, the perception, the plan,
the filter and the physics blocks' loop. Prints each run's figures (seconds) and, for the fastest, the ratio to
the bare physics and what 2/3 of the bare physics' real-time factor leaves beyond the replayed physics.
"""
from __future__ import annotations

import argparse
import collections
import time

import mujoco

import bigcbf.sim.world as world_module
from bigcbf.episode import Episode
from bigcbf.params.stack import SIMULATION
from bigcbf.scenario import load_scenario
from bigcbf.sim.perf import bare_physics_realtime_factor, replay_realtime_factor


def _timed(acc: dict, count: collections.Counter, obj, name: str, key: str) -> None:
    f = getattr(obj, name)

    def wrapped(*a, **k):
        t0 = time.perf_counter()
        out = f(*a, **k)
        acc[key] += time.perf_counter() - t0
        count[key] += 1
        return out
    setattr(obj, name, wrapped)


class _TimedMujoco:
    """``mujoco`` as ``bigcbf.sim.world`` sees it, with ``mj_step`` timed."""

    def __init__(self, acc: dict, count: collections.Counter):
        self.acc, self.count = acc, count

    def __getattr__(self, name):
        if name != "mj_step":
            return getattr(mujoco, name)

        def step(m, d, n=1):
            t0 = time.perf_counter()
            mujoco.mj_step(m, d, n)
            self.acc["mj_step"] += time.perf_counter() - t0
            self.count["mj_step"] += 1
        return step


def run_once(scenario) -> dict:
    world_module.mujoco = mujoco
    ep = Episode(scenario, "big-cbf", 0, SIMULATION, perception="lidar")
    log = ep.world.record_blocks()
    t0 = time.perf_counter()
    res = ep.run()
    episode_s = time.perf_counter() - t0
    n = max(1, int(round(res.sim_time_s / ep.world.model.opt.timestep)))
    out = {"sim_s": res.sim_time_s, "episode_s": episode_s,
           "bare_s": res.sim_time_s / bare_physics_realtime_factor(ep.world.model, n),
           "replay_s": res.sim_time_s / replay_realtime_factor(ep.world.model, log)[0]}
    acc: dict = collections.defaultdict(float)
    count: collections.Counter = collections.Counter()
    world_module.mujoco = _TimedMujoco(acc, count)
    try:
        ep = Episode(scenario, "big-cbf", 0, SIMULATION, perception="lidar")
        for obj, name, key in ((ep, "_physics", "physics_blocks"), (ep, "_plan", "plan"), (ep.cbf, "filter", "filter"),
                               (ep.world, "scan", "lidar"), (ep, "_estimate", "perception")):
            _timed(acc, count, obj, name, key)
        ep.run()
    finally:
        world_module.mujoco = mujoco
    out.update(acc)
    out["blocks_beyond_mj_step"] = acc["physics_blocks"] - acc["mj_step"]
    out["calls"] = dict(count)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    sc = load_scenario("mixed_dense_traffic", 0)
    Episode(sc, "big-cbf", 0, SIMULATION, perception="lidar").run()          # warm-up: numba's compile or cache
    runs = [run_once(sc) for _ in range(max(1, args.runs))]
    for r in runs:
        print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()})
    b = min(runs, key=lambda r: r["episode_s"])
    print(f"episode / bare physics real-time factor: {b['bare_s'] / b['episode_s']:.3f} "
          f"(the replayed physics alone: {b['bare_s'] / b['replay_s']:.3f})")
    print(f"2/3 of the bare physics' factor allows {1.5 * b['bare_s']:.3f} s: {1.5 * b['bare_s'] - b['replay_s']:.3f} s "
          f"beyond the replayed physics, of which the LiDAR's ray casting takes {b['lidar']:.3f} s")


if __name__ == "__main__":
    main()
