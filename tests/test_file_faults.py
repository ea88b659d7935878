"""Faults set from files (issue 16, item 5): each fault does what it says, draws from its own stream, is off by
default, and a bad key or value is a one-line error naming the file and the field."""
from __future__ import annotations

import math

import numpy as np
import pytest

from bigcbf.errors import UserError
from bigcbf.params.faults import EventSchedule, PedestrianTurn, RobotFaults
from bigcbf.params.robot import ImuModel, OdometryModel, RobotProfile
from bigcbf.params.toml_io import load
from bigcbf.scenario import load_scenario, parse_scenario
from bigcbf.sim.faults import EventProcess, sector_mask
from bigcbf.sim.firmware import Encoders, ImperfectionLayer
from bigcbf.sim.pedestrians import Pedestrians
from bigcbf.sim.scene import open_room
from bigcbf.sim.world import SimWorld


# --- event schedules ----------------------------------------------------------------------------------------------

def test_explicit_events_cover_start_to_start_plus_duration_and_merge():
    p = EventProcess(EventSchedule(times_s=(1.0, 1.2, 3.0), duration_s=0.3), None)
    assert not p.active(0.99) and p.active(1.0) and p.active(1.49) and not p.active(1.5)
    assert p.event_at(1.25) == 1.2 and p.event_at(3.1) == 3.0 and p.event_at(2.0) is None
    assert p.end_of_outage(1.1) == pytest.approx(1.5)        # [1.0, 1.3) and [1.2, 1.5) are one outage
    assert p.end_of_outage(2.0) == 2.0 and p.end_of_outage(3.0) == pytest.approx(3.3)


def test_random_events_cover_the_poisson_share_of_time():
    """A Poisson process of rate lambda with events of length D covers 1 - exp(-lambda D) of the time."""
    for rate, d in ((0.3, 1.0), (0.2, 0.3)):
        p = EventProcess(EventSchedule(rate_per_s=rate, duration_s=d), np.random.default_rng(7))
        covered = np.mean([p.active(t) for t in np.arange(0.0, 4000.0, 0.1)])
        assert covered == pytest.approx(1 - math.exp(-rate * d), abs=0.02)


def test_schedules_are_off_by_default_and_validated():
    assert not EventSchedule().enabled and not RobotFaults().any and not PedestrianTurn().enabled
    assert RobotProfile().is_ideal and RobotProfile().faults == RobotFaults()
    from bigcbf.errors import FieldError
    for make, field in ((lambda: EventSchedule(rate_per_s=0.2), "duration_s"),     # events need a duration
                        (lambda: EventSchedule(rate_per_s=11.0, duration_s=1.0), "rate_per_s"),
                        (lambda: EventSchedule(times_s=(-1.0,), duration_s=1.0), "times_s"),
                        (lambda: RobotFaults(blanked_sectors_deg=((0.0, 0.0),)), "blanked_sectors_deg"),
                        (lambda: PedestrianTurn(times_s=(1.0,), duration_s=1.0, angle_deg=200.0), "angle_deg")):
        with pytest.raises(FieldError) as err:
            make()
        assert err.value.field == field


# --- LiDAR: dropout and blanked sectors ---------------------------------------------------------------------------

def _scans(profile: RobotProfile, seed: int = 4, n: int = 8) -> list:
    """The scans at 0.0, 0.1, ... s of a robot standing in a 3 m room."""
    world = SimWorld(open_room(3.0), profile=profile, seed=seed)
    out = []
    for k in range(n):
        out.append(world.scan())
        world.step(50)
    return out


NOISY = RobotProfile(latency_jitter_s=0.02).merged(
    lidar=RobotProfile().lidar.__class__(range_noise_std_m=0.01, range_noise_frac=0.01))


def test_a_dropped_scan_is_absent_and_the_others_are_unchanged():
    faulty = NOISY.merged(faults=RobotFaults(scan_dropout=EventSchedule(times_s=(0.15,), duration_s=0.3)))
    plain, dropped = _scans(NOISY), _scans(faulty)
    assert [s is None for s in dropped] == [False, False, True, True, True, False, False, False]  # 0.2, 0.3, 0.4 s
    for a, b in zip(plain, dropped):       # the scan noise has its own stream: the scans that arrive are the same
        if b is not None:
            np.testing.assert_array_equal(a.ranges, b.ranges)


