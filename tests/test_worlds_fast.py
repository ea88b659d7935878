"""The ``fast`` world family (issue 23, item 4): walkers 1-2x the robot's top speed from the side, head-on and from
behind; every walker seen for the last second before it can reach the robot's path (a generator check); the
generated suite's place of the family; a real episode in one of its worlds."""
import math

import numpy as np
import pytest

from bigcbf.worlds import FAMILIES, SPLITS, Draft, check, generate, parse, time_limit
from bigcbf.worlds.fast import KINDS, SPEED_FACTOR, V_MAX_MPS, VISIBLE_BEFORE_S, visible_in_time


@pytest.mark.parametrize("seed", [0, 1, 2, 1000, 1001])
def test_fast_worlds_pass_every_check(seed):
    w = generate("fast", seed)
    assert w.toml == generate("fast", seed).toml                      # seeded by family and seed only
    d = w.draft
    res = check(d)
    assert res.ok and time_limit(res.path_length_m, len(d.pedestrians)) == w.time_limit_s
    assert visible_in_time(d, w.time_limit_s) is None
    assert 1 <= len(d.pedestrians) <= 3
    for p in d.pedestrians:
        assert SPEED_FACTOR[0] * V_MAX_MPS - 1e-3 <= p["speed_mps"] <= SPEED_FACTOR[1] * V_MAX_MPS + 1e-3
        assert p["name"].rstrip("0123456789") in {k.replace("-", "") for k in KINDS}
    sc = parse(w.toml)                                                # a valid scenario file
    assert sc.name == f"fast_{seed:05d}" and len(sc.pedestrians) == len(d.pedestrians)


def test_the_family_draws_every_kind_in_corridors_and_on_open_floor():
    kinds, layouts = set(), set()
    for seed in range(12):
        d = generate("fast", seed).draft
        kinds |= {p["name"].rstrip("0123456789") for p in d.pedestrians}
        layouts.add(d.params["layout"].split()[0])
        kinds |= {"reactive" if p["reactive"] else "non-reactive" for p in d.pedestrians}
    assert kinds == {"side", "headon", "behind", "reactive", "non-reactive"} and layouts == {"corridor", "open"}


def _draft(walker: dict, boxes=()) -> Draft:
    d = Draft(start=(0.0, 0.0, 0.0), goal=(8.0, 0.0), bounds=(-1.0, 9.0, -3.0, 3.0))
    for c, h in boxes:
        d.box(c, h)
    d.pedestrian(**walker)
    return d


def test_the_visibility_check_by_hand():
    # crossing at x = 3.2 at 1.6 m/s, at the path (|y| <= 0.25 + 0.15) at t = t0 + (3 - 0.4) / 1.6 = 4 s
    walker = dict(name="w", waypoints=[(3.2, 3.0), (3.2, -3.0)], speed=1.6, start_time=4.0 - 2.6 / 1.6,
                  radius=0.25, reactive=False)
    assert visible_in_time(_draft(walker), 30.0) is None               # nothing in the way
    # a box between the robot (x 1.5-3.2 by then) and the walker's last metres before the path hides it
    hidden = visible_in_time(_draft(walker, boxes=[((2.6, 1.0), (0.8, 0.25))]), 30.0)
    assert hidden is not None and "hidden" in hidden
    # a box the line of sight passes (behind the walker): still seen
    assert visible_in_time(_draft(walker, boxes=[((6.0, 2.0), (0.5, 0.5))]), 30.0) is None
    # a walker that can reach the path within the first second is refused
    early = visible_in_time(_draft({**walker, "start_time": 0.0, "waypoints": [(3.2, 1.5), (3.2, -3.0)]}), 30.0)
    assert early is not None and f"within {VISIBLE_BEFORE_S:g} s" in early
    # beyond the LiDAR's range (8 m) a second before it reaches the path: coming up from far behind at 0.8 m/s,
    # at x = -1.2 m at t = 13.5 s, when the robot would be 6.75-8 m ahead
    far = dict(walker, waypoints=[(-12.0, 0.0), (8.0, 0.0)], speed=0.8, start_time=0.0)
    assert "range" in visible_in_time(_draft(far), 30.0)
    # a walker that never comes near the path is not judged
    assert visible_in_time(_draft(dict(walker, waypoints=[(3.2, 3.0), (5.0, 2.5)])), 30.0) is None


def test_the_suite_has_the_family_last_with_its_splits():
    assert FAMILIES.names()[-1] == "fast" and FAMILIES["fast"].splits == SPLITS
    assert len(SPLITS["dev"]) == 30 and len(SPLITS["test"]) == 30


def test_a_real_episode_in_a_fast_world():
    """A fast world run by DWA for a few seconds: the contact fields agree with the collision flag, and a walker
    closing on the robot gives a finite time to contact."""
    from bigcbf.episode import Episode
    seed = next(s for s in range(30) if any(p["name"].startswith("behind") and p["start_time_s"] < 1.0
                                            for p in generate("fast", s).draft.pedestrians))
    sc = parse(generate("fast", seed).toml)
    res = Episode(sc, "dwa", 0, time_limit_s=4.0).run()
    assert res.collision == (res.at_fault_collision or res.passive_collision)
    assert not (res.at_fault_collision and res.passive_collision)
    assert (res.contact is not None) == res.collision
    assert math.isfinite(res.min_time_to_contact_s) and res.min_time_to_contact_s >= 0.0
    assert res.personal_space_s >= 0.0 and res.control_steps > 0
