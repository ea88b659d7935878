"""The replay's mapping onto the model survives a log that barely drives an axis (found by the real-work fuzzer:
a truncated MCAP gave the nominal replay a zero gain on vy and `bigcbf replay` a LinAlgError)."""
import numpy as np

from twin.replay import _invertible_gain, model_profile


def test_an_unmeasured_axis_of_the_models_own_gain_is_taken_as_ideal():
    A0 = np.array([[0.97, 0.01, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.95]])      # vy never moved: singular
    fixed, weak = _invertible_gain(A0)
    assert weak == ["vy"] and fixed[1, 1] == 1.0 and fixed[0, 1] == 0.0 and fixed[0, 0] == 0.97
    prof = model_profile(np.diag([0.9, 0.85, 0.9]), np.zeros(3), 0.1, fixed, np.zeros(3), 0.02)
    assert np.isfinite(np.array(prof.gain)).all() and prof.gain[1][1] == 0.85
    same, none = _invertible_gain(np.diag([0.9, 0.8, 0.7]))
    assert none == [] and np.array_equal(same, np.diag([0.9, 0.8, 0.7]))
    assert _invertible_gain(np.full((3, 3), np.nan))[1] == ["vx", "vy", "wz"]
