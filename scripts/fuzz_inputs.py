#!/usr/bin/env python3
"""Property-based fuzzer over every user input that runs the REAL commands to completion (issue 21, item 5).

Unlike tests/test_fuzz_inputs.py (which stops each command at its work), every case here is a subprocess that runs
the real episode, bench worker, recording, calibration, replay, profile, scenario generator, Python API or
Gymnasium environment to its end, in its own folder, under a wall-clock limit (``--timeout``, default 120 s) and an
address-space limit (``--mem-gib``, RLIMIT_AS, default 4 GiB; a normal run needs under 2 GiB).

Generator families (the classes of issue 21; ``--list-families``): scenario, config, robot_profile, stack_profile,
log, cli, paths (security / data loss), bounds (no size bounds), api, gym, planner, false_result. Inputs are small
(episodes of 1-4 s in 5 m worlds, 5-10 s logs) so that a case takes a few seconds.

Each case is classified (most serious first):

  data-loss      an input file (or a shipped profile/scenario of the package) changed or vanished
  traceback      "Traceback" on stderr, or an exit status other than 0/1/2 with no signal
  killed-memory  a MemoryError / failed allocation under the address-space limit (no size bound)
  crash          ended by a signal (segfault, abort)
  hang           still running after the wall limit (killed)
  half-written   a temporary file (.NAME.tmp*) left behind, or an output that exists but does not parse/decode
                 (MP4 that ffmpeg cannot decode, MCAP without its footer magic, TOML/JSON/CSV/SQLite/PNG invalid)
  worker-error   a bench episode recorded as an error row (a crash inside the bench worker, kept in the table)
  false-result   exit 0 with a result to review: success far from the goal or at t < 0.5 s, a robot that never moved
                 without a warning, a silently blind LiDAR driving into a post, a non-finite number in --json, an
                 out-of-order log calibrated without a warning, ...
  messy-error    a refusal that is not one line (exit 2 with extra lines, or exit 1 without a traceback)
  user-error     exit 2, the last stderr line ``PROG: error: ...`` and only ``note:`` lines before it
  ok             exit 0, nothing to flag

Output (``--out DIR``): report.jsonl (one object per case), summary.md / summary.json (counts per class and per
family, distinct failure signatures) and, for every case that is neither ok nor user-error, repro/CASE/ with the
case's input files, cmd.sh (the exact command, run from that folder), stdout.txt and stderr.txt.

    python scripts/fuzz_inputs.py --n 1000 --seed 0 --jobs 2 --timeout 120 --out fuzz-out
    python scripts/fuzz_inputs.py --sample --out /tmp/fz      # the fixed case table tests/test_fuzz_real.py runs
"""
from __future__ import annotations

import argparse
import copy
import csv
import hashlib
import io
import json
import math
import os
import random
import re
import resource
import shlex
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
import tomllib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PY = str(ROOT / ".venv" / "bin" / "python") if (ROOT / ".venv" / "bin" / "python").exists() else sys.executable
BIGCBF = str(Path(PY).parent / "bigcbf")
EPS_G_DEFAULT = 0.15            # StackParams.eps_g_m
CLASSES = ["data-loss", "traceback", "killed-memory", "crash", "hang", "half-written", "worker-error",
           "false-result", "messy-error", "user-error", "ok"]
FAMILIES = ["scenario", "config", "robot_profile", "stack_profile", "log", "cli", "paths", "bounds", "api", "gym",
            "planner", "false_result"]
#: package files no command may change unless told to (profile simulate without --out writes the shipped profile)
GUARDED = [ROOT / "bigcbf" / "profiles", ROOT / "bigcbf" / "scenarios", ROOT / "scenarios"]
#: the code under test: the checkout (default) or a snapshot (--code DIR, e.g. `git archive HEAD | tar -x -C DIR`),
#: put first on PYTHONPATH so that a half-edited file in a shared checkout does not count as a finding
CODE: Path | None = None


# --- a case ------------------------------------------------------------------------------------------------------

@dataclass
class Case:
    family: str
    name: str
    argv: list[str]                                    # "bigcbf ..." or "python FILE"; paths relative to the folder
    files: dict[str, bytes] = field(default_factory=dict)        # inputs written into the case folder
    links: dict[str, str] = field(default_factory=dict)          # symbolic links: name -> target
    outputs: list[str] = field(default_factory=list)             # what the command may write (validated)
    expect: dict = field(default_factory=dict)                   # facts for the false-result checks
    id: str = ""


def toml_dumps(doc: dict) -> bytes | None:
    import tomli_w
    try:
        return tomli_w.dumps(doc).encode()
    except (TypeError, ValueError):
        return None


# --- generators ----------------------------------------------------------------------------------------------------

WEIRD = [math.nan, math.inf, -math.inf, 1e308, -1e308, 1e300, -1.0, 0.0, 1e-300, 1e-9, 2**63, -2**63, 10**30, 10**9,
         100000, True, "x", "", "\u00e9", [], {}, [[]], [1, 2, 3], {"uniform": [1, 0]}, {"choice": []},
         {"uniform": [math.nan, 1]}, {"choice": [1, "a"]}, 0.5, 2.0, 7, 250.1, 1000]


def weird(rng: random.Random):
    r = rng.random()
    if r < 0.55:
        return copy.deepcopy(rng.choice(WEIRD))
    if r < 0.75:
        return rng.choice([rng.uniform(-10, 10), rng.uniform(0, 1), 10 ** rng.uniform(-12, 12)])
    if r < 0.85:
        return rng.randint(-10**6, 10**6)
    if r < 0.95:
        return [rng.uniform(-5, 5) for _ in range(rng.randint(0, 4))]
    return "".join(rng.choice("ab/\\.\x01\n\u00e9 ") for _ in range(rng.randint(0, 6)))


def _leaves(node, path=()):
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _leaves(v, path + (k,))
    elif isinstance(node, list) and node and not all(isinstance(x, (int, float)) for x in node):
        for i, v in enumerate(node):
            yield from _leaves(v, path + (i,))
    yield path


def _parent(doc, path):
    for k in path[:-1]:
        doc = doc[k]
    return doc


def mutate(rng: random.Random, base: dict, n: int | None = None, scale=(2, 50, 300)) -> tuple[dict, list[str]]:
    """``base`` with 1-3 edits: a leaf set to a weird value, a key removed or added, a list multiplied."""
    doc, edits = copy.deepcopy(base), []
    for _ in range(n or rng.randint(1, 3)):
        paths = [p for p in _leaves(doc) if p]
        if not paths:
            doc["x"] = weird(rng)
            continue
        path = rng.choice(paths)
        op = rng.choice(["set", "set", "set", "delete", "add", "grow"])
        par = _parent(doc, path)
        if op == "set":
            par[path[-1]] = weird(rng)
        elif op == "delete":
            del par[path[-1]]
        elif op == "add" and isinstance(par, dict):
            par[rng.choice(["x", "radius", "seed", "file", "name", "waypoints", "Name"])] = weird(rng)
        elif op == "grow" and isinstance(par[path[-1]], list) and par[path[-1]]:
            par[path[-1]] = par[path[-1]] * rng.choice(scale)
        else:
            par[path[-1]] = weird(rng)
        edits.append(f"{op} {'.'.join(map(str, path))}")
    return doc, edits


def base_scenario(rng: random.Random, *, peds=True) -> dict:
    doc = {"name": "fz", "description": "fuzz", "time_limit_s": float(rng.choice([1, 2, 3, 4])), "extent_m": 5.0,
           "robot": {"start": [0.0, 0.0, 0.0], "goal": [3.0, 0.0]},
           "walls": [{"start": [-1.0, 1.5], "end": [5.0, 1.5]}],
           "cylinders": [{"center": [1.8, 0.7], "radius_m": {"uniform": [0.15, 0.3]}}]}
    if rng.random() < 0.4:
        doc["boxes"] = [{"center": [2.0, -0.9], "half_size": [0.3, 0.2], "yaw_rad": 0.3}]
    if peds and rng.random() < 0.6:
        doc["pedestrians"] = [{"name": "a", "waypoints": [[2.5, -2.5], [2.5, 2.5]],
                               "speed_mps": {"uniform": [0.8, 1.2]}, "start_time_s": 0.5}]
    if rng.random() < 0.3:
        doc["floor_patches"] = [{"center": [1.0, 0.0], "half_size": [0.5, 0.5], "friction": 0.4}]
    if rng.random() < 0.3:
        doc["robot_profile"] = {"latency_s": 0.05,
                                "faults": {"scan_dropout": {"times_s": [0.5], "rate_per_s": 1.0, "duration_s": 0.1}}}
    return doc


def robot_base() -> dict:
    return {"latency_s": 0.05, "latency_jitter_s": 0.01, "gain": [[0.9, 0, 0], [0, 0.9, 0], [0, 0, 1.0]],
            "bias": [0.01, 0.0, 0.0], "residual_max": [0.02, 0.02, 0.05], "residual_hold_s": 0.05,
            "floor_friction": 0.8,
            "lidar": {"n_beams": 360, "rate_hz": 10.0, "range_min_m": 0.12, "range_max_m": 8.0},
            "odometry": {"encoder_counts_per_rev": 1320, "scale_error": 0.05},
            "imu": {"gyro_noise_density_radps_rthz": 1e-3},
            "faults": {"latency_spikes": {"times_s": [0.5], "rate_per_s": 1.0, "duration_s": 0.1}}}


_STACK = None


def stack_base() -> dict:
    global _STACK
    if _STACK is None:
        out = subprocess.run([PY, "-c", "import json; from bigcbf.params.stack import SIMULATION; "
                              "from bigcbf.params.toml_io import to_dict; print(json.dumps(to_dict(SIMULATION)))"],
                             capture_output=True, text=True, check=True, cwd=ROOT, env=_env(ROOT))
        _STACK = json.loads(out.stdout)
    return copy.deepcopy(_STACK)


