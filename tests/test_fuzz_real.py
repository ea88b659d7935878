"""The fuzzer that runs the real commands (scripts/fuzz_inputs.py, issue 21 item 5): its fixed sample, one case per
class of the issue, each a real subprocess (episode, bench, recording, calibration, replay, API, Gymnasium) that must
end in its stated class -- no traceback, no hang, no lost or half-written file; and the classifier itself, shown
each kind of failure it must catch. The full run is ``make fuzz`` (or ``python scripts/fuzz_inputs.py --n 1000``).

Cases of classes not fixed yet are expected failures with their reason (SAMPLE_TABLE's third column): the test
passes now and tightens when the reason is removed.
"""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load():
    spec = importlib.util.spec_from_file_location("fuzz_inputs", ROOT / "scripts" / "fuzz_inputs.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules["fuzz_inputs"] = mod
    spec.loader.exec_module(mod)
    return mod


fz = _load()


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """A real 10 s calibration drive (``bigcbf record calibration``) and its calibrated profile."""
    d = tmp_path_factory.mktemp("fuzzbase")
    fz.make_base(d)
    return d


def _params():
    out = []
    for i, (name, want, why) in enumerate(fz.SAMPLE_TABLE):
        marks = [pytest.mark.xfail(reason=why, strict=False)] if why else []
        out.append(pytest.param(i, want, why, id=name, marks=marks))
    return out


@pytest.mark.parametrize("index,want,why", _params())
def test_sample_case(base, tmp_path, index, want, why):
    case, want2, _ = fz.sample_cases()[index]
    assert want2 == want
    case.id = f"s{index:02d}"
    rec = fz.run_case(case, tmp_path / "work", timeout=15.0 if why else 90.0)
    assert rec["class"] == want, (case.argv, rec["class"], rec["flags"], rec["stderr_tail"])


def test_generated_cases_are_reproducible_and_cover_every_family(base):
    a, b = fz.generate(150, 3), fz.generate(150, 3)
    assert [(c.argv, c.files, c.links) for c in a] == [(c.argv, c.files, c.links) for c in b]
    assert {c.family for c in a} == set(fz.FAMILIES)
    assert [c.argv for c in fz.generate(20, 4)] != [c.argv for c in a[:20]]


def _py(tmp_path, body: str, **kw) -> dict:
    case = fz.Case("self-test", body.splitlines()[0], ["python", "case.py"],
                   {"case.py": fz._script(body), "in.toml": b"x = 1\n"}, id="t", **kw)
    return fz.run_case(case, tmp_path / "work", timeout=8.0, mem_gib=2.0)


@pytest.mark.parametrize("body,kw,want", [
    ("out({'a': 1})", {}, "ok"),
    ("raise UserError('bad value', field='x')", {}, "user-error"),
    ("raise KeyError('boom')", {}, "traceback"),
    ("open('in.toml', 'w').write('')", {}, "data-loss"),
    ("open('.out.tmp.mcap', 'w').write('')", {}, "half-written"),
    ("open('o.mcap', 'wb').write(b'\\x89MCAP0\\r\\n' + bytes(100))", {"outputs": ["o.mcap"]}, "half-written"),
    ("open('o.toml', 'w').write('x = ')", {"outputs": ["o.toml"]}, "half-written"),
    ("import time\ntime.sleep(60)", {}, "hang"),
    ("np.ones(2**31)", {}, "killed-memory"),
    ("import os, signal\nos.kill(os.getpid(), signal.SIGSEGV)", {}, "crash"),
    ("print('note: x', file=sys.stderr)\nprint('second', file=sys.stderr)\nsys.exit(2)", {}, "messy-error"),
    ("out({'success': True, 'final_goal_dist_m': 1.6, 'time_s': 3.0, 'sim_time_s': 3.0})",
     {"expect": {"kind": "run", "d0": 3.0}}, "false-result"),
    ("out({'success': False, 'final_goal_dist_m': 3.0, 'time_s': 2.0, 'sim_time_s': 2.0, 'warnings': {}})",
     {"expect": {"kind": "run", "d0": 3.0}}, "false-result"),
])
def test_the_classifier_catches_each_class(tmp_path, body, kw, want):
    rec = _py(tmp_path, body, **kw)
    assert rec["class"] == want, rec
    if want not in ("ok", "user-error"):           # a reproducer: the inputs and the exact command
        repro = Path(rec["repro"])
        assert (repro / "cmd.sh").is_file() and (repro / "case.py").is_file()
