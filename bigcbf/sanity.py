"""Checks that keep an episode's result from being false without a word (issue 21).

Parameter ranges (bigcbf/params) catch a value that is wrong on its own; these catch combinations that make a
result meaningless, and put them in the episode's ``warnings`` dict (``EpisodeResult.warnings``: name -> a count
or a number, beside MuJoCo's own warning counts) with a line for the user (:func:`describe`):

``started_in_goal_region`` (1)
    the robot's state was already inside the goal region (eq:goal_region (5), ``eps_g_m``) at the first control
    step: the episode "succeeds" at t = 0 without moving. (The scenario loader checks that the robot *fits* in a
    region of Table I's 0.15 m around the goal; it does not know the run's eps_g_m, so the episode says it.)
``odometry_diverged`` (metres)
    at the end of the episode the true position and the odometry the stack navigated on (and success is judged
    on, as in the paper) are more than ``max(ODOM_DIVERGED_M, ODOM_DIVERGED_EPS * eps_g_m)`` apart (0.5 m or
    three goal tolerances): e.g. wheels spinning on a floor without friction "reach" the goal. The value is the
    distance; ``final_goal_dist_m`` (true) is beside ``success`` in the metrics.
``lidar_sees_obstacles_late`` (metres)
    the LiDAR model cannot see the scene's obstacles in time. Rule: an obstacle of radius r whose centre is at
    distance d from the sensor is seen by at least two beams iff 2 asin(r / d) >= 2 (2 pi / n_beams), i.e.
    d <= r / sin(2 pi / n_beams), and it is in range iff d - r <= range_max_m; so it is first seen at
    d* = min(r / sin(2 pi / n_beams), range_max_m + r) (never with fewer than 4 beams), which leaves a gap
    g = d* - r - r_R between it and the robot's footprint. The robot needs
    s = v_max (T_scan + T_C) + v_max^2 / (2 a) + d0 to stop clear of it (a scan period and a control period of
    reaction at the stack's v_max_mps, braking at a, the stack's base clearance d0_m): the warning is given when
    the obstacle with the smallest g has g < s; its value is that g (negative: not seen before contact). a is the
    calibrated wheel acceleration limit of the stack's execution model when it has one, else the robot profile's,
    else friction mu g (the floor's friction coefficient). Obstacles: cylinders (r = radius), boxes (r = the
    smaller half side), walls (r = half the length) and pedestrians (r = their radius).
"""
from __future__ import annotations

import math

ODOM_DIVERGED_M = 0.5
ODOM_DIVERGED_EPS = 3.0
G = 9.81
FLOOR_FRICTION = 1.0        # the scene's floor (bigcbf/assets/rosmaster_x3/scene.xml) unless the profile sets one


def obstacle_radii(scene) -> list[tuple[str, float]]:
    """(name, r) of every obstacle the scene holds (module docstring)."""
    out = [(f"cylinders[{i}]", c.radius) for i, c in enumerate(scene.cylinders)]
    out += [(f"boxes[{i}]", min(b.half_x, b.half_y)) for i, b in enumerate(scene.boxes)]
    out += [(f"walls[{i}]", 0.5 * math.hypot(w.x1 - w.x0, w.y1 - w.y0)) for i, w in enumerate(scene.walls)]
    out += [(f"pedestrian {p.name}", p.radius) for p in scene.pedestrians]
    return out


def first_seen_gap(r: float, n_beams: int, range_max_m: float, r_robot_m: float) -> float:
    """The gap between the robot's footprint and an obstacle of radius r when at least two beams first see it
    (module docstring); -inf when no distance qualifies."""
    step = 2 * math.pi / n_beams
    if step >= math.pi / 2:
        return -math.inf
    d = min(r / math.sin(step), range_max_m + r)
    return d - r - r_robot_m


