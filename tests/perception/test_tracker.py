"""The tracker on hand-made cluster centres: assignment, gates, birth, confirmation, deletion, capacity."""
import numpy as np
import pytest

from bigcbf.params.perception import PerceptionParams
from bigcbf.perception.tracker import Tracker

ORIGIN = np.zeros(2)


def _tracker(**kw):
    return Tracker(PerceptionParams(**kw))


def test_assignment_minimises_total_distance():
    tr = _tracker(gate_min_m=0.5, gate_max_m=1.0, confirm_hits=1)
    tr.step(0.0, np.array([[0.0, 0.0], [0.6, 0.0]]), np.array([0.2, 0.2]), ORIGIN)
    assert tr.ids.tolist() == [0, 1]
    # both clusters are inside both gates (0.35 and 0.25 from each track); the pairing with the least total
    # distance is track 0 -> (0.25, 0) [0.25 m] and track 1 -> (0.35, 0) [0.25 m]; the swap costs 0.35 + 0.35
    rows, cols = tr.associate(np.array([[0.35, 0.0], [0.25, 0.0]]), np.array([0.2, 0.2]))
    assert dict(zip(rows.tolist(), cols.tolist())) == {0: 1, 1: 0}


def test_gates():
    tr = _tracker(confirm_hits=1)
    tr.step(0.0, np.array([[1.0, 0.0]]), np.array([0.25]), ORIGIN)
    z = np.array([[1.2, 0.0], [2.5, 0.0], [1.1, 0.0]])
    r = np.array([0.25, 0.25, 0.6])
    # 1.2: within gate_min_m; 2.5: beyond gate_max_m; 1.1 with radius 0.6: radius differs by > gate_radius_m
    for k, expect in ((0, True), (1, False), (2, False)):
        rows, _ = tr.associate(z[k:k + 1], r[k:k + 1])
        assert (len(rows) == 1) == expect


def test_birth_confirmation_and_deletion():
    p = PerceptionParams(confirm_hits=3, tentative_max_misses=1, coast_s=0.3)
    tr = Tracker(p)
    z, r = np.array([[2.0, 0.0]]), np.array([0.2])
    for k in range(3):
        tr.step(0.1 * k, z, r, ORIGIN)
        assert tr.confirmed.tolist() == [k == 2]
    assert len(tr.obstacles(ORIGIN)) == 1
    for t in (0.3, 0.4, 0.5):                    # coasting: kept while t - last_hit <= coast_s
        tr.step(t, np.zeros((0, 2)), np.zeros(0), ORIGIN)
        assert len(tr) == 1
    tr.step(0.6, np.zeros((0, 2)), np.zeros(0), ORIGIN)
    assert len(tr) == 0
    # a tentative track dies after tentative_max_misses + 1 misses
    tr.step(1.0, z, r, ORIGIN)
    tr.step(1.1, np.zeros((0, 2)), np.zeros(0), ORIGIN)
    assert len(tr) == 1
    tr.step(1.2, np.zeros((0, 2)), np.zeros(0), ORIGIN)
    assert len(tr) == 0


def test_no_birth_inside_a_known_object_and_rejected_reported():
    tr = _tracker(confirm_hits=1)
    tr.step(0.0, np.array([[2.0, 0.0]]), np.array([0.3]), ORIGIN)
    # next scan: the object's cluster plus a merged blob centred inside it with a much larger radius
    rej = tr.step(0.1, np.array([[2.0, 0.0], [2.1, 0.0]]), np.array([0.3, 0.7]), ORIGIN)
    assert len(tr) == 1 and rej.tolist() == [1]


def test_capacity_keeps_the_nearest():
    tr = _tracker(max_candidates=3, max_tracks=2, confirm_hits=1)
    z = np.array([[5.0, 0.0], [1.0, 0.0], [3.0, 0.0], [2.0, 0.0], [4.0, 0.0]])
    tr.step(0.0, z, np.full(5, 0.2), ORIGIN)
    assert sorted(tr.x[:, 0].tolist()) == [1.0, 2.0, 3.0]
    obs = tr.obstacles(ORIGIN)
    assert obs.p[:, 0].tolist() == [1.0, 2.0]
    assert obs.cov.shape == (2, 2, 2) and np.all(obs.r == pytest.approx(0.2))


# --- covariances: the static objects' filter and the physical bound of coasting tracks ----------------------------

