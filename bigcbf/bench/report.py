"""Reports of a bench: episodes.csv, summary.json, summary.md, success_heatmap.png, cbf_burden.png.

Aggregates (per method, and per method and scenario), over the episodes that ran without error:
- ``success_pct``: 100 x successful episodes / episodes; ``success_ci95_pct``: its 95 % Wilson interval [lo, hi]
  (``bigcbf/bench/stats.py``); ``collision_pct``, ``collision_ci95_pct``: the same for episodes with a contact.
- ``time_s``: mean completion time of the *successful* episodes (the time to reach the goal; a timeout's time is
  the time limit and says nothing about speed). ``None`` when no episode succeeded.
- ``min_clearance_m``: mean over episodes of the episode's minimum true clearance: the signed distance between the
  robot's collision outline (a 0.30 x 0.20 m rectangle at the true pose, ``bigcbf/sim/truth.py``) and the nearest
  obstacle's surface, negative for a penetration (not the paper's disc of radius r_R).
- ``e_cbf``: mean over episodes of E_CBF, eq:sim_cbf_energy (27) (a per-episode sum, as in the paper).
- ``cbf_active_pct`` / ``qp_infeasible_pct``: 100 x control steps with an active constraint / an infeasible QP,
  over all control steps of all episodes of the group (the paper's "fraction of control steps");
  ``qp_infeasible_ci95_pct``: the latter's 95 % interval with the episode as the independent unit
  (:func:`bigcbf.bench.stats.ratio_ci_pct`; None with fewer than two episodes). ``velocity_relaxed_pct``: 100 x
  control steps whose distance rows held but not every velocity-aware row (the common filter's lexicographic
  fallback, ``bigcbf/control/cbf.py``; 0 with the switch off; None for rows from before it was recorded).
- ``cbf_active_episode_pct``: the mean over episodes of each episode's active ratio, x 100 (a long episode, e.g. a
  stalled timeout at 0 %, weighs as much as a short one; the pooled figure weighs episodes by their length).
- ``e_cbf_infeasible_share_pct``: 100 x the E_CBF of control steps whose QP was infeasible / all E_CBF, summed over
  the group's episodes (``None`` when E_CBF is 0).
- ``m_img_mean_m``, ``m_img_p90_m``, ``m_exec_mean_m``, ``m_exec_p90_m``: the margins kappa_l m_i
  (eq:shared_barrier (20)) of each layer: the mean over episodes of each episode's mean and of each episode's 90th
  percentile (episode metrics of the same names; the imagination's only for methods that imagine, ``None`` otherwise).
- ``goal_error_m``: mean over the successful episodes of the true distance to the goal at the end (success is judged
  on the robot's own odometry, as in the paper; an odometry fault makes the two differ).
- ``missed_scans``: mean over episodes of the LiDAR scans that never arrived (a scan-dropout fault).
- ``collisions``, ``timeouts``: counts.
- contacts by who moved (``bigcbf/sim/contacts.py``): ``at_fault_collisions`` / ``passive_collisions``, the counts
  of episodes whose contact the robot drove into (its radial speed above v_freeze) / did not, with
  ``at_fault_collision_pct``, ``passive_collision_pct`` and their Wilson intervals (``*_ci95_pct``), over the
  episodes that record the classification (``None`` when none does: rows from before it existed);
  ``personal_space_s``: mean over episodes of the time a pedestrian's body was within 0.5 m of the robot;
  ``min_time_to_contact_s``: mean over the episodes in which some pedestrian closed on the robot of the smallest
  constant-velocity time to contact; ``near_miss_pct``: the share of the episodes with such a time below 1 s
  and no contact (``NEAR_MISS_TTC_S``), with its Wilson interval.
- ``planner_p95_ms``, ``cbf_p95_ms``, ``perception_p95_ms``: mean over episodes of each episode's P95 wall time
  (wall-clock figures: they depend on the machine and its load, unlike every other number here).
- chatter and stall (defined in bigcbf/control/liveness.py), means over episodes: ``mode_switches_per_min``,
  ``side_reversals`` (left/right reversals of the mode history), ``lateral_reversals`` (of the command's lateral
  component; every method), ``no_progress_s`` (time in 2 s windows with < 0.1 m progress toward the goal),
  ``stopped_time_s``. Rows recorded before these metrics existed are left out of their means.

Suites with splits and families (``generated``) also get ``by_family``: the same figures per method, split and
family (and over each split, key ``all``), a success table per family in summary.md and a heatmap of method x
family and split instead of method x scenario. ``paired``: each method's success minus the reference method's
(BIG-CBF when it ran, else the first method) over the episodes both finished (same scene, same seed), with the
95 % interval of Newcombe's method 10 and the exact McNemar p-value (``bigcbf/bench/stats.py``). Every row of the
tables names the code versions (``code_sha``) and the configuration hash (``params_hash``) its episodes ran with.
With variants (``bigcbf bench --variant NAME=V1,V2``, ``bigcbf/bench/variants.py``) every row of every table and
figure is a method under one combination of the axes' values, ``dwa [route=on]`` (summary.json's ``methods`` is
keyed by these names; ``paired`` compares each with the reference method under the same combination), episodes.csv
has a column ``variant``, and ``variants`` holds the axes, each method's success, collisions, at-fault and passive
collisions and QP infeasible fraction per combination with their intervals (``by_method``), and per method, axis and
value after the axis's first, the paired differences value - first of those (``paired``: Newcombe's interval and
McNemar's p; the QP fraction's paired interval) over the episodes both ran; summary.md gives them in a table with
methods as rows and the combinations as column groups, then the paired differences.
The ``faults`` suite (family: the fault, split: its level) also gets
``by_fault`` (``bigcbf/bench/faults.py``): per fault, level (``none``: its scenes without the fault) and method the
same figures, and in summary.md collisions and success per method and fault, then a table per fault.
"""
from __future__ import annotations

import csv
import json
import math
import shutil
from pathlib import Path
from typing import Iterable, Sequence

from ..errors import UserError
from ..outputs import atomic_output, check_output_dir, check_output_file, strict_json, write_text
from .stats import fmt_ci, paired_difference, paired_ratio_difference, ratio_ci_pct, wilson_pct
from .paper import (METHOD_ORDER, PAPER_SCENARIO_SUCCESS, PAPER_TABLE_II, PAPER_TABLE_III, SCENARIO_ORDER,
                    TABLE2_KEYS, comparability, ordered, paper_tests, summary_successes)
from .paper import display as _method_display
from .variants import arm_label, combination_label, split_label

KEY_FIELDS = ("scenario", "method", "seed", "params_hash", "scenario_sha")
FIGURES = ("success_heatmap.png", "cbf_burden.png")
DOCS_BEGIN = "<!-- bench-results:begin -->"
DOCS_END = "<!-- bench-results:end -->"


def display(label: str) -> str:
    """How a report row is named: the paper's name of its method, then its variant (``DWA [route=on]``)."""
    method, variant = split_label(label)
    return f"{_method_display(method)} [{variant}]" if variant else _method_display(method)


def _mean(xs: Sequence[float]) -> float | None:
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return sum(xs) / len(xs) if xs else None


