"""TOML parameters: round trip, and errors that name the file and the field."""
import pytest

from bigcbf.errors import UserError
from bigcbf.params import RobotProfile, load, save


def test_robot_profile_round_trip(tmp_path):
    p = RobotProfile(latency_s=0.08, latency_jitter_s=0.02, gain=((0.9, 0, 0), (0, 0.85, 0), (0, 0, 0.95)),
                     bias=(0.02, 0, 0), residual_max=(0.01, 0.01, 0.02), floor_friction=0.4)
    save(p, tmp_path / "r.toml")
    assert load(RobotProfile, tmp_path / "r.toml") == p


def test_defaults_are_ideal(tmp_path):
    (tmp_path / "e.toml").write_text("")
    p = load(RobotProfile, tmp_path / "e.toml")
    assert p.is_ideal and p.floor_friction is None


@pytest.mark.parametrize("text, field, words", [
    ("latency_ms = 80", "latency_ms", "unknown key"),
    ("latency_s = 'slow'", "latency_s", "expected a number"),
    ("bias = [0.1, 0.2]", "bias", "3 values"),
    ("gain = [[1, 0, 0], [0, 1, 0], [0, 0, 'x']]", "gain[2][2]", "expected a number"),
    ("latency_s = -0.1", None, ">= 0"),
])
def test_bad_values_name_file_and_field(tmp_path, text, field, words):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(UserError) as err:
        load(RobotProfile, f)
    msg = str(err.value)
    assert str(f) in msg and words in msg
    if field:
        assert f"'{field}'" in msg


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(UserError, match="file not found"):
        load(RobotProfile, tmp_path / "nope.toml")
    (tmp_path / "m.toml").write_text("latency_s = [")
    with pytest.raises(UserError, match="not valid TOML"):
        load(RobotProfile, tmp_path / "m.toml")