def test_coast_bound_by_hand():
    from bigcbf.perception.tracker import coast_bound
    p = PerceptionParams(walk_speed_max_mps=2.0, walk_accel_max_mps2=2.5)
    # static: does not move
    assert coast_bound(1.0, True, 0.0, 0.5, p) == 0.0
    # dynamic, |v| = 1, sigma_v0 = 0.1: tau = 0.5 -> min(3 * 0.5, 1.25 * 0.25 + 0.05) = 0.3625
    assert coast_bound(0.5, False, 1.0, 0.1, p) == pytest.approx(0.3625)
    # tau = 2 -> min(3 * 2, 1.25 * 4 + 0.2) = 5.2; with sigma_v0 = 1.5: min(6, 5 + 3) = 6 (the speed bound)
    assert coast_bound(2.0, False, 1.0, 0.1, p) == pytest.approx(5.2)
    assert coast_bound(2.0, False, 1.0, 1.5, p) == pytest.approx(6.0)


def test_cap_covariance_by_hand():
    from bigcbf.perception.tracker import cap_covariance
    cov = np.array([[[0.09, 0.0], [0.0, 0.01]], [[0.01, 0.0], [0.0, 0.01]]])
    out = cap_covariance(cov, np.array([0.2, 0.2]))
    np.testing.assert_allclose(out[0], [[0.04, 0.0], [0.0, 0.01 * 0.04 / 0.09]])
    np.testing.assert_allclose(out[1], cov[1])                 # already within: unchanged


def test_static_track_covariance_is_the_constant_position_filters():
    """A post measured at 10 Hz: the reported covariance converges to the constant-position filter's steady state,
    P = (-a + sqrt(a^2 + 4 a R)) / 2 with a = q dt = 1e-4 m^2, R = 0.05^2 (P^2 + a P - a R = 0): 4.525e-4 m^2.
    R is the fit covariance handed to step() plus fit_model_sigma_m^2."""
    tr = _tracker(confirm_hits=1)
    rng = np.random.default_rng(0)
    cov = (0.05 ** 2 - PerceptionParams().fit_model_sigma_m ** 2) * np.eye(2)[None]
    for k in range(60):
        tr.step(0.1 * k, np.array([[2.0, 1.0]]) + rng.normal(0, 0.05, (1, 2)), np.array([0.2]), ORIGIN, cov)
    obs = tr.obstacles(ORIGIN)
    a, R = 1e-3 * 0.1, 0.05 ** 2
    steady = (-a + np.sqrt(a * a + 4 * a * R)) / 2
    assert obs.static[0]
    np.testing.assert_allclose(obs.cov[0], steady * np.eye(2), rtol=1e-3, atol=1e-9)
    assert np.linalg.norm(obs.p[0] - [2.0, 1.0]) < 0.04


def test_hidden_post_does_not_swell_and_hidden_walker_is_bounded():
    """A static post hidden behind a nearer object coasts with the covariance of its last update (it does not move:
    before the bound its CV covariance grew to 1.2-1.3 m rings of beta sigma); a coasting walker's standard deviation
    stays within its last update's plus coast_bound."""
    from bigcbf.perception.tracker import coast_bound
    p = PerceptionParams(confirm_hits=1, coast_s=1.0)
    tr = Tracker(p)
    for k in range(30):                                     # post at (2, 0), walker along x at 1 m/s
        tr.step(0.1 * k, np.array([[2.0, 0.0], [0.1 * k, 3.0]]), np.array([0.1, 0.25]), ORIGIN)
    before = tr.obstacles(ORIGIN)
    post = int(np.flatnonzero(before.static)[0])
    walker = int(np.flatnonzero(~before.static)[0])
    sigma_w0 = np.sqrt(np.linalg.eigvalsh(tr.P_hit[walker])[-1])
    sv0, speed = tr.sv_hit[walker], np.linalg.norm(tr.x[walker, 2:])
    for k in range(1, 10):                                  # both hidden for 0.9 s
        t = 2.9 + 0.1 * k
        tr.step(t, np.zeros((0, 2)), np.zeros(0), ORIGIN)
        obs = tr.obstacles(ORIGIN)
        i = int(np.flatnonzero(obs.ids == before.ids[post])[0])
        np.testing.assert_allclose(obs.cov[i], before.cov[post], rtol=1e-12)
        j = int(np.flatnonzero(obs.ids == before.ids[walker])[0])
        bound = sigma_w0 + coast_bound(0.1 * k, False, speed, sv0, p)
        assert np.sqrt(np.linalg.eigvalsh(obs.cov[j])[-1]) <= bound + 1e-12
    # without the bound the CV filter's own covariance of the post would have grown (accel PSD 0.5 over 0.9 s)
    assert np.sqrt(np.linalg.eigvalsh(tr.P[post, :2, :2])[-1]) > 3 * np.sqrt(np.linalg.eigvalsh(before.cov[post])[-1])


