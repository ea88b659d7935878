"""DWA's compiled first-collision scan (dwa._first_hit) against the array code it replaced (surface_distance over
every state and obstacle, then the first state below min(start, 0)), on random rollouts and on a real window."""
import numpy as np
from bigcbf.control.baselines.common import Geometry, integrate, predict, surface_distance
from bigcbf.control.baselines.dwa import DwaParams, _first_hit, window_samples
from bigcbf.params.stack import StackParams
from bigcbf.types import Obstacles, RobotState


def reference_first(paths, pred, params, geometry):
    sd = surface_distance(paths, pred, params, geometry)
    hit = (sd[:, 1:] < np.minimum(sd[:, :1], 0.0) - 1e-9).any(axis=2)
    return np.where(hit.any(axis=1), hit.argmax(axis=1), -1)


def obstacles(rng, m):
    p = rng.uniform(-3, 3, (m, 2))
    v = rng.uniform(-1, 1, (m, 2)) * (rng.random(m) < 0.5)[:, None]
    r = np.where(rng.random(m) < 0.5, 0.0, rng.uniform(0.1, 0.4, m))
    return Obstacles(p, v, np.tile(np.eye(2) * 0.01, (m, 1, 1)), r, np.linalg.norm(v, axis=1) == 0)


def test_first_hit_matches_the_array_code():
    outcomes = set()
    for seed in range(12):
        outcomes |= check_one(seed)
    assert outcomes == {"hit", "free"}          # the cases exercise both outcomes


def check_one(seed):
    rng = np.random.default_rng(seed)
    params = StackParams()
    state = RobotState(*rng.uniform(-0.5, 0.5, 2), rng.uniform(-3, 3), *rng.uniform(-0.5, 0.5, 3))
    U = window_samples(state, params, DwaParams()).reshape(-1, 3)
    paths, _ = integrate(state, np.repeat(U[:, None, :], params.N, axis=1), params.dt_s, params)
    pred = predict(obstacles(rng, int(rng.integers(1, 30))), params)
    geo = Geometry(float(rng.uniform(0, 0.2)))
    got = _first_hit(np.ascontiguousarray(paths), np.ascontiguousarray(pred.p), geo.radius(pred.r, params)) - 1
    ref = reference_first(paths, pred, params, geo)
    np.testing.assert_array_equal(got, ref)
    return {"hit" if k >= 0 else "free" for k in ref}