def summarize(rows: Iterable[dict]) -> dict:
    """The aggregate figures of a group of result rows (see the module docstring for the definitions)."""
    rows = list(rows)
    ok = [r["metrics"] for r in rows if r["status"] == "ok"]
    n = len(ok)
    return {
        "episodes": len(rows),
        "ok": n,
        "errors": len(rows) - n,
        "success_pct": 100.0 * sum(bool(m["success"]) for m in ok) / n if n else None,
        "success_ci95_pct": wilson_pct(sum(bool(m["success"]) for m in ok), n),
        "collision_pct": 100.0 * sum(bool(m["collision"]) for m in ok) / n if n else None,
        "collision_ci95_pct": wilson_pct(sum(bool(m["collision"]) for m in ok), n),
        "time_s": _mean([m["time_s"] for m in ok if m["success"]]),
        "goal_error_m": _mean([m["final_goal_dist_m"] for m in ok if m["success"]]),
        "missed_scans": _mean([m.get("missed_scans") for m in ok]),
        "min_clearance_m": _mean([m["min_clearance_m"] for m in ok]),
        "e_cbf": _mean([m["e_cbf"] for m in ok]),
        "cbf_active_pct": _step_pct(ok, "cbf_active_ratio"),
        "qp_infeasible_pct": _step_pct(ok, "qp_infeasible_ratio"),
        "qp_infeasible_ci95_pct": ratio_ci_pct(*_infeasible_steps(ok)),
        "velocity_relaxed_pct": _step_pct([m for m in ok if "velocity_relaxed_ratio" in m], "velocity_relaxed_ratio"),
        "collisions": sum(bool(m["collision"]) for m in ok),
        "timeouts": sum(bool(m["timeout"]) for m in ok),
        **contact_figures(ok),
        "planner_p95_ms": _mean([m["planner_p95_ms"] for m in ok]),
        "cbf_p95_ms": _mean([m["cbf_p95_ms"] for m in ok]),
        "perception_p95_ms": _mean([m["perception_p95_ms"] for m in ok]),
        "stopped_time_s": _mean([m["stopped_time_s"] for m in ok]),
        "cbf_active_episode_pct": (100.0 * _mean([m["cbf_active_ratio"] for m in ok])) if n else None,
        "e_cbf_infeasible_share_pct": _share([m.get("e_cbf_infeasible") for m in ok], [m["e_cbf"] for m in ok]),
        **{k: _mean([m.get(k) for m in ok]) for k in MARGIN_KEYS},
        **{k: _mean([m.get(k) for m in ok]) for k in LIVENESS_KEYS},
    }


def _step_pct(ok: Sequence[dict], key: str) -> float | None:
    """The pooled percentage of control steps of a per-episode step fraction ``key`` (None without episodes)."""
    steps = sum(int(m["control_steps"]) for m in ok)
    return 100.0 * sum(round(m[key] * m["control_steps"]) for m in ok) / steps if steps else None


def _infeasible_steps(ok: Sequence[dict]) -> tuple[list[int], list[int]]:
    """Each episode's infeasible control steps and its control steps (the pooled fraction's clusters)."""
    return ([round(m["qp_infeasible_ratio"] * m["control_steps"]) for m in ok],
            [int(m["control_steps"]) for m in ok])


#: a near miss: an episode without contact whose smallest time to contact with a pedestrian was below this [s]
NEAR_MISS_TTC_S = 1.0


def contact_figures(ok: Sequence[dict]) -> dict:
    """The contacts by who moved and the near misses of a group's episode metrics (module docstring)."""
    rated = [m for m in ok if "at_fault_collision" in m]
    n = len(rated)
    out = {}
    for kind in ("at_fault", "passive"):
        k = sum(bool(m[f"{kind}_collision"]) for m in rated)
        out[f"{kind}_collisions"] = k if n else None
        out[f"{kind}_collision_pct"] = 100.0 * k / n if n else None
        out[f"{kind}_collision_ci95_pct"] = wilson_pct(k, n)
    ttc = [m.get("min_time_to_contact_s") for m in rated]
    near = sum(1 for m, t in zip(rated, ttc) if t is not None and t < NEAR_MISS_TTC_S and not m["collision"])
    out.update(personal_space_s=_mean([m.get("personal_space_s") for m in rated]),
               min_time_to_contact_s=_mean(ttc), near_miss_pct=100.0 * near / n if n else None,
               near_miss_ci95_pct=wilson_pct(near, n))
    return out


def _contact_cell(s: dict, kind: str) -> str:
    """'n: % [95 % CI]' of at-fault or passive collisions, '–' without the classification."""
    k = s.get(f"{kind}_collisions")
    if k is None:
        return "–"
    return f"{k}: " + fmt_ci(s.get(f"{kind}_collision_pct"), s.get(f"{kind}_collision_ci95_pct"))


def _contacts_lines(labels: Sequence[str], stats: Sequence[dict], h: str, first: str = "Method") -> list[str]:
    """The contacts by who moved and the near misses, one row per group."""
    lines = [f"{h}# Contacts: at fault or passive, and near misses", ""]
    lines += _table([first, "Episodes", "Collisions", "At fault: n, % [95 % CI]", "Passive: n, % [95 % CI]",
                     "Near misses (%) [95 % CI]", "Min TTC (s)", "Personal space (s)"],
                    ([display(lab), str(s["ok"]), _f(s["collisions"]), _contact_cell(s, "at_fault"),
                      _contact_cell(s, "passive"), fmt_ci(s.get("near_miss_pct"), s.get("near_miss_ci95_pct")),
                      _f(s.get("min_time_to_contact_s")), _f(s.get("personal_space_s"), 1)]
                     for lab, s in zip(labels, stats)))
    lines += ["", "At fault: the robot moved into the body it touched (its speed along the contact normal above "
              "v_freeze = 0.05 m/s at first contact); passive: it did not (stopped, moving away or along; e.g. a "
              "walker faster than the robot catching it). Near misses: episodes without contact whose smallest "
              f"constant-velocity time to contact with a pedestrian was below {NEAR_MISS_TTC_S:g} s. Min TTC: mean "
              "of that smallest time over the episodes in which a pedestrian closed on the robot. Personal space: "
              "mean time with a pedestrian's body within 0.5 m of the robot (bigcbf/sim/contacts.py).", ""]
    return lines


#: the per-episode chatter and stall metrics (EpisodeResult) averaged in ``summarize``
LIVENESS_KEYS = ("mode_switches_per_min", "side_reversals", "lateral_reversals", "no_progress_s")


def _family_order(scenarios: Sequence[str], groups: dict) -> tuple[list[str], list[str]]:
    """Splits and families in the order of their first scenario."""
    splits, families = [], []
    for s in scenarios:
        g = groups.get(s)
        if g is None:
            continue
        if g["split"] not in splits:
            splits.append(g["split"])
        if g["family"] not in families:
            families.append(g["family"])
    return splits, families


def by_family(rows: Sequence[dict], methods: Sequence[str], scenarios: Sequence[str], groups: dict) -> dict:
    """{method: {split: {family: summary, "all": summary}}} over the scenarios that have a group."""
    splits, families = _family_order(scenarios, groups)
    out: dict = {}
    for m in methods:
        out[m] = {}
        for sp in splits:
            mine = [r for r in rows if r["method"] == m and groups.get(r["scenario"], {}).get("split") == sp]
            out[m][sp] = {f: summarize(r for r in mine if groups[r["scenario"]]["family"] == f) for f in families
                          if any(groups[s]["family"] == f and groups[s]["split"] == sp for s in scenarios
                                 if s in groups)}
            out[m][sp]["all"] = summarize(mine)
    return out


#: the per-episode margin metrics (EpisodeResult) averaged over episodes in the summary
MARGIN_KEYS = ("m_img_mean_m", "m_img_p90_m", "m_exec_mean_m", "m_exec_p90_m")