def test_static_track_that_starts_moving_follows_it():
    """The constant-position filter restarts from the CV filter when they disagree (gate_chi2): a standing person
    who starts walking is not reported where it stood."""
    tr = _tracker(confirm_hits=1)
    errs = []
    for k in range(40):
        x = 2.0 + max(0.0, 0.1 * (k - 20))                 # stands 2 s, then walks at 1 m/s
        tr.step(0.1 * k, np.array([[x, 1.0]]), np.array([0.25]), ORIGIN)
        errs.append(np.linalg.norm(tr.obstacles(ORIGIN).p[0] - [x, 1.0]))
    assert max(errs) < 0.3 and not tr.obstacles(ORIGIN).static[0]


def test_young_track_is_not_classified_on_its_first_noisy_centres():
    """A static bin 4.5 m away whose first fitted centres jump 11 cm (few beams, range noise): with the fit's own
    covariance (about 8 cm std along the line of sight for four beams there; ``geometry.circle_fit_covariance``)
    and a speed that must exceed dynamic_sigma = 2 standard deviations, the jump is not evidence of motion. With
    the former fixed 5 cm measurement std and a 1-sigma test it was classified dynamic at its fourth update."""
    zs = ([4.36, -0.905], [4.47, -0.945], [4.53, -0.945], [4.53, -0.945])
    ray = np.array([4.45, -0.93]) / np.linalg.norm([4.45, -0.93])
    cov = 0.08 ** 2 * np.outer(ray, ray) + 0.01 ** 2 * np.eye(2)
    old = _tracker(confirm_hits=3, classify_after_hits=1, dynamic_sigma=1.0, fit_model_sigma_m=0.05)
    for k, z in enumerate(zs):
        old.step(0.1 * k, np.array([z]), np.array([0.15]), ORIGIN)
    assert not old.static[0]
    tr = _tracker(confirm_hits=3)
    rng = np.random.default_rng(1)
    for k in range(20):
        z = np.array([zs[min(k, 3)]]) + (rng.normal(0, 0.01, (1, 2)) if k >= 4 else 0.0)
        tr.step(0.1 * k, z, np.array([0.15]), ORIGIN, cov[None])
        assert tr.static[0], f"classified dynamic at update {k + 1}"


def test_walker_near_the_robot_is_classified_within_three_updates():
    """The other side of the significance test: a walker 1.5 m away at 1 m/s, measured well (2 cm std), is
    dynamic at its fourth measurement (the earliest n_dynamic = 3 allows) and reported with its velocity."""
    tr = _tracker(confirm_hits=3)
    cov = np.array([0.02 ** 2 * np.eye(2)])
    for k in range(4):
        tr.step(0.1 * k, np.array([[1.5, -1.0 + 0.1 * k]]), np.array([0.25]), ORIGIN, cov)
    obs = tr.obstacles(ORIGIN)
    assert not obs.static[0] and np.linalg.norm(obs.v[0] - [0.0, 1.0]) < 0.35


def test_surface_owner_by_hand():
    """A point belongs to the confirmed track on whose predicted circle it lies: ||p - c| - r| <= merge_tol_m + 2
    sigma_max (sigma_max: the largest position std of the track), the nearest such circle; tentative tracks own
    nothing."""
    tr = _tracker(confirm_hits=1, merge_tol_m=0.05)
    tr.step(0.0, np.array([[2.0, 0.0], [2.0, 1.0], [5.0, 0.0]]), np.array([0.2, 0.3, 0.2]), ORIGIN)
    tr.P[0, :2, :2] = np.diag([0.02 ** 2, 0.01 ** 2])          # tolerance 0.05 + 2 * 0.02 = 0.09 m
    tr.P[1, :2, :2] = np.diag([0.01 ** 2, 0.01 ** 2])          # tolerance 0.07 m
    tr.confirmed[2] = False                                     # tentative: owns nothing
    pts = np.array([[1.75, 0.0],     # 0.25 from (2, 0): 0.05 off circle 0 -> 0
                    [1.72, 0.0],     # 0.08 off circle 0 (tolerance 0.09 m) -> 0
                    [1.70, 0.0],     # 0.10 off circle 0 -> none (tolerance 0.09 m)
                    [2.0, 0.64],     # 0.36 from (2, 1): 0.06 off circle 1 (0.44 off circle 0) -> 1
                    [2.0, 0.5],      # 0.3 off circle 0, 0.2 off circle 1 -> none
                    [2.0, 0.28],     # 0.08 off circle 0 (tol 0.09), 0.42 off circle 1 -> 0
                    [4.8, 0.0]])     # on the tentative track's circle -> none
    assert tr.surface_owner(pts).tolist() == [0, 0, -1, 1, -1, 0, -1]
    # the nearest circle wins where both tolerances hold: circles of 0.2 m at (0, 0) and (0, 0.5) (gap 0.1 m)
    tr2 = _tracker(confirm_hits=1, merge_tol_m=0.1)
    tr2.step(0.0, np.array([[0.0, 0.0], [0.0, 0.5]]), np.array([0.2, 0.2]), ORIGIN)
    tr2.P[:, :2, :2] = 0.0
    # (0, 0.24): 0.04 off circle 0, 0.06 off circle 1 -> 0; (0, 0.27): 0.07 off 0, 0.03 off 1 -> 1
    assert tr2.surface_owner(np.array([[0.0, 0.24], [0.0, 0.27]])).tolist() == [0, 1]
    assert tr2.surface_owner(np.zeros((0, 2))).tolist() == []