def test_a_blanked_sector_reads_inf_and_the_rest_is_unchanged():
    sectors = ((90.5, 60.0), (180.0, 21.0))       # edges between beams (one per degree, from -180 deg)
    faulty = NOISY.merged(faults=RobotFaults(blanked_sectors_deg=sectors))
    a, b = _scans(NOISY, n=1)[0], _scans(faulty, n=1)[0]
    deg = np.round(np.degrees(a.angles)).astype(int)
    inside = ((deg >= 61) & (deg <= 120)) | (deg >= 170) | (deg <= -170)        # the second one wraps at +-180
    assert inside.sum() == 60 + 21
    assert np.all(np.isfinite(a.ranges))                                         # every beam hits a wall
    assert np.all(np.isinf(b.ranges[inside]))
    np.testing.assert_array_equal(a.ranges[~inside], b.ranges[~inside])
    np.testing.assert_array_equal(sector_mask(a.angles, sectors), inside)


# --- latency spikes -----------------------------------------------------------------------------------------------

def test_a_latency_spike_delays_exactly_the_commands_issued_during_it():
    spikes = RobotFaults(latency_spikes=EventSchedule(times_s=(1.0,), duration_s=0.3))
    layer = ImperfectionLayer(RobotProfile(latency_s=0.02, faults=spikes), np.random.default_rng(0))
    # issued at: before, at the start, inside, at the end (outside: [1.0, 1.3)), after
    got = [layer.submit(t, (0.1, 0, 0)) for t in (0.95, 1.0, 1.25, 1.3, 1.35)]
    np.testing.assert_allclose(got, [0.97, 1.32, 1.32, 1.32, 1.37])
    # the wheels hold the last command they received during the stall, then get the newest
    layer = ImperfectionLayer(RobotProfile(latency_s=0.02, faults=spikes), np.random.default_rng(0))
    for k, t in enumerate((0.9, 0.95, 1.0, 1.05, 1.1, 1.15, 1.2, 1.25, 1.3, 1.35)):
        layer.submit(t, (0.1 * k, 0, 0))
    assert layer.at(1.31)[0] == pytest.approx(0.1)           # still the command of 0.95 s (k = 1)
    assert layer.at(1.32)[0] == pytest.approx(0.8)           # then every queued one at once; the newest is k = 8
    assert layer.at(1.36)[0] == pytest.approx(0.8) and layer.at(1.37)[0] == pytest.approx(0.9)


def test_latency_spikes_do_not_change_the_jitter_draws():
    base = RobotProfile(latency_s=0.02, latency_jitter_s=0.03)
    spiky = base.merged(faults=RobotFaults(latency_spikes=EventSchedule(rate_per_s=0.5, duration_s=0.4)))
    w0, w1 = SimWorld(open_room(3.0), base, seed=3), SimWorld(open_room(3.0), spiky, seed=3)
    t = np.arange(0.0, 20.0, 0.05)
    a = np.array([w0.imperfection.submit(x, (0.1, 0, 0)) for x in t])
    b = np.array([w1.imperfection.submit(x, (0.1, 0, 0)) for x in t])
    stalled = np.array([w1.imperfection.spikes.active(x) for x in t])
    assert 10 < stalled.sum() < len(t) - 10
    late = b > a + 1e-12
    assert np.all(late[stalled])                             # every command issued in a stall is late ...
    free = ~stalled & (np.concatenate([[0.0], np.diff(b)]) >= 0)
    # ... and the others are on time, unless the previous one (late) still holds them back (FIFO)
    held = np.concatenate([[False], b[1:] == np.maximum.accumulate(b)[:-1]])
    np.testing.assert_array_equal(a[free & ~held], b[free & ~held])


# --- odometry and IMU noise and bias ------------------------------------------------------------------------------