def _share(part: Sequence[float | None], whole: Sequence[float]) -> float | None:
    """100 x sum(part) / sum(whole) over the episodes that report ``part`` (None when that sum of whole is 0)."""
    pairs = [(p, w) for p, w in zip(part, whole) if p is not None and w is not None and math.isfinite(w)]
    total = sum(w for _, w in pairs)
    return 100.0 * sum(p for p, _ in pairs) / total if total > 0 else None


def build_summary(rows: Sequence[dict], methods: Sequence[str], scenarios: Sequence[str], seeds: Sequence[int],
                  info: dict | None = None, groups: dict | None = None, variants: dict | None = None) -> dict:
    """summary.json's content: figures keyed by method and by method then scenario, the paper's, and errors;
    with ``groups`` (scenario -> {"split", "family"}) also by method, split and family; with ``variants``
    (``bigcbf.bench.runner._variant_info``) every row is a method under one combination (``dwa [route=on]``) and
    ``variants`` compares each method's combinations (:func:`variant_summary`)."""
    base_methods = list(methods)
    if variants:
        rows, methods = relabel(rows, methods, variants)
    by_m = {m: [r for r in rows if r["method"] == m] for m in methods}
    versions = sorted({r["code_sha"] for r in rows if r["status"] == "ok" and r.get("code_sha")})
    extra = {}
    if groups:
        groups = {s: g for s, g in groups.items() if s in scenarios}
        extra = {"groups": groups, "by_family": by_family(rows, methods, scenarios, groups)}
        from .faults import FAULTS, by_fault
        if any(g["family"] in FAULTS for g in groups.values()):      # the faults suite (or some of its files)
            extra["by_fault"] = by_fault(rows, methods, groups, summarize)
    summary = {
        "bench": {**(info or {}), "methods": list(methods), "scenarios": list(scenarios), "seeds": list(seeds),
                  "episodes_expected": len(methods) * len(scenarios) * len(seeds), "episodes_recorded": len(rows),
                  "ok": sum(r["status"] == "ok" for r in rows), "errors": sum(r["status"] == "error" for r in rows),
                  "code_versions": versions},
        "methods": {m: {**summarize(by_m[m]), **provenance(by_m[m])} for m in methods},
        "paired": paired(rows, methods),
        "by_scenario": {m: {s: summarize(r for r in by_m[m] if r["scenario"] == s) for s in scenarios}
                        for m in methods},
        "paper": {"table_ii": {m: PAPER_TABLE_II[m] for m in METHOD_ORDER},
                  "scenario_success_pct": PAPER_SCENARIO_SUCCESS,
                  "table_iii": {m: PAPER_TABLE_III[m] for m in METHOD_ORDER},
                  "comparable": comparability(rows, scenarios, seeds, (info or {}).get("suite"),
                                              default_params_hash((info or {}).get("suite"),
                                                                  (info or {}).get("perception", "lidar")))},
        "error_episodes": [{k: r[k] for k in ("scenario", "method", "seed", "error")}
                           for r in rows if r["status"] == "error"],
        **extra,
    }
    comp = summary["paper"]["comparable"]
    if comp["table_ii"]["comparable"]:
        summary["paper"]["tests"] = paper_tests(summary["methods"], summary["by_scenario"], methods, comp["scenes"])
    if variants:
        summary["variants"] = variant_summary(rows, base_methods, variants, summary["methods"])
    return summary


def relabel(rows: Sequence[dict], methods: Sequence[str], variants: dict) -> tuple[list[dict], list[str]]:
    """Rows whose ``method`` is their report row's name, ``method [axis=value, ...]`` (from the row's params_hash),
    with ``base_method`` and ``variant`` (the combination) added; and those names, each method's combinations in
    order."""
    by_hash = variants["by_hash"]
    out = [{**r, "method": arm_label(r["method"], by_hash.get(r["params_hash"], ())), "base_method": r["method"],
            "variant": by_hash.get(r["params_hash"], ())} for r in rows]
    return out, [arm_label(m, c) for m in methods for c in variants["combinations"]]


#: a method's figures under each combination in summary.json's ``variants.by_method`` (as in ``methods``)
VARIANT_FIGURES = ("ok", "success_pct", "success_ci95_pct", "collisions", "collision_pct", "collision_ci95_pct",
                   "at_fault_collisions", "at_fault_collision_pct", "at_fault_collision_ci95_pct",
                   "passive_collisions", "passive_collision_pct", "passive_collision_ci95_pct", "qp_infeasible_pct",
                   "qp_infeasible_ci95_pct", "velocity_relaxed_pct")
#: the episode outcomes whose paired differences between variants summary.json gives
PAIRED_OUTCOMES = ("success", "collision", "at_fault_collision", "passive_collision")


def variant_summary(rows: Sequence[dict], methods: Sequence[str], variants: dict, per_arm: dict) -> dict:
    """summary.json's ``variants``: the axes (name, configuration path, values), the combinations, each report
    row's method, combination and params_hash, each method's figures per combination, and each method's paired
    differences (:func:`variant_pairs`)."""
    from .variants import VARIANT_AXES
    combos = variants["combinations"]
    hash_of = {c: h for h, c in variants["by_hash"].items()}
    return {
        "axes": [{"name": a, "path": VARIANT_AXES.get(a).path, "values": list(vs)} for a, vs in variants["axes"]],
        "combinations": [combination_label(c) for c in combos],
        "arms": {arm_label(m, c): {"method": m, "variant": dict(c), "params_hash": hash_of.get(c)}
                 for m in methods for c in combos},
        "by_method": {m: {combination_label(c): {k: per_arm[arm_label(m, c)].get(k) for k in VARIANT_FIGURES}
                          for c in combos} for m in methods},
        "paired": {m: variant_pairs(rows, m, variants["axes"]) for m in methods},
    }


def variant_pairs(rows: Sequence[dict], method: str, axes: Sequence[tuple[str, Sequence[str]]]) -> list[dict]:
    """For each axis and each of its values after the first: ``method``'s episodes with that value paired with its
    episodes with the first value and everything else equal (scene, seed, the other axes' values; pooled over
    those), and the differences value - first of success, any collision, at-fault and passive collision
    (:func:`bigcbf.bench.stats.paired_difference`: Newcombe's interval, McNemar's p) and of the QP infeasible
    fraction of control steps (:func:`bigcbf.bench.stats.paired_ratio_difference`). Episodes without the contact
    classification (older rows) are left out of the two contact comparisons."""
    done = {(r["scenario"], r["seed"], tuple(r["variant"])): r["metrics"] for r in rows
            if r["status"] == "ok" and r.get("base_method") == method}
    out = []
    for i, (axis, values) in enumerate(axes):
        for value in values[1:]:
            pairs = []
            for (scene, seed, combo), mine in sorted(done.items(), key=lambda kv: (kv[0][0], kv[0][1], kv[0][2])):
                if combo[i][1] != value:
                    continue
                ref = done.get((scene, seed, combo[:i] + ((axis, values[0]),) + combo[i + 1:]))
                if ref is not None:
                    pairs.append((mine, ref))
            entry: dict = {"axis": axis, "from": values[0], "to": value, "pairs": len(pairs)}
            for key in PAIRED_OUTCOMES:
                both = [(a, b) for a, b in pairs if key in a and key in b]
                entry[key] = paired_difference([bool(a[key]) for a, _ in both], [bool(b[key]) for _, b in both])
            mine_steps, ref_steps = _infeasible_steps([a for a, _ in pairs]), _infeasible_steps([b for _, b in pairs])
            entry["qp_infeasible"] = paired_ratio_difference(*mine_steps, *ref_steps)
            out.append(entry)
    return out


