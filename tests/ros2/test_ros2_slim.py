"""Robot side without a simulator (issue 28, item 3): ``bigcbf filter --ros2`` runs in a process where mujoco,
dm_control and cv2 cannot be imported (a sys.meta_path finder refuses them), drives a feeder robot on loopback and
ends cleanly. Also: the filter path's modules parse as Python 3.10 (the slim install declares it) where a
python3.10 exists.

The fresh-environment run (opt-in, it needs an environment built beforehand): ``BIGCBF_SLIM_PYTHON`` names the
interpreter of a virtual environment with only the slim dependencies (docs/ros2.md, "Slim install"), e.g.::

    python3.10 -m venv /tmp/slim310
    /tmp/slim310/bin/pip install numpy scipy numba proxsuite rosbags tomli tomli-w cyclonedds==11.0.1
    BIGCBF_SLIM_PYTHON=/tmp/slim310/bin/python pytest tests/ros2/test_ros2_slim.py

and the same filter process then runs on that interpreter, where mujoco, dm_control and cv2 are not installed at
all (checked), with the repository on PYTHONPATH (what ``pip install --no-deps`` of the wheel gives)."""
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bigcbf.logio import convert, msgdefs
from bigcbf.ros2 import transport
from bigcbf.types import RobotState

BLOCKED = ("mujoco", "dm_control", "cv2")
BLOCKER = f"""
import importlib.abc, sys
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in {BLOCKED!r}:
            raise ImportError(f'{{name}} is blocked: robot-side code must not import it')
sys.meta_path.insert(0, Block())
from bigcbf.cli import main
status = main(sys.argv[1:])
leaked = [m for m in sys.modules if m.split('.')[0] in {BLOCKED!r} or m.startswith('bigcbf.sim')]
assert not leaked, leaked
sys.exit(status)
"""
ROOT = Path(__file__).resolve().parents[2]



def _feed(domain_id, proc, seconds=40.0):
    n = transport.Node("robot", domain_id, loopback=True)
    scan = n.publisher("/scan", msgdefs.LASER_SCAN, transport.DEFAULT)
    odom = n.publisher("/odom", msgdefs.ODOMETRY, transport.DEFAULT)
    tf = n.publisher("/tf_static", msgdefs.TF_MESSAGE, transport.LATCHED)       # the laser mount, as a robot has
    tf(convert.static_tf_msg(0.0, [("base_link", "laser", (0.05, 0.0, 0.2), 0.0)]))
    cmds = []
    n.subscribe("/cmd_vel", msgdefs.TWIST, lambda m, t: cmds.append(convert.twist_u(m)), transport.DEFAULT)
    import math

    import numpy as np

    from bigcbf.types import LaserScan
    ranges = np.full(360, np.inf, np.float32)
    t, end = 0.0, time.monotonic() + seconds
    while not (cmds and cmds[-1][0] > 0.05) and time.monotonic() < end and proc.poll() is None:
        scan(convert.laser_scan_msg(LaserScan(stamp=t, angle_min=-math.pi, angle_increment=2 * math.pi / 360,
                                              range_min=0.05, range_max=12.0, ranges=ranges)))
        odom(convert.odometry_msg(t, RobotState(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
        n.spin_once(0.05)
        t += 0.05
    n.close()
    return cmds


SLIM = os.environ.get("BIGCBF_SLIM_PYTHON")


@pytest.mark.parametrize("python", [sys.executable] + ([SLIM] if SLIM else []), ids=lambda p: "slim-env" if p == SLIM else "this-env")
def test_slim_filter_process(domain_id, python):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    if python == SLIM:
        r = subprocess.run([python, "-c", "import importlib.util as u; print([m for m in ('mujoco', 'dm_control', "
                            "'cv2') if u.find_spec(m)])"], capture_output=True, text=True)
        assert r.stdout.strip() == "[]", f"{python} has a simulator package: {r.stdout}{r.stderr}"
    proc = subprocess.Popen([python, "-c", BLOCKER, "filter", "--ros2", "--loopback", "--domain-id",
                             str(domain_id), "--goal", "3,0", "--idle-exit", "1", "--json"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        cmds = _feed(domain_id, proc)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err[-2000:]
    assert cmds and cmds[-1][0] > 0.05, err[-2000:]          # it drove toward the goal
    assert json.loads(out)["steps"] >= 1


def test_blocker_blocks():
    """The finder above does refuse (else the slim test could not fail)."""
    r = subprocess.run([sys.executable, "-c", BLOCKER.replace("from bigcbf.cli import main", "import cv2"), "x"],
                       capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode != 0 and "cv2 is blocked" in r.stderr


def _python310():
    import glob
    for cand in [os.environ.get("BIGCBF_PY310"), shutil.which("python3.10"),
                 *sorted(glob.glob(os.path.expanduser("~/.pyenv/versions/3.10*/bin/python3.10")))]:
        if cand and subprocess.run([cand, "--version"], capture_output=True).returncode == 0:
            return cand
    return None


PY310 = _python310()


@pytest.mark.skipif(PY310 is None, reason="no working python3.10 here")
def test_filter_path_parses_on_python310():
    files = [ROOT / "bigcbf" / "cli" / "filter.py", *sorted((ROOT / "bigcbf" / "ros2").glob("*.py"))]
    for sub in ("control", "perception", "params", "logio"):
        files += sorted((ROOT / "bigcbf" / sub).rglob("*.py"))
    files += [ROOT / "bigcbf" / f for f in ("types.py", "errors.py", "registry.py", "outputs.py", "__init__.py")]
    code = "import sys, ast\nfor f in sys.argv[1:]: ast.parse(open(f).read(), f, feature_version=(3, 10))"
    r = subprocess.run([PY310, "-c", code, *map(str, files)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr[-2000:]
