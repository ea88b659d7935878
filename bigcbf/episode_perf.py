"""Speed of whole episodes (figures for ``bigcbf perf``): simulated seconds per wall second, perception on.

- ``episode_realtime_factor``: one BIG-CBF episode with LiDAR perception, everything but the scene's compilation.
- ``episode_physics_realtime_factor``: bare ``mj_step`` of that episode's own compiled model (its walls, obstacles
  and pedestrian bodies) from its initial state with constant wheel targets, as many steps as the episode took,
  timed in the same run right after it: the floor the episode loop could reach.
- ``episode_physics_ratio``: the first over the second (1 would mean the stack and the loop cost nothing).
- ``episode_replay_realtime_factor``: the episode's own physics stepped again without the stack, block by block
  with its recorded wheel targets and pedestrian positions (``sim.perf.replay_realtime_factor``): the same
  contacts and solver work as the episode (the drive at constant targets has fewer contacts: it is the cheaper
  physics), timed in the same run.
- ``episode_replay_ratio``: ``episode_realtime_factor`` over that: the stack's and the loop's share alone.
- before the timed episode, the same episode once untimed (deterministic: the same code paths), so that what the
  first call of a compiled kernel costs (numba compiles it, or loads it from its cache, in the first process
  after an install) is not in the figures: the first ``bigcbf perf`` after ``make setup`` read a ratio of 0.066
  for 0.36 without it (a 3-s warm-up in another scene left kernels that scene never calls: 0.036 with an empty
  numba cache).
- ``episode_route_tick_mean_ms`` (with the route layer on, ``big-cbf-plus`` in ``bigcbf perf``): the route
  layer's time (map updates, replans, look-ahead points) per control tick of that episode.
"""
from __future__ import annotations

from .episode import Episode
from .control.route import RouteParams
from .params.stack import SIMULATION
from .scenario import load_scenario
from .sim.perf import bare_physics_realtime_factor, replay_realtime_factor


def episode_figures(method: str, quick: bool = False, route: RouteParams | None = None) -> dict:
    """The figures of the module docstring for one ``method`` episode (``route``: its route layer, off by default)."""
    sc = load_scenario("single_person_crossing" if quick else "mixed_dense_traffic", 0)
    Episode(sc, method, 0, SIMULATION, perception="lidar", route=route).run()       # the warm-up (docstring)
    ep = Episode(sc, method, 0, SIMULATION, perception="lidar", route=route)
    log = ep.world.record_blocks()
    res = ep.run()
    model = ep.world.model
    n_steps = max(1, int(round(res.sim_time_s / model.opt.timestep)))
    episode_rf = res.sim_time_s / res.wall_time_s
    physics_rf = bare_physics_realtime_factor(model, n_steps)
    replay_rf, _ = replay_realtime_factor(model, log)
    out = {"episode_realtime_factor": round(episode_rf, 2),
           "episode_physics_realtime_factor": round(physics_rf, 2),
           "episode_physics_ratio": round(episode_rf / physics_rf, 3),
           "episode_replay_realtime_factor": round(replay_rf, 2),
           "episode_replay_ratio": round(episode_rf / replay_rf, 3),
           "episode_scenario": sc.name,
           "episode_sim_time_s": res.sim_time_s}
    if ep.route is not None:              # the route layer's own share, per control tick of this episode
        ticks = max(1, len(ep.route.goal_ms))
        out["episode_route_tick_mean_ms"] = round(sum(ep.route.scan_ms + ep.route.plan_ms + ep.route.goal_ms) / ticks,
                                                  4)
    return out


def bench(quick: bool = False) -> dict:
    return episode_figures("big-cbf", quick)
