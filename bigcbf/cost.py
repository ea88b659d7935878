"""A machine-free cost model of an episode: its work in abstract *cost units*, from its configuration alone, and the
bound above which an episode is refused before it runs.

An episode's work is the sum of these terms (T the time limit [s], dt = 2 ms the physics step, G the static geoms:
walls, boxes and cylinders; P the pedestrians; M the obstacles a planner weighs: the tracks and wall points the
perception reports at most, ``max_tracks + wall_max_points``, or in ``truth`` mode every pedestrian and static
obstacle; N the imagination / rollout steps of the stack)::

    physics   (T / dt) x (PHYSICS_BASE + G + P)                  MuJoCo steps x bodies/geoms
    lidar     (T rate_hz) x n_beams x (LIDAR_BASE + G + P)       rays x scans (each ray tests every visible geom)
    walkers   (T x 50 Hz) x P^2                                  the social forces, pairwise, at 50 Hz
    planner   per method, per planning cycle, times the cycles:
                big-cbf(-noshared)  (T / T_B) x 6 behaviors x N x M     (the imagination)
                mppi                (T / T_B) x samples x iterations x N x M
                dwa                 (T / T_C) x (n_xy^2 n_wz + 1) x N x M
                pl-cbf              (T / T_C) x 4 (n_angle + 2) x (horizon_s / dt) x M   (4 start states)
                backup-cbf          (T / T_C) x 4 x (horizon_s / dt) x M
                apf, cbf-only       (T / T_C) x M
              plus the common CBF filter (T / T_C) x (max_obstacle_constraints + wall_sectors); a method installed
              from elsewhere (an entry point, ``package.module:Class``) counts only that filter (its own cost is its
              author's).

each multiplied by its weight (cost units per operation, :data:`WEIGHTS`). The weights are relative costs measured
once on the development machine (calibration below), so that a unit is about the same amount of work whatever term
it comes from; the bound :data:`MAX_EPISODE_UNITS` is in units, not seconds, and does not depend on the machine
that checks it.

Calibration (the development machine: 2 shared CPU cores, Python 3.11, MuJoCo 3; real episodes, warm JIT, wall
time of ``Episode.run``). Weights from differences of short runs in an 12 x 6 m room (4 walls; big-cbf unless
named; 10.1 s simulated; ops are per term before weighting):

    cbf-only 0.67 s, big-cbf 0.74 s           -> physics ~120 us a step: PHYSICS_BASE x 0.024 with PHYSICS_BASE 5000
    n_beams 360 -> 4000: +0.39 s              -> ~1.05 us a ray: LIDAR_BASE 150 x 0.007
    4 -> 1000 walls (far from the robot): +0.26 s   -> 0.007-0.024 unit per ray x geom and step x geom
    0 -> 200 walkers: +2.0 s for 2.0e7 pair updates -> 0.1 unit a pair update
    mppi samples 512 -> 4096: +0.97 s for 9.2e7 ops; dwa n_xy 9 -> 41: +2.7 s for 1.8e8 ops -> 0.015 unit an op

So one unit is about one microsecond of that machine for each term alone; whole shipped episodes took 1.5-5.7 us a
unit (mixed_dense_traffic 15.8 s simulated with big-cbf: 1.0e6 units, 1.98 s; crowd_crossing 19.4 s with big-cbf:
1.26e6 units, 7.2 s: the perception and the imagination with many tracks cost more than their terms say). The bound
:data:`MAX_EPISODE_UNITS` = 1e8 units is therefore 100-600 s of one episode there. The shipped nine scenes (three
seeds, every registered method at its defaults, their full time limits) cost at most 5.52e6 units
(mixed_dense_traffic with dwa, since DWA samples Fox's dynamic window as DWB does, 20 x 20 velocities over 1.5 s at
20 Hz; 3.59e6 with mppi before that; :data:`SHIPPED_MAX_UNITS`): 18 times below the bound; the generated families
(``bigcbf.worlds``, seeds 0-5, every method) at most 3.53e6 with the earlier DWA (crowd seed 5, mppi). The documented
maxima together (1000 walls, 200 walkers, 600 s, big-cbf), which took ~7.5 minutes, estimate at 1.86e8 units
(walkers 1.2e8, physics 4.5e7, lidar 2.0e7) and are refused. What the issue found hang or exhaust the machine
(``samples = 1e9``, ``n_xy = 1e5``, ``n_beams = 1e9``, ``iterations = 1e9``, ``rate_hz`` > 250) is outside the
documented parameter ranges already; within them, extreme combinations (``samples = 20000`` with ``iterations =
100``: 2.6e10 units) are refused here.

Files are read with size caps (``params.toml_io.MAX_TOML_BYTES``: 1 MiB for TOML), so reading costs at most that.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import UserError

#: the physics step the terms count in [s] (SimWorld's MuJoCo timestep)
PHYSICS_DT_S = 0.002
#: the social-force update rate of the pedestrians [Hz] (bigcbf.sim.pedestrians)
WALKER_RATE_HZ = 50.0
#: BIG-CBF's behaviors imagined every T_B (bigcbf.control.behaviors.BEHAVIORS)
N_BEHAVIORS = 6
#: geoms-equivalent of the robot's own bodies in a physics step (the Mecanum X3 with its rollers and contacts)
PHYSICS_BASE = 5000.0
#: geoms-equivalent of a ray's fixed cost (the cast itself and the perception's share per beam)
LIDAR_BASE = 150.0

#: cost units per operation of each term (the calibration's relative costs, about microseconds there)
WEIGHTS = {
    "physics": 0.024,    # per physics step x (PHYSICS_BASE + geoms)
    "lidar": 0.007,      # per ray x (LIDAR_BASE + geoms)
    "walkers": 0.1,      # per walker pair and social-force update
    "planner": 0.015,    # per rollout step x obstacle (vectorised numpy / numba)
    "filter": 2.0,       # per CBF constraint and control tick (a small QP)
}

#: the largest episode accepted [cost units]; an episode above it is refused before it runs (module docstring)
MAX_EPISODE_UNITS = 1e8

#: the most expensive shipped scene x method x seed at its defaults (module docstring; tests/test_param_ranges.py
#: checks that every shipped scene stays at least 10 times below the bound)
SHIPPED_MAX_UNITS = 5.52e6
#: the margin the shipped scenes and the generated families keep below the bound, at least
MIN_MARGIN = 10.0


@dataclass(frozen=True)
class EpisodeCost:
    """An episode's estimated work: units per term and their total."""

    terms: dict[str, float]

    @property
    def total(self) -> float:
        return float(sum(self.terms.values()))

    def dominant(self, n: int = 2) -> list[tuple[str, float]]:
        return sorted(self.terms.items(), key=lambda kv: -kv[1])[:n]


