"""The command line a newcomer meets: `bigcbf methods` with every method's parameters, defaults and units; `run`'s
--profile (the stack's) vs --robot-profile (the simulated robot's) and --time-limit; and a user planner's mistakes
as one line naming the method. Episodes are real, cut short with --time-limit."""
import dataclasses
import json
import re
import sys
import tomllib
from pathlib import Path

import pytest

from bigcbf.cli import main
from bigcbf.control.methods import METHODS, method_params_type

PLUGINS = Path(__file__).parent / "plugins"
ROOT = Path(__file__).resolve().parents[1]
SCENE = "required_sidestepping"
ROW = re.compile(r"^    (\S+) += (.*?)(?: {2,}\[(.*?)\]| *$)")


def _rows(lines):
    """{key: (default text, unit)} of the indented parameter rows."""
    out = {}
    for line in lines:
        m = ROW.match(line)
        if m:
            out[m.group(1)] = (m.group(2).strip(), m.group(3))
    return out


def _blocks(text):
    """The listing split per method: {name: [its lines]} (a block starts with an unindented line)."""
    blocks, name = {}, None
    for line in text.splitlines():
        if line and not line.startswith(" ") and not line.startswith("any other planner"):
            name = line.split()[0]
            blocks[name] = [line]
        elif name is not None:
            blocks[name].append(line)
    return blocks


def _toml(text):
    """A printed default read back as TOML ("unset": None)."""
    return None if text == "unset" else tomllib.loads(f"v = {text}")["v"]


def _flat(obj, prefix=""):
    out = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            out.update(_flat(v, prefix + f.name + "."))
        else:
            out[prefix + f.name] = v
    return out


def _same(printed, value):
    if isinstance(value, (tuple, list)):
        return isinstance(printed, list) and len(printed) == len(value) and all(
            _same(p, v) for p, v in zip(printed, value))
    if isinstance(value, bool) or value is None:
        return printed is value
    return printed == value and type(printed) is type(value)


def test_methods_lists_every_method_with_its_dataclass_defaults_and_units(capsys):
    assert main(["methods"]) == 0
    blocks = _blocks(capsys.readouterr().out)
    assert list(blocks) == METHODS.names()
    with_params = 0
    for name, lines in blocks.items():
        ptype = method_params_type(name)
        rows = _rows(lines)
        if ptype is None:            # its parameters are the stack's: listed by 'bigcbf methods NAME'
            assert "the stack's, [stack]" in lines[0] and rows == {}
            continue
        with_params += 1
        assert f"parameters [methods.{name}] ({ptype.__name__})" in lines[0]
        defaults = ptype()
        assert list(rows) == [f.name for f in dataclasses.fields(ptype)], name
        for key, (text, unit) in rows.items():
            assert _same(_toml(text), getattr(defaults, key)), (name, key, text)
            assert unit, (name, key)        # every shipped parameter states its unit ([-]: dimensionless)
    assert with_params == 6                # the five baselines with parameters and big-cbf-plus's switches
    dwa = _rows(blocks["dwa"])
    assert dwa["acc_xy_mps2"] == ("2.0", "m/s^2") and dwa["n_wz"] == ("1", "-") and dwa["margin_m"][1] == "m"
    assert _rows(blocks["mppi"])["samples"] == ("512", "-")


def test_methods_name_shows_one_in_full(capsys):
    assert main(["methods", "dwa"]) == 0
    out = capsys.readouterr().out
    assert list(_blocks(out)) == ["dwa"] and "DWA (Fox et al. 1997)" in out and "[methods.dwa]" in out
    # BIG-CBF's parameters are the stack's: every one, with the value a run uses by default
    from bigcbf.params.stack import default_stack_params

    assert main(["methods", "big-cbf"]) == 0
    rows = _rows(capsys.readouterr().out.splitlines())
    flat = _flat(default_stack_params())
    assert set(rows) == set(flat)
    for key, (text, unit) in rows.items():
        assert _same(_toml(text), flat[key]), (key, text)
    assert rows["alpha_per_s"][1] == "1/s" and rows["u_min"][1] == "m/s, m/s, rad/s"
    assert rows["uncertainty.tau95_s"][1] == "s"