METHODS = ["big-cbf", "cbf-only", "big-cbf-noshared", "backup-cbf", "pl-cbf", "apf", "dwa", "mppi"]
METHOD_TABLES = {"backup-cbf": {"a_brake_mps2": 2.0, "margin_m": 0.0, "blends": [0.0, 0.5, 1.0]},
                 "pl-cbf": {"n_dir": 8, "v_dir_mps": 0.5, "t_move_s": 1.0, "a_max_mps2": 2.0, "margin_m": 0.0},
                 "apf": {"k_att_per_s": 1.0, "d_conic_m": 0.8, "rho0_m": 0.6, "lookahead_s": 0.0},
                 "dwa": {"acc_xy_mps2": 2.0, "window_s": 0.25, "n_xy": 9, "n_wz": 1, "w_heading": 1.0},
                 "mppi": {"samples": 512, "iterations": 2, "sigma_mps": 0.35, "gamma": 0.1, "ess_fraction": 0.1}}
SCEN_OK = 'name = "fz"\ndescription = "fuzz"\ntime_limit_s = 2\nextent_m = 5\n[robot]\nstart = [0, 0, 0]\n' \
          'goal = [3, 0]\n[[cylinders]]\ncenter = [1.6, 0.7]\nradius_m = 0.2\n'
SCEN_PED = SCEN_OK + '[[pedestrians]]\nname = "a"\nwaypoints = [[2.5, -2.5], [2.5, 2.5]]\nspeed_mps = 1\n'
SCEN_POST = 'name = "post"\ndescription = "a post on the way"\ntime_limit_s = 4\nextent_m = 5\n[robot]\n' \
            'start = [0, 0, 0]\ngoal = [3, 0]\n[[cylinders]]\ncenter = [1.2, 0]\nradius_m = 0.2\n'
NUMS = ["-1", "0", "1", "2", "1.5", "nan", "inf", "-inf", "1e400", "9" * 25, "0x10", "", " ", "1e-9", "1e-300",
        "600", "601", "100000000", "\u00e9", "4294967295", "4294967296", "3", "5", "10"]


def _run_cmd(rng, scen="s.toml", tl=True) -> list[str]:
    argv = ["bigcbf", "run", scen, "--json", "--method", rng.choice(METHODS[:3] + METHODS[:8]),
            "--seed", str(rng.randint(0, 5))]
    if tl:
        argv += ["--time-limit", str(rng.choice([1, 2, 3]))]
    return argv


def _maybe_outputs(rng, argv: list[str], outs: list[str], video=0.15, log=0.2) -> None:
    if rng.random() < video:
        argv += ["--video", "out.mp4"]
        outs.append("out.mp4")
    if rng.random() < log:
        argv += ["--log", "out.mcap"]
        outs.append("out.mcap")


def _scen_expect(doc: dict) -> dict:
    try:
        s, g = doc["robot"]["start"], doc["robot"]["goal"]
        d0 = math.hypot(float(g[0]) - float(s[0]), float(g[1]) - float(s[1]))
        return {"kind": "run", "d0": d0} if math.isfinite(d0) else {"kind": "run"}
    except Exception:   # noqa: BLE001 - a mutated document: no expectation
        return {"kind": "run"}


def gen_scenario(rng: random.Random) -> Case:
    doc, edits = mutate(rng, base_scenario(rng))
    text = toml_dumps(doc) or SCEN_OK.encode()
    argv, outs = _run_cmd(rng, tl=rng.random() < 0.5), []
    _maybe_outputs(rng, argv, outs)
    if rng.random() < 0.15:       # the same scenario through a one-episode bench (the bench worker)
        argv = ["bigcbf", "bench", "--out", "bench", "--scenarios", "s.toml", "--methods", rng.choice(METHODS),
                "--seeds", "1", "--workers", "1", "--progress", "off"]
        outs = ["bench"]
    return Case("scenario", "; ".join(edits), argv, {"s.toml": text}, outputs=outs, expect=_scen_expect(doc))


def gen_config(rng: random.Random) -> Case:
    method = rng.choice(METHODS)
    doc: dict = {}
    st = stack_base()
    doc["stack"] = {k: st[k] for k in rng.sample(sorted(k for k in st if not isinstance(st[k], dict)), 3)}
    if rng.random() < 0.5:
        doc["perception"] = {"gate_chi2": 9.21, "max_tracks": 8, "min_points": 3, "coast_s": 1.0}
    if rng.random() < 0.5:
        doc["pedestrians"] = {"A_robot_mps2": 1.0}
    if method in METHOD_TABLES:
        doc["methods"] = {method: dict(METHOD_TABLES[method])}
    doc, edits = mutate(rng, doc, scale=(2, 50))
    text = toml_dumps(doc) or b"[stack]\n"
    argv = ["bigcbf", "run", "s.toml", "--json", "--method", method, "--config", "c.toml", "--time-limit",
            str(rng.choice([1, 2]))]
    return Case("config", f"{method}: " + "; ".join(edits), argv, {"s.toml": SCEN_PED.encode(), "c.toml": text},
                expect={"kind": "run", "d0": 3.0})


def gen_robot_profile(rng: random.Random) -> Case:
    doc, edits = mutate(rng, robot_base())
    text = toml_dumps(doc) or b""
    r = rng.random()
    if r < 0.5:
        argv, outs, exp = _run_cmd(rng) + ["--robot-profile", "r.toml"], [], {"kind": "run", "d0": 3.0}
    elif r < 0.8:
        argv = ["bigcbf", "record", "calibration", "--robot-profile", "r.toml", "--out", "o.mcap", "--duration", "5",
                "--json", "--seed", str(rng.randint(0, 3))]
        outs, exp = ["o.mcap"], {"kind": "record"}
    else:
        argv = ["bigcbf", "profile", "simulate", "--robot-profile", "r.toml", "--out", "p.toml", "--duration", "5",
                "--json"]
        outs, exp = ["p.toml"], {"kind": "profile"}
    return Case("robot_profile", "; ".join(edits), argv, {"s.toml": SCEN_OK.encode(), "r.toml": text},
                outputs=outs, expect=exp)


def gen_stack_profile(rng: random.Random) -> Case:
    base = stack_base()
    doc, edits = mutate(rng, base, scale=(2, 50))
    text = toml_dumps(doc) or b""
    if rng.random() < 0.75:
        argv, exp = _run_cmd(rng) + ["--profile", "p.toml"], {"kind": "run", "d0": 3.0}
        files = {"s.toml": SCEN_PED.encode(), "p.toml": text}
    else:
        argv, exp = ["bigcbf", "replay", "drive.mcap", "--json", "--profile", "p.toml"], {"kind": "replay"}
        files = {"p.toml": text, "drive.mcap": BASE["drive.mcap"]}
    return Case("stack_profile", "; ".join(edits), argv, files, expect=exp)


# logs: a recorded calibration drive, mutated

def _mcap_messages(data: bytes):
    from mcap.reader import make_reader
    r = make_reader(io.BytesIO(data))
    s = r.get_summary()
    msgs = [(ch.topic, m.log_time, m.publish_time, m.data) for _, ch, m in r.iter_messages(log_time_order=True)]
    return s, msgs


def _mcap_write(summary, msgs) -> bytes:
    from mcap.writer import Writer
    buf = io.BytesIO()
    w = Writer(buf)
    w.start(profile="ros2", library="fuzz")
    sids = {k: w.register_schema(name=v.name, encoding=v.encoding, data=v.data) for k, v in summary.schemas.items()}
    chans = {}
    for ch in summary.channels.values():
        chans[ch.topic] = w.register_channel(topic=ch.topic, message_encoding=ch.message_encoding,
                                             schema_id=sids[ch.schema_id], metadata=dict(ch.metadata))
    for seq, (topic, lt, pt, data) in enumerate(msgs):
        w.add_message(channel_id=chans[topic], log_time=lt, data=data, publish_time=pt, sequence=seq)
    w.finish()
    return buf.getvalue()


