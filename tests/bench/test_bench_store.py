"""The results database and the episode task (hashes, error rows, pickling)."""
from __future__ import annotations

import dataclasses
import os
import pickle
import sqlite3
import subprocess
import sys

import pytest

from bigcbf.bench.store import ResultStore
from bigcbf.bench.tasks import EpisodeTask, guarded, params_key, params_toml
from bigcbf.errors import UserError
from bigcbf.params.stack import SIMULATION


def ok_row(seed, **kw):
    r = dict(scenario="a", method="big-cbf", seed=seed, params_hash="p", scenario_sha="s", status="ok", error=None,
             metrics={"success": True, "e_cbf": 0.1 * seed, "min_clearance_m": float("inf")}, worker_wall_s=1.0,
             host="h", pid=1)
    r.update(kw)
    return r


def test_store_roundtrip_wal_and_upsert(tmp_path):
    path = tmp_path / "results.sqlite"
    with ResultStore(path) as st:
        assert st.db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        st.put(ok_row(0))
        st.put(ok_row(1, status="error", error="RuntimeError: x", metrics=None))
        assert st.ok_keys() == {("a", "big-cbf", 0, "p", "s")}
        st.put(ok_row(1))                                   # the retry of the error replaces it
        st.put(ok_row(0, status="error", error="late", metrics=None))   # an ok row is never replaced
    with ResultStore(path) as st:                           # reopened: everything was committed
        rows = {r["seed"]: r for r in st.rows()}
        assert st.count() == 2
    assert rows[0]["status"] == "ok" and rows[0]["attempts"] == 1 and rows[0]["error"] is None
    assert rows[1]["status"] == "ok" and rows[1]["attempts"] == 2
    assert rows[1]["metrics"]["e_cbf"] == 0.1 and rows[1]["metrics"]["min_clearance_m"] == float("inf")
    with ResultStore(path) as st:
        keys = [("a", "big-cbf", 1, "p", "s"), ("zz", "big-cbf", 0, "p", "s"), ("a", "big-cbf", 0, "p", "s")]
        assert [r["seed"] for r in st.rows(keys)] == [1, 0]   # in the keys' order, unknown keys left out


def test_store_rejects_bad_files(tmp_path):
    bad = tmp_path / "results.sqlite"
    bad.write_text("this is not a database " * 100)
    with pytest.raises(UserError, match="results.sqlite"):
        ResultStore(bad)
    with pytest.raises(UserError, match="directory"):
        ResultStore(tmp_path)
    other = tmp_path / "other.sqlite"
    with ResultStore(other):
        pass
    con = sqlite3.connect(other)
    con.execute("UPDATE meta SET value='0' WHERE key='schema'")
    con.commit()
    con.close()
    with pytest.raises(UserError, match="schema"):
        ResultStore(other)


def test_params_hash_stable_and_sensitive():
    text = params_toml(SIMULATION)
    h = params_key(text, "lidar")
    assert h == params_key(params_toml(dataclasses.replace(SIMULATION)), "lidar")
    assert h != params_key(params_toml(dataclasses.replace(SIMULATION, alpha_per_s=1.6)), "lidar")
    assert h != params_key(text, "truth")
    # the same in another interpreter with another string-hash seed
    code = ("from bigcbf.bench.tasks import params_key, params_toml; from bigcbf.params.stack import SIMULATION;"
            "print(params_key(params_toml(SIMULATION), 'lidar'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONHASHSEED": "12345"}).stdout.strip()
    assert out == h


def _task(seed=0, method="cbf-only"):
    t = params_toml(SIMULATION)
    return EpisodeTask("a", "s", "name = 'a'\n", method, seed, params_key(t, "lidar"), t)


def _boom(task):
    raise ValueError(f"bad seed {task.seed}")


def test_guarded_records_exceptions_and_tasks_pickle():
    row = guarded(_boom, _task(3))
    assert row["status"] == "error" and row["metrics"] is None
    assert row["error"].startswith("ValueError: bad seed 3 (at test_bench_store.py:")
    assert (row["scenario"], row["method"], row["seed"]) == ("a", "cbf-only", 3)
    row = guarded(lambda task: {"x": 1}, _task())
    assert row["status"] == "ok" and row["metrics"] == {"x": 1} and row["error"] is None
    t = _task()
    assert pickle.loads(pickle.dumps(t)) == t
