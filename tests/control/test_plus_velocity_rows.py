"""big-cbf-plus runs the common filter with its velocity-aware rows (PlusRules.velocity_rows, issue 23); off, the run's
[stack] filter; big-cbf keeps the paper's filter."""
from bigcbf.control.methods import filter_params, make_planner
from bigcbf.episode import Episode
from bigcbf.params.stack import PlusRules, StackParams
from bigcbf.scenario import load_scenario


def test_plus_filter_has_velocity_rows_by_default():
    p = StackParams()
    assert not p.cbf_velocity_rows
    assert filter_params(make_planner("big-cbf-plus", p), p).cbf_velocity_rows
    assert not filter_params(make_planner("big-cbf-plus", p, PlusRules(velocity_rows=False)), p).cbf_velocity_rows
    assert not filter_params(make_planner("big-cbf", p), p).cbf_velocity_rows


def test_episode_builds_plus_filter_with_the_rows():
    sc = load_scenario("crowd_crossing", 0)
    assert Episode(sc, "big-cbf-plus", 0, time_limit_s=1).cbf.params.cbf_velocity_rows
    assert not Episode(sc, "big-cbf", 0, time_limit_s=1).cbf.params.cbf_velocity_rows


def test_plus_last_resort_is_its_own_setting():
    p = StackParams()
    assert p.cbf_last_resort == "slack"
    assert filter_params(make_planner("big-cbf-plus", p), p).cbf_last_resort == "passive"
    assert filter_params(make_planner("big-cbf-plus", p, PlusRules(last_resort="brake")), p).cbf_last_resort == "brake"
    assert filter_params(make_planner("big-cbf", p), p).cbf_last_resort == "slack"


def test_plus_last_resort_bad_value_names_the_field():
    import pytest
    from bigcbf.errors import FieldError
    with pytest.raises(FieldError, match="must be one of slack, brake, evade, passive") as err:
        PlusRules(last_resort="teleport")
    assert "last_resort" in repr(vars(err.value))