def mutate_log(rng: random.Random, data: bytes) -> tuple[bytes, str, dict]:
    kind = rng.choice(["truncate", "corrupt", "reorder", "drop", "shift", "dup_times", "short", "empty", "reverse"])
    exp: dict = {}
    if kind == "truncate":
        cut = int(len(data) * rng.uniform(0.05, 0.999))
        return data[:cut], f"truncate at {cut}/{len(data)}", {"truncated": True}
    if kind == "corrupt":
        b = bytearray(data)
        n = rng.choice([1, 8, 64])
        for _ in range(n):
            i = rng.randrange(16, len(b) - 16)
            b[i] = rng.randrange(256)
        return bytes(b), f"corrupt {n} bytes", {}
    summary, msgs = _mcap_messages(data)
    topics = sorted({t for t, *_ in msgs})
    if kind == "reorder":
        topic = rng.choice(["/cmd_vel", "/odom", "/scan"])
        idx = [i for i, m in enumerate(msgs) if m[0] == topic]
        times = [msgs[i][1] for i in idx]
        k = rng.randint(2, max(2, len(idx) // 4))
        for _ in range(k):                   # swap the log times of random pairs of this topic's messages
            a, b = rng.sample(range(len(times)), 2)
            times[a], times[b] = times[b], times[a]
        for i, t in zip(idx, times):
            msgs[i] = (msgs[i][0], t, t, msgs[i][3])
        desc, exp = f"reorder {k} pairs of {topic} times", {"reordered": True, "topic": topic}
    elif kind == "reverse":
        topic = rng.choice(["/cmd_vel", "/odom"])
        idx = [i for i, m in enumerate(msgs) if m[0] == topic]
        times = [msgs[i][1] for i in idx][::-1]
        for i, t in zip(idx, times):
            msgs[i] = (msgs[i][0], t, t, msgs[i][3])
        desc, exp = f"reverse the times of {topic}", {"reordered": True, "topic": topic}
    elif kind == "drop":
        drop = rng.sample(topics, rng.randint(1, 3))
        msgs = [m for m in msgs if m[0] not in drop]
        desc = f"drop {drop}"
    elif kind == "shift":
        off = rng.choice([-10**9, 10**18, 2**63 - 1])
        topic = rng.choice(topics)
        msgs = [(t, max(0, min(2**64 - 1, lt + off)) if t == topic else lt,
                 max(0, min(2**64 - 1, pt + off)) if t == topic else pt, d) for t, lt, pt, d in msgs]
        desc = f"shift {topic} by {off} ns"
    elif kind == "dup_times":
        t0 = msgs[0][1]
        msgs = [(t, t0, t0, d) for t, _, _, d in msgs]
        desc, exp = "every message at one time", {"reordered": True}
    elif kind == "short":
        t0 = msgs[0][1]
        dur = rng.choice([0.05, 0.5, 2.0])
        msgs = [m for m in msgs if m[1] - t0 <= dur * 1e9]
        desc = f"only the first {dur} s"
    else:
        msgs, desc = [], "no messages"
    return _mcap_write(summary, msgs), desc, exp


def gen_log(rng: random.Random) -> Case:
    data, desc, exp = mutate_log(rng, BASE["drive.mcap"])
    outs: list[str] = []
    if rng.random() < 0.6:
        argv = ["bigcbf", "calibrate", "log.mcap", "--json"]
        if rng.random() < 0.4:
            argv += ["--out", "p.toml"]
            outs.append("p.toml")
        if rng.random() < 0.15:
            argv += ["--report", "rep"]
            outs.append("rep")
        if rng.random() < 0.2:
            argv += ["--scan-clock", rng.choice(["auto", "stamps", "log"])]
        if rng.random() < 0.15:
            argv += ["--no-scan"]
        exp["kind"] = "calibrate"
    else:
        argv = ["bigcbf", "replay", "log.mcap", "--json"]
        if rng.random() < 0.3:
            argv += ["--window", rng.choice(["5", "1", "0.5", "20"])]
        if rng.random() < 0.15:
            argv += ["--video", "r.mp4"]
            outs.append("r.mp4")
        if rng.random() < 0.25:
            argv += ["--save-robot-profile", "rp.toml"]
            outs.append("rp.toml")
        exp["kind"] = "replay"
    return Case("log", desc, argv, {"log.mcap": data}, outputs=outs, expect=exp)


def gen_cli(rng: random.Random) -> Case:
    cmd = rng.choice(["run", "run", "bench", "record", "calibrate", "replay", "profile", "generate"])
    num = lambda: rng.choice(NUMS)   # noqa: E731
    files = {"s.toml": SCEN_PED.encode()}
    outs: list[str] = []
    exp: dict = {}
    if cmd == "run":
        argv = ["bigcbf", "run", rng.choice(["s.toml", "single_person_crossing", "nope", "", "s"]), "--json",
                "--time-limit", rng.choice(["1", "2", "3"] + NUMS[:8])]
        for opt, vals in (("--seed", NUMS), ("--method", METHODS + ["teleport", "", "os:system"]),
                          ("--perception", ["lidar", "truth", "x"]), ("--camera", ["top", "track", "x"])):
            if rng.random() < 0.5:
                argv += [opt, rng.choice(vals)]
        _maybe_outputs(rng, argv, outs, 0.1, 0.15)
        exp = {"kind": "run", "d0": 3.0} if argv[2] == "s.toml" else {"kind": "run"}
    elif cmd == "bench":
        argv = ["bigcbf", "bench", "--out", rng.choice(["b", "b", "b/c", "."]), "--scenarios", "s.toml",
                "--methods", rng.choice(METHODS), "--progress", rng.choice(["off", "on", "auto"])]
        argv += rng.choice([["--seeds", rng.choice(["1", "1", "0", "-1", "1.5", "nan", "10001"])],
                            ["--seed-list", num()], ["--seed-list", "0", "0"]])
        argv += ["--workers", rng.choice(["1", "1", "1", "0", "-1", "x"])]
        if rng.random() < 0.3:
            argv += ["--perception", rng.choice(["truth", "lidar", "x"])]
        outs = [argv[3]] if argv[3] != "." else []
    elif cmd == "record":
        argv = ["bigcbf", "record", "calibration", "--robot-profile", "r.toml", "--out", "o.mcap", "--json",
                "--duration", rng.choice(["5", "5", "6", "4.99", "0", "nan", "1e9", "-5", "3601"]),
                "--seed", rng.choice(["0", "1", "-1", "1.5", "4294967296"])]
        files["r.toml"] = rng.choice([b"", b"latency_s = 0.05\n", b"latency_s = 0.3\nfloor_friction = 0.5\n"])
        outs, exp = ["o.mcap"], {"kind": "record"}
    elif cmd == "calibrate":
        argv = ["bigcbf", "calibrate", "drive.mcap", "--json"]
        for opt, vals in (("--cmd-timeout", NUMS), ("--coverage", ["0.95", "0", "1", "0.5", "nan", "2", "1e-9"]),
                          ("--scan-clock", ["auto", "stamps", "log", "x"]),
                          ("--cmd-topic", ["/cmd_vel", "/odom", "/nope", ""]),
                          ("--odom-topic", ["/odom", "/ground_truth/odom", "/cmd_vel", "/scan"]),
                          ("--scan-topic", ["/scan", "/odom", "/nope"])):
            if rng.random() < 0.3:
                argv += [opt, rng.choice(vals)]
        files["drive.mcap"] = BASE["drive.mcap"]
        exp = {"kind": "calibrate"}
    elif cmd == "replay":
        argv = ["bigcbf", "replay", "drive.mcap", "--json", "--window", rng.choice(NUMS + ["5", "0.1", "9.9"])]
        if rng.random() < 0.3:
            argv += ["--cmd-topic", rng.choice(["/cmd_vel", "/odom", "/nope"])]
        if rng.random() < 0.3:
            argv += ["--odom-topic", rng.choice(["/odom", "/ground_truth/odom", "/scan"])]
        files["drive.mcap"] = BASE["drive.mcap"]
        exp = {"kind": "replay"}
    elif cmd == "profile":
        argv = ["bigcbf", "profile", "simulate", "--out", "p.toml", "--json",
                "--robot-profile", rng.choice(["x3_sim", "x3_hardware", "r.toml", "nope"]),
                "--duration", rng.choice(["5", "6", "0", "nan", "1e9"]), "--base", rng.choice(["simulation",
                                                                                               "physical", "x"]),
                "--seed", rng.choice(["0", "2", "-1"])]
        if rng.random() < 0.3:
            argv += ["--log", "l.mcap"]
            outs.append("l.mcap")
        files["r.toml"] = b"latency_s = 0.05\n"
        outs.append("p.toml")
        exp = {"kind": "profile"}
    else:
        argv = ["bigcbf", "scenarios", "generate", rng.choice(["posts", "clutter", "corridor", "doorway", "crowd",
                                                              "room", "nope", ""]),
                "--seed", rng.choice(["0", "1", "7", "-1", "4294967296", "1e3", "x"]), "--out", "g.toml"]
        if rng.random() < 0.3:
            argv.append("--force")
        outs = ["g.toml"]
    return Case("cli", " ".join(argv[1:3]), argv, files, outputs=outs, expect=exp)


EVIL_NAMES = ["../../evil", "/tmp/fz-abs-evil", "a/b", "x\x1b[2Jy", "a\nb", "..", ".", "", "results.sqlite",
              "s.toml", "\x00"[0:0] + "nul", "con", "a" * 300]


def gen_paths(rng: random.Random) -> Case:
    """Security / data loss: names that are paths, outputs onto inputs (also through links)."""
    drive = BASE["drive.mcap"]
    choices = [
        ("calibrate --out onto its log", ["bigcbf", "calibrate", "d.mcap", "--out", "d.mcap"], {"d.mcap": drive}),
        ("calibrate --out via a link", ["bigcbf", "calibrate", "d.mcap", "--out", "l.toml"], {"d.mcap": drive},
         {"l.toml": "d.mcap"}),
        ("calibrate --report onto the log's folder", ["bigcbf", "calibrate", "d.mcap", "--report", "."],
         {"d.mcap": drive}),
        ("replay --video onto its log", ["bigcbf", "replay", "d.mcap", "--video", "d.mcap"], {"d.mcap": drive}),
        ("replay --save-robot-profile onto --profile", ["bigcbf", "replay", "d.mcap", "--profile", "p.toml",
                                                        "--save-robot-profile", "p.toml"],
         {"d.mcap": drive, "p.toml": BASE["profile.toml"]}),
        ("record --out onto its robot profile", ["bigcbf", "record", "calibration", "--robot-profile", "r.toml",
                                                 "--out", "r.toml", "--duration", "5"], {"r.toml": b"latency_s = 0.05\n"}),
        ("record --out via a hard-link-like link", ["bigcbf", "record", "calibration", "--robot-profile", "r.toml",
                                                     "--out", "l.mcap", "--duration", "5"],
         {"r.toml": b"latency_s = 0.05\n"}, {"l.mcap": "r.toml"}),
        ("run --log onto the scenario", ["bigcbf", "run", "s.toml", "--log", "s.toml", "--time-limit", "1"],
         {"s.toml": SCEN_OK.encode()}),
        ("run --video onto the scenario", ["bigcbf", "run", "s.toml", "--video", "s.toml", "--time-limit", "1"],
         {"s.toml": SCEN_OK.encode()}),
        ("run --video onto --log", ["bigcbf", "run", "s.toml", "--video", "x.mp4", "--log", "x.mp4",
                                    "--time-limit", "1"], {"s.toml": SCEN_OK.encode()}),
        ("run --log via a link onto the config", ["bigcbf", "run", "s.toml", "--config", "c.toml", "--log",
                                                  "l.mcap", "--time-limit", "1"],
         {"s.toml": SCEN_OK.encode(), "c.toml": b"[stack]\n"}, {"l.mcap": "c.toml"}),
        ("profile simulate --out onto its robot profile", ["bigcbf", "profile", "simulate", "--robot-profile",
                                                           "r.toml", "--out", "r.toml", "--duration", "5"],
         {"r.toml": b"latency_s = 0.05\n"}),
        ("profile simulate --log onto --out", ["bigcbf", "profile", "simulate", "--robot-profile", "x3_sim",
                                               "--out", "p.toml", "--log", "p.toml", "--duration", "5"], {}),
        ("scenarios generate --out onto a scenario --force", ["bigcbf", "scenarios", "generate", "posts", "--out",
                                                              "s.toml", "--force"], {"s.toml": SCEN_OK.encode()}),
        ("bench --out the inputs' folder", ["bigcbf", "bench", "--out", ".", "--scenarios", "s.toml", "--methods",
                                            "cbf-only", "--seeds", "1", "--workers", "1"], {"s.toml": SCEN_OK.encode()}),
        ("bench --docs the scenario", ["bigcbf", "bench", "--out", "b", "--scenarios", "s.toml", "--methods",
                                       "cbf-only", "--seeds", "1", "--workers", "1", "--docs", "s.toml"],
         {"s.toml": SCEN_OK.encode()}),
    ]
    if rng.random() < 0.45:           # an evil scenario / pedestrian name in a run with outputs or a bench
        name = rng.choice(EVIL_NAMES)
        where = rng.choice(["scenario", "pedestrian"])
        doc = tomllib.loads(SCEN_PED)
        if where == "scenario":
            doc["name"] = name
        else:
            doc["pedestrians"][0]["name"] = name
        text = toml_dumps(doc) or SCEN_PED.encode()
        if rng.random() < 0.5:
            argv = ["bigcbf", "bench", "--out", "b", "--scenarios", "s.toml", "--methods", "cbf-only", "--seeds", "1",
                    "--workers", "1", "--progress", "off"]
            outs = ["b"]
        else:
            argv = ["bigcbf", "run", "s.toml", "--json", "--time-limit", "1", "--log", "o.mcap"]
            outs = ["o.mcap"]
        return Case("paths", f"{where} name {name!r}", argv, {"s.toml": text}, outputs=outs,
                    expect={"kind": "bench" if "bench" in argv else "run", "evil": name})
    c = rng.choice(choices)
    return Case("paths", c[0], c[1], c[2], links=c[3] if len(c) > 3 else {},
                outputs=[a for a in c[1] if a.endswith((".mp4", ".mcap", ".toml")) and a not in c[2]])


def gen_bounds(rng: random.Random) -> Case:
    """No size bounds: huge counts and tiny steps."""
    big = rng.choice([10**5, 10**6, 10**9, 10**12])
    options = [
        ("mppi samples", "mppi", "[methods.mppi]\nsamples = %d\n" % big),
        ("mppi iterations", "mppi", "[methods.mppi]\niterations = %d\n" % big),
        ("dwa n_xy", "dwa", "[methods.dwa]\nn_xy = %d\n" % big),
        ("dwa n_wz", "dwa", "[methods.dwa]\nn_wz = %d\n" % big),
        ("pl-cbf n_dir", "pl-cbf", "[methods.pl-cbf]\nn_dir = %d\n" % big),
        ("backup-cbf blends", "backup-cbf", "[methods.backup-cbf]\nblends = [%s]\n" %
         ", ".join(f"{i / 2000:.4f}" for i in range(2001))),
        ("perception max_tracks", "big-cbf", "[perception]\nmax_tracks = %d\n" % big),
        ("perception max_candidates", "big-cbf", "[perception]\nmax_candidates = %d\n" % big),
        ("stack N", "big-cbf", "[stack]\nN = %d\n" % big),
        ("stack dt_s tiny", "big-cbf", "[stack]\ndt_s = 1e-9\n"),
    ]
    r = rng.random()
    if r < 0.4:
        name, method, cfg = rng.choice(options)
        argv = ["bigcbf", "run", "s.toml", "--json", "--method", method, "--config", "c.toml", "--time-limit", "2"]
        return Case("bounds", f"{name} = {big}", argv, {"s.toml": SCEN_PED.encode(), "c.toml": cfg.encode()},
                    expect={"kind": "run", "d0": 3.0})
    if r < 0.6:
        key, val = rng.choice([("n_beams", big), ("rate_hz", rng.choice([251, 1000, 1e6])),
                               ("range_max_m", 1e9), ("range_min_m", 1e-12)])
        prof = f"[lidar]\n{key} = {val}\n".encode()
        argv = ["bigcbf", "run", "s.toml", "--json", "--robot-profile", "r.toml", "--time-limit", "2"]
        return Case("bounds", f"lidar {key} = {val}", argv, {"s.toml": SCEN_OK.encode(), "r.toml": prof},
                    expect={"kind": "run", "d0": 3.0})
    if r < 0.75:
        w = rng.choice(["1e-300", "1e-9", "1e300", "0.001"])
        return Case("bounds", f"replay --window {w}", ["bigcbf", "replay", "d.mcap", "--json", "--window", w],
                    {"d.mcap": BASE["drive.mcap"]}, expect={"kind": "replay"})
    if r < 0.85:
        dev = rng.choice(["/dev/zero", "/dev/urandom", "/dev/stdin", "/proc/self/mem"])
        which = rng.choice(["--config", "--profile", "--robot-profile"])
        return Case("bounds", f"run {which} {dev}", ["bigcbf", "run", "s.toml", which, dev, "--time-limit", "1"],
                    {"s.toml": SCEN_OK.encode()})
    what = rng.choice(["walls", "pedestrians", "time"])
    doc = tomllib.loads(SCEN_OK)
    if what == "walls":
        n = rng.choice([200, 1000, 5000])
        doc["walls"] = [{"start": [-4.0 + 0.008 * i, 4.0], "end": [-4.0 + 0.008 * i, 4.5]} for i in range(n)]
    elif what == "pedestrians":
        n = rng.choice([50, 200, 1000])
        doc["pedestrians"] = [{"name": f"p{i}", "waypoints": [[-4 + 0.3 * (i % 25), 3.0 + 0.3 * (i // 25 % 4)],
                                                              [-4 + 0.3 * (i % 25), 4.0]], "speed_mps": 0.5}
                              for i in range(n)]
    else:
        n = 600
        doc["time_limit_s"] = 600.0
    argv = ["bigcbf", "run", "s.toml", "--json", "--method", "cbf-only"]
    return Case("bounds", f"{n} {what}", argv, {"s.toml": toml_dumps(doc)}, expect={"kind": "run", "d0": 3.0})


API_PRELUDE = """import json, math, sys
import numpy as np
from bigcbf.errors import UserError
def out(o): print(json.dumps(o, default=str))
try:
{body}
except UserError as e:
    print(f"api: error: {{e}}", file=sys.stderr)
    sys.exit(2)
"""


def _script(body: str) -> bytes:
    return API_PRELUDE.format(body="\n".join("    " + ln for ln in body.strip().splitlines())).encode()


SEEDS = ["-1", "None", "1.5", "2**40", "True", "'3'", "np.int64(3)", "np.float64(2.0)", "math.nan", "0", "[1]"]
LIMITS = ["math.nan", "math.inf", "1e9", "-1", "0", "1e-9", "'2'", "2", "None", "True", "np.float32(2)", "1e-300"]


def gen_api(rng: random.Random) -> Case:
    r = rng.random()
    files = {"s.toml": SCEN_PED.encode()}
    if r < 0.55:
        seed, tl = rng.choice(SEEDS), rng.choice(LIMITS[:7] + ["2", "2", "1"])
        method = rng.choice(["'cbf-only'", "'big-cbf'", "'mppi'", "None", "3", "''", "'os:system'"])
        cfg = rng.choice(["None", "None", "'c.toml'", "{}", "'missing.toml'", "b's.toml'"])
        body = f"""import bigcbf
res = bigcbf.run_episode('s.toml', {method}, seed={seed}, time_limit_s={tl}, config={cfg})
out(res.metrics())"""
        files["c.toml"] = b"[stack]\nalpha_per_s = 1.5\n"
        exp = {"kind": "run", "d0": 3.0}
        name = f"run_episode(method={method}, seed={seed}, time_limit_s={tl}, config={cfg})"
    elif r < 0.8:
        kw = rng.choice(["methods=[]", "scenarios=[]", "seeds=[]", "seeds=0", "seeds=[-1]", "seeds=[2**40]",
                         "workers=0", "methods=['cbf-only']", "methods='cbf-only'", "seeds=[0, 0]", "seeds=1.5",
                         "methods=[None]"])
        kws = {"methods": "['cbf-only']", "scenarios": "['s.toml']", "seeds": "1", "workers": "1"}
        k, v = kw.split("=", 1)
        kws[k] = v
        body = f"""import bigcbf
if __name__ == '__main__':
    o = bigcbf.run_bench('b', {', '.join(f'{a}={b}' for a, b in kws.items())})
    out(o.summary['bench'])"""
        exp, name = {"kind": "api-bench"}, f"run_bench({kw})"
        return Case("api", name, ["python", "case.py"], {**files, "case.py": _script(body)}, outputs=["b"],
                    expect=exp)
    else:
        what = rng.choice(["load_config('s.toml')", "load_config(3)", "load_config(None, 's.toml')",
                           "load_scenario('s.toml', seed=-1)", "load_scenario(None)", "load_scenario('s.toml', 1.5)",
                           "load_scenario('')", "load_config('/dev/zero')", "methods()", "scenarios()",
                           "bench_config('b', methods=[])", "load_scenario('s.toml', seed=2**40)"])
        body = f"""import bigcbf
o = bigcbf.{what}
out(repr(o)[:200])"""
        exp, name = {}, what
    return Case("api", name, ["python", "case.py"], {**files, "case.py": _script(body)}, expect=exp)


ACTIONS = ["[0.3, 0.0, 0.0]", "[math.nan, 0, 0]", "[1, 2]", "'abc'", "[1e9, 0, 0]", "None", "[[0.1, 0, 0]]",
           "np.zeros(3, dtype=object)", "np.array([0.2, 0, 0], np.float32)", "[math.inf, 0, 0]", "{'vx': 1}",
           "[True, False, True]", "np.zeros((3, 1))", "[0.3, 0, 0, 0]"]


def gen_gym(rng: random.Random) -> Case:
    seed = rng.choice(SEEDS + ["0", "1", "None"])
    tl = rng.choice(LIMITS + ["2", "2", "1"])
    act = rng.choice(ACTIONS[:1] * 4 + ACTIONS)
    kw = rng.choice(["", "", "perception='truth'", "render_mode='rgb_array'", "width=10", "camera='x'",
                     "config='c.toml'", "render_mode='human'"])
    body = f"""from bigcbf.gym_env import NavigationEnv
env = NavigationEnv(scenario='s.toml', time_limit_s={tl}{', ' + kw if kw else ''})
obs, info = env.reset(seed={seed})
steps = term = trunc = 0
while not (term or trunc) and steps < 200:
    obs, rew, term, trunc, info = env.step({act})
    steps += 1
    if steps == 1 and env.render_mode:
        env.render()
assert np.isfinite(rew), rew
res = env.episode.result().metrics()
env.close()
out(res)"""
    files = {"s.toml": SCEN_PED.encode(), "case.py": _script(body), "c.toml": b"[stack]\nalpha_per_s = 1.5\n"}
    return Case("gym", f"time_limit_s={tl} seed={seed} action={act} {kw}", ["python", "case.py"], files,
                expect={"kind": "gym"})


PLANNERS = b'''import numpy as np
from bigcbf.control.planner import PlanInfo


class _Base:
    def __init__(self, params, *a):
        self.params = params

    def reset(self, seed):
        pass


class TwoVec(_Base):
    def plan(self, t, state, obstacles, goal):
        return np.array([0.3, 0.0]), PlanInfo("fz", False, 0.0)


class NanPlan(_Base):
    def plan(self, t, state, obstacles, goal):
        return np.array([np.nan, 0.0, 0.0]), PlanInfo("fz", False, 0.0)


class Raises(_Base):
    def plan(self, t, state, obstacles, goal):
        raise ValueError("planner bug")


class NoTuple(_Base):
    def plan(self, t, state, obstacles, goal):
        return np.array([0.3, 0.0, 0.0])


class Huge(_Base):
    def plan(self, t, state, obstacles, goal):
        return np.array([1e300, -1e300, 1e300]), PlanInfo("fz", False, 0.0)


class Strings(_Base):
    def plan(self, t, state, obstacles, goal):
        return ["a", "b", "c"], PlanInfo("fz", False, 0.0)


class NoneInfo(_Base):
    def plan(self, t, state, obstacles, goal):
        return np.array([0.3, 0.0, 0.0]), None


class Good(_Base):
    def plan(self, t, state, obstacles, goal):
        d = np.asarray(goal, float) - np.array([state.px, state.py])
        return np.array([*(0.4 * d / max(np.linalg.norm(d), 1e-9)), 0.0]), PlanInfo("fz", False, 0.0)


def not_a_class(*a):
    return None

BROKEN_AT_IMPORT = False
'''


def gen_planner(rng: random.Random) -> Case:
    method = rng.choice(["fzplan:TwoVec", "fzplan:NanPlan", "fzplan:Raises", "fzplan:NoTuple", "fzplan:Huge",
                         "fzplan:Strings", "fzplan:NoneInfo", "fzplan:Good", "fzplan:not_a_class", "fzplan",
                         "os:system", "builtins:eval", "subprocess:Popen", "fzplan:BROKEN_AT_IMPORT", "fzplan:nope",
                         "nomodule:X", "fzplan:_Base"])
    if rng.random() < 0.7:
        argv = ["bigcbf", "run", "s.toml", "--json", "--method", method, "--time-limit", "2"]
        exp, outs = {"kind": "run", "d0": 3.0}, []
    else:
        argv = ["bigcbf", "bench", "--out", "b", "--scenarios", "s.toml", "--methods", method, "--seeds", "1",
                "--workers", "1", "--progress", "off"]
        exp, outs = {"kind": "bench"}, ["b"]
    return Case("planner", method, argv, {"s.toml": SCEN_OK.encode(), "fzplan.py": PLANNERS}, outputs=outs,
                expect=exp)


def gen_false_result(rng: random.Random) -> Case:
    """The issue's false results: each must end as a clear error or a warning, never a plain exit 0."""
    c = rng.choice(["eps_g", "friction", "blind_range", "one_beam", "latency_record", "reorder_calibrate",
                    "dead_lidar_rate", "goal_at_start"])
    if c == "eps_g":
        v = rng.choice(["1e9", "100", "5"])
        return Case("false_result", f"[stack] eps_g_m = {v}",
                    ["bigcbf", "run", "s.toml", "--json", "--config", "c.toml", "--time-limit", "2"],
                    {"s.toml": SCEN_OK.encode(), "c.toml": f"[stack]\neps_g_m = {v}\n".encode()},
                    expect={"kind": "run", "d0": 3.0})
    if c == "friction":
        v = rng.choice(["1e-6", "1e-3", "0.001"])
        where = rng.choice(["profile", "patch"])
        if where == "profile":
            return Case("false_result", f"robot floor_friction {v}",
                        ["bigcbf", "run", "s.toml", "--json", "--robot-profile", "r.toml", "--time-limit", "4"],
                        {"s.toml": SCEN_OK.encode(), "r.toml": f"floor_friction = {v}\n".encode()},
                        expect={"kind": "run", "d0": 3.0})
        text = SCEN_OK.replace("time_limit_s = 2", "time_limit_s = 4") + \
            f"[[floor_patches]]\ncenter = [1.5, 0]\nhalf_size = [3, 3]\nfriction = {v}\n"
        return Case("false_result", f"floor patch friction {v}", ["bigcbf", "run", "s.toml", "--json"],
                    {"s.toml": text.encode()}, expect={"kind": "run", "d0": 3.0})
    if c in ("blind_range", "one_beam", "dead_lidar_rate"):
        prof = {"blind_range": f"[lidar]\nrange_max_m = {rng.choice(['1e-9', '0.13', '0.2'])}\nrange_min_m = 0\n",
                "one_beam": f"[lidar]\nn_beams = {rng.choice([1, 2, 3])}\n",
                "dead_lidar_rate": "[lidar]\nrate_hz = 0.01\n"}[c]
        return Case("false_result", prof.strip().replace("\n", " "),
                    ["bigcbf", "run", "s.toml", "--json", "--robot-profile", "r.toml", "--method",
                     rng.choice(["big-cbf", "cbf-only"])],
                    {"s.toml": SCEN_POST.encode(), "r.toml": prof.encode()},
                    expect={"kind": "run", "d0": 3.0, "blind": True})
    if c == "latency_record":
        lat = rng.choice(["10", "5", "4.9"])
        return Case("false_result", f"record latency_s = {lat}",
                    ["bigcbf", "record", "calibration", "--robot-profile", "r.toml", "--out", "o.mcap", "--duration",
                     "10", "--json"], {"r.toml": f"latency_s = {lat}\n".encode()}, outputs=["o.mcap"],
                    expect={"kind": "record"})
    if c == "goal_at_start":
        text = SCEN_OK.replace("goal = [3, 0]", "goal = [0.05, 0]")
        return Case("false_result", "goal 5 cm from the start", ["bigcbf", "run", "s.toml", "--json"],
                    {"s.toml": text.encode()}, expect={"kind": "run", "d0": 0.05})
    summary, msgs = _mcap_messages(BASE["drive.mcap"])
    idx = [i for i, m in enumerate(msgs) if m[0] == "/cmd_vel"]
    times = [msgs[i][1] for i in idx]
    rng2 = random.Random(rng.random())
    rng2.shuffle(times)
    for i, t in zip(idx, times):
        msgs[i] = (msgs[i][0], t, t, msgs[i][3])
    return Case("false_result", "calibrate a log with shuffled /cmd_vel times",
                ["bigcbf", "calibrate", "log.mcap", "--json"], {"log.mcap": _mcap_write(summary, msgs)},
                expect={"kind": "calibrate", "reordered": True})


GENERATORS = {"scenario": gen_scenario, "config": gen_config, "robot_profile": gen_robot_profile,
              "stack_profile": gen_stack_profile, "log": gen_log, "cli": gen_cli, "paths": gen_paths,
              "bounds": gen_bounds, "api": gen_api, "gym": gen_gym, "planner": gen_planner,
              "false_result": gen_false_result}
WEIGHTS = {"scenario": 14, "config": 10, "robot_profile": 10, "stack_profile": 7, "log": 12, "cli": 12, "paths": 8,
           "bounds": 7, "api": 7, "gym": 6, "planner": 5, "false_result": 6}

BASE: dict[str, bytes] = {}


def make_base(folder: Path) -> None:
    """The real inputs the generators mutate: a 10 s calibration drive (``bigcbf record calibration``) and its
    calibrated profile."""
    folder.mkdir(parents=True, exist_ok=True)
    log, prof = folder / "drive.mcap", folder / "profile.toml"
    if not log.exists():
        (folder / "empty.toml").write_text("")
        subprocess.run([BIGCBF, "record", "calibration", "--robot-profile", str(folder / "empty.toml"), "--duration",
                        "10", "--out", str(log), "--seed", "0"], check=True, capture_output=True, env=_env(folder))
    if not prof.exists():
        subprocess.run([BIGCBF, "calibrate", str(log), "--out", str(prof)], check=True, capture_output=True,
                       env=_env(folder))
    BASE["drive.mcap"], BASE["profile.toml"] = log.read_bytes(), prof.read_bytes()


def generate(n: int, seed: int, families: list[str] | None = None) -> list[Case]:
    fams = families or FAMILIES
    weights = [WEIGHTS[f] for f in fams]
    cases = []
    for i in range(n):
        rng = random.Random(seed * 1_000_003 + i)
        fam = rng.choices(fams, weights)[0]
        c = GENERATORS[fam](rng)
        c.id = f"{i:05d}"
        cases.append(c)
    return cases


# --- running and classifying ----------------------------------------------------------------------------------------

def _env(folder: Path) -> dict:
    env = dict(os.environ)
    path = [str(folder)] + ([str(CODE)] if CODE else [])
    env.update(MUJOCO_GL=env.get("MUJOCO_GL", "egl"), PYTHONPATH=os.pathsep.join(path), PYTHONHASHSEED="0",
               MPLBACKEND="Agg", NUMBA_NUM_THREADS="1", OMP_NUM_THREADS="1")
    return env


def _digest(p: Path) -> str | None:
    try:
        if p.is_dir():
            return "dir"
        return hashlib.sha256(p.read_bytes()).hexdigest()
    except OSError:
        return None


def _guarded_state() -> dict[str, tuple]:
    st = {}
    for d in GUARDED:
        for f in sorted(d.rglob("*.toml")) if d.exists() else []:
            s = f.stat()
            st[str(f)] = (s.st_size, s.st_mtime_ns)
    return st


def _argv_real(case: Case) -> list[str]:
    head = {"bigcbf": BIGCBF, "python": PY}[case.argv[0]]
    return [head] + case.argv[1:]


def prepare(case: Case, folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in case.files.items():
        (folder / name).write_bytes(data)
    for name, target in case.links.items():
        os.symlink(target, folder / name)


def _ffmpeg() -> str | None:
    try:
        import imageio_ffmpeg
        return imageio_ffmpeg.get_ffmpeg_exe()
    except Exception:   # noqa: BLE001 - checked without it
        return shutil.which("ffmpeg")


def check_output(p: Path) -> str | None:
    """None if ``p`` (a file) is a valid file of its kind, else why not."""
    try:
        data = p.read_bytes()
    except OSError as exc:
        return f"unreadable: {exc}"
    suf = p.suffix.lower()
    try:
        if suf == ".mcap":
            if len(data) < 16 or not data.startswith(b"\x89MCAP0\r\n") or not data.endswith(b"\x89MCAP0\r\n"):
                return "MCAP without its header/footer magic"
            from mcap.reader import make_reader
            for _ in make_reader(io.BytesIO(data)).iter_messages():
                pass
        elif suf == ".toml":
            tomllib.loads(data.decode())
        elif suf == ".json":
            json.loads(data)
        elif suf == ".csv":
            list(csv.reader(io.StringIO(data.decode())))
        elif suf == ".png":
            if not (data.startswith(b"\x89PNG\r\n\x1a\n") and data[-12:].find(b"IEND") >= 0):
                return "PNG without its IEND chunk"
        elif suf == ".sqlite":
            con = sqlite3.connect(f"file:{p}?mode=ro", uri=True)
            try:
                ok = con.execute("pragma integrity_check").fetchone()[0]
            finally:
                con.close()
            if ok != "ok":
                return f"SQLite integrity: {ok}"
        elif suf == ".mp4":
            ff = _ffmpeg()
            if ff:
                r = subprocess.run([ff, "-v", "error", "-i", str(p), "-f", "null", "-"], capture_output=True,
                                   text=True, timeout=120)
                if r.returncode != 0 or r.stderr.strip():
                    return f"MP4 does not decode: {r.stderr.strip()[:200]}"
    except Exception as exc:   # noqa: BLE001 - any parse failure is the finding
        return f"{type(exc).__name__}: {str(exc)[:200]}"
    return None


TMP_RE = re.compile(r"^\..*\.tmp|\.tmp$|\.part$|~$")
MEM_RE = re.compile(r"MemoryError|Unable to allocate|std::bad_alloc|Cannot allocate memory|out of memory", re.I)


def _numbers(o):
    if isinstance(o, dict):
        for v in o.values():
            yield from _numbers(v)
    elif isinstance(o, list):
        for v in o:
            yield from _numbers(v)
    elif isinstance(o, float):
        yield o


def _has_warning(o) -> bool:
    if isinstance(o, dict):
        for k, v in o.items():
            if ("warn" in str(k).lower() or "note" in str(k).lower()) and v:
                return True
            if _has_warning(v):
                return True
    elif isinstance(o, list):
        return any(_has_warning(v) for v in o)
    return False


def false_result_flags(case: Case, stdout: str, stderr: str) -> list[str]:
    """Suspicions about a result that exited 0 (for review)."""
    kind = case.expect.get("kind")
    if not kind:
        return []
    text = stdout.strip().splitlines()
    obj = None
    for ln in reversed(text):
        if ln.startswith("{"):
            try:
                obj = json.loads(ln, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
            except ValueError as exc:
                return [f"non-strict or invalid JSON on stdout ({str(exc)[:60]})"]
            break
    if obj is None:
        try:
            obj = json.loads(stdout, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c))) \
                if stdout.strip().startswith("{") else None
        except ValueError:
            obj = None
    if not isinstance(obj, dict):
        return []
    flags = []
    warned = _has_warning(obj) or "warning" in stderr.lower() or "note:" in stderr
    if any(not math.isfinite(x) for x in _numbers(obj)):
        flags.append("non-finite number in the JSON")
    if kind in ("run", "gym") and "success" in obj:
        d, t = obj.get("final_goal_dist_m"), obj.get("time_s")
        if obj["success"] and isinstance(d, (int, float)) and d > 2 * EPS_G_DEFAULT and not warned:
            flags.append(f"success {d:.2f} m from the goal")
        if (obj["success"] and isinstance(t, (int, float)) and t < 0.5 and case.expect.get("d0", 1) > 2 * EPS_G_DEFAULT
                and not warned):
            flags.append(f"success at t = {t:.2f} s")
        d0, sim = case.expect.get("d0"), obj.get("sim_time_s") or 0
        if (d0 is not None and isinstance(d, (int, float)) and abs(d - d0) < 0.02 and sim >= 1.0
                and not obj["success"] and not warned):
            flags.append(f"robot never moved in {sim:.1f} s, no warning")
        mc = obj.get("min_clearance_m")
        if isinstance(mc, (int, float)) and mc < 0 and not obj.get("collision"):
            flags.append(f"min_clearance {mc:.3f} m < 0 without a collision")
        if case.expect.get("blind") and obj.get("collision") and not warned:
            flags.append("collision with a degraded LiDAR, no warning")
        if obj.get("stopped_time_s", 0) > sim + 1e-6:
            flags.append("stopped longer than simulated")
    if kind == "record":
        dm = obj.get("max_distance_m")
        if isinstance(dm, (int, float)) and dm < 0.05 and not warned:
            flags.append(f"recorded robot moved {dm:.3f} m, no warning")
    if kind == "calibrate":
        tau = obj.get("tau95_s")
        if isinstance(tau, (int, float)) and (tau < 0 or tau > 5):
            flags.append(f"tau95 = {tau}")
        if case.expect.get("reordered") and not warned:
            flags.append(f"out-of-order log times calibrated without a warning (tau95 = {tau})")
    if kind in ("calibrate", "replay") and case.expect.get("truncated") and not warned:
        flags.append("a truncated log read without a warning")
    if kind == "replay" and case.expect.get("reordered") and case.expect.get("topic") != "/scan" and not warned:
        flags.append("out-of-order log times replayed without a warning")
    return flags


def _bench_errors(folder: Path, outs: list[str]) -> list[str]:
    errs = []
    for o in outs + ["."]:
        f = folder / o / "episodes.csv"
        if f.is_file():
            try:
                for row in csv.DictReader(io.StringIO(f.read_text())):
                    if row.get("status") == "error":
                        errs.append(row.get("error", "")[:300])
            except Exception:   # noqa: BLE001 - an invalid CSV is flagged by check_output
                pass
    return errs


NUM_RE = re.compile(r"[-+]?\d[\d.e+-]*")


def signature(cls: str, stderr: str, flags: list[str]) -> str:
    if cls in ("traceback", "killed-memory"):
        frames = re.findall(r'File "([^"]+)", line (\d+), in (\S+)', stderr)
        exc = [ln for ln in stderr.strip().splitlines() if re.match(r"^[A-Za-z_.]+(Error|Exception|Exit|Interrupt)"
                                                                      r"\b|^[A-Za-z_.]+Error:", ln)]
        own = [f for f in frames if "site-packages" not in f[0] and "/lib/python" not in f[0]]
        last = (own or frames or [("?", "?", "?")])[-1]
        etype = exc[-1].split(":")[0] if exc else "?"
        return f"{cls}: {etype} at {Path(last[0]).name}:{last[1]} in {last[2]}"
    if cls == "worker-error":
        m = re.search(r"^(\w+):.*?\(at ([^)]*)\)", flags[0] if flags else "")
        return f"worker-error: {m.group(1)} at {m.group(2)}" if m else f"worker-error: {(flags or ['?'])[0][:80]}"
    if cls in ("data-loss", "half-written", "false-result"):
        return f"{cls}: {NUM_RE.sub('N', flags[0]) if flags else '?'}"
    if cls == "messy-error":
        return f"messy-error: {flags[0] if flags else '?'}"
    return cls


def classify(case: Case, folder: Path, rc: int | None, timed_out: bool, out: str, err: str,
             before: dict[str, str | None], guarded_before: dict) -> tuple[str, list[str]]:
    flags: dict[str, list[str]] = {c: [] for c in CLASSES}
    argv = list(case.argv)
    forced = {argv[i + 1] for i in range(len(argv) - 1) if argv[i] == "--out"} if "--force" in argv else set()
    for name, dig in before.items():
        now = _digest(folder / name)
        if now != dig and name not in forced:      # --force: the user asked to replace that file
            flags["data-loss"].append(f"input {name} {'removed' if now is None else 'changed'}")
    if _guarded_state() != guarded_before:
        flags["data-loss"].append("a shipped profile or scenario of the package changed")
    for p in folder.rglob("*"):
        if TMP_RE.search(p.name):
            flags["half-written"].append(f"temporary file left: {p.relative_to(folder)}")
    for o in case.outputs:
        p = folder / o
        if o in before or not p.exists():
            continue
        for f in ([p] if p.is_file() else sorted(x for x in p.rglob("*") if x.is_file())):
            why = check_output(f)
            if why:
                flags["half-written"].append(f"{f.relative_to(folder)}: {why}")
    if timed_out:
        flags["hang"].append("no end within the wall limit")
    elif MEM_RE.search(err):
        flags["killed-memory"].append(MEM_RE.search(err).group(0))
    elif rc is not None and rc < 0:
        flags["crash"].append(f"signal {-rc} ({signal.Signals(-rc).name if -rc in signal.Signals._value2member_map_ else '?'})")
    elif "Traceback" in err or rc not in (0, 1, 2):
        flags["traceback"].append(err.strip().splitlines()[-1][:300] if err.strip() else f"exit {rc}")
    else:
        lines = [ln for ln in err.splitlines() if ln.strip()]
        if rc == 2:
            body_ok = lines and ": error: " in lines[-1] and all(ln.startswith(("note:", "warning:"))
                                                                  for ln in lines[:-1])
            if body_ok:
                flags["user-error"].append(lines[-1][:300])
            else:
                flags["messy-error"].append(f"exit 2 with {len(lines)} stderr lines")
        be = _bench_errors(folder, case.outputs)
        if be:
            flags["worker-error"].extend(be)
        elif rc == 1:
            flags["messy-error"].append("exit 1: " + (lines[-1][:200] if lines else "(no message)"))
        if rc == 0:
            flags["false-result"].extend(false_result_flags(case, out, err))
    for cls in CLASSES:
        if flags[cls]:
            return cls, flags[cls]
    return "ok", []


def run_case(case: Case, work: Path, timeout: float = 120.0, mem_gib: float = 4.0, keep=False) -> dict:
    folder = work / f"case-{case.id}"
    if folder.exists():
        shutil.rmtree(folder)
    prepare(case, folder)
    before = {n: _digest(folder / n) for n in list(case.files) + list(case.links)}
    guarded_before = _guarded_state()
    limit = int(mem_gib * 2**30)

    def limits():
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))

    t0 = time.monotonic()
    timed_out = False
    with open(folder / ".fz-stdout", "wb+") as fo, open(folder / ".fz-stderr", "wb+") as fe:
        proc = subprocess.Popen(_argv_real(case), cwd=folder, env=_env(folder), stdin=subprocess.DEVNULL,
                                stdout=fo, stderr=fe, preexec_fn=limits, start_new_session=True)
        try:
            rc = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            timed_out = True
            os.killpg(proc.pid, signal.SIGKILL)
            rc = proc.wait()
        try:                          # bench workers and other children: none may outlive the case
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        fo.seek(0), fe.seek(0)
        out = fo.read()[-200_000:].decode("utf-8", "replace")
        err = fe.read()[-200_000:].decode("utf-8", "replace")
    (folder / ".fz-stdout").unlink()
    (folder / ".fz-stderr").unlink()
    wall = time.monotonic() - t0
    cls, flags = classify(case, folder, rc, timed_out, out, err, before, guarded_before)
    rec = {"id": case.id, "family": case.family, "name": case.name, "argv": case.argv, "class": cls,
           "flags": flags[:5], "rc": rc, "wall_s": round(wall, 2), "signature": signature(cls, err, flags),
           "stderr_tail": err.strip().splitlines()[-3:] if err.strip() else []}
    if cls not in ("ok", "user-error"):
        repro = work.parent / "repro" / f"{case.id}-{case.family}-{cls}"
        if repro.exists():
            shutil.rmtree(repro)
        prepare(case, repro)
        (repro / "cmd.sh").write_text("#!/bin/sh\n# " + case.name.replace("\n", " ") + f"\n# class: {cls}: "
                                      + "; ".join(flags[:3]).replace("\n", " ") + "\ncd \"$(dirname \"$0\")\"\n"
                                      + "export MUJOCO_GL=egl PYTHONPATH=." + (f":{CODE}" if CODE else "")
                                      + f"\n{shlex.join(_argv_real(case))}\n")
        (repro / "cmd.sh").chmod(0o755)
        (repro / "stdout.txt").write_text(out)
        (repro / "stderr.txt").write_text(err)
        rec["repro"] = str(repro)
    if not keep:
        shutil.rmtree(folder, ignore_errors=True)
    return rec


# --- the fixed sample the test suite runs ----------------------------------------------------------------------------

#: the fixed sample: (name, the class it must have, why it does not yet: a reason for an expected failure or "")
SAMPLE_TABLE = [
    ("a valid small scenario", "ok", ""),
    ("negative extent", "user-error", ""),
    ("calibrate --out onto its log", "user-error", ""),
    ("scenario named '../../evil' with --log", "user-error", ""),
    ("lidar rate_hz = 1000", "user-error", ""),
    ("calibrate a truncated MCAP", "ok", ""),                     # read up to the damage, with a warning
    ("replay a truncated MCAP", "ok", ""),
    ("--method os:system", "user-error", ""),
    ("a planner returning a 2-vector", "user-error", ""),
    ("mppi samples = 1e9", "user-error", ""),
    ("replay --window 1e-300", "user-error", ""),
    ("run --config /dev/zero", "user-error", ""),
    ("run_episode(seed=-1)", "user-error", ""),
    ("run_bench(methods=[])", "user-error", ""),
    ("a NaN action", "user-error", ""),
    ("time limit nan", "user-error", ""),
    ("[stack] eps_g_m = 1e9", "user-error", ""),
    ("record with latency_s = 10", "user-error", ""),
    ("calibrate a log with reversed /cmd_vel times", "ok", ""),   # repaired, with a warning
    # found by the 1,000-case run (seed 2026) and fixed since: each now a one-line error or a clean run
    ("replay a log whose /cmd_vel channel has no message", "user-error", ""),
    ("a planner that raises", "user-error", ""),
    ("a planner returning 1e300", "user-error", ""),
    ("50 overlapping floor patches", "ok", ""),
    ("profile simulate --duration 1e9", "user-error", ""),
    ("gym time_limit_s = 1e-300", "user-error", ""),
    # found by the second 1,000-case run (seed 2027) and fixed since
    ("replay a log whose /odom channel has no message", "user-error", ""),
    ("replay a log whose /odom times are shifted by 2^63 ns", "user-error", ""),
    ("replay --profile whose uncertainty is a number", "user-error", ""),
]


def sample_cases() -> list[tuple[Case, str, str]]:
    """(case, the class it must have, why not yet) for each class of the issue (SAMPLE_TABLE);
    tests/test_fuzz_real.py runs these."""
    cases = _sample_cases()
    assert [c.name for c in cases] == [n for n, _, _ in SAMPLE_TABLE]
    return [(c, want, why) for c, (_, want, why) in zip(cases, SAMPLE_TABLE)]


def _sample_cases() -> list[Case]:
    drive = BASE["drive.mcap"]
    cut = drive[: len(drive) * 2 // 3]
    s, msgs = _mcap_messages(drive)
    idx = [i for i, m in enumerate(msgs) if m[0] == "/cmd_vel"]
    times = [msgs[i][1] for i in idx][::-1]
    for i, t in zip(idx, times):
        msgs[i] = (msgs[i][0], t, t, msgs[i][3])
    reversed_log = _mcap_write(s, msgs)
    no_cmd = _mcap_write(s, [m for m in msgs if m[0] != "/cmd_vel"])
    no_odom = _mcap_write(s, [m for m in msgs if m[0] != "/odom"])
    far = 2 ** 63 - 1 - max(m[1] for m in msgs)
    shifted = _mcap_write(s, [(m[0], m[1] + far, m[2] + far, m[3]) if m[0] == "/odom" else m for m in msgs])
    patches = SCEN_OK + "".join("[[floor_patches]]\ncenter = [1.0, 0.0]\nhalf_size = [1.5, 1.5]\nfriction = 0.8\n"
                                for _ in range(50))
    ped = SCEN_PED.encode()
    C = Case
    return [
        C("scenario", "a valid small scenario", ["bigcbf", "run", "s.toml", "--json", "--method", "cbf-only",
                                                  "--time-limit", "1", "--log", "o.mcap"], {"s.toml": ped},
           outputs=["o.mcap"], expect={"kind": "run", "d0": 3.0}),
        C("scenario", "negative extent", ["bigcbf", "run", "s.toml"],
           {"s.toml": SCEN_OK.replace("extent_m = 5", "extent_m = -3").encode()}),
        C("paths", "calibrate --out onto its log", ["bigcbf", "calibrate", "d.mcap", "--out", "d.mcap"],
           {"d.mcap": drive}),
        C("paths", "scenario named '../../evil' with --log", ["bigcbf", "run", "s.toml", "--time-limit", "1",
                                                               "--log", "o.mcap"],
           {"s.toml": SCEN_PED.replace('name = "fz"', 'name = "../../evil"').encode()}, outputs=["o.mcap"]),
        C("bounds", "lidar rate_hz = 1000", ["bigcbf", "run", "s.toml", "--robot-profile", "r.toml",
                                              "--time-limit", "1"],
           {"s.toml": SCEN_OK.encode(), "r.toml": b"[lidar]\nrate_hz = 1000\n"}),
        C("log", "calibrate a truncated MCAP", ["bigcbf", "calibrate", "log.mcap", "--json"], {"log.mcap": cut},
           expect={"kind": "calibrate", "truncated": True}),
        C("log", "replay a truncated MCAP", ["bigcbf", "replay", "log.mcap", "--json"], {"log.mcap": cut},
           expect={"kind": "replay", "truncated": True}),
        C("planner", "--method os:system", ["bigcbf", "run", "s.toml", "--method", "os:system", "--time-limit",
                                             "1"], {"s.toml": SCEN_OK.encode()}),
        C("planner", "a planner returning a 2-vector", ["bigcbf", "run", "s.toml", "--method", "fzplan:TwoVec",
                                                         "--time-limit", "1"],
           {"s.toml": SCEN_OK.encode(), "fzplan.py": PLANNERS}),
        C("bounds", "mppi samples = 1e9", ["bigcbf", "run", "s.toml", "--method", "mppi", "--config", "c.toml",
                                            "--time-limit", "1"],
           {"s.toml": SCEN_OK.encode(), "c.toml": b"[methods.mppi]\nsamples = 1000000000\n"}),
        C("bounds", "replay --window 1e-300", ["bigcbf", "replay", "d.mcap", "--window", "1e-300"],
           {"d.mcap": drive}),
        C("bounds", "run --config /dev/zero", ["bigcbf", "run", "s.toml", "--config", "/dev/zero"],
           {"s.toml": SCEN_OK.encode()}),
        C("api", "run_episode(seed=-1)", ["python", "case.py"],
           {"s.toml": ped, "case.py": _script("import bigcbf\nbigcbf.run_episode('s.toml', seed=-1)")}),
        C("api", "run_bench(methods=[])", ["python", "case.py"],
           {"s.toml": ped, "case.py": _script("import bigcbf\nif __name__ == '__main__':\n"
                                              "    bigcbf.run_bench('b', methods=[], scenarios=['s.toml'], seeds=1)")}),
        C("gym", "a NaN action", ["python", "case.py"],
           {"s.toml": ped, "case.py": _script("from bigcbf.gym_env import NavigationEnv\n"
                                              "env = NavigationEnv(scenario='s.toml', time_limit_s=1)\n"
                                              "env.reset(seed=0)\nenv.step([math.nan, 0, 0])")}),
        C("gym", "time limit nan", ["python", "case.py"],
           {"s.toml": ped, "case.py": _script("from bigcbf.gym_env import NavigationEnv\n"
                                              "NavigationEnv(scenario='s.toml', time_limit_s=math.nan)")}),
        C("false_result", "[stack] eps_g_m = 1e9", ["bigcbf", "run", "s.toml", "--json", "--config", "c.toml",
                                                     "--time-limit", "1"],
           {"s.toml": SCEN_OK.encode(), "c.toml": b"[stack]\neps_g_m = 1e9\n"}, expect={"kind": "run", "d0": 3.0}),
        C("false_result", "record with latency_s = 10", ["bigcbf", "record", "calibration", "--robot-profile",
                                                          "r.toml", "--out", "o.mcap", "--duration", "5", "--json"],
           {"r.toml": b"latency_s = 10\n"}, outputs=["o.mcap"], expect={"kind": "record"}),
        C("false_result", "calibrate a log with reversed /cmd_vel times", ["bigcbf", "calibrate", "log.mcap",
                                                                            "--json"],
           {"log.mcap": reversed_log}, expect={"kind": "calibrate", "reordered": True}),
        C("log", "replay a log whose /cmd_vel channel has no message", ["bigcbf", "replay", "log.mcap", "--json"],
          {"log.mcap": no_cmd}),
        C("planner", "a planner that raises", ["bigcbf", "run", "s.toml", "--method", "fzplan:Raises",
                                                "--time-limit", "1"], {"s.toml": SCEN_OK.encode(), "fzplan.py": PLANNERS}),
        C("planner", "a planner returning 1e300", ["bigcbf", "run", "s.toml", "--method", "fzplan:Huge",
                                                    "--time-limit", "1"],
          {"s.toml": SCEN_OK.encode(), "fzplan.py": PLANNERS}),
        C("scenario", "50 overlapping floor patches", ["bigcbf", "run", "s.toml", "--json", "--method", "cbf-only",
                                                        "--time-limit", "1"], {"s.toml": patches.encode()},
          expect={"kind": "run", "d0": 3.0}),
        C("cli", "profile simulate --duration 1e9", ["bigcbf", "profile", "simulate", "--robot-profile", "x3_sim",
                                                      "--out", "p.toml", "--duration", "1e9"], {}, outputs=["p.toml"]),
        C("gym", "gym time_limit_s = 1e-300", ["python", "case.py"],
          {"s.toml": ped, "case.py": _script("from bigcbf.gym_env import NavigationEnv\n"
                                             "env = NavigationEnv(scenario='s.toml', time_limit_s=1e-300)\n"
                                             "env.reset(seed=0)\nenv.step([0.3, 0, 0])")}),
        C("log", "replay a log whose /odom channel has no message", ["bigcbf", "replay", "log.mcap", "--json"],
          {"log.mcap": no_odom}),
        C("log", "replay a log whose /odom times are shifted by 2^63 ns", ["bigcbf", "replay", "log.mcap", "--json"],
          {"log.mcap": shifted}),
        C("stack_profile", "replay --profile whose uncertainty is a number", ["bigcbf", "replay", "d.mcap",
                                                                             "--profile", "p.toml", "--json"],
          {"d.mcap": drive, "p.toml": b"uncertainty = 1.0\n"}),
    ]


# --- main ------------------------------------------------------------------------------------------------------------

def summarize(records: list[dict]) -> dict:
    by_class = {c: 0 for c in CLASSES}
    by_family: dict[str, dict[str, int]] = {}
    sigs: dict[str, dict] = {}
    for r in records:
        by_class[r["class"]] += 1
        by_family.setdefault(r["family"], {}).setdefault(r["class"], 0)
        by_family[r["family"]][r["class"]] += 1
        if r["class"] not in ("ok", "user-error"):
            s = sigs.setdefault(r["signature"], {"class": r["class"], "count": 0, "example": r["id"],
                                                 "name": r["name"], "argv": r["argv"], "repro": r.get("repro"),
                                                 "flags": r["flags"][:2]})
            s["count"] += 1
    order = {c: i for i, c in enumerate(CLASSES)}
    ranked = sorted(sigs.items(), key=lambda kv: (order[kv[1]["class"]], -kv[1]["count"]))
    return {"cases": len(records), "by_class": by_class, "by_family": by_family,
            "signatures": [{"signature": k, **v} for k, v in ranked]}


def write_summary(out: Path, summary: dict) -> str:
    lines = [f"# fuzz_inputs: {summary['cases']} cases", "", "| family | " + " | ".join(CLASSES) + " |",
             "|---" * (len(CLASSES) + 1) + "|"]
    for fam in sorted(summary["by_family"]):
        row = summary["by_family"][fam]
        lines.append(f"| {fam} | " + " | ".join(str(row.get(c, 0)) for c in CLASSES) + " |")
    lines.append("| **all** | " + " | ".join(str(summary["by_class"][c]) for c in CLASSES) + " |")
    lines += ["", "## distinct failure signatures (most serious first)", ""]
    for s in summary["signatures"]:
        lines.append(f"- **{s['signature']}** x{s['count']} -- e.g. case {s['example']} ({s['name'][:100]!r}): "
                     f"`{shlex.join(s['argv'])[:200]}`; repro: {s['repro']}")
    text = "\n".join(lines) + "\n"
    (out / "summary.md").write_text(text)
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    return text


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=100, help="generated cases (default 100)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--jobs", type=int, default=1, help="cases at once (default 1)")
    ap.add_argument("--timeout", type=float, default=120.0, help="wall limit per case, seconds (120)")
    ap.add_argument("--mem-gib", type=float, default=4.0, help="address-space limit per case, GiB (4)")
    ap.add_argument("--out", type=Path, required=True, help="report folder (report.jsonl, summary.md, repro/)")
    ap.add_argument("--families", nargs="+", choices=FAMILIES, help="only these generator families")
    ap.add_argument("--sample", action="store_true", help="the fixed case table of the test suite instead")
    ap.add_argument("--budget-s", type=float, default=None, help="start no case after this many seconds")
    ap.add_argument("--keep", action="store_true", help="keep every case's folder under OUT/work")
    ap.add_argument("--code", type=Path, help="run this copy of the code (first on PYTHONPATH; default: the "
                    "checkout), e.g. a snapshot: git archive HEAD | tar -x -C DIR")
    ap.add_argument("--list-families", action="store_true")
    a = ap.parse_args(argv)
    if a.list_families:
        for f in FAMILIES:
            print(f"{f:14s} {(GENERATORS[f].__doc__ or '').strip().splitlines()[0] if GENERATORS[f].__doc__ else ''}")
        return 0
    global CODE, GUARDED
    if a.code:
        CODE = a.code.resolve()
        GUARDED = [CODE / "bigcbf" / "profiles", CODE / "bigcbf" / "scenarios", CODE / "scenarios"] + GUARDED
    a.out.mkdir(parents=True, exist_ok=True)
    make_base(a.out / "base")
    if a.sample:
        cases = []
        for i, (c, want, _) in enumerate(sample_cases()):
            c.id, c.expect = f"s{i:02d}", {**c.expect, "want": want}
            cases.append(c)
    else:
        cases = generate(a.n, a.seed, a.families)
    work = a.out / "work"
    work.mkdir(exist_ok=True)
    report = open(a.out / "report.jsonl", "w")
    records: list[dict] = []
    lock = threading.Lock()
    t_start = time.monotonic()

    def one(c: Case):
        if a.budget_s and time.monotonic() - t_start > a.budget_s:
            return
        rec = run_case(c, work, a.timeout, a.mem_gib, a.keep)
        with lock:
            records.append(rec)
            report.write(json.dumps(rec) + "\n")
            report.flush()
            print(f"[{len(records):4d}/{len(cases)}] {rec['id']} {rec['family']:13s} {rec['class']:13s} "
                  f"{rec['wall_s']:6.1f}s {rec['name'][:70]!r}", flush=True)

    with ThreadPoolExecutor(max(1, a.jobs)) as ex:
        list(ex.map(one, cases))
    report.close()
    summary = summarize(records)
    print(write_summary(a.out, summary))
    bad = sum(summary["by_class"][c] for c in ("data-loss", "traceback", "killed-memory", "crash", "hang",
                                                "half-written"))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
