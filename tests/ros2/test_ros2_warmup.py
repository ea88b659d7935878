"""The filter node's warm-up (``SafetyStack.warm_up``, run by ``bigcbf filter`` before it answers) leaves no compiled
kernel for the first real encounter to compile.

numba compiles a kernel at its first call with each argument type (array layouts included); on a fresh install,
or for a layout met for the first time, that is seconds in the middle of a control step. Found in a clean-clone CI
run: the lock-step loopback test's filter node compiled the CBF filter's QP kernels when the filter first engaged
(about t = 4.5 s; the old warm-up never made it active), the step overran its budget, the command was zero, and the
twin's episode left the in-process one (min clearance 0.636 against 0.893). Reproduced with the old warm-up on a
numba cache filled by the warm-up alone: the same step stalled more than 20 s on the loaded machine.

Here, in a fresh interpreter: the stack of each node method is built and warmed up, every numba kernel of the
package is listed with the argument types it has machine code for, then the scans and odometry of a real episode
(single_person_crossing, seed 0: a person crossing the path, the filter active) go through the stack; the kernels'
lists must not grow. (Types, not compile events: a kernel loaded from numba's cache counts as well, so the test
says the same with a warm or a cold cache.)
"""
import json
import pickle
import subprocess
import sys

import pytest

from bigcbf.config import RunConfig
from bigcbf.episode import Episode
from bigcbf.scenario import load_scenario

CHILD = r"""
import json, pickle, sys
import numba
from bigcbf.api import load_config
from bigcbf.cli.run import config_note
from bigcbf.ros2.stack import SafetyStack

def kernels():
    out = {}
    for name, mod in list(sys.modules.items()):
        if not name.startswith("bigcbf."):
            continue
        for attr, obj in list(vars(mod).items()):
            if isinstance(obj, numba.core.registry.CPUDispatcher):
                out[f"{name}.{attr}"] = sorted(str(s) for s in obj.signatures)
    return out

method, path = sys.argv[1], sys.argv[2]
with open(path, "rb") as f:
    goal, mount, ticks = pickle.load(f)
stack = SafetyStack.from_config(method, load_config(None, None, notes=config_note), seed=0)
stack.set_mount(*mount)
stack.set_goal(*goal)
stack.warm_up()
before = kernels()
active = 0
for t, state, scan in ticks:
    if scan is not None:
        stack.scan(scan, state)
    active += stack.control(t, state).active
after = kernels()
new = {k: sorted(set(v) - set(before.get(k, []))) for k, v in after.items()}
print(json.dumps({"new": {k: v for k, v in new.items() if v}, "kernels": len(before), "active": active,
                  "ticks": len(ticks)}))
"""


@pytest.fixture(scope="module")
def ticks(tmp_path_factory):
    """The stack's inputs of the in-process episode: (t, odometry state, the scan new at that tick or None)."""
    sc = load_scenario("single_person_crossing", 0)
    ep = Episode.from_config(sc, "big-cbf", 0, RunConfig())
    out, last = [], [None]

    def keep(rec):
        new = rec.scan if rec.scan is not None and rec.scan is not last[0] else None
        last[0] = rec.scan
        out.append((rec.t, rec.state, new))
    ep.observers.append(keep)
    ep.run()
    x, y, _, yaw = ep.world.sensor_frames()["laser"]
    path = tmp_path_factory.mktemp("warmup") / "ticks.pkl"
    path.write_bytes(pickle.dumps((tuple(ep.goal), (x, y, yaw), out)))
    return path


@pytest.mark.slow
@pytest.mark.parametrize("method", ["big-cbf", "big-cbf-plus"])
def test_after_the_warm_up_a_real_encounter_compiles_nothing(ticks, method):
    res = subprocess.run([sys.executable, "-c", CHILD, method, str(ticks)], capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    out = json.loads(res.stdout.strip().splitlines()[-1])
    assert out["ticks"] > 200 and out["kernels"] > 40
    if method == "big-cbf":                   # the episode engages the filter (what the old warm-up never did);
        assert out["active"] > 0              # big-cbf-plus, given big-cbf's states, plans clear of it
    assert out["new"] == {}
