"""The whole perception pipeline on synthetic scans (exact ray casting, bigcbf.perception.synthetic; no physics)
fed at 10 Hz along scripted robot and pedestrian trajectories."""
import numpy as np
import pytest

from bigcbf.params.perception import PerceptionParams
from bigcbf.perception import Perception
from bigcbf.perception.synthetic import box_segments as box
from bigcbf.perception.synthetic import ray_scan


def simulate(perception, duration, robot, circles=lambda t: [], segments=(), dt=0.1, noise=0.0, seed=0):
    """Feed scans at 1/dt Hz for ``duration`` s. robot(t) -> pose, circles(t) -> [(cx, cy, r)], static segments.
    Returns a list of (t, pose, obstacles)."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(int(round(duration / dt)) + 1):
        t = k * dt
        pose = robot(t)
        scan = ray_scan(pose, circles(t), segments, stamp=t, noise=noise, rng=rng)
        out.append((t, pose, perception.update(scan, pose)))
    return out


def tracks(obs):
    """The tracked entities (ids >= 0) of an Obstacles."""
    return obs.subset(obs.ids >= 0)


def walls(obs):
    """The wall points (ids -1) of an Obstacles."""
    return obs.subset(obs.ids < 0)


def track_near(obs, xy, tol=0.3):
    """The index (in tracks(obs)) of the track within tol of xy, or None."""
    tr = tracks(obs)
    if len(tr) == 0:
        return None
    d = np.linalg.norm(tr.p - np.asarray(xy), axis=1)
    k = int(np.argmin(d))
    return k if d[k] <= tol else None


STILL = lambda t: (0.0, 0.0, 0.0)  # noqa: E731


def _seg_dist(p, segs):
    """Distance from point p to the nearest of the segments (x0, y0, x1, y1)."""
    best = np.inf
    for x0, y0, x1, y1 in segs:
        a, b = np.array([x0, y0]), np.array([x1, y1])
        s = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
        best = min(best, float(np.linalg.norm(a + s * (b - a) - p)))
    return best


@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_single_circle_centre_and_radius_within_2cm(noise):
    perc = Perception()
    res = simulate(perc, 2.0, lambda t: (0.0, 0.0, 0.3), lambda t: [(2.0, 0.7, 0.25)], noise=noise)
    for t, _, obs in res[3:]:                            # confirmed after 3 hits
        tr = tracks(obs)
        assert len(tr) == 1
        assert np.linalg.norm(tr.p[0] - [2.0, 0.7]) < 0.02
        assert abs(tr.r[0] - 0.25) < 0.02
        assert tr.static[0] and np.all(tr.v[0] == 0)
        cov = tr.cov[0]
        assert np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0)
    assert len(tracks(res[1][2])) == 0                   # tentative tracks are not reported


def test_output_layout_tracks_then_wall_points():
    p = PerceptionParams()
    perc = Perception(p)
    segs = [(-3.0, 1.0, 3.0, 1.0)]
    res = simulate(perc, 0.5, STILL, lambda t: [(2.0, -0.5, 0.2)], segments=segs)
    obs = res[-1][2]
    n_tr = int(np.sum(obs.ids >= 0))
    assert n_tr == 1 and np.all(obs.ids[:n_tr] >= 0) and np.all(obs.ids[n_tr:] == -1)   # tracks first
    w = walls(obs)
    assert 0 < len(w) <= p.wall_max_points
    assert np.all(w.r == 0) and np.all(w.v == 0) and np.all(w.static)
    # covariance from the scan (geometry.wall_point_covariance): range noise along the beam, the beam's angular
    # step across it; the robot (laser 4.35 cm ahead of it) looks at the wall along +y at its nearest point
    for q, cov in zip(w.p, w.cov):
        d = q - np.array([p.laser_x_m, 0.0])
        r = np.hypot(*d)
        u = d / r
        var_r = (p.range_sigma_m + p.range_sigma_frac * r) ** 2
        var_t = (r * np.pi / 180) ** 2 / 12
        assert u @ cov @ u == pytest.approx(var_r, rel=1e-6)
        assert np.array([-u[1], u[0]]) @ cov @ np.array([-u[1], u[0]]) == pytest.approx(var_t, rel=1e-6)
    assert all(abs(y - 1.0) < 1e-4 for y in w.p[:, 1])               # on the wall surface
    assert np.min(np.linalg.norm(w.p, axis=1)) == pytest.approx(1.0, abs=0.02)   # its nearest point is included
    assert np.all(tracks(obs).r > 0)


def _check_identities(res, truths, tol=0.3):
    """Every track within tol of pedestrian k's true position must carry pedestrian k's id (no swap), pedestrian k
    must be tracked before and after the crossing, and the ids must differ."""
    ids = {}
    for t, _, obs in res:
        tr = tracks(obs)
        for k, f in enumerate(truths):
            j = track_near(obs, f(t)[:2], tol)
            if j is None:
                continue
            ids.setdefault(k, set()).add(int(tr.ids[j]))
    assert all(len(v) == 1 for v in ids.values()), ids
    assert len(ids) == len(truths) and len({next(iter(v)) for v in ids.values()}) == len(truths)
    return ids


def test_two_pedestrians_crossing_keep_identities_through_occlusion():
    # opposite directions on lines 0.7 m apart: from the robot, B passes behind A (partly hidden for ~0.5 s)
    A = lambda t: (2.0, -2.5 + t, 0.25)  # noqa: E731
    B = lambda t: (2.7, 2.5 - t, 0.25)  # noqa: E731
    res = simulate(Perception(), 5.0, STILL, lambda t: [A(t), B(t)])
    _check_identities(res, [A, B])
    # both are tracked again, moving, after the crossing
    tr = tracks(res[-1][2])
    assert len(tr) == 2 and not tr.static.any()
    assert np.linalg.norm(tr.v[track_near(res[-1][2], A(5.0)[:2])] - [0, 1]) < 0.15


def test_two_pedestrians_crossing_paths_keep_identities():
    # X-shaped paths through (2.5, 0); B reaches the crossing 1.0 s after A
    da, db = np.array([0.6, 0.8]), np.array([0.6, -0.8])
    X = np.array([2.5, 0.0])
    A = lambda t: (*(X + (t - 2.5) * da), 0.25)  # noqa: E731
    B = lambda t: (*(X + (t - 3.5) * db), 0.25)  # noqa: E731
    ts = np.arange(0, 6.01, 0.1)
    gap = min(np.linalg.norm(np.subtract(A(t)[:2], B(t)[:2])) for t in ts)
    assert gap > 0.5                                      # a physically possible crossing (no overlap)
    res = simulate(Perception(), 6.0, lambda t: (0.0, 0.0, 0.2 * t), lambda t: [A(t), B(t)], noise=0.005)
    _check_identities(res, [A, B])


@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_walls_give_no_phantom_dynamic_track(noise):
    # a corridor 2.4 m wide with a doorway on the left, a free wall end ahead, and a 0.6 m panel (a compact static
    # obstacle); the robot drives down the corridor, weaving and turning
    segs = [(-2, -1.2, 9, -1.2), (-2, 1.2, 2.0, 1.2), (3.0, 1.2, 9, 1.2), (6.0, -1.2, 6.0, 0.2),
            (4.0, 0.8, 4.0, 1.2)]
    robot = lambda t: (0.5 * t, 0.4 * np.sin(0.8 * t), 0.6 * np.sin(0.5 * t))  # noqa: E731
    perc = Perception()
    res = simulate(perc, 10.0, robot, segments=segs, noise=noise)
    for t, pose, obs in res:
        tr = tracks(obs)
        assert tr.static.all(), f"phantom dynamic track at t={t}: {tr.p[~tr.static]}"
        assert np.all(tr.v == 0)
        w = walls(obs)
        assert len(w) <= 24
        d_robot = np.linalg.norm(w.p - np.array(pose[:2]), axis=1)
        assert np.all(d_robot <= 3.0 + 1e-9) and np.all(np.diff(d_robot) >= -1e-12)      # nearest first
        assert max((_seg_dist(q, segs) for q in w.p), default=0.0) < 5 * noise + 1e-6     # on the walls
    assert max(len(walls(obs)) for _, _, obs in res) == 24
    # the KF speed of any track there is small too (not only the reported zero velocity)
    assert np.all(np.linalg.norm(perc.tracker.x[:, 2:], axis=1) < PerceptionParams().v_dynamic_mps)


def test_pedestrian_along_a_wall_is_the_only_dynamic_track():
    segs = [(-3.0, 2.0, 9.0, 2.0)]
    ped = lambda t: (-1.0 + 0.9 * t, 1.45, 0.25)  # noqa: E731  (0.3 m from the wall surface)
    res = simulate(Perception(), 8.0, lambda t: (0.4 * t, 0.0, 0.3 * np.sin(t)), lambda t: [ped(t)], segs,
                   noise=0.01)
    dyn = set()
    for t, _, obs in res:
        tr = tracks(obs)
        dyn |= set(tr.ids[~tr.static].tolist())
    assert len(dyn) == 1
    obs = res[-1][2]
    j = track_near(obs, ped(8.0)[:2])
    assert tracks(obs).ids[j] in dyn
    assert np.linalg.norm(tracks(obs).v[j] - [0.9, 0.0]) < 0.15


@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_moving_robot_static_objects_are_static_with_zero_velocity(noise):
    # a box (reported as points on its surface: it is not round) and a post (a static circle)
    segs = box(2.5, 1.0, 0.2, 0.2, 0.4)
    circles = [(3.5, -0.8, 0.15)]
    robot = lambda t: (0.4 * t, 0.2 * np.sin(t), 0.8 * np.sin(0.6 * t))  # noqa: E731  (translating and turning)
    perc = Perception()
    res = simulate(perc, 6.0, robot, lambda t: circles, segs, noise=noise)
    post_err = []
    for t, _, obs in res[3:]:
        tr = tracks(obs)
        assert len(tr) == 1 and tr.static.all() and np.all(tr.v == 0)
        post_err.append(np.linalg.norm(tr.p[track_near(obs, (3.5, -0.8))] - [3.5, -0.8]))
        w = walls(obs)
        on_box = np.array([_seg_dist(q, segs) for q in w.p])
        assert np.sum(on_box < 3 * noise + 1e-6) >= 1                      # the box: points on its surface
    assert max(post_err) < 0.02 + 2 * noise
    # the KF velocities are small, or not significant (the box's centre, from a rectangle fit, is a poor measurement)
    T = perc.tracker
    sv = np.sqrt(np.linalg.eigvalsh(T.P[:, 2:, 2:])[:, -1])
    speed = np.linalg.norm(T.x[:, 2:], axis=1)
    assert np.all((speed < 0.15) | (speed < PerceptionParams().dynamic_sigma * sv))


@pytest.mark.parametrize("noise", [0.0, 0.01])
def test_pedestrian_at_1mps_velocity_within_015_after_1s(noise):
    # the robot itself moves and turns: velocities are estimated in odom, not fooled by the robot's motion
    ped = lambda t: (3.0, -2.5 + 1.0 * t, 0.25)  # noqa: E731
    robot = lambda t: (0.3 * t, 0.0, 0.3 * t)  # noqa: E731
    res = simulate(Perception(), 5.0, robot, lambda t: [ped(t)], noise=noise)
    first = next(t for t, _, obs in res if len(tracks(obs)))
    assert first <= 0.3
    sq = []
    for t, _, obs in res:
        if t < first + 1.0 - 1e-9:
            continue
        tr = tracks(obs)
        assert len(tr) == 1 and not tr.static[0]
        assert np.linalg.norm(tr.v[0] - [0.0, 1.0]) < 0.15
        sq.append(np.sum((tr.p[0] - ped(t)[:2]) ** 2))
    rmse = float(np.sqrt(np.mean(sq)))
    assert rmse < 0.03
    print(f"pedestrian 1 m/s, noise {noise} m: position RMSE {rmse:.4f} m")


def test_at_most_8_tracks_nearest_first():
    rng = np.random.default_rng(7)
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    dist = rng.permutation(np.linspace(1.0, 4.3, 12))
    rad = rng.uniform(0.1, 0.3, 12)
    posts = [(d * np.cos(a), d * np.sin(a), r) for d, a, r in zip(dist, ang, rad)]
    p = PerceptionParams()
    obs = simulate(Perception(p), 0.5, STILL, lambda t: posts)[-1][2]
    tr = tracks(obs)
    assert len(tr) == p.max_tracks == 8
    surf = np.linalg.norm(tr.p, axis=1) - tr.r
    assert np.all(np.diff(surf) > 0)                               # nearest first
    true_surf = np.sort(dist - rad)
    assert surf == pytest.approx(true_surf[:8], abs=0.03)          # the 8 nearest ones
    assert len(set(tr.ids.tolist())) == 8 and np.all(tr.ids >= 0)


def test_static_box_is_points_on_its_surface_never_a_circle():
    """A box is tracked (so that it would be followed if it moved) but reported by points on its surface: the circle
    around a square box covers (sqrt 2 - 1) / 2 of its side beyond each face. Its track stays static, one identity."""
    segs = box(2.0, 0.6, 0.2, 0.2, 0.5)
    robot = lambda t: (0.5 * t, -0.6 + 0.1 * np.sin(t), 0.5 * np.sin(0.7 * t))  # noqa: E731  (drives past it)
    perc = Perception()
    ids = set()
    res = simulate(perc, 8.0, robot, segments=segs, noise=0.01)
    for t, pose, obs in res:
        assert len(tracks(obs)) == 0, f"a circle at t={t}"
        w = walls(obs)
        near = np.array([_seg_dist(q, segs) for q in w.p])
        if t >= 0.1 and np.linalg.norm(np.subtract(pose[:2], (2.0, 0.6))) < 3.0:
            assert np.sum(near < 0.05) >= 2, f"box not represented at t={t}"
        assert np.all(near < 0.05)                                       # nothing off its surface
        T = perc.tracker
        ids |= set(T.ids[T.confirmed].tolist())
        assert T.static.all()
    assert len(ids) == 1


def test_bottleneck_stays_open():
    """A 1.0 m wide, 0.6 m deep opening between two blocks (a bottleneck's jambs seen end-on are compact clusters):
    the obstacles keep the opening's centre line 0.5 m clear (within the noise) while the robot drives into it.
    A circle around a jamb's end (r ~ 0.5 m, completed into a square of its 0.6 m face) left 0.3 m."""
    segs = box(3.0, -0.8, 0.3, 0.3) + box(3.0, 1.5, 0.3, 1.0)            # y in [-1.1, -0.5] and [0.5, 2.5]
    robot = lambda t: (1.0 + 0.5 * t, 0.0, 0.0)  # noqa: E731
    res = simulate(Perception(), 4.0, robot, segments=segs, noise=0.005)
    for t, pose, obs in res:
        # distance from each obstacle's surface to the centre line {(x, 0): 2.7 <= x <= 3.3}
        dx = np.maximum(np.abs(obs.p[:, 0] - 3.0) - 0.3, 0.0)
        clear = np.hypot(dx, obs.p[:, 1]) - obs.r
        assert clear.min() > 0.5 - 0.02, (t, obs.p[np.argmin(clear)], obs.r[np.argmin(clear)])


def test_hysteresis_pedestrian_stops_and_goes():
    # walks 1 m/s for 2 s, stands 2 s, walks again: dynamic -> static -> dynamic, one identity
    def ped(t):
        y = -2.0 + min(t, 2.0) + max(t - 4.0, 0.0)
        return (2.5, y, 0.25)
    res = simulate(Perception(), 6.0, STILL, lambda t: [ped(t)])
    cls = {round(t, 1): (int(tracks(o).ids[0]), bool(tracks(o).static[0])) for t, _, o in res if len(tracks(o))}
    assert len({i for i, _ in cls.values()}) == 1
    assert not cls[1.0][1] and not cls[2.0][1]          # dynamic while walking
    first_static = min(t for t, (_, s) in cls.items() if 2.0 < t and s)
    assert first_static <= 3.0                           # static within 1 s of stopping (dwell n_static updates)
    assert all(cls[t][1] for t in cls if first_static <= t <= 4.0)
    first_dyn = min(t for t, (_, s) in cls.items() if t > 4.0 and not s)
    assert first_dyn <= 4.6                              # dynamic again within n_dynamic updates
    assert all(not cls[t][1] for t in cls if t >= first_dyn)


@pytest.mark.parametrize("segs, x, speed", [
    ([(1.5, -0.25, 1.5, 0.25)], 3.0, 1.2),      # a 0.5 m panel (a static track) hides it for ~0.4 s
    ([(1.4, -0.5, 1.4, 0.5)], 2.0, 1.4),        # a 1 m wall (wall points) hides it for 0.7 s (0.9 s unusable)
])
def test_occluded_pedestrian_coasts_and_keeps_identity(segs, x, speed):
    ped = lambda t: (x, -1.6 + speed * t, 0.25)  # noqa: E731
    res = simulate(Perception(), 2.5, STILL, lambda t: [ped(t)], segs)
    ped_ids, hidden_cov = set(), []
    for t, _, obs in res:
        scan = ray_scan((0, 0, 0), [ped(t)], segs)
        visible = np.isfinite(scan.ranges) & (scan.ranges > x - 0.5)
        tr = tracks(obs)
        dyn = tr.subset(~tr.static)
        if len(dyn):
            ped_ids |= set(dyn.ids.tolist())
        if t > 0.5 and not visible.any():                # fully hidden: the track coasts
            assert len(dyn) == 1
            hidden_cov.append(np.trace(dyn.cov[0]))
            assert np.linalg.norm(dyn.p[0] - ped(t)[:2]) < 0.1
    assert len(hidden_cov) >= 3 and np.all(np.diff(hidden_cov) > 0)     # growing covariance while coasting
    assert len(ped_ids) == 1


def test_track_deleted_after_coast_time():
    p = PerceptionParams()
    perc = Perception(p)
    res = simulate(perc, 3.0, STILL, lambda t: [(2.0, 0.0, 0.2)] if t < 1.0 else [])
    shown = [t for t, _, obs in res if len(tracks(obs))]
    assert max(shown) == pytest.approx(0.9 + p.coast_s, abs=0.05)


def test_deterministic_and_reset():
    def run(perc):
        return simulate(perc, 2.0, lambda t: (0.2 * t, 0, 0), lambda t: [(2, -1 + t, 0.25)], noise=0.01)

    perc = Perception()
    a = run(perc)
    perc.reset()
    b = run(perc)
    for (_, _, oa), (_, _, ob) in zip(a, b):
        assert np.array_equal(oa.p, ob.p) and np.array_equal(oa.ids, ob.ids) and np.array_equal(oa.cov, ob.cov)
    assert perc.last_ms > 0


def test_bad_inputs():
    perc = Perception()
    scan = ray_scan((0, 0, 0), [(2, 0, 0.2)], stamp=1.0)
    perc.update(scan, (0, 0, 0))
    with pytest.raises(ValueError, match="before the previous"):
        perc.update(ray_scan((0, 0, 0), [(2, 0, 0.2)], stamp=0.5), (0, 0, 0))
    with pytest.raises(ValueError, match="pose"):
        perc.update(scan, (0, float("nan"), 0))
    perc.reset()
    perc.update(ray_scan((0, 0, 0), [(2, 0, 0.2)], stamp=0.5), (0, 0, 0))   # fine after reset


def test_pedestrian_passing_close_to_a_post_does_not_drag_it():
    # the pedestrian passes 0.1 m from a post: for a few scans both are one cluster. The post's track must keep its
    # identity, place and static class. (The merged cluster becomes wall points or, when its circle's radius is
    # within gate_radius_m of the pedestrian's, a measurement of the pedestrian's track: which one depends on the
    # breakpoint distance, i.e. on the range noise model.)
    post = (3.0, 0.0, 0.1)
    ped = lambda t: (3.45, -2.0 + 1.0 * t, 0.25)  # noqa: E731  (surface gap 0.1 m at t = 2 s)
    res = simulate(Perception(), 4.0, STILL, lambda t: [post, ped(t)])
    post_ids = set()
    for t, _, obs in res[3:]:
        j = track_near(obs, post[:2], 0.1)
        assert j is not None, f"post lost at t={t}"
        tr = tracks(obs)
        assert tr.static[j] and np.linalg.norm(tr.p[j] - post[:2]) < 0.05
        post_ids.add(int(tr.ids[j]))
    assert len(post_ids) == 1
    assert not tracks(res[-1][2]).static[track_near(res[-1][2], ped(4.0)[:2])]


def _confirmed_perception(centres, radii, static=True):
    """A Perception whose tracker holds confirmed, motionless tracks of these circles (three exact measurements)."""
    perc = Perception()
    z, r = np.asarray(centres, float), np.asarray(radii, float)
    for k in range(3):
        perc.tracker.step(0.1 * k, z, r, np.zeros(2), 1e-4 * np.eye(2)[None].repeat(len(z), 0))
    assert perc.tracker.confirmed.all()
    perc.tracker.static[:] = static
    return perc


def test_segmentation_splits_two_known_objects_in_one_cluster():
    """Two walkers (r 0.25 m) side by side 3 m ahead, 0.04 m apart: one scan-order cluster (the breakpoint distance
    there is ~0.2 m). With their tracks known, _segment splits it along their predicted circles: two clusters,
    each exactly the beams that hit one circle, both marked partly hidden, both compact."""
    from bigcbf.perception.geometry import cluster_points, compact_mask, scan_to_points
    a, b = (3.0, -0.27, 0.25), (3.0, 0.27, 0.25)
    perc = _confirmed_perception([a[:2], b[:2]], [a[2], b[2]], static=False)
    pr = perc.params
    scan = ray_scan(STILL(0.3), [a, b], stamp=0.3)
    sp = scan_to_points(scan, STILL(0.3), pr)
    clusters = cluster_points(sp, pr)
    assert len(clusters) == 1                                         # merged without the tracks
    perc.tracker.predict(0.3)
    out, compact = perc._segment(sp, clusters, compact_mask(sp, clusters, pr))
    assert len(out) == 2 and compact.tolist() == [True, True] and all(c.occluded for c in out)
    assert sorted(np.concatenate([c.idx for c in out]).tolist()) == sorted(clusters[0].idx.tolist())
    for c in out:                                                    # each part lies on one circle (exact rays)
        q = sp.xy[c.idx]
        on_a = np.abs(np.linalg.norm(q - a[:2], axis=1) - a[2]) < 1e-6
        on_b = np.abs(np.linalg.norm(q - b[:2], axis=1) - b[2]) < 1e-6
        assert on_a.all() or on_b.all()
    # the whole pipeline on that scan: both walkers are measured (two circles at their centres, no wall points)
    obs = perc.update(scan, STILL(0.3))
    tr = tracks(obs)
    assert len(tr) == 2 and len(walls(obs)) == 0
    assert sorted(np.linalg.norm(tr.p - np.array([a[:2], b[:2]])[:, None], axis=2).min(axis=0)) < [0.02, 0.02]


def test_segmentation_cuts_a_walker_out_of_a_wall_but_not_a_post():
    """An extended cluster (a wall at y = 1) with a walker (dynamic track, r 0.25 m) touching it: the walker's points
    become a cluster of their own, the wall's stay one; a static post against the wall is left in the wall cluster
    (only walkers are cut out of extended clusters: a static track there is most likely part of the structure)."""
    from bigcbf.perception.geometry import cluster_points, compact_mask, scan_to_points
    wall = [(0.5, 1.0, 4.0, 1.0)]
    walker = (2.0, 0.73, 0.25)                                     # 0.02 m from the wall
    for static, n_expect in ((False, 2), (True, 1)):
        perc = _confirmed_perception([walker[:2]], [walker[2]], static=static)
        pr = perc.params
        scan = ray_scan(STILL(0.3), [walker], wall, stamp=0.3)
        sp = scan_to_points(scan, STILL(0.3), pr)
        clusters = cluster_points(sp, pr)
        mask = compact_mask(sp, clusters, pr)
        assert len(clusters) == 1 and not mask[0]
        perc.tracker.predict(0.3)
        out, compact = perc._segment(sp, clusters, compact_mask(sp, clusters, pr))
        assert len(out) == n_expect
        if not static:
            w = [c for c, k in zip(out, compact) if k]
            assert len(w) == 1
            # the walker's cluster: every beam that hit its circle, plus the few wall returns within the ownership
            # tolerance of the circle (merge_tol_m + 2 sigma, ``Tracker.surface_owner``) where the wall passes 2 cm
            # from it; the rest of the wall stays one cluster
            T = perc.tracker
            tol = pr.merge_tol_m + 2 * np.sqrt(np.linalg.eigvalsh(T.P[0, :2, :2])[-1])
            off = np.abs(np.linalg.norm(sp.xy - walker[:2], axis=1) - walker[2])
            on_circle = set(np.flatnonzero(off < 1e-6).tolist())
            mine = set(w[0].idx.tolist())
            assert on_circle <= mine and np.all(off[w[0].idx] <= tol)
            assert len(mine - on_circle) <= 4
            rest = sp.xy[[c for c, k in zip(out, compact) if not k][0].idx]
            assert np.all(np.abs(rest[:, 1] - 1.0) < 1e-6)              # the wall's points stay together


def test_segmentation_leaves_single_objects_alone():
    """A cluster on one track's circle only (a post alone, a walker alone) is passed through unchanged."""
    from bigcbf.perception.geometry import cluster_points, compact_mask, scan_to_points
    post = (2.5, 0.0, 0.2)
    for static in (True, False):
        perc = _confirmed_perception([post[:2]], [post[2]], static=static)
        sp = scan_to_points(ray_scan(STILL(0.3), [post], stamp=0.3), STILL(0.3), perc.params)
        clusters = cluster_points(sp, perc.params)
        mask = compact_mask(sp, clusters, perc.params)
        perc.tracker.predict(0.3)
        out, compact = perc._segment(sp, clusters, mask)
        assert out is clusters and compact is mask
