"""The ``faults`` bench suite: every method under each fault at a mild and a severe level, on shipped scenes where
the fault matters, beside the same scenes without it.

``bigcbf bench --suite faults --out DIR`` writes, for each fault, level and scene, the shipped scene's file with the
fault added into ``DIR/faults/<fault>/<scene>__<fault>_<level>.toml`` (an ordinary scenario file: ``bigcbf run
FILE`` reruns any of them). Each file keeps the scene's text (its walls, pedestrians and random ranges in the same
order) and adds ``draws_as = "<scene>"``, so that for a given seed it draws the *same world* as the shipped scene:
every cell of the report differs from the scene's own row (level ``none``, the shipped scene itself) by the fault
only. The faults' own random events come from the episode seed, each fault from its own stream
(``bigcbf/params/faults.py``); the methods see the same faults for the same seed (paired episodes).

Faults and levels (``FAULTS``; the robot profile's keys are set in the file's ``[robot_profile]`` tables over the
simulated X3 of ``bigcbf/profiles/x3_sim.toml``, the pedestrians' in each ``[[pedestrians]]``):

==================  =================================================================================================
lidar_noise         range noise std: mild 0.02 m + 1 % of the range, severe 0.05 m + 2 % (the X3's: 0.005 m +
                    0.5 %); scenes multi_static_clutter, crowd_crossing
scan_dropout        whole scans missing: mild 0.3 s outages at 0.2 per second, severe 1.0 s outages at 0.3 per
                    second (Poisson); multi_static_clutter, crowd_crossing
blanked_sector      LiDAR beams read inf (occluded or dirty window): mild 45 deg centred 45 deg left of the front,
                    severe 90 deg centred on the front; multi_static_clutter, crowd_crossing
latency_spikes      the command link stalls: mild 0.3 s at 0.2 per second, severe 1.0 s at 0.2 per second;
                    crowd_crossing, corridor_meeting
odometry_drift      gyro bias / gyro noise density / wheel-radius error / wheel-speed noise density: mild 0.005 rad/s,
                    1e-3 rad/s/sqrt(Hz), 3 %, 0.05 rad/s/sqrt(Hz); severe 0.02 rad/s, 5e-3, 8 %, 0.2;
                    double_squeeze, multi_static_clutter
pedestrian_stops    every pedestrian stops at random: mild 2 s stops at 0.1 per second, severe 3 s stops at 0.3 per
                    second; crowd_crossing, single_person_crossing
pedestrian_turns    every pedestrian turns at random: mild 90 deg to a random side for 1.5 s at 0.1 per second,
                    severe 180 deg (turns back) for 2 s at 0.2 per second; crowd_crossing, single_person_crossing
==================  =================================================================================================

The stack is not told: its perception and stack parameters stay those of the simulated X3 (e.g. the perception
still assumes the X3's range noise under ``lidar_noise``). The report (``bigcbf/bench/report.py``) gives success
and collisions per method, fault and level (each fault's ``none`` column: its scenes without the fault); results
of a 2-seed run in docs/benchmark.md ("The faults suite"). A SuiteEntry's family is the fault (``none`` for the shipped scenes)
and its split the level; ``bigcbf bench --suite faults --split severe`` runs one level.

Each fault is written once, in its :class:`Fault` registered in :data:`FAULTS` (its levels are its tags); the suite
(``bigcbf/bench/suites.py``), the report and the tests read the names from there. This module imports no other
module of the bench: the report passes its ``summarize`` to :func:`by_fault`.
"""
from __future__ import annotations

import textwrap
from dataclasses import dataclass, field
from pathlib import Path

from ..registry import Registry
from ..worlds import toml_key, toml_value

LEVELS = ("mild", "severe")
#: the split and family of the shipped scenes themselves (no fault)
REFERENCE = "none"


@dataclass(frozen=True)
class Level:
    summary: str                                            # what this level sets, in words
    robot_profile: dict = field(default_factory=dict)       # merged into the scene's [robot_profile]
    pedestrian: dict = field(default_factory=dict)          # keys added to every [[pedestrians]]


@dataclass(frozen=True)
class Fault:
    name: str
    description: str
    scenes: tuple[str, ...]
    levels: dict[str, Level]

    @property
    def tags(self) -> tuple[str, ...]:
        """Its registry tags: its levels."""
        return tuple(self.levels)


#: name -> Fault, in the order the suite writes and the report lists them
FAULTS: Registry[Fault] = Registry("fault")