def default_params_hash(suite: str | None, perception: str = "lidar") -> str | None:
    """The episode key's parameter hash of a suite's default run configuration (the paper's and every other
    suite's: RunConfig(); the hardware suite's: its physical preset), with LiDAR perception (the paper's); None for
    another perception mode (never comparable with the paper)."""
    from ..config import RunConfig
    from .suites import SUITES
    from .tasks import params_key, params_toml

    if perception != "lidar":
        return None
    make = SUITES.get(suite).params if suite in SUITES else None
    return params_key(params_toml(make() if make is not None else RunConfig()), perception)


def provenance(rows: Sequence[dict]) -> dict:
    """The code versions and configuration hashes the rows ran with (sorted, distinct)."""
    return {"code_versions": sorted({r["code_sha"] for r in rows if r.get("code_sha")}),
            "params_hashes": sorted({r["params_hash"] for r in rows if r.get("params_hash")})}


def reference_method(methods: Sequence[str]) -> str | None:
    """The method the others are compared with: BIG-CBF when it ran, else the first (of report rows
    ``method [variant]``: their methods)."""
    bases = [split_label(m)[0] for m in methods]
    return "big-cbf" if "big-cbf" in bases else (bases[0] if bases else None)


def paired(rows: Sequence[dict], methods: Sequence[str]) -> dict:
    """{"reference": M, "by_method": {method: paired_difference(method, M)}} over the (scenario, seed) pairs both
    finished without error (:func:`bigcbf.bench.stats.paired_difference`). A report row ``method [variant]`` is
    compared with the reference method under the same variant."""
    ref = reference_method(methods)
    done = {}
    for r in rows:
        if r["status"] == "ok":
            done[(r["method"], r["scenario"], r["seed"])] = bool(r["metrics"]["success"])
    out = {}
    for m in methods:
        variant = split_label(m)[1]
        ref_row = f"{ref} [{variant}]" if variant else ref
        if m == ref_row:
            continue
        keys = sorted(k[1:] for k in done if k[0] == m and (ref_row, *k[1:]) in done)
        out[m] = paired_difference([done[(m, *k)] for k in keys], [done[(ref_row, *k)] for k in keys])
    return {"reference": ref, "by_method": out}


# --- episodes.csv --------------------------------------------------------------------------------------------------

def write_csv(rows: Sequence[dict], path: Path, groups: dict | None = None, variants: dict | None = None) -> None:
    """Every metric of every episode, one line each; lists and dicts (mode_history, warnings) as JSON text; with
    ``groups``, each scenario's split and family after the key columns; with ``variants``, each episode's
    combination (``route=on, cbf_velocity_rows=off``) in column ``variant`` after them."""
    metric_cols: list[str] = []
    for r in rows:
        for k in r["metrics"] or {}:
            if k not in metric_cols and k not in KEY_FIELDS:
                metric_cols.append(k)
    labels = ["split", "family"] if groups else []
    if variants:
        labels.append("variant")
    cols = (list(KEY_FIELDS) + labels + ["status", "error"] + metric_cols
            + ["worker_wall_s", "host", "code_sha", "attempts"])
    with atomic_output(path, "episode table") as tmp, tmp.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for r in rows:
            m = r["metrics"] or {}
            line = []
            for c in cols:
                if c == "variant":
                    v = combination_label(variants["by_hash"].get(r["params_hash"], ()))
                elif c in labels:
                    v = (groups.get(r["scenario"]) or {}).get(c)
                else:
                    v = m.get(c) if c in metric_cols else r.get(c)
                line.append(json.dumps(v) if isinstance(v, (list, dict)) else ("" if v is None else v))
            w.writerow(line)


# --- summary.json / summary.md -------------------------------------------------------------------------------------

def write_json(summary: dict, path: Path) -> None:
    """summary.json, strict (non-finite numbers are null: strict parsers reject NaN and Infinity)."""
    write_text(path, strict_json(summary, indent=2) + "\n", "summary")


def _f(v, digits: int = 2) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if isinstance(v, int) and not isinstance(v, bool):
        return str(v)
    return f"{v:.{digits}f}"


def _table(header: Sequence[str], lines: Iterable[Sequence[str]], align: str | None = None) -> list[str]:
    align = align or "l" + "r" * (len(header) - 1)
    out = ["| " + " | ".join(header) + " |",
           "|" + "|".join(":---" if a == "l" else "---:" for a in align) + "|"]
    out += ["| " + " | ".join(line) + " |" for line in lines]
    return out