def test_a_gyro_bias_turns_the_odometry_heading_at_its_rate():
    profile = RobotProfile(imu=ImuModel(gyro_bias_radps=0.01))
    world = SimWorld(open_room(3.0), profile, seed=0)
    world.advance(3.0)                                       # standing still: the true yaw rate is 0
    assert abs(world.true_state().theta) < 1e-5
    assert world.odom().theta == pytest.approx(0.01 * 3.0, abs=1e-5)      # by hand: 0.01 rad/s x 3 s


def test_a_wheel_radius_error_scales_the_odometry_distance():
    """Odometry does not act on the physics: the same drive with scale_error 0.05 integrates 1.05 x the distance
    (the heading comes from the gyro, which the wheel radius does not touch)."""
    odo = []
    for e in (0.0, 0.05):
        world = SimWorld(open_room(3.0), RobotProfile(odometry=OdometryModel(scale_error=e)), seed=0)
        world.command((0.3, 0.1, 0.0))
        world.advance(2.0)
        odo.append(np.array([world.odom().px, world.odom().py]))
    assert np.linalg.norm(odo[0]) > 0.4
    np.testing.assert_allclose(odo[1], 1.05 * odo[0], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("counts", [0, 1320])
def test_wheel_speed_noise_has_its_density(counts):
    """White noise of density N on a speed averaged over dt has std N / sqrt(dt): the wheel angle the odometry
    integrates random-walks by N sqrt(t) whatever the step."""
    n_density, dt = 0.2, 0.01
    enc = Encoders(OdometryModel(encoder_counts_per_rev=counts, wheel_noise_density_radps_rthz=n_density),
                   rng=np.random.default_rng(1))
    inc = np.array([enc.increment(np.full(4, 3.0), dt) for _ in range(20000)])
    assert inc.mean() == pytest.approx(3.0, abs=0.02)
    q = 0.0 if counts == 0 else 2 * np.pi / counts / dt       # a count's worth of speed adds quantisation noise
    assert inc.std() == pytest.approx(math.hypot(n_density / math.sqrt(dt), q / math.sqrt(12)), rel=0.05)
    quiet = Encoders(OdometryModel(encoder_counts_per_rev=counts))
    assert np.all(quiet.increment(np.full(4, 3.0), dt) == pytest.approx(3.0, abs=q + 1e-12))


# --- pedestrians that stop and turn -------------------------------------------------------------------------------

def _walk(stops=None, turns=None, until=6.0, seed=0):
    """One pedestrian walking +x from the origin at 1 m/s from t = 0; positions and velocities at 50 Hz."""
    peds = Pedestrians([[(0, 0), (20, 0)]], [1.0], [0.0], [0.25], [False], [False],
                       stops=None if stops is None else [stops], turns=None if turns is None else [turns], seed=seed)
    ts, ps, vs = [], [], []
    for k in range(int(round(until / 0.02))):
        t = 0.02 * k
        peds.step(t, 0.02)
        ts.append(t)
        ps.append(peds.p[0].copy())
        vs.append(peds.v[0].copy())
    return np.array(ts), np.array(ps), np.array(vs), peds


def test_a_pedestrian_stops_at_the_given_time_for_the_given_duration():
    t, p, v, peds = _walk(stops=EventSchedule(times_s=(2.0,), duration_s=1.5))
    _, p0, v0, _ = _walk()
    k2 = int(np.searchsorted(t, 2.0))
    np.testing.assert_array_equal(p[:k2], p0[:k2])                          # identical until the stop begins
    assert v[k2 - 1, 0] > 0.98                                               # walking at ~1 m/s
    assert peds.stopped(0, 2.0) and peds.stopped(0, 3.49) and not peds.stopped(0, 3.5)
    # its preferred velocity is 0 from 2.0 s: the speed relaxes as exp(-(t - 2) / tau), tau = 0.5 s
    k3 = int(np.searchsorted(t, 3.48))
    assert v[k3, 0] == pytest.approx(math.exp(-(t[k3] - 2.0) / 0.5), abs=0.03)
    assert v[k3, 0] < 0.07
    assert v[-1, 0] == pytest.approx(1.0, abs=0.02)                          # walking again
    assert p0[-1, 0] - p[-1, 0] == pytest.approx(1.5, abs=0.05)              # 1.5 s behind


def test_a_pedestrian_turns_back_then_resumes_its_way():
    t, p, v, peds = _walk(turns=PedestrianTurn(times_s=(2.0,), duration_s=2.0, angle_deg=180.0))
    k = int(np.searchsorted(t, 3.9))
    assert v[k, 0] < -0.9 and abs(v[k, 1]) < 1e-9                            # walking back along -x
    assert v[-1, 0] > 0.9                                                    # and on its way again by 6 s
    t, p, v, _ = _walk(turns=PedestrianTurn(times_s=(2.0,), duration_s=2.0, angle_deg=90.0))
    k = int(np.searchsorted(t, 3.9))
    assert v[k, 1] > 0.9 and abs(v[k, 0]) < 0.05                             # 90 deg counter-clockwise: +y


def test_pedestrian_faults_have_their_own_streams():
    stops = EventSchedule(rate_per_s=0.5, duration_s=1.0)
    turns = PedestrianTurn(rate_per_s=0.5, duration_s=1.0, angle_deg=90.0, random_side=True)
    _, p_turn, _, a = _walk(turns=turns, until=20.0, seed=3)
    _, _, _, b = _walk(stops=stops, turns=turns, until=20.0, seed=3)
    _, _, _, c = _walk(turns=turns, until=20.0, seed=4)
    first = [x._turns[0]._random[:8] for x in (a, b, c)]
    assert len(first[0]) == 8 and first[0] == first[1]       # stops on: the same turns ...
    assert first[0] != first[2]                              # ... another seed: other turns
    _, p_none, _, _ = _walk(until=20.0, seed=3)
    assert np.abs(p_turn - p_none).max() > 0.5


# --- in an episode: the stack sees faults through its sensors only -------------------------------------------------

SCENE = """
name = "fault_probe"
description = "A post and a crossing pedestrian, for the fault tests."
time_limit_s = 3.0
[robot]
start = [0.0, 0.0, 0.0]
goal = [6.0, 0.0]
[[cylinders]]
center = [2.5, 0.8]
radius_m = 0.2
[[pedestrians]]
name = "p"
waypoints = [[3.0, -2.5], [3.0, 2.5]]
speed_mps = 0.8
reactive = false
"""


def test_a_missing_scan_leaves_the_estimates_ageing_and_nothing_crashes(tmp_path):
    from bigcbf.control.prediction import q_sigma_for
    from bigcbf.episode import Episode
    from bigcbf.params.stack import SIMULATION

    path = tmp_path / "probe.toml"
    path.write_text(SCENE + "[robot_profile.faults.scan_dropout]\ntimes_s = [0.95]\nduration_s = 1.0\n")
    sc = load_scenario(path, 0)
    ep = Episode(sc, "big-cbf", 0, SIMULATION)
    recs = {}
    ep.observers.append(lambda rec: recs.setdefault(round(rec.t, 3), rec))
    res = ep.run()
    assert res.missed_scans == 10 and not res.collision                      # the scans of 1.0 ... 1.9 s
    assert recs[1.5].scan.stamp == pytest.approx(0.9)                        # the latest scan that arrived
    base, later = recs[0.9].obstacles, recs[1.5].obstacles                   # 0.9 s: age 0; 1.5 s: age 0.6 s
    assert len(base) > 0 and np.array_equal(base.ids, later.ids)
    np.testing.assert_allclose(later.p, base.p + 0.6 * base.v, atol=1e-9)
    grow = q_sigma_for(base, SIMULATION.uncertainty) * (0.6 - 0.1)           # eq:cov_prop (3) beyond one scan period
    np.testing.assert_allclose(later.cov, base.cov + grow[:, None, None] * np.eye(2), atol=1e-12)
    assert recs[2.0].scan.stamp == pytest.approx(2.0)                        # scans again
    # without the fault, the same episode misses nothing, and its estimates are never older than one scan
    plain = Episode(load_scenario(_write(tmp_path, SCENE), 0), "big-cbf", 0, SIMULATION).run()
    assert plain.missed_scans == 0


def _write(tmp_path, text):
    p = tmp_path / "plain.toml"
    p.write_text(text)
    return p


def test_every_fault_off_keeps_the_shipped_episodes():
    """The shipped scenes set no fault (their golden values are tests/test_episode.py's)."""
    from bigcbf.scenario import all_scenario_files
    for name in all_scenario_files():
        sc = load_scenario(name, 0)
        assert not sc.robot_profile.faults.any, name
        assert sc.robot_profile.odometry.wheel_noise_density_radps_rthz == 0.0
        assert sc.robot_profile.imu.gyro_bias_radps == 0.0
        assert not any(p.stop.enabled or p.turn.enabled for p in sc.pedestrians), name


# --- files: keys, errors, draws_as --------------------------------------------------------------------------------

@pytest.mark.parametrize("text, field", [
    ("[faults]\nblanked = 1\n", "faults.blanked"),
    ("[faults.scan_dropout]\nrate = 0.2\n", "faults.scan_dropout.rate"),
    ("[faults.scan_dropout]\nrate_per_s = -1.0\nduration_s = 1.0\n", "faults.scan_dropout.rate_per_s"),
    ("[faults.latency_spikes]\nrate_per_s = 0.2\n", "faults.latency_spikes.duration_s"),
    ("[faults.latency_spikes]\ntimes_s = [1e9]\nduration_s = 1.0\n", "faults.latency_spikes.times_s"),
    ("[faults]\nblanked_sectors_deg = [[0.0, 400.0]]\n", "faults.blanked_sectors_deg"),
    ("[faults]\nblanked_sectors_deg = [[0.0]]\n", "faults.blanked_sectors_deg[0]"),
    ("[odometry]\nwheel_noise_density_radps_rthz = -0.1\n", "odometry.wheel_noise_density_radps_rthz"),
    ("[imu]\ngyro_bias_radps = nan\n", "imu.gyro_bias_radps"),
    ("[imu]\ngyro_bias_radps = 5.0\n", "imu.gyro_bias_radps"),
])
def test_bad_robot_fault_keys_are_one_line_errors(tmp_path, text, field):
    path = tmp_path / "robot.toml"
    path.write_text(text)
    with pytest.raises(UserError) as err:
        load(RobotProfile, path)
    assert str(path) in str(err.value) and f"field '{field}'" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("extra, field", [
    ("stop = { times_s = [1.0], duration = 2.0 }", "pedestrians[0].stop.duration"),
    ("stop = { rate_per_s = 0.2 }", "pedestrians[0].stop.duration_s"),
    ("turn = { times_s = [1.0], duration_s = 1.0, angle_deg = 270.0 }", "pedestrians[0].turn.angle_deg"),
    ("turn = { times_s = [1.0], duration_s = 1.0, random_side = 1 }", "pedestrians[0].turn.random_side"),
    ("turn = 3", "pedestrians[0].turn"),
])
def test_bad_pedestrian_fault_keys_are_one_line_errors(extra, field):
    with pytest.raises(UserError) as err:
        parse_scenario(SCENE + extra + "\n", "probe.toml")
    assert "probe.toml" in str(err.value) and f"field '{field}'" in str(err.value)


def test_draws_as_draws_another_scene_s_worlds():
    base = load_scenario("crowd_crossing", 5)
    from bigcbf.scenario import resolve_path
    text = resolve_path("crowd_crossing").read_text().replace('name = "crowd_crossing"', 'name = "variant"')
    other = parse_scenario(text, "variant.toml", 5)
    same = parse_scenario(text.replace('name = "variant"', 'name = "variant"\ndraws_as = "crowd_crossing"'),
                          "variant.toml", 5)
    assert other.pedestrians != base.pedestrians
    assert same.pedestrians == base.pedestrians and same.name == "variant"
    with pytest.raises(UserError, match="draws_as"):
        parse_scenario(text.replace('name = "variant"', 'name = "variant"\ndraws_as = 3'), "variant.toml", 5)