def braking_accel(stack, robot_profile, floor_friction: float | None) -> tuple[float, str]:
    """(a [m/s^2], where it came from) for the stopping distance (module docstring)."""
    a = stack.uncertainty.execution.wheel_accel_max_mps2
    if a is not None:
        return float(a), "the stack's calibrated wheel acceleration limit"
    a = getattr(robot_profile, "wheel_accel_max_mps2", None)
    if a is not None:
        return float(a), "the robot profile's wheel acceleration limit"
    mu = FLOOR_FRICTION if floor_friction is None else float(floor_friction)
    return mu * G, f"the floor's friction ({mu:g} g)"


def sensor_check(scene, lidar, stack, robot_profile=None) -> tuple[dict, list[str]]:
    """({"lidar_sees_obstacles_late": gap} or {}, lines): whether the LiDAR ``lidar`` (n_beams, range_max_m,
    rate_hz) sees the scene's obstacles in time for the stack to stop (module docstring)."""
    obstacles = obstacle_radii(scene)
    if not obstacles:
        return {}, []
    r_robot = stack.uncertainty.r_robot_m
    gaps = [(first_seen_gap(r, lidar.n_beams, lidar.range_max_m, r_robot), name, r) for name, r in obstacles]
    gap, name, r = min(gaps)
    a, source = braking_accel(stack, robot_profile, getattr(scene, "floor_friction", None))
    v = stack.v_max_mps
    need = v * (1.0 / lidar.rate_hz + stack.T_C_s) + v * v / (2 * a) + stack.uncertainty.d0_m
    if gap >= need:
        return {}, []
    seen = ("is never seen by two beams" if not math.isfinite(gap) else
            f"is first seen by two beams {gap:.2f} m from the robot's footprint")
    line = (f"the LiDAR ({lidar.n_beams} beams, range_max {lidar.range_max_m:g} m) cannot see the scene's obstacles "
            f"in time: {name} (r {r:.2f} m) {seen}, the robot needs {need:.2f} m to stop clear of it (v_max "
            f"{v:g} m/s, braking {a:.2f} m/s^2 from {source}, d0 {stack.uncertainty.d0_m:g} m); collisions in "
            "this episode say more about the sensor than the method")
    value = round(gap, 4) if math.isfinite(gap) else -1e9
    return {"lidar_sees_obstacles_late": value}, [line]


def odometry_check(true_xy, odom_xy, eps_g_m: float) -> tuple[dict, list[str]]:
    """({"odometry_diverged": distance} or {}, lines) at the end of an episode (module docstring)."""
    dist = math.hypot(true_xy[0] - odom_xy[0], true_xy[1] - odom_xy[1])
    bound = max(ODOM_DIVERGED_M, ODOM_DIVERGED_EPS * eps_g_m)
    if not dist > bound:
        return {}, []
    return ({"odometry_diverged": round(dist, 4)},
            [f"the odometry ended {dist:.2f} m from the true position (bound {bound:.2f} m): success is judged on the "
             "odometry, as in the paper; final_goal_dist_m is the true distance to the goal"])


def describe(warnings: dict) -> list[str]:
    """One line per warning of this module in an EpisodeResult's ``warnings`` (for the command line)."""
    out = []
    if "started_in_goal_region" in warnings:
        out.append("the robot started inside the goal region (eps_g_m): the episode succeeded at its first control "
                   "step without moving")
    if "odometry_diverged" in warnings:
        out.append(f"the odometry ended {warnings['odometry_diverged']:.2f} m from the true position: success is "
                   "judged on the odometry (as in the paper); see final_goal_dist_m for the true distance")
    if "lidar_sees_obstacles_late" in warnings:
        g = warnings["lidar_sees_obstacles_late"]
        out.append("the LiDAR cannot see the scene's obstacles in time to stop ("
                   + ("some obstacle is never seen by two beams" if g <= -1e8 else
                      f"the worst obstacle is first seen {g:.2f} m from the footprint") + ")")
    return out
