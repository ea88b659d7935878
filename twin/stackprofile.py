"""The stack's uncertainty profile of a simulated robot, made by the twin (``bigcbf profile simulate``).

    record a calibration drive of the simulated robot (twin.record, with the robot profile's imperfections and
    sensor noise) -> calibrate it (twin.calibrate) -> write the calibrated terms as a StackParams TOML

The file holds what the calibration measures and the paper calibrates ("the latency and execution-residual
terms were obtained from an independent calibration sequence", Sec. IV-A; "latency and command-dependent
execution-residual terms obtained from hardware measurements", Sec. V): ``[uncertainty] tau95_s`` and
``[uncertainty.execution]`` (A, d, the residual bound e_exec(u) and its horizon). Every other key (d0, beta,
e_ZOH, kappa, ...) comes from the preset the profile is overlaid on (Table I for simulation, the Sec. V values for
the hardware preset), as in the paper, where e_ZOH is a listed parameter. A ``[provenance]`` table says what
made it: the robot profile file and its sha256, seed, drive duration, code version (git commit, the bigcbf
package's code fingerprint), date; ``load_stack_params`` ignores that table.

Equations: tau95, A, d and e_exec(u) are the terms of eq:uncertainty_margin (21) and of eq:execution (1); see
twin.calibrate for how each is estimated.
"""
from __future__ import annotations

import hashlib
import subprocess
import tempfile
from datetime import datetime, timezone
from pathlib import Path

import tomli_w

from bigcbf.errors import UserError
from bigcbf.params.robot import RobotProfile
from bigcbf.params.stack import StackParams, load_stack_params
from bigcbf.params.toml_io import from_dict, load_toml

#: the calibration drive's default length [s] (the drive program's cycles are ~35 s: three full cycles and more)
DURATION_S = 120.0


def file_sha256(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def git_commit(root: Path) -> str:
    """The commit of the checkout holding ``root`` (with ``+dirty`` when files differ from it, the stack profiles
    of bigcbf/profiles/stack/ aside: ``make profiles`` writes one before it makes the next), or ``unknown``
    outside a git checkout (an installed wheel)."""
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True, text=True, timeout=10,
                             check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ":(top)",
                                ":(top,exclude)bigcbf/profiles/stack"], cwd=root,
                               capture_output=True, text=True, timeout=10, check=True).stdout.strip()
        return sha + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def calibrated_tables(cal) -> dict:
    """The calibrated keys of a twin.calibrate.Calibration as a StackParams table: tau95_s and the execution
    model (rounded as ``Calibration.profile_dict`` rounds them: bounds up, so rounding never shrinks a margin)."""
    d = cal.profile_dict()["uncertainty"]
    return {"uncertainty": {"tau95_s": d["tau95_s"], "execution": d["execution"]}}


def simulate_stack_profile(robot_profile: str | Path, out: str | Path, *, seed: int = 0,
                           duration_s: float = DURATION_S, base: StackParams | None = None,
                           log: str | Path | None = None) -> dict:
    """Record a calibration drive of the simulated robot with ``robot_profile`` (a TOML file), calibrate it and
    write the stack profile to ``out``. ``log``: keep the drive's MCAP there (default: a temporary file).
    ``base``: the preset the profile is meant for (validated against it). Returns the written tables and the
    calibration's summary (``provenance``, ``calibration``: twin.calibrate's JSON)."""
    from bigcbf import PACKAGE, PROFILES, __version__
    from bigcbf.bench.tasks import code_sha

    from .calibrate import calibrate_log
    from .record import record_calibration

    robot_profile = Path(robot_profile)
    profile = from_dict(RobotProfile, load_toml(robot_profile), file=str(robot_profile))
    out = Path(out)
    if out.is_dir():
        raise UserError("is a directory, expected a .toml file path", file=str(out))
    with tempfile.TemporaryDirectory(prefix="bigcbf-profile-") as tmp:
        drive = Path(log) if log is not None else Path(tmp) / "calibration.mcap"
        record_calibration(profile, drive, seed=seed, duration_s=duration_s)
        cal = calibrate_log(drive)
    tables = calibrated_tables(cal)
    shipped = robot_profile.resolve().parent == PROFILES.resolve()
    ref = robot_profile.stem if shipped else str(robot_profile)
    provenance = {
        "robot_profile": f"bigcbf/profiles/{robot_profile.name}" if shipped else str(robot_profile),
        "robot_profile_sha256": file_sha256(robot_profile),
        "seed": int(seed), "duration_s": float(duration_s),
        "git_commit": git_commit(PACKAGE), "bigcbf_version": __version__, "code_sha": code_sha(),
        "date_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "command": f"bigcbf profile simulate --robot-profile {ref} --seed {seed} --duration {duration_s:g}",
    }
    cj = cal.to_json()
    header = [
        f"Stack uncertainty profile of the simulated robot {ref}, made by the twin:",
        f"`{provenance['command']}` recorded a {duration_s:g} s calibration drive of it",
        "(twin/record.py) and calibrated it (twin/calibrate.py). Do not edit by hand: run the command again.",
        f"tau95 {cj['tau95_s']:.4f} s (actuation p95 {cj['delay']['actuation95_s']:.4f} s, perception p95 "
        f"{cj['delay']['perception95_s']:.4f} s); residual bound held-out coverage "
        f"{cj['e_exec']['coverage_heldout']:.3f} (stated {cj['e_exec']['coverage']}).",
        "Every other key comes from the preset it is overlaid on (bigcbf/params/stack.py: SIMULATION or PHYSICAL);",
        "[provenance] is informational (load_stack_params ignores it).",
    ]
    text = "".join(f"# {h}\n" for h in header) + tomli_w.dumps({**tables, "provenance": provenance})
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp_out = out.with_name(out.name + ".tmp")
    tmp_out.write_text(text)
    load_stack_params(tmp_out, base=base)           # validated before it replaces anything
    tmp_out.replace(out)
    return {"tables": tables, "provenance": provenance, "calibration": cj, "path": str(out)}