def summary_markdown(summary: dict, *, level: int = 1, image_dir: str = "") -> str:
    """summary.md: Table II's columns per method, success per scenario, the paper's numbers beside ours.

    Length: summary.md's sections in document order, each block one section (the longer ones are already helpers:
    _paired_lines, _contacts_lines, _fault_sections, _table_ii_lines)."""
    h = "#" * level
    b = summary["bench"]
    methods, scenarios = b["methods"], b["scenarios"]
    per_m, per_ms = summary["methods"], summary["by_scenario"]
    n_seeds = len(b["seeds"])
    lines = [f"{h} Benchmark results", ""]
    var = summary.get("variants")
    arms = (f"{len(var['by_method'])} methods x {len(var['combinations'])} variant combinations" if var else
            f"{len(methods)} methods")
    lines.append(f"{b['episodes_recorded']} of {b['episodes_expected']} episodes recorded: {arms} x "
                 f"{len(scenarios)} scenarios x {n_seeds} seed{'s' if n_seeds != 1 else ''} (the same seeds for every "
                 "method); "
                 f"{b['ok']} ran, {b['errors']} crashed (recorded as errors, left out of the figures).")
    names = {"perception": "perception", "params_hash": "parameter hash", "engine": "engine", "workers": "workers",
             "runs": "invocations that ran episodes", "wall_time_s": "their wall time (s)",
             "episodes_per_min": "episodes per minute"}
    extra = [f"{label}: {b[k]}" for k, label in names.items() if b.get(k) is not None]
    if extra:
        lines += ["", "; ".join(extra) + "."]
    if len(b.get("code_versions", [])) > 1:
        lines += ["", f"**Warning:** these episodes ran with {len(b['code_versions'])} different versions of the code "
                  f"({', '.join(b['code_versions'])}; column code_sha of episodes.csv); for consistent numbers, run "
                  "again into a new --out."]
    lines += ["", f"{h}# Aggregate performance (Table II columns)", ""]
    lines += _table(["Method", "Episodes", "Success (%) [95 % CI]", "Time (s)", "Clearance (m)", "E_CBF",
                     "Active (%)", "QP infeas. (%)", "Collisions: n, % [95 % CI]", "Planner P95 (ms)", "Code",
                     "Config"],
                    ([display(m), str(s["ok"]), fmt_ci(s["success_pct"], s.get("success_ci95_pct")), _f(s["time_s"]),
                      _f(s["min_clearance_m"]), _f(s["e_cbf"]), _f(s["cbf_active_pct"]), _f(s["qp_infeasible_pct"]),
                      f"{s['collisions']}: " + fmt_ci(s.get("collision_pct"), s.get("collision_ci95_pct")),
                      _f(s["planner_p95_ms"]), ", ".join(s.get("code_versions", [])) or "–",
                      ", ".join(s.get("params_hashes", [])) or "–"] for m in methods for s in [per_m[m]]))
    lines += ["", "Success and collisions: the share of the episodes with its 95 % Wilson interval. Time: mean over "
              "successful episodes. Clearance, E_CBF (eq:sim_cbf_energy (27)): means over episodes. Active, QP "
              "infeas.: share of all control steps. Planner P95: mean of the per-episode P95 wall time. Code: the "
              "code versions the method's episodes ran with; Config: the run configuration's hash (the episode "
              "key's params_hash).", ""]
    lines += _variant_lines(summary, h)
    lines += _paired_lines(summary, h)
    lines += _contacts_lines(methods, [per_m[m] for m in methods], h)
    lines += [f"{h}# Chatter and stall", ""]
    lines += _liveness_table(methods, [per_m[m] for m in methods], first="Method")
    lines += ["", LIVENESS_NOTE, ""]
    lines += [f"{h}# CBF burden and shared-uncertainty margins", ""]
    lines += _table(["Method", "Active, steps (%)", "Active, episode mean (%)", "E_CBF", "E_CBF from infeasible (%)",
                     "m img mean / p90 (m)", "m exec mean / p90 (m)"],
                    ([display(m), _f(s["cbf_active_pct"]), _f(s["cbf_active_episode_pct"]), _f(s["e_cbf"]),
                      _f(s["e_cbf_infeasible_share_pct"], 1),
                      f"{_f(s['m_img_mean_m'], 3)} / {_f(s['m_img_p90_m'], 3)}",
                      f"{_f(s['m_exec_mean_m'], 3)} / {_f(s['m_exec_p90_m'], 3)}"] for m in methods for s in [per_m[m]]))
    lines += ["", "Active, steps: share of all control steps (the paper's definition); episode mean: mean of the "
              "episodes' ratios. m: the margin kappa_l m_i that each layer adds to r_R + r_i + d0 "
              "(eq:shared_barrier (20)), the mean over episodes of the episode's mean / 90th percentile; imagination "
              "over the selected rollout's steps and obstacles at each selection (NoShared: its fixed margin), "
              "execution over the CBF rows at each control step.", ""]
    fam = summary.get("by_family")
    if fam:     # procedural worlds and faults: the paper's tables are about its own scenes, not these
        lines += _fault_sections(summary, h) if summary.get("by_fault") else _family_sections(summary, h)
        lines += [f"![success rate per method, family and split]({image_dir}success_heatmap.png)", "",
                  f"![CBF burden per method]({image_dir}cbf_burden.png)", ""]
        return _errors_section(summary, h, lines)
    lines += [f"{h}# Per scenario: CBF activation and margins", ""]
    lines += _table(["Method", "Scenario", "Success (%)", "Active, steps / episode mean (%)", "E_CBF",
                     "E_CBF from infeasible (%)", "m img mean / p90 (m)", "m exec mean / p90 (m)"],
                    ([display(m), sc.replace("_", " "), _f(s["success_pct"], 0),
                      f"{_f(s['cbf_active_pct'])} / {_f(s['cbf_active_episode_pct'])}", _f(s["e_cbf"]),
                      _f(s["e_cbf_infeasible_share_pct"], 1),
                      f"{_f(s['m_img_mean_m'], 3)} / {_f(s['m_img_p90_m'], 3)}",
                      f"{_f(s['m_exec_mean_m'], 3)} / {_f(s['m_exec_p90_m'], 3)}"]
                     for m in methods for sc in scenarios for s in [per_ms[m][sc]]), align="llrrrrrr")
    lines += ["", f"{h}# Success per scenario (%)", ""]
    lines += _table(["Method"] + [s.replace("_", " ") for s in scenarios],
                    ([display(m)] + [_f(per_ms[m][s]["success_pct"], 0) for s in scenarios] for m in methods))
    lines += ["", f"![success rate per method and scenario]({image_dir}success_heatmap.png)", "",
              f"![CBF burden per method]({image_dir}cbf_burden.png)", ""]
    if b.get("suite") == "hardware":
        lines += _table_iii_lines(summary, methods, h)
    else:
        lines += _table_ii_lines(summary, methods, scenarios, h)
    return _errors_section(summary, h, lines)


def _variant_lines(summary: dict, h: str) -> list[str]:
    """The variants (summary["variants"]): each method's figures per combination (one column group each), then its
    paired differences value vs first value of each axis."""
    var = summary.get("variants")
    if not var:
        return []
    combos = var["combinations"]
    single = len(var["axes"]) == 1
    short = [c.split("=", 1)[1] if single else c for c in combos]
    axes = "; ".join(f"{a['name']} ({a['path']}): {', '.join(a['values'])}" for a in var["axes"])
    lines = [f"{h}# Variants: every method under each combination", "",
             f"Every method ran under every combination of {axes}, on the same scenes and seeds (rows above: "
             "`method [axis=value]`). Per method and combination:", ""]
    cols = ["Success (%)", "Collisions", "At fault", "Passive", "QP infeas. (%)", "Cone relaxed (%)"]
    head = ["Method"] + [f"{c}: {col}" for c in short for col in cols]
    body = []
    for m, per in var["by_method"].items():
        row = [display(m)]
        for c in combos:
            s = per[c]
            row += [fmt_ci(s["success_pct"], s["success_ci95_pct"]),
                    "–" if s["collisions"] is None or not s["ok"] else
                    f"{s['collisions']}: " + fmt_ci(s["collision_pct"], s["collision_ci95_pct"]),
                    _contact_cell(s, "at_fault"), _contact_cell(s, "passive"),
                    fmt_ci(s["qp_infeasible_pct"], s["qp_infeasible_ci95_pct"], 2), _f(s.get("velocity_relaxed_pct"))]
        body.append(row)
    lines += _table(head, body)
    lines += ["", "Each cell: n: % [95 % interval] (Wilson; success as % only). At fault / passive: contacts the robot "
              "drove into / did not (bigcbf/sim/contacts.py). QP infeas.: infeasible control steps / all control "
              "steps, its interval from the spread between episodes (bigcbf/bench/stats.py). Cone relaxed: control steps whose "
              "distance rows held but not every velocity-aware row (the filter's lexicographic fallback).", "",
              f"{h}# Variants: paired differences (each value vs the first, same method, scenes and seeds)", ""]
    body = []
    for m, entries in var["paired"].items():
        for e in entries:
            body.append([display(m), f"{e['axis']}: {e['from']} → {e['to']}", str(e["pairs"])]
                        + [_diff_cell(e[k]) for k in PAIRED_OUTCOMES]
                        + [fmt_ci(e["qp_infeasible"]["diff_pct"], e["qp_infeasible"]["ci95_pct"], 2)])
    lines += _table(["Method", "Change", "Pairs", "Success Δ (pp), p", "Collision Δ (pp), p", "At fault Δ (pp), p",
                     "Passive Δ (pp), p", "QP infeas. Δ (pp)"], body, align="ll" + "r" * 6)
    lines += ["", "Δ: the rate with the second value minus the rate with the first, over the episodes both ran "
              "(same scene and seed, the other axes' values equal), in percentage points with the 95 % interval of "
              "Newcombe's method 10, and the exact McNemar p; QP infeas. Δ: the difference of the pooled fractions "
              "with its paired interval. An interval that excludes 0 is a significant difference at the 5 % level.",
              ""]
    return lines


def _diff_cell(d: dict) -> str:
    """'+4.0 [-2.1, 10.3], p 0.5' of a paired difference, '–' without pairs."""
    if d["diff_pct"] is None:
        return "–"
    return f"{d['diff_pct']:+.1f} [{d['ci95_pct'][0]:.1f}, {d['ci95_pct'][1]:.1f}], p {d['mcnemar_p']:.3g}"


