"""``bigcbf perf``'s physics floor of the same run (issue 26): the episode's physics replayed without the stack."""
import numpy as np

from bigcbf.episode import Episode
from bigcbf.params.stack import SIMULATION
from bigcbf.scenario import load_scenario
from bigcbf.sim.perf import replay_realtime_factor


def test_replay_is_the_episodes_physics_to_the_bit():
    """The recorded blocks (state before the first, then wheel targets, mocap positions and steps per block) step
    the same compiled model to the episode's final state exactly, pedestrians and contacts included; recording
    changes nothing in the episode."""
    sc = load_scenario("single_person_crossing", 0)
    plain = Episode(sc, "big-cbf", 0, SIMULATION, perception="lidar")
    res0 = plain.run()
    ep = Episode(sc, "big-cbf", 0, SIMULATION, perception="lidar")
    log = ep.world.record_blocks()
    res = ep.run()
    assert res.time_s == res0.time_s and res.min_clearance_m == res0.min_clearance_m
    np.testing.assert_array_equal(ep.world.data.qpos, plain.world.data.qpos)
    steps = sum(nb for nb, _, _ in log.blocks)
    assert steps == int(round(res.sim_time_s / ep.world.dt))
    assert any(np.any(m != log.blocks[0][2]) for _, _, m in log.blocks)       # the pedestrian did move
    rf, qpos = replay_realtime_factor(ep.world.model, log)
    assert rf > 0
    np.testing.assert_array_equal(qpos, ep.world.data.qpos)