#: what to reduce for each term (the refusal's advice)
_ADVICE = {
    "physics": "the time limit or the number of walls, boxes and cylinders",
    "lidar": "the LiDAR's n_beams or rate_hz, the time limit or the number of obstacles",
    "walkers": "the number of pedestrians or the time limit",
    "planner": "the method's samples/iterations/grid (e.g. [methods.mppi] samples, [methods.dwa] n_xy), the stack's "
               "N, the perception's max_tracks/wall_max_points, or the time limit",
    "filter": "the stack's max_obstacle_constraints/wall_sectors or T_C_s, or the time limit",
}


def _planner_ops(method: str | None, params, method_params, M: int, T: float) -> float:
    """Rollout-step x obstacle operations of the method's planner over the episode."""
    N = params.N
    cycles_b = T / params.T_B_s
    ticks = T / params.T_C_s
    if method in ("big-cbf", "big-cbf-noshared"):
        return cycles_b * N_BEHAVIORS * N * M
    mp = method_params
    if mp is None and method is not None:
        from .control.methods import method_params_type
        try:
            ptype = method_params_type(method)
        except UserError:
            ptype = None              # an unknown method: make_planner names it
        mp = ptype() if ptype is not None else None
    if method == "mppi" and mp is not None:
        return cycles_b * mp.samples * mp.iterations * N * M
    if method == "dwa" and mp is not None:
        return ticks * (mp.n_xy ** 2 * mp.n_wz + 1) * N * M
    if method == "pl-cbf" and mp is not None:
        return ticks * 4 * (mp.n_angle + 2) * round(mp.horizon_s / params.dt_s) * M
    if method == "backup-cbf" and mp is not None:
        return ticks * 4 * round(mp.horizon_s / params.dt_s) * M
    if method in ("apf", "cbf-only"):
        return ticks * M
    return 0.0                       # external input or a method from elsewhere: only the filter is counted


def episode_cost(scenario, method: str | None, params, *, method_params=None, perception_params=None,
                 lidar=None, time_limit_s: float | None = None, perception: str = "lidar") -> EpisodeCost:
    """The estimated work of one episode (module docstring); nothing is built or run."""
    from .params.perception import PerceptionParams
    T = float(scenario.time_limit_s if time_limit_s is None else time_limit_s)
    lid = scenario.robot_profile.lidar if lidar is None else lidar
    pp = perception_params if perception_params is not None else PerceptionParams()
    G = len(scenario.walls) + len(scenario.boxes) + len(scenario.cylinders)
    P = len(scenario.pedestrians)
    M = (P + G) if perception == "truth" else pp.max_tracks + pp.wall_max_points
    steps = T / PHYSICS_DT_S
    ops = {
        "physics": steps * (PHYSICS_BASE + G + P),
        "lidar": T * lid.rate_hz * lid.n_beams * (LIDAR_BASE + G + P),
        "walkers": T * WALKER_RATE_HZ * P * P,
        "planner": _planner_ops(method, params, method_params, M, T),
        "filter": (T / params.T_C_s) * (params.max_obstacle_constraints + params.wall_sectors),
    }
    return EpisodeCost({k: WEIGHTS[k] * v for k, v in ops.items()})


def check_episode_cost(scenario, method: str | None, params, **kwargs) -> EpisodeCost:
    """:func:`episode_cost`, and a one-line UserError naming the scenario's file when it exceeds
    :data:`MAX_EPISODE_UNITS` (which terms dominate and what to reduce)."""
    cost = episode_cost(scenario, method, params, **kwargs)
    if cost.total > MAX_EPISODE_UNITS:
        top = cost.dominant(2)
        parts = ", ".join(f"{k} {v:.2g}" for k, v in top if v > 0)
        advice = "; ".join(f"{k}: reduce {_ADVICE[k]}" for k, v in top if v > 0.2 * cost.total)
        raise UserError(f"this episode ({method or 'external'}) would cost {cost.total:.3g} units, above the bound "
                        f"of {MAX_EPISODE_UNITS:.3g} (bigcbf/cost.py); most of it is {parts}: {advice}",
                        file=scenario.file or None)
    return cost


__all__ = ["EpisodeCost", "episode_cost", "check_episode_cost", "MAX_EPISODE_UNITS", "WEIGHTS"]
