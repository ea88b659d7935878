"""The ``francis2023`` bench suite: the 13 social-navigation archetypes of Francis et al. 2023 ("Principles and
guidelines for evaluating social robot navigation algorithms", Fig. 7) that robot_sf (ll7/robot_sf_ll7) maps as
single-person scenes, written as scenario files at the X3's scale (``bigcbf/scenarios/francis2023/``; each file's
comments say how its geometry was scaled), and the solvability check of each file and seed.

**Solvability** (:func:`check_file`): a seed's drawn world (the file's random ranges resolved, as the bench draws
it) becomes a :class:`bigcbf.worlds.Draft` over the bounding box of its walls and boxes and goes through the
generated worlds' checks (:func:`bigcbf.worlds.check`, described in ``bigcbf/worlds/geometry.py``): a route for the
footprint (r_R 0.15 m + 0.10 m clearance) from the start to the goal through passages of at least 0.8 m, also with
every pedestrian standing where it waits and where it stops; pedestrians' paths clear of walls; no pedestrian
starting close to the robot; some pedestrian coming within 1 m of the route. And the file's time limit is at least
the generated worlds' rule for that route (:func:`bigcbf.worlds.time_limit`).

Each archetype is the suite's *family* (the reports give success per archetype); the split is the suite's name.
"""
from __future__ import annotations

from pathlib import Path

from .. import SCENARIOS

#: the archetypes in Francis et al. 2023's order (Fig. 7 a-f, i-o): (file stem, figure panel)
ARCHETYPES: tuple[tuple[str, str], ...] = (
    ("frontal_approach", "7a"), ("pedestrian_obstruction", "7b"), ("pedestrian_overtaking", "7c"),
    ("robot_overtaking", "7d"), ("down_path", "7e"), ("intersection", "7f"), ("blind_corner", "7i"),
    ("narrow_hallway", "7j"), ("narrow_doorway", "7k"), ("entering_room", "7l"), ("exiting_room", "7m"),
    ("entering_elevator", "7n"), ("exiting_elevator", "7o"))

FOLDER = SCENARIOS / "francis2023"
SPLIT = "francis2023"
SEEDS = 30


def files() -> dict[str, Path]:
    """Archetype -> its scenario file, in Francis et al.'s order."""
    return {name: FOLDER / f"francis2023_{name}.toml" for name, _ in ARCHETYPES}


def draft(sc):
    """The :class:`bigcbf.worlds.Draft` of a drawn scenario (``bigcbf.scenario.Scenario``): its geometry as
    TOML-ready tables, searched over the bounding box of its walls and boxes (open corridor ends stay open to the
    pedestrians, closed to the route search) and of the start and the goal."""
    import numpy as np

    from ..worlds import Draft

    d = Draft(start=tuple(float(v) for v in sc.robot.start), goal=tuple(float(v) for v in sc.robot.goal),
              bounds=(0.0, 0.0, 0.0, 0.0),
              walls=[{"start": list(w.start), "end": list(w.end), "thickness_m": w.thickness_m} for w in sc.walls],
              boxes=[{"center": list(b.center), "half_size": list(b.half_size), "yaw_rad": b.yaw_rad}
                     for b in sc.boxes],
              cylinders=[{"center": list(c.center), "radius_m": c.radius_m} for c in sc.cylinders],
              pedestrians=[{"name": p.name, "waypoints": [list(w) for w in p.waypoints], "speed_mps": p.speed_mps,
                            "start_time_s": p.start_time_s, "radius_m": p.radius_m, "loop": p.loop,
                            "reactive": p.reactive} for p in sc.pedestrians])
    pts = [np.array(sc.robot.start[:2]), np.array(sc.robot.goal)]
    for w in sc.walls:
        pts += [np.array(w.start), np.array(w.end)]
    for b in sc.boxes:
        c, s = np.cos(b.yaw_rad), np.sin(b.yaw_rad)
        pts += [np.array(b.center) + [c * u - s * v, s * u + c * v]
                for u in (-b.half_size[0], b.half_size[0]) for v in (-b.half_size[1], b.half_size[1])]
    for c in sc.cylinders:
        pts += [np.array(c.center) - c.radius_m, np.array(c.center) + c.radius_m]
    p = np.array(pts)
    d.bounds = (float(p[:, 0].min()), float(p[:, 0].max()), float(p[:, 1].min()), float(p[:, 1].max()))
    return d


def check_file(path: str | Path, seed: int):
    """The solvability check of one scenario file for one seed (module docstring): the
    :class:`bigcbf.worlds.CheckResult` of its drawn world, with ``ok`` False (and the reason) also when the file's
    time limit is shorter than the rule's for the route found."""
    from dataclasses import replace

    from ..scenario import load_scenario
    from ..worlds import check, time_limit

    sc = load_scenario(path, seed)
    res = check(draft(sc))
    if res.ok:
        need = time_limit(res.path_length_m, len(sc.pedestrians))
        if sc.time_limit_s < need:
            return replace(res, ok=False, reason=f"time_limit_s {sc.time_limit_s:g} s is shorter than the rule's "
                                                 f"{need:g} s for its {res.path_length_m:.2f} m route")
    return res
