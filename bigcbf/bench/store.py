"""The results database: SQLite in WAL mode, one row per episode, written by the bench's parent process only.

Table ``episodes`` is keyed by (scenario, method, seed, params_hash, scenario_sha). Each row is committed as soon
as its episode ends, so a killed run loses at most the episodes that were still running. A row has status
``ok`` (``metrics`` holds the episode's metrics as JSON) or ``error`` (``error`` holds the message). On a rerun,
``ok`` rows are kept and their episodes skipped; ``error`` rows are run again and replaced (``attempts`` counts
the tries). Tables ``params`` and ``scenarios`` keep the parameter TOML and scenario file behind each hash, so the
database describes itself.
"""
from __future__ import annotations

import json
import sqlite3
from datetime import datetime, timezone
from pathlib import Path
from typing import Iterable

from ..errors import UserError

SCHEMA_VERSION = "1"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS episodes (
    scenario TEXT NOT NULL,
    method TEXT NOT NULL,
    seed INTEGER NOT NULL,
    params_hash TEXT NOT NULL,
    scenario_sha TEXT NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('ok', 'error')),
    error TEXT,
    metrics TEXT,
    worker_wall_s REAL,
    host TEXT,
    pid INTEGER,
    code_sha TEXT,
    finished_utc TEXT NOT NULL,
    attempts INTEGER NOT NULL DEFAULT 1,
    PRIMARY KEY (scenario, method, seed, params_hash, scenario_sha)
);
CREATE TABLE IF NOT EXISTS params (params_hash TEXT PRIMARY KEY, perception TEXT NOT NULL, toml TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS scenarios (scenario_sha TEXT PRIMARY KEY, name TEXT NOT NULL, toml TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS runs (
    started_utc TEXT NOT NULL,
    params_hash TEXT NOT NULL,
    engine TEXT NOT NULL,
    workers TEXT,
    host TEXT,
    episodes_run INTEGER NOT NULL,
    errors INTEGER NOT NULL,
    wall_time_s REAL NOT NULL,
    completed INTEGER NOT NULL
);
"""

KEY_COLUMNS = ("scenario", "method", "seed", "params_hash", "scenario_sha")
ROW_COLUMNS = KEY_COLUMNS + ("status", "error", "metrics", "worker_wall_s", "host", "pid", "code_sha",
                             "finished_utc", "attempts")


def _environment_error(path: Path, exc: sqlite3.Error, fresh: bool = False) -> UserError:
    """An SQLite error caused by the disk or the file system (full, read-only, I/O) as one line."""
    what = "create" if fresh else "write"
    return UserError(f"cannot {what} the results database ({exc}); the episodes already in it are kept: free space "
                     "(or fix the file system) and rerun the same command to resume", file=str(path))


class ResultStore:
    """The episodes table of one bench directory. Not shared between processes: only the parent writes."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        if self.path.is_dir():
            raise UserError("expected an SQLite database file, found a directory", file=str(self.path))
        fresh = not self.path.exists() or self.path.stat().st_size == 0
        try:
            self.db = sqlite3.connect(self.path, timeout=30.0)
            if not fresh and self.db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'meta'"
                                             ).fetchone() is None:
                self.db.close()               # another program's database: never add our tables to it
                raise UserError("not a bigcbf results database (an SQLite file without its tables); use a new --out",
                                file=str(self.path))
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=NORMAL")   # WAL + NORMAL: a committed row survives a killed process
            self.db.executescript(_SCHEMA)
            cols = {r[1] for r in self.db.execute("PRAGMA table_info(episodes)")}
            if "code_sha" not in cols:      # databases written before rows carried the code version
                self.db.execute("ALTER TABLE episodes ADD COLUMN code_sha TEXT")
                self.db.commit()
            version = self.db.execute("SELECT value FROM meta WHERE key='schema'").fetchone()
            if version is None:
                self.db.execute("INSERT INTO meta VALUES ('schema', ?)", (SCHEMA_VERSION,))
                self.db.commit()
            elif version[0] != SCHEMA_VERSION:
                raise UserError(f"results schema {version[0]}, this bigcbf writes {SCHEMA_VERSION}; use a new --out",
                                file=str(self.path))
        except sqlite3.OperationalError as exc:       # the disk or the file system, not the file's content
            raise _environment_error(self.path, exc, fresh) from None
        except sqlite3.DatabaseError as exc:
            raise UserError(f"not a bigcbf results database ({exc})", file=str(self.path)) from None

    def close(self) -> None:
        self.db.close()

    def _write(self, sql: str, values: tuple) -> None:
        """Execute one write and commit it; a full disk or a read-only file system is a UserError."""
        try:
            self.db.execute(sql, values)
            self.db.commit()
        except sqlite3.OperationalError as exc:
            raise _environment_error(self.path, exc) from None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # --- descriptions behind the hashes ---------------------------------------------------------------------
    def add_params(self, params_hash: str, perception: str, toml: str) -> None:
        self._write("INSERT OR IGNORE INTO params VALUES (?, ?, ?)", (params_hash, perception, toml))

    def add_scenario(self, scenario_sha: str, name: str, toml: str) -> None:
        self._write("INSERT OR IGNORE INTO scenarios VALUES (?, ?, ?)", (scenario_sha, name, toml))

    def add_run(self, *, started_utc: str, params_hash: str, engine: str, workers, host: str, episodes_run: int,
                errors: int, wall_time_s: float, completed: bool) -> None:
        """Record one invocation that ran episodes (for the rate over a resumed bench)."""
        self._write("INSERT INTO runs VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (started_utc, params_hash, engine, str(workers), host, episodes_run, errors, wall_time_s,
                     int(completed)))

    def runs(self, params_hash: str | None = None) -> list[dict]:
        cols = ("started_utc", "params_hash", "engine", "workers", "host", "episodes_run", "errors", "wall_time_s",
                "completed")
        cur = self.db.execute(f"SELECT {', '.join(cols)} FROM runs ORDER BY started_utc")
        out = [dict(zip(cols, r)) for r in cur]
        return out if params_hash is None else [r for r in out if r["params_hash"] == params_hash]

    # --- episodes ------------------------------------------------------------------------------------------
    def put(self, row: dict) -> None:
        """Insert or replace one episode's row and commit. An ``ok`` row is never replaced."""
        values = (row["scenario"], row["method"], int(row["seed"]), row["params_hash"], row["scenario_sha"],
                  row["status"], row.get("error"),
                  None if row.get("metrics") is None else json.dumps(row["metrics"], allow_nan=True),
                  row.get("worker_wall_s"), row.get("host"), row.get("pid"), row.get("code_sha"),
                  datetime.now(timezone.utc).isoformat(timespec="seconds"))
        self._write(
            "INSERT INTO episodes (scenario, method, seed, params_hash, scenario_sha, status, error, metrics, "
            "worker_wall_s, host, pid, code_sha, finished_utc) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) "
            "ON CONFLICT (scenario, method, seed, params_hash, scenario_sha) DO UPDATE SET "
            "status=excluded.status, error=excluded.error, metrics=excluded.metrics, "
            "worker_wall_s=excluded.worker_wall_s, host=excluded.host, pid=excluded.pid, code_sha=excluded.code_sha, "
            "finished_utc=excluded.finished_utc, attempts=episodes.attempts + 1 "
            "WHERE episodes.status != 'ok'", values)

    def ok_keys(self) -> set[tuple]:
        """Keys of the episodes that finished without error (these are not run again)."""
        cur = self.db.execute(f"SELECT {', '.join(KEY_COLUMNS)} FROM episodes WHERE status = 'ok'")
        return {tuple(r) for r in cur}

    def rows(self, keys: Iterable[tuple] | None = None) -> list[dict]:
        """Rows as dicts (``metrics`` decoded), all of them or those with the given keys, in the keys' order."""
        cur = self.db.execute(f"SELECT {', '.join(ROW_COLUMNS)} FROM episodes")
        by_key = {}
        for r in cur:
            d = dict(zip(ROW_COLUMNS, r))
            d["metrics"] = None if d["metrics"] is None else json.loads(d["metrics"])
            by_key[tuple(d[k] for k in KEY_COLUMNS)] = d
        if keys is None:
            return list(by_key.values())
        return [by_key[k] for k in keys if k in by_key]

    def count(self) -> int:
        return self.db.execute("SELECT COUNT(*) FROM episodes").fetchone()[0]