def _paired_lines(summary: dict, h: str) -> list[str]:
    """The paired differences in success against the reference method (summary["paired"])."""
    pr = summary.get("paired") or {}
    ref, by = pr.get("reference"), pr.get("by_method") or {}
    if not by:
        return []
    lines = [f"{h}# Paired differences in success (vs {display(ref)})", ""]
    lines += _table(["Method", "Pairs", f"Only this succeeded", f"Only {display(ref)} succeeded",
                     "Difference (pp) [95 % CI]", "McNemar p"],
                    ([display(m), str(d["n"]), str(d["b"]), str(d["c"]), fmt_ci(d["diff_pct"], d["ci95_pct"]),
                      "–" if d["mcnemar_p"] is None else f"{d['mcnemar_p']:.3g}"] for m, d in by.items()))
    lines += ["", f"Each method's success minus {display(ref)}'s over the episodes both finished (same scene, same "
              "seed" + (", same variant" if summary.get("variants") else "") + "), in percentage points, with the 95 % "
              "interval of Newcombe's method 10 for paired proportions and the exact McNemar test of the discordant "
              "pairs (bigcbf/bench/stats.py). An interval that excludes 0 is a significant difference at the 5 % "
              "level.", ""]
    return lines


def _errors_section(summary: dict, h: str, lines: list[str]) -> str:
    errs = summary["error_episodes"]
    if errs:
        lines += ["", f"{h}# Episodes that crashed", ""]
        lines += [f"- {e['scenario']} / {e['method']} / seed {e['seed']}: {e['error']}" for e in errs[:50]]
        if len(errs) > 50:
            lines.append(f"- ... and {len(errs) - 50} more (see episodes.csv)")
    return "\n".join(lines) + "\n"

def _verdict(summary: dict, table: str) -> dict:
    """Whether the bench's figures may stand beside the paper's ``table`` (:func:`bigcbf.bench.paper.comparability`);
    a summary.json written before that check existed is taken as not comparable, for want of evidence."""
    comp = summary["paper"].get("comparable")
    if comp is None:
        return {"comparable": False, "why": "this summary predates the comparability check; run the bench again",
                "scenes": []}
    return {**comp[table], "scenes": comp.get("scenes", [])}


def _table_iii_lines(summary: dict, methods: Sequence[str], h: str) -> list[str]:
    """Ours beside the paper's Table III (the hardware suite)."""
    per_m = summary["methods"]
    paper = summary["paper"]["table_iii"]
    verdict = _verdict(summary, "table_iii")
    if not verdict["comparable"]:
        return [f"{h}# The paper's Table III", "",
                f"Not comparable with the paper's Table III, so its figures are not shown beside these: "
                f"{verdict['why']}. (`bigcbf bench --out DIR --suite hardware` runs its three scenes.)"]
    lines = [f"{h}# Ours beside the paper's Table III (hardware)", "",
             "Each pair is ours (the twin: the lab-scale scenes with a real X3-class robot profile and the physical "
             "preset) / the paper's (a physical X3, 15 supervised trials per method: three scenes x 5; its success "
             "as k/15). – where the paper gives no number.", ""]
    cols = [("Time (s)", "time_s"), ("Clearance (m)", "min_clearance_m"), ("E_CBF", "e_cbf"),
            ("Active (%)", "cbf_active_pct"), ("QP infeas. (%)", "qp_infeasible_pct"), ("Collisions", "collisions")]

    def success(m):
        s, pp = per_m[m], paper.get(m, {})
        ours = (f"{summary_successes(s)[0]}/{s['ok']} ({_f(s['success_pct'], 1)})" if s["success_pct"] is not None
                else "–")
        theirs = f"{pp['successes']}/{pp['trials']} ({_f(pp['success_pct'], 1)})" if pp else "–"
        return f"{ours} / {theirs}"
    lines += _table(["Method", "Episodes", "Success (%)"] + [c for c, _ in cols],
                    ([display(m), str(per_m[m]["ok"]), success(m)]
                     + [f"{_f(per_m[m][k])} / {_f(paper.get(m, {}).get(k))}" for _, k in cols] for m in methods))
    return lines


def _table_ii_lines(summary: dict, methods: Sequence[str], scenarios: Sequence[str], h: str) -> list[str]:
    """Ours beside the paper's Table II (and the per-scenario success its text quotes)."""
    per_m, per_ms = summary["methods"], summary["by_scenario"]
    lines: list[str] = []
    paper = summary["paper"]["table_ii"]
    verdict = _verdict(summary, "table_ii")
    if not verdict["comparable"]:
        lines += [f"{h}# The paper's Table II", "",
                  f"Not comparable with the paper's Table II, so its figures are not shown beside these: "
                  f"{verdict['why']}. (The paper: the nine scenes, 50 seeds each, every method with its defaults; "
                  "`bigcbf bench --out DIR` runs exactly that.)"]
        return lines
    lines += [f"{h}# Ours beside the paper's Table II", "",
              "Each pair is ours / the paper's (the paper: 450 episodes per method, its own simulator; collisions and "
              "planner P95 from its text; – where the paper gives no number).", ""]
    cols = [("Success (%)", "success_pct"), ("Time (s)", "time_s"), ("Clearance (m)", "min_clearance_m"),
            ("E_CBF", "e_cbf"), ("Active (%)", "cbf_active_pct"), ("QP infeas. (%)", "qp_infeasible_pct"),
            ("Collisions", "collisions"), ("Planner P95 (ms)", "planner_p95_ms")]
    lines += _table(["Method"] + [c for c, _ in cols],
                    ([display(m)] + [f"{_f(per_m[m][k])} / {_f(paper.get(m, {}).get(k))}" for _, k in cols]
                     for m in methods))
    quoted = [s for s in scenarios if s in summary["paper"]["scenario_success_pct"] and s in verdict["scenes"]]
    if quoted:
        pss = summary["paper"]["scenario_success_pct"]
        lines += ["", "Success per scenario where the paper's text quotes it, ours / the paper's (%):", ""]
        lines += _table(["Method"] + [s.replace("_", " ") for s in quoted],
                        ([display(m)] + [f"{_f(per_ms[m][s]['success_pct'], 0)} / {_f(pss[s].get(m), 0)}"
                                         for s in quoted] for m in methods))
    tests = summary["paper"].get("tests")
    if tests:
        def cell(t):
            if t is None or t["diff_pct"] is None:
                return "–"
            mark = " *" if t["fisher_p"] < 0.05 else ""
            return (f"{t['diff_pct']:+.1f} [{t['ci95_pct'][0]:+.1f}, {t['ci95_pct'][1]:+.1f}] "
                    f"p {t['fisher_p']:.2g}{mark}")
        lines += ["", "Success against the paper's, two-sample tests: ours minus the paper's in percentage points, "
                      "Newcombe's 95 % interval for independent proportions, Fisher's exact two-sided p; * where "
                      "p < 0.05 (overall: our episodes of the nine vs the paper's 450; per scene: vs its 50).", ""]
        lines += _table(["Method", "Overall"] + [s.replace("_", " ") for s in quoted],
                        ([display(m), cell(tests[m]["overall"])] + [cell(tests[m]["scenes"].get(s)) for s in quoted]
                         for m in methods if m in tests))
    return lines


LIVENESS_NOTE = ("Means over episodes (bigcbf/control/liveness.py): mode switches per minute; left/right reversals "
                 "of the mode history (PASS/SIDE-L vs -R, through any neutral modes; 0 for methods without sided "
                 "modes) and of the command's lateral component relative to the goal direction (every method; "
                 "0.1 m/s dead band, a side counts once held 0.25 s); time in 2 s windows that brought the robot "
                 "less than 0.1 m closer to the goal; time below the freeze speed.")