for _fault in (
    Fault("lidar_noise", "LiDAR range noise (Gaussian, std growing with the range)",
          ("multi_static_clutter", "crowd_crossing"),
          {"mild": Level("range noise std 0.02 m + 1 % of the range",
                         {"lidar": {"range_noise_std_m": 0.02, "range_noise_frac": 0.01}}),
           "severe": Level("range noise std 0.05 m + 2 % of the range",
                           {"lidar": {"range_noise_std_m": 0.05, "range_noise_frac": 0.02}})}),
    Fault("scan_dropout", "whole LiDAR scans missing (a USB/serial hiccup, a driver restart)",
          ("multi_static_clutter", "crowd_crossing"),
          {"mild": Level("0.3 s outages at 0.2 per second (Poisson)",
                         {"faults": {"scan_dropout": {"rate_per_s": 0.2, "duration_s": 0.3}}}),
           "severe": Level("1.0 s outages at 0.3 per second (Poisson)",
                           {"faults": {"scan_dropout": {"rate_per_s": 0.3, "duration_s": 1.0}}})}),
    Fault("blanked_sector", "a LiDAR sector reads no return (an occluded or dirty window)",
          ("multi_static_clutter", "crowd_crossing"),
          {"mild": Level("45 deg centred 45 deg left of the front",
                         {"faults": {"blanked_sectors_deg": [[45.0, 45.0]]}}),
           "severe": Level("90 deg centred on the front",
                           {"faults": {"blanked_sectors_deg": [[0.0, 90.0]]}})}),
    Fault("latency_spikes", "the command link stalls (a Wi-Fi / USB hiccup); commands issued meanwhile arrive late",
          ("crowd_crossing", "corridor_meeting"),
          {"mild": Level("0.3 s stalls at 0.2 per second (Poisson)",
                         {"faults": {"latency_spikes": {"rate_per_s": 0.2, "duration_s": 0.3}}}),
           "severe": Level("1.0 s stalls at 0.2 per second (Poisson)",
                           {"faults": {"latency_spikes": {"rate_per_s": 0.2, "duration_s": 1.0}}})}),
    Fault("odometry_drift", "odometry and IMU noise and bias: a gyro bias turns the heading, a wheel-radius error "
                            "scales the distances, noise on the gyro and the wheel speeds",
          ("double_squeeze", "multi_static_clutter"),
          {"mild": Level("gyro bias 0.005 rad/s, gyro noise 1e-3 rad/s/sqrt(Hz), wheel radius +3 %, wheel-speed "
                         "noise 0.05 rad/s/sqrt(Hz)",
                         {"imu": {"gyro_bias_radps": 0.005, "gyro_noise_density_radps_rthz": 1e-3},
                          "odometry": {"scale_error": 0.03, "wheel_noise_density_radps_rthz": 0.05}}),
           "severe": Level("gyro bias 0.02 rad/s, gyro noise 5e-3 rad/s/sqrt(Hz), wheel radius +8 %, wheel-speed "
                           "noise 0.2 rad/s/sqrt(Hz)",
                           {"imu": {"gyro_bias_radps": 0.02, "gyro_noise_density_radps_rthz": 5e-3},
                            "odometry": {"scale_error": 0.08, "wheel_noise_density_radps_rthz": 0.2}})}),
    Fault("pedestrian_stops", "pedestrians stop suddenly, at random",
          ("crowd_crossing", "single_person_crossing"),
          {"mild": Level("2 s stops at 0.1 per second per pedestrian",
                         pedestrian={"stop": {"rate_per_s": 0.1, "duration_s": 2.0}}),
           "severe": Level("3 s stops at 0.3 per second per pedestrian",
                           pedestrian={"stop": {"rate_per_s": 0.3, "duration_s": 3.0}})}),
    Fault("pedestrian_turns", "pedestrians turn suddenly, at random, then walk back onto their way",
          ("crowd_crossing", "single_person_crossing"),
          {"mild": Level("90 deg to a random side for 1.5 s at 0.1 per second per pedestrian",
                         pedestrian={"turn": {"rate_per_s": 0.1, "duration_s": 1.5, "angle_deg": 90.0,
                                              "random_side": True}}),
           "severe": Level("180 deg (turns back) for 2 s at 0.2 per second per pedestrian",
                           pedestrian={"turn": {"rate_per_s": 0.2, "duration_s": 2.0, "angle_deg": 180.0}})}),
):
    FAULTS.add(_fault)
del _fault


def scenes() -> list[str]:
    """The shipped scenes the suite uses, in the order the faults first name them."""
    out: list[str] = []
    for f in FAULTS.values():
        out += [s for s in f.scenes if s not in out]
    return out


def variant_name(scene: str, fault: str, level: str) -> str:
    return f"{scene}__{fault}_{level}"


# --- writing a scene's file with a fault -----------------------------------------------------------------------------

def _is_range(v) -> bool:
    return isinstance(v, dict) and bool(v) and set(v) <= {"uniform", "choice"}


def _is_section(v) -> bool:
    """A value written as a [table] or [[array of tables]] (random ranges and other values are written inline)."""
    if isinstance(v, dict):
        return not _is_range(v)
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) and not _is_range(x) for x in v)


def _value(v) -> str:
    if isinstance(v, str) and "\n" in v and "'''" not in v:
        return "'''\n" + v + ("" if v.endswith("\n") else "\n") + "'''"
    return toml_value(v)


