"""The simulated pedestrians' social-force parameters (``[pedestrians]`` of a run configuration;
``bigcbf.sim.pedestrians`` uses them). Here, with the other parameter dataclasses, so that reading a run
configuration needs no simulator (the robot-side filter node reads one: docs/ros2.md)."""
from __future__ import annotations

from dataclasses import dataclass

from .checks import check_ranges, ranged


@dataclass(frozen=True)
class SocialForceParams:
    tau_s: float = ranged(0.5, 0, 10, lo_open=True)  # relaxation time to the preferred velocity
    A_mps2: float = ranged(2.0, 0, 100)  # pedestrian-pedestrian interaction strength
    B_m: float = ranged(0.3, 0, 10, lo_open=True)  # interaction range
    A_robot_mps2: float = ranged(1.0, 0, 100)  # pedestrian-robot strength (reactive pedestrians only)
    anisotropy: float = ranged(0.35, 0, 1)  # lambda: weight of interactions from behind
    waypoint_tol_m: float = ranged(0.15, 0, 10, lo_open=True)
    max_speed_factor: float = ranged(1.3, 0, 10, lo_open=True)

    def __post_init__(self):
        check_ranges(self, positive=("tau_s", "B_m", "waypoint_tol_m", "max_speed_factor"),
                     nonneg=("A_mps2", "A_robot_mps2"), unit=("anisotropy",))
