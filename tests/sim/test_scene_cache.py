"""The per-process cache of compiled scenes (bigcbf/sim/scene.py, ``cached_model``; issue 26, item 2)."""
import numpy as np

from bigcbf import run_episode
from bigcbf.scenario import load_scenario
from bigcbf.sim import scene as scene_mod
from bigcbf.sim.scene import build_model, cached_model


def _arrays(m):
    return [np.asarray(getattr(m, k)) for k in ("geom_pos", "geom_size", "geom_friction", "body_mass", "actuator_gainprm",
                                                "dof_damping", "cam_projection")]


def test_a_cached_scene_is_the_compiled_one_and_each_caller_gets_its_own_copy(monkeypatch):
    monkeypatch.setattr(scene_mod, "_MODEL_CACHE", type(scene_mod._MODEL_CACHE)())
    spec = load_scenario("corridor_meeting", 3).scene()
    a, b = cached_model(spec), cached_model(spec)
    ref = build_model(spec)
    assert a is not b and len(scene_mod._MODEL_CACHE) == 1
    for x, y, z in zip(_arrays(a), _arrays(b), _arrays(ref)):
        assert np.array_equal(x, z) and np.array_equal(y, z)
    a.geom_friction[:] = 9.0                          # a caller changing its model does not reach the cache
    assert np.array_equal(cached_model(spec).geom_friction, ref.geom_friction)
    # another seed is another scene (its walker's start differs); the cache keeps the last MODEL_CACHE_SIZE
    for seed in range(scene_mod.MODEL_CACHE_SIZE + 2):
        cached_model(load_scenario("corridor_meeting", seed).scene())
    assert len(scene_mod._MODEL_CACHE) == scene_mod.MODEL_CACHE_SIZE


def test_a_robot_file_edited_between_episodes_is_compiled_anew(monkeypatch, tmp_path):
    monkeypatch.setattr(scene_mod, "_MODEL_CACHE", type(scene_mod._MODEL_CACHE)())
    spec = load_scenario("corridor_meeting", 0).scene()
    cached_model(spec)
    stamp = scene_mod._robot_files_stamp(spec.robot)
    edited = tuple((p, size + 1, t) if k == 0 else (p, size, t) for k, (p, size, t) in enumerate(stamp))
    monkeypatch.setattr(scene_mod, "_robot_files_stamp", lambda name: edited)
    cached_model(spec)
    assert len(scene_mod._MODEL_CACHE) == 2


def test_an_episode_on_a_cached_scene_is_the_same_bit_for_bit(monkeypatch):
    monkeypatch.setattr(scene_mod, "_MODEL_CACHE", type(scene_mod._MODEL_CACHE)())
    first = run_episode("single_person_crossing", "cbf-only", 1, time_limit_s=4.0).metrics()
    assert len(scene_mod._MODEL_CACHE) == 1
    second = run_episode("single_person_crossing", "cbf-only", 1, time_limit_s=4.0).metrics()
    for k in ("time_s", "min_clearance_m", "e_cbf", "final_goal_dist_m", "control_steps", "cbf_active_ratio"):
        assert first[k] == second[k], k