def _liveness_table(labels: Sequence[str], stats: Sequence[dict], first: str) -> list[str]:
    return _table([first, "Episodes", "Switches/min", "Reversals (modes)", "Reversals (command)",
                   "No progress (s)", "Stopped (s)"],
                  ([display(lab), str(s["ok"]), _f(s["mode_switches_per_min"], 1), _f(s["side_reversals"]),
                    _f(s["lateral_reversals"]), _f(s["no_progress_s"], 1), _f(s["stopped_time_s"], 1)]
                   for lab, s in zip(labels, stats)))


def _family_sections(summary: dict, h: str) -> list[str]:
    """Success per family for each split, then every figure per method and family."""
    fam = summary["by_family"]
    methods = summary["bench"]["methods"]
    groups = summary["groups"]
    lines = []
    for split in fam[methods[0]]:
        families = [f for f in fam[methods[0]][split] if f != "all"]
        n_worlds = {f: sum(g["split"] == split and g["family"] == f for g in groups.values()) for f in families}
        total = sum(n_worlds.values())
        lines += [f"{h}# Success per family (%), split {split}", "",
                  f"{total} world{'s' if total != 1 else ''} ({', '.join(f'{f} {n}' for f, n in n_worlds.items())}); "
                  "each cell: success % over the episodes that ran.", ""]
        lines += _table(["Method"] + families + ["all"],
                        ([display(m)] + [_f(fam[m][split][f]["success_pct"], 0) for f in families + ["all"]]
                         for m in methods))
        lines += ["", f"{h}# Per family, split {split}", ""]
        head = ["Method", "Family", "Episodes", "Success (%) [95 % CI]", "Collisions", "At fault", "Passive",
                "Timeouts", "Time (s)", "Switches/min", "Reversals (modes)", "Reversals (command)",
                "No progress (s)"]
        body = []
        for m in methods:
            for f in families + ["all"]:
                s = fam[m][split][f]
                body.append([display(m), f, str(s["ok"]), fmt_ci(s["success_pct"], s.get("success_ci95_pct")),
                             _f(s["collisions"]), _contact_cell(s, "at_fault"), _contact_cell(s, "passive"),
                             _f(s["timeouts"]), _f(s["time_s"], 1), _f(s["mode_switches_per_min"], 1),
                             _f(s["side_reversals"]), _f(s["lateral_reversals"]), _f(s["no_progress_s"], 1)])
        lines += _table(head, body, align="ll" + "r" * (len(head) - 2)) + [""]
    return lines


def _fault_sections(summary: dict, h: str) -> list[str]:
    """The faults suite: collisions and success per method and fault (levels none / mild / severe), then one table
    per fault with every level."""
    bf = summary["by_fault"]
    methods = summary["bench"]["methods"]
    faults = list(bf)
    n_seeds = len(summary["bench"]["seeds"])

    def cells(key, digits=None):
        out = []
        for m in methods:
            row = [display(m)]
            for f in faults:
                vals = [bf[f]["levels"][lv][m][key] for lv in bf[f]["levels"]]
                row.append(" / ".join(_f(v) if digits is None else _f(v, digits) for v in vals))
            out.append(row)
        return out
    levels = " / ".join(next(iter(bf.values()))["levels"]) if bf else ""
    lines = [f"{h}# Collisions per method and fault ({levels})", "",
             f"Each fault on its scenes ({n_seeds} seed{'s' if n_seeds != 1 else ''} each; the same worlds at every "
             "level: level none is the shipped scene itself). Faults and levels: bigcbf/bench/faults.py and the "
             "tables below.", ""]
    lines += _table(["Method"] + faults, cells("collisions"))
    lines += ["", f"{h}# At-fault collisions per method and fault ({levels})", "",
              "Contacts the robot moved into (its speed along the contact normal above v_freeze at first contact; "
              "the others were passive: bigcbf/sim/contacts.py).", ""]
    lines += _table(["Method"] + faults, cells("at_fault_collisions"))
    lines += ["", f"{h}# Success per method and fault (%, {levels})", ""]
    lines += _table(["Method"] + faults, cells("success_pct", 0))
    for f in faults:
        d = bf[f]
        lines += ["", f"{h}# Fault {f}: {d['description']}", "",
                  f"Scenes: {', '.join(s.replace('_', ' ') for s in d['scenes'])}. "
                  + " ".join(f"{lv}: {txt}." for lv, txt in d["levels_described"].items()), ""]
        head = ["Method", "Level", "Episodes", "Success (%)", "Collisions", "At fault", "Timeouts", "Time (s)",
                "Clearance (m)", "Goal error (m)", "QP infeas. (%)", "Missed scans"]
        body = []
        for m in methods:
            for lv, per_m in d["levels"].items():
                s = per_m[m]
                body.append([display(m), lv, str(s["ok"]), _f(s["success_pct"], 1), _f(s["collisions"]),
                             _f(s["at_fault_collisions"]), _f(s["timeouts"]), _f(s["time_s"], 1), _f(s["min_clearance_m"]), _f(s["goal_error_m"]),
                             _f(s["qp_infeasible_pct"]), _f(s["missed_scans"], 1)])
        lines += _table(head, body, align="ll" + "r" * (len(head) - 2))
    lines += ["", "Clearance: mean over episodes of the minimum true clearance. Goal error: the true distance to the "
              "goal at the end of the successful episodes (success is judged on the robot's odometry). Missed "
              "scans: LiDAR scans that never arrived, mean per episode.", ""]
    return lines


# --- figures -------------------------------------------------------------------------------------------------------

def plot_heatmap(summary: dict, path: Path) -> None:
    """Method x scenario success rate, annotated in %, like the paper's Fig. 6."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    methods, scenarios = summary["bench"]["methods"], summary["bench"]["scenarios"]
    fam = summary.get("by_family")
    if fam:     # columns: family and split
        cols = [(sp, f) for sp in fam[methods[0]] for f in fam[methods[0]][sp] if f != "all"]
        cells = [[fam[m][sp][f] for sp, f in cols] for m in methods]
        scenarios = [f"{f}_({sp})" for sp, f in cols]
    else:
        cells = [[summary["by_scenario"][m][s] for s in scenarios] for m in methods]
    z = np.array([[np.nan if c["success_pct"] is None else c["success_pct"] for c in row] for row in cells], float)
    fig, ax = plt.subplots(figsize=(max(6.5, 2.2 + 1.05 * len(scenarios)), 1.6 + 0.5 * len(methods)), dpi=150)
    im = ax.imshow(z, cmap="RdYlGn", vmin=0, vmax=100, aspect="auto")
    for i in range(len(methods)):
        for j in range(len(scenarios)):
            v = z[i, j]
            colour = "black" if np.isnan(v) or 25 < v < 85 else "white"
            ax.text(j, i - 0.1, "–" if np.isnan(v) else f"{v:.0f}", ha="center", va="center", fontsize=9,
                    color=colour, fontweight="bold")
            ci = cells[i][j].get("success_ci95_pct")
            if ci is not None:          # the 95 % Wilson interval under the rate
                ax.text(j, i + 0.18, f"{ci[0]:.0f}-{ci[1]:.0f}", ha="center", va="center", fontsize=6, color=colour)
            hits = _heatmap_contacts(cells[i][j])
            if hits:                    # contacts: at fault / passive (or all, unclassified)
                ax.text(j, i + 0.38, hits, ha="center", va="center", fontsize=5, color=colour)
    ax.set_xticks(range(len(scenarios)), [s.replace("_", "\n") for s in scenarios], fontsize=8)
    ax.set_yticks(range(len(methods)), [display(m) for m in methods], fontsize=9)
    ax.tick_params(length=0)
    n = len(summary["bench"]["seeds"])
    if summary.get("by_fault"):
        ax.set_title(f"Success rate (%) per method, fault and level (none: without the fault)\n({n} "
                     f"seed{'s' if n != 1 else ''} per scene, paired{HIT_NOTE})", fontsize=10)
    elif fam:
        ax.set_title(f"Success rate (%) per method, family and split\n({n} seed{'s' if n != 1 else ''} per world, "
                     f"paired{HIT_NOTE})", fontsize=10)
    else:
        ax.set_title(f"Success rate (%) per method and scenario, 95 % interval below\n({n} seed{'s' if n != 1 else ''} "
                     f"each, paired{HIT_NOTE})", fontsize=10)
    fig.colorbar(im, ax=ax, fraction=0.03, pad=0.02, label="success (%)")
    fig.tight_layout()
    _savefig(fig, path)


#: the heatmaps' legend of their contact lines
HIT_NOTE = "; hit nF mP: contacts at fault / passive"


def _heatmap_contacts(s: dict) -> str:
    """A heatmap cell's contact line: 'hit 2F 1P' (at fault, passive), 'hit 3' unclassified, '' without."""
    if not s.get("collisions"):
        return ""
    if s.get("at_fault_collisions") is None:
        return f"hit {s['collisions']}"
    return f"hit {s['at_fault_collisions']}F {s['passive_collisions']}P"