def dumps(doc: dict) -> str:
    """TOML text of a parsed scenario file, keeping every key's order (random ranges, whose draws follow the
    document's order, stay where they were): within a table, values come first and tables after them unless a value
    follows a table, which is then written inline."""
    lines: list[str] = []

    def table(d: dict, path: str) -> None:
        items = list(d.items())
        last_value = max((i for i, (_, v) in enumerate(items) if not _is_section(v)), default=-1)
        for i, (k, v) in enumerate(items):
            if i <= last_value:
                lines.append(f"{toml_key(k)} = {_value(v)}")
        for i, (k, v) in enumerate(items):
            if i > last_value:
                name = f"{path}.{toml_key(k)}" if path else toml_key(k)
                for item in ([v] if isinstance(v, dict) else v):
                    lines.extend(["", f"[{name}]" if isinstance(v, dict) else f"[[{name}]]"])
                    table(item, name)

    table(doc, "")
    return "\n".join(lines) + "\n"


def _same_order(a, b) -> bool:
    if isinstance(a, dict) and isinstance(b, dict):
        return list(a) == list(b) and all(_same_order(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same_order(x, y) for x, y in zip(a, b))
    return True


def _merge(base: dict, over: dict) -> dict:
    """``over`` merged into a copy of ``base`` (tables key by key; new keys after the existing ones)."""
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def variant_text(scene: str, fault: str, level: str) -> tuple[str, str]:
    """(name, TOML text) of the shipped ``scene`` with ``fault`` at ``level``."""
    from ..params.toml_io import load_toml, parse_toml
    from ..scenario import resolve_path

    f, lv = FAULTS[fault], FAULTS[fault].levels[level]
    raw = load_toml(resolve_path(scene))
    name = variant_name(scene, fault, level)
    draws = raw.get("name", scene)
    about = (f"Fault {fault} ({f.description}), level {level}: {lv.summary}. Written by `bigcbf bench --suite "
             f"faults` (bigcbf/bench/faults.py) from the shipped scene {scene}; it draws that scene's worlds "
             f"(draws_as), so for a given seed it is the same world with the fault.")
    description = str(raw.get("description", "")).strip() + "\n\n" + "\n".join(textwrap.wrap(about, 116)) + "\n"
    doc: dict = {"name": name, "draws_as": draws}
    for k, v in raw.items():
        if k in ("name", "draws_as"):
            continue
        doc[k] = description if k == "description" else v
    if "description" not in doc:
        doc["description"] = description
    if lv.robot_profile:
        doc["robot_profile"] = _merge(doc.get("robot_profile", {}), lv.robot_profile)
    if lv.pedestrian:
        doc["pedestrians"] = [_merge(p, lv.pedestrian) for p in doc.get("pedestrians", [])]
    text = (f"# {name}: the shipped scene {scene} with the fault {fault} ({level}), written by `bigcbf bench "
            f"--suite faults`; run it with `bigcbf run FILE`.\n" + dumps(doc))
    back = parse_toml(text, name)
    if back != doc or not _same_order(back, doc):        # the writer must keep every draw where it was
        raise RuntimeError(f"the faults suite wrote {name} differently from what it meant to")
    return name, text


def write_variants(out: Path, levels=None) -> list[tuple[Path, str, str]]:
    """Write every fault's variants into ``out/faults/<fault>/`` (files whose text changed only) and return
    (path, level, fault) for each."""
    from ..outputs import write_text

    entries = []
    for fault in FAULTS.values():
        for level in (levels or LEVELS):
            for scene in fault.scenes:
                name, text = variant_text(scene, fault.name, level)
                path = Path(out) / "faults" / fault.name / f"{name}.toml"
                try:
                    same = path.read_text() == text
                except (OSError, UnicodeDecodeError):
                    same = False
                if not same:
                    write_text(path, text, "fault scenario")
                entries.append((path, level, fault.name))
    return entries


# --- the report's tables ---------------------------------------------------------------------------------------------

def by_fault(rows, methods, groups: dict, summarize) -> dict:
    """{fault: {"scenes": [...], "levels": {level: {method: summary}}}} for the faults present in ``groups``
    (scenario name -> {"split": level, "family": fault}); level ``none`` is the fault's scenes without it (the
    rows of the shipped scenes, family ``none``). ``summarize``: the report's aggregate of a group of result rows
    (``bigcbf.bench.report.summarize``, passed in so that this module needs nothing of the report's)."""
    present = [f for f in FAULTS if any(g["family"] == f for g in groups.values())]
    out = {}
    for fname in present:
        f = FAULTS[fname]
        levels = {}
        ref = {s for s, g in groups.items() if g["family"] == REFERENCE and s in f.scenes}
        if ref:
            levels[REFERENCE] = {m: summarize(r for r in rows if r["method"] == m and r["scenario"] in ref)
                                 for m in methods}
        for level in LEVELS:
            mine = {s for s, g in groups.items() if g["family"] == fname and g["split"] == level}
            if mine:
                levels[level] = {m: summarize(r for r in rows if r["method"] == m and r["scenario"] in mine)
                                 for m in methods}
        out[fname] = {"scenes": list(f.scenes), "description": f.description,
                      "levels_described": {lv: x.summary for lv, x in f.levels.items()}, "levels": levels}
    return out


__all__ = ["FAULTS", "LEVELS", "REFERENCE", "Fault", "Level", "scenes", "variant_name", "variant_text",
           "write_variants", "by_fault", "dumps"]