def test_roundness_smoothing_by_hand():
    """A track is round while the smoothed share of circle-model measurements is >= 1/2: with shape_smoothing
    0.3 and a round first measurement, two non-round ones give 1 -> 0.7 -> 0.49 (not round), two round ones then
    0.49 * 0.7 + 0.3 = 0.643 (round again), and a track born non-round starts at 0."""
    tr = _tracker(confirm_hits=1, shape_smoothing=0.3)
    z, r = np.array([[2.0, 0.0], [0.0, 3.0]]), np.array([0.2, 0.2])
    tr.step(0.0, z, r, ORIGIN, round_=np.array([True, False]))
    assert tr.roundness.tolist() == [1.0, 0.0] and tr.is_round().tolist() == [True, False]
    expect = [0.7, 0.49, 0.643]
    for k, rnd in enumerate((False, False, True)):
        tr.step(0.1 * (k + 1), z, r, ORIGIN, round_=np.array([rnd, False]))
        assert tr.roundness[0] == pytest.approx(expect[k])
        assert tr.is_round()[0] == (expect[k] >= 0.5)
    assert tr.roundness[1] == 0.0


def test_report_budget_shape_and_tentative_surfaces():
    """Tracker.report: the circles are the confirmed tracks that are dynamic or round, the max_tracks nearest
    (surface distance); the static ones beyond the budget, the static non-round ones and the tentative ones measured
    in this scan come back as their last clusters' points; nothing is lost."""
    tr = _tracker(confirm_hits=1, max_tracks=3)
    # five round posts at 1..5 m (r 0.1), a non-round box at 1.5 m; each cluster's "surface" marks its track
    z = np.array([[1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [4.0, 0.0], [5.0, 0.0], [0.0, 1.5]])
    r = np.full(6, 0.1)
    surf = [np.array([[k, 0.0]]) for k in range(6)]
    tr.step(0.0, z, r, ORIGIN, round_=np.array([1, 1, 1, 1, 1, 0], bool), surface=surf)
    circles, surfaces = tr.report(ORIGIN)
    assert circles.p.tolist() == [[1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]             # nearest three round ones
    assert sorted(s[0, 0] for s in surfaces) == [3.0, 4.0, 5.0]                   # beyond the budget + the box
    # a tentative track measured now is reported by its points; once it misses a scan, no longer
    tr2 = _tracker(confirm_hits=3)
    tr2.step(0.0, np.array([[2.0, 0.0]]), np.array([0.2]), ORIGIN, surface=[np.array([[1.8, 0.0], [1.9, 0.1]])])
    circles, surfaces = tr2.report(ORIGIN)
    assert len(circles) == 0 and len(surfaces) == 1 and surfaces[0].shape == (2, 2)
    tr2.step(0.1, np.zeros((0, 2)), np.zeros(0), ORIGIN)
    assert len(tr2) == 1 and tr2.report(ORIGIN)[1] == []
    # a dynamic track beyond the budget: its points only while measured (a walker's old points are stale)
    tr3 = _tracker(confirm_hits=1, max_tracks=1)
    tr3.step(0.0, np.array([[1.0, 0.0], [3.0, 0.0]]), np.array([0.2, 0.2]), ORIGIN,
             surface=[np.array([[0.8, 0.0]]), np.array([[2.8, 0.0]])])
    tr3.static[1] = False
    assert [s[0, 0] for s in tr3.report(ORIGIN)[1]] == [2.8]
    tr3.step(0.1, np.array([[1.0, 0.0]]), np.array([0.2]), ORIGIN, surface=[np.array([[0.8, 0.0]])])
    assert len(tr3) == 2 and tr3.report(ORIGIN)[1] == []