def plot_burden(summary: dict, path: Path) -> None:
    """Mean E_CBF and CBF-active % per method (bars), with the paper's Table II values (black diamonds)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    methods = summary["bench"]["methods"]
    table = "table_iii" if summary["bench"].get("suite") == "hardware" else "table_ii"
    paper = summary["paper"][table] if _verdict(summary, table)["comparable"] else {}
    y = np.arange(len(methods))
    fig, axes = plt.subplots(1, 2, figsize=(10, 1.6 + 0.45 * len(methods)), dpi=150, sharey=True,
                             layout="constrained")
    for ax, key, label in ((axes[0], "e_cbf", "mean $E_{CBF}$ per episode, eq:sim_cbf_energy (27)"),
                           (axes[1], "cbf_active_pct", "CBF active (% of control steps)")):
        ours = np.array([np.nan if (v := summary["methods"][m][key]) is None else v for m in methods], float)
        ref = np.array([np.nan if (v := paper.get(m, {}).get(key)) is None else v for m in methods], float)
        ax.barh(y, np.nan_to_num(ours), color="tab:blue", alpha=0.8, label="ours")
        if paper:
            ax.scatter(ref, y, marker="D", color="black", zorder=3,
                       label="paper (Table III)" if table == "table_iii" else "paper (Table II)")
        for yi, v in zip(y, ours):
            if not np.isnan(v):
                ax.text(v, yi + 0.32, f" {v:.2f}", va="center", fontsize=7, color="tab:blue")
        if key == "e_cbf":
            ax.set_xscale("symlog", linthresh=0.01)
        top = np.nanmax(np.concatenate([ours, ref, [1e-3]]))
        ax.set_xlim(0, top * (3.0 if key == "e_cbf" else 1.2))
        ax.set_xlabel(label, fontsize=9)
        ax.grid(axis="x", alpha=0.3)
    axes[0].set_yticks(y, [display(m) for m in methods], fontsize=9)
    axes[0].invert_yaxis()
    handles, labels = axes[1].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, loc="outside lower center", ncol=2, frameon=False)
    title = "Burden on the common CBF filter (lower: the planner's commands need less correction)"
    if not paper:
        title += "\nthe paper's figures left out: not comparable (" + _verdict(summary, table)["why"][:90] + ")"
    fig.suptitle(title, fontsize=10)
    _savefig(fig, path)


def _savefig(fig, path: Path) -> None:
    import matplotlib.pyplot as plt
    try:
        with atomic_output(path, "figure") as tmp:
            fig.savefig(tmp)
    finally:
        plt.close(fig)


# --- everything at once --------------------------------------------------------------------------------------------

def write_reports(out: Path, rows: Sequence[dict], methods: Sequence[str], scenarios: Sequence[str],
                  seeds: Sequence[int], info: dict | None = None, groups: dict | None = None,
                  variants: dict | None = None) -> dict:
    """Write episodes.csv, summary.json, summary.md and the two figures into ``out``; return the summary.
    ``groups``: scenario name -> {"split", "family"} (suites with splits); ``variants``: the bench's variant
    combinations (:func:`build_summary`)."""
    out = Path(out)
    summary = build_summary(rows, methods, scenarios, seeds, info, groups, variants)
    write_csv(rows, out / "episodes.csv", groups, variants)
    write_json(summary, out / "summary.json")
    write_text(out / "summary.md", summary_markdown(summary), "summary")
    plot_heatmap(summary, out / "success_heatmap.png")
    plot_burden(summary, out / "cbf_burden.png")
    return summary


def update_docs_page(page: Path, out: Path) -> None:
    """Put a bench's results into a Markdown page, between the DOCS_BEGIN and DOCS_END marker lines, and copy the
    figures to ``<page dir>/<page stem>/`` (e.g. docs/benchmark.md -> docs/benchmark/success_heatmap.png)."""
    page, out = Path(page), Path(out)
    text = check_docs_page(page)
    try:
        summary = json.loads((out / "summary.json").read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise UserError(f"no readable summary.json ({exc})", file=str(out / "summary.json")) from None
    img_dir = page.parent / page.stem
    for name in FIGURES:
        with atomic_output(img_dir / name, "figure") as tmp:
            shutil.copyfile(out / name, tmp)
    body = summary_markdown(summary, level=3, image_dir=f"{page.stem}/")
    head, rest = text.split(DOCS_BEGIN)
    _, tail = rest.split(DOCS_END)
    write_text(page, f"{head}{DOCS_BEGIN}\n{body}{DOCS_END}{tail}", "page")


def check_docs_page(page: Path) -> str:
    """``bench --docs PAGE`` before the bench runs: the page is a readable UTF-8 file with the two marker lines,
    and it and its figure folder can be written. Returns its text."""
    page = Path(page)
    try:
        text = page.read_bytes().decode("utf-8")
    except OSError as exc:
        raise UserError(f"cannot read the page ({exc.strerror or exc})", file=str(page)) from None
    except UnicodeDecodeError:
        raise UserError("the page is not UTF-8 text", file=str(page)) from None
    if text.count(DOCS_BEGIN) != 1 or text.count(DOCS_END) != 1 or text.index(DOCS_BEGIN) > text.index(DOCS_END):
        raise UserError(f"the page needs one line '{DOCS_BEGIN}' and, after it, one line '{DOCS_END}'",
                        file=str(page))
    check_output_file(page, "page")
    check_output_dir(page.parent / page.stem, "page's figure folder")
    return text


def default_order(methods: Iterable[str], scenarios: Iterable[str]) -> tuple[list[str], list[str]]:
    """Methods and scenarios in the paper's order (others after, in the given order)."""
    return ordered(methods, METHOD_ORDER), ordered(scenarios, SCENARIO_ORDER)


__all__ = ["summarize", "build_summary", "write_csv", "write_json", "summary_markdown", "plot_heatmap",
           "plot_burden", "write_reports", "update_docs_page", "check_docs_page", "default_order", "TABLE2_KEYS"]
