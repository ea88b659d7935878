"""PerceptionParams from TOML: defaults, unknown keys and bad values are UserErrors naming file and field."""
import pytest

from bigcbf.errors import UserError
from bigcbf.params import PerceptionParams, from_dict, load, save, to_dict


def test_defaults_match_the_interface():
    p = PerceptionParams()
    assert p.max_tracks == 8
    assert (p.laser_x_m, p.laser_y_m, p.laser_yaw_rad) == (0.0435, 0.0, 0.0)
    assert p.v_static_mps < p.v_dynamic_mps and p.wall_max_points <= 24


def test_roundtrip_through_toml(tmp_path):
    p = PerceptionParams(max_tracks=6, v_dynamic_mps=0.4, laser_x_m=0.05)
    f = tmp_path / "perception.toml"
    save(p, f)
    assert load(PerceptionParams, f) == p
    assert from_dict(PerceptionParams, to_dict(p)) == p


def test_unknown_key_names_file_and_field(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text("max_trakcs = 4\n")
    with pytest.raises(UserError) as e:
        load(PerceptionParams, f)
    assert "bad.toml" in str(e.value) and "max_trakcs" in str(e.value)


@pytest.mark.parametrize("text, field", [
    ("v_static_mps = 0.5\nv_dynamic_mps = 0.3\n", "v_static_mps"),
    ("max_tracks = -1\n", "max_tracks"),
    ("radius_min_m = 0.0\n", "radius_min_m"),
    ("n_static = 0\n", "n_static"),
    ("coast_s = 'long'\n", "coast_s"),
    ("max_candidates = 4\n", "max_candidates"),
])
def test_bad_values_are_user_errors(tmp_path, text, field):
    f = tmp_path / "p.toml"
    f.write_text(text)
    with pytest.raises(UserError) as e:
        load(PerceptionParams, f)
    assert "p.toml" in str(e.value) and field in str(e.value)
