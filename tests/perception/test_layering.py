"""bigcbf.perception runs on a robot: importing it (and its perf provider) must not pull in the simulator."""
import subprocess
import sys


def test_no_simulator_import():
    code = ("import sys, bigcbf.perception, bigcbf.perception.perf, bigcbf.params.perception\n"
            "bad = [m for m in sys.modules\n"
            "       if m.split('.')[0] in ('mujoco', 'dm_control') or m.startswith('bigcbf.sim')]\n"
            "assert not bad, bad\n")
    subprocess.run([sys.executable, "-c", code], check=True)