def test_methods_of_a_users_planner_and_json(capsys, monkeypatch):
    monkeypatch.syspath_prepend(str(PLUGINS))
    assert main(["methods", "my_planners:GoalSeeker"]) == 0
    out = capsys.readouterr().out
    assert '[methods."my_planners:GoalSeeker"] (GoalSeekerParams)' in out
    assert _rows(out.splitlines()) == {"speed_mps": ("0.5", "m/s")}
    assert main(["methods", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert [r["key"] for r in data["apf"]["parameters"]][:2] == ["k_att_per_s", "d_conic_m"]
    assert data["big-cbf"]["parameters"] is None


@pytest.mark.parametrize("argv, message", [
    (["methods", "nope"], "unknown method 'nope'; known: big-cbf"),
    (["methods", "os:system"], "method 'os:system': it is a built-in function, not a planner class"),
    (["run", SCENE, "--method", "os:system"], "method 'os:system': it is a built-in function, not a planner class"),
    (["run", SCENE, "--method", "os:path"], "method 'os:path': it is a module, not a planner class"),
    (["run", SCENE, "--method", "collections:OrderedDict"],
     "it is the class OrderedDict, which is not a planner (no reset, plan"),
    (["run", SCENE, "--method", "bad_planners:NoPlan"], "it is the class NoPlan, which is not a planner (no plan;"),
    (["run", SCENE, "--method", "bad_planners:NOT_A_CLASS"], "it is an int object, not a planner class"),
])
def test_a_method_that_is_not_a_planner_is_one_line(argv, message, capsys, monkeypatch):
    monkeypatch.syspath_prepend(str(PLUGINS))
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


@pytest.mark.parametrize("cls, message", [
    ("TwoVector", "plan() returned a command of shape (2,), expected 3 numbers (vx, vy, wz) (at t = 0.00 s"),
    ("NanCommand", "plan() returned a command that is not finite ([0.3, 0.0, nan]), expected 3 finite numbers"),
    ("CommandOnly", "plan() returned ndarray array([0.3, 0. , 0. ]), expected a tuple (u_in, PlanInfo)"),
    ("DictInfo", "plan() returned dict {'mode': 'BAD'} as its info, expected a bigcbf.control.planner.PlanInfo"),
])
def test_a_planners_bad_output_is_one_line_naming_the_method(cls, message, capsys, monkeypatch):
    monkeypatch.syspath_prepend(str(PLUGINS))
    assert main(["run", SCENE, "--method", f"bad_planners:{cls}", "--time-limit", "1.5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"error: method 'bad_planners:{cls}': {message}" in err[0], err
    if cls == "NanCommand":          # the episode ran until the planner went wrong, not a check before it
        assert "at t = 1.00 s" in err[0]


def test_the_python_api_raises_the_same_user_error(monkeypatch):
    import bigcbf
    from bigcbf.errors import UserError

    monkeypatch.syspath_prepend(str(PLUGINS))
    with pytest.raises(UserError, match=r"method 'bad_planners:TwoVector': plan\(\) returned a command of shape"):
        bigcbf.run_episode(SCENE, "bad_planners:TwoVector", time_limit_s=1.0)


def _run_json(capsys, *extra):
    assert main(["run", SCENE, "--json", *extra]) == 0
    return json.loads(capsys.readouterr().out)


def test_time_limit_cuts_the_episode(capsys):
    out = _run_json(capsys, "--time-limit", "1.5", "--method", "cbf-only")
    assert out["timeout"] and out["time_s"] == 1.5 and out["control_steps"] == 30


@pytest.mark.parametrize("value, message", [
    ("0", "argument --time-limit: expected a time limit in seconds in [0.1, 600], got 0"),
    ("0.05", "argument --time-limit: expected a time limit in seconds in [0.1, 600], got 0.05"),
    ("-3", "argument --time-limit: expected a time limit in seconds in [0.1, 600], got -3"),
    ("601", "argument --time-limit: expected a time limit in seconds in [0.1, 600], got 601"),
    ("inf", "argument --time-limit: expected a finite number, got 'inf'"),
    ("2s", "argument --time-limit: expected a number, got '2s'"),
])
def test_a_bad_time_limit_is_one_line(value, message, capsys):
    assert main(["run", SCENE, "--time-limit", value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err


def test_the_time_limit_cap_is_the_scenarios():
    from bigcbf.cli.run import MAX_TIME_LIMIT_S
    from bigcbf.scenario import MAX_TIME_LIMIT_S as SCENARIO_CAP

    assert MAX_TIME_LIMIT_S == SCENARIO_CAP


def test_robot_profile_replaces_the_scenarios_base_and_keeps_its_overrides(tmp_path):
    from bigcbf.cli.argtypes import robot_profile_arg
    from bigcbf.cli.run import load_run_scenario
    from bigcbf.scenario import load_robot_profile

    hw = robot_profile_arg("x3_hardware")
    assert load_run_scenario(SCENE, 0, hw).robot_profile == load_robot_profile("x3_hardware")
    assert load_run_scenario(SCENE, 0).robot_profile == load_robot_profile("x3_sim")
    # delay_and_slip overrides latency_s (0.12 s) over its base: the override stays, the rest is the new base's
    sc = load_run_scenario("delay_and_slip", 0, hw)
    assert sc.robot_profile.latency_s == 0.12
    assert sc.robot_profile.odometry == load_robot_profile("x3_hardware").odometry
    assert sc.robot_profile.odometry != load_robot_profile("x3_sim").odometry
    # a file of one's own: an ideal robot
    ideal = tmp_path / "ideal.toml"
    ideal.write_text("")
    sc = load_run_scenario(SCENE, 0, robot_profile_arg(str(ideal)))
    assert sc.robot_profile.latency_s == 0.0 and sc.robot_profile_base == str(ideal)


def test_robot_profile_changes_the_episode(capsys):
    from bigcbf.episode import DETERMINISTIC_KEYS

    keys = [k for k in DETERMINISTIC_KEYS if k != "mode_history"]
    sim = _run_json(capsys, "--time-limit", "1.5", "--method", "cbf-only")
    assert {k: sim[k] for k in keys} == {k: v for k, v in _run_json(
        capsys, "--time-limit", "1.5", "--method", "cbf-only", "--robot-profile", "x3_sim").items() if k in keys}
    hw = _run_json(capsys, "--time-limit", "1.5", "--method", "cbf-only", "--robot-profile", "x3_hardware")
    assert hw["final_goal_dist_m"] != sim["final_goal_dist_m"]


def test_bad_robot_profiles_are_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('latency_s = "slow"\n')
    for value, message in [
        ("x3", "argument --robot-profile: no shipped robot profile 'x3' (shipped: x3_hardware, x3_sim, "),
        ("nope.toml", "argument --robot-profile: nope.toml: file not found"),
        (str(tmp_path), "and not a .toml file"),
        (str(bad), f"{bad}: field 'latency_s': expected a number, got 'slow'"),
    ]:
        assert main(["run", SCENE, "--robot-profile", value]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and message in err[0] and "Traceback" not in err[0], err


def test_help_tells_the_stack_profile_from_the_robot_profile(capsys):
    assert main(["run", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "--profile STACK.toml the STACK's uncertainty profile (tau95, execution model" in text
    assert "not how the simulated robot behaves: that is --robot-profile" in text
    assert "--robot-profile NAME|FILE the SIMULATED ROBOT's imperfections" in text
    assert "shipped robot profile (x3_sim, x3_hardware)" in text


def _readme_row(command):
    """The cells of the README's Subcommands row of ``command`` (split on the table's unescaped bars)."""
    row = next(line for line in (ROOT / "README.md").read_text().splitlines()
               if line.startswith(f"| `bigcbf {command}"))
    return re.split(r"(?<!\\)\|", row)


def test_the_readme_rows_of_run_and_methods_say_what_the_parser_has():
    from bigcbf.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    for command in ("run", "methods"):
        usage = _readme_row(command)[1]
        documented = set(re.findall(r"--[a-z][a-z-]*", usage))
        options = {o for a in sub[command]._actions for o in a.option_strings if o.startswith("--")} - {"--help"}
        assert documented == options, (command, documented ^ options)
    assert "NAME" in _readme_row("methods")[1]


@pytest.fixture(autouse=True)
def _forget_imported_plugins():
    """The plugin modules are imported from tests/plugins by each test's own sys.path: forget them afterwards."""
    yield
    for mod in ("bad_planners", "my_planners"):
        sys.modules.pop(mod, None)


@pytest.mark.parametrize("cls", ["Obstacles", "RobotState"])
def test_the_extending_pages_tables_name_every_field(cls):
    """docs/extending.md's tables of what plan() receives list exactly the dataclass's fields, each with a unit."""
    import bigcbf.types

    page = (ROOT / "docs" / "extending.md").read_text().split("\n")
    start = next(i for i, line in enumerate(page) if line.startswith(f"| `{cls}` field |"))
    rows = []
    for line in page[start + 2:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[2], line                       # the unit column is filled ("-" where there is none)
        rows += [n for n in re.findall(r"`([\w.]+)`", cells[0]) if not n.startswith(".")]
    assert rows == [f.name for f in dataclasses.fields(getattr(bigcbf.types, cls))]
