"""A user's planner factory that cannot be called as factory(params), or that raises, is one line naming the
method (a UserError), in the CLI as in the Python API, not a traceback from inside the episode."""
import subprocess
import sys
import textwrap

import pytest

from bigcbf.control.methods import make_planner
from bigcbf.errors import UserError
from bigcbf.params.stack import StackParams

MODULE = textwrap.dedent("""
    def three_args(x, y, z):
        return 1
    def raises(params):
        raise ValueError("boom")
    class Fine:
        def __init__(self, params):
            self.params = params
        def reset(self, seed):
            pass
        def plan(self, t, state, obstacles, goal):
            raise NotImplementedError
""")


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    (tmp_path / "user_factories_mod.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


@pytest.mark.parametrize("attr, words", [("three_args", "cannot be called as factory(params)"),
                                         ("raises", "its factory raised ValueError: boom")])
def test_bad_user_factory_is_one_user_error(user_module, attr, words):
    with pytest.raises(UserError, match=words.replace("(", r"\(").replace(")", r"\)")):
        make_planner(f"user_factories_mod:{attr}", StackParams())


def test_good_user_factory_builds(user_module):
    assert make_planner("user_factories_mod:Fine", StackParams()).params == StackParams()


def test_cli_prints_one_line(user_module):
    env = {"PYTHONPATH": str(user_module), "MUJOCO_GL": "disable", "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", "import sys; from bigcbf.cli import main; sys.exit(main())", "run", "crowd_crossing", "--method",
                          "user_factories_mod:raises", "--time-limit", "1"], capture_output=True, text=True, env=env)
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr
    assert out.stderr.strip().splitlines() == [
        "bigcbf run: error: method 'user_factories_mod:raises': its factory raised ValueError: boom"]
