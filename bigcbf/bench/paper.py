"""The paper's reported benchmark numbers (Sec. IV-B), to print beside ours, and the paper's display order.

Sources in ``paper/big-cbf.tex``:
- Table II (``tab:overall_sim``): success %, time (s), clearance (m), E_CBF, CBF active %, QP infeasible % for
  each of the eight methods, 450 episodes each (9 scenarios x 50 seeds).
- The text of Sec. IV-B: zero collisions for every method; planner P95 for BIG-CBF (55.68 ms), MPPI (77.80 ms)
  and DWA (2.12 ms); per-scenario success in required sidestepping, multi-static clutter and corridor meeting
  ("BIG-CBF achieved 98% in corridor meeting, where all comparison methods achieved 100%").
- Table III (``tab:real_results``): the hardware evaluation (Sec. V-B), 15 supervised trials per method (three
  scenes x 5): successes of 15, time (s), clearance (m), E_CBF, CBF active %, QP infeasible %.
Numbers the paper does not give are ``None`` (never guessed).
"""
from __future__ import annotations

#: Methods in the paper's Table II order (our registry names).
METHOD_ORDER = ("cbf-only", "backup-cbf", "pl-cbf", "apf", "dwa", "mppi", "big-cbf-noshared", "big-cbf")

#: Scenarios in the order of the paper's scenario figure (fig:simulation_scenarios), panels (a)-(i).
SCENARIO_ORDER = ("blind_corner", "corridor_meeting", "single_person_crossing", "crowd_crossing", "delay_and_slip",
                  "double_squeeze", "mixed_dense_traffic", "multi_static_clutter", "required_sidestepping")

#: How the paper names each method.
DISPLAY_NAME = {
    "cbf-only": "CBF-only", "backup-cbf": "Backup-CBF + CBF", "pl-cbf": "PL-CBF + CBF", "apf": "APF + CBF",
    "dwa": "DWA + CBF", "mppi": "MPPI + CBF", "big-cbf-noshared": "BIG-CBF-NoShared", "big-cbf": "BIG-CBF",
}

#: Table II columns, in our summary's keys.
TABLE2_KEYS = ("success_pct", "time_s", "min_clearance_m", "e_cbf", "cbf_active_pct", "qp_infeasible_pct")

_T2 = {  # success %, time s, clearance m, E_CBF, active %, QP infeasible %   (Table II, verbatim)
    "cbf-only": (68.67, 15.13, 0.35, 7.03, 62.51, 0.04),
    "backup-cbf": (76.00, 13.70, 0.35, 4.97, 39.06, 0.06),
    "pl-cbf": (74.89, 14.51, 0.33, 6.08, 44.29, 0.08),
    "apf": (82.44, 14.52, 0.51, 0.17, 14.73, 0.00),
    "dwa": (93.78, 11.31, 0.41, 0.83, 30.24, 0.03),
    "mppi": (83.33, 12.35, 0.41, 0.45, 36.94, 0.03),
    "big-cbf-noshared": (98.89, 11.21, 0.52, 0.10, 15.64, 0.00),
    "big-cbf": (99.78, 11.72, 0.55, 0.02, 9.10, 0.00),
}
_PLANNER_P95_MS = {"big-cbf": 55.68, "mppi": 77.80, "dwa": 2.12}

#: The paper's aggregate numbers per method: Table II plus collisions (0 for all, text) and planner P95 (text).
PAPER_TABLE_II: dict[str, dict[str, float | int | None]] = {
    m: {**dict(zip(TABLE2_KEYS, v)), "collisions": 0, "planner_p95_ms": _PLANNER_P95_MS.get(m)}
    for m, v in _T2.items()
}

#: Per-scenario success % quoted in the text of Sec. IV-B (the heatmap itself is not in the source).
PAPER_SCENARIO_SUCCESS: dict[str, dict[str, float]] = {
    "required_sidestepping": {"cbf-only": 50, "backup-cbf": 52, "pl-cbf": 52, "apf": 56, "dwa": 100, "mppi": 66,
                              "big-cbf-noshared": 100, "big-cbf": 100},
    "multi_static_clutter": {"cbf-only": 0, "backup-cbf": 0, "pl-cbf": 0, "apf": 0, "dwa": 68, "mppi": 2,
                             "big-cbf-noshared": 94, "big-cbf": 100},
    "corridor_meeting": {**{m: 100 for m in METHOD_ORDER}, "big-cbf": 98},
}


def display(method: str) -> str:
    """The paper's name of a method (the registry name for methods the paper does not have)."""
    return DISPLAY_NAME.get(method, method)


def ordered(names, order) -> list[str]:
    """``names`` sorted by their position in ``order``; names not in ``order`` keep their relative order, last."""
    names = list(names)
    rank = {n: i for i, n in enumerate(order)}
    return sorted(names, key=lambda n: (rank.get(n, len(rank)), names.index(n)))


#: Table III columns, in our summary's keys (success as a percentage of the 15 trials; the paper prints "k/15").
TABLE3_KEYS = ("success_pct", "time_s", "min_clearance_m", "e_cbf", "cbf_active_pct", "qp_infeasible_pct")
TABLE3_TRIALS = 15

_T3 = {  # successes of 15, time s, clearance m, E_CBF, active %, QP infeasible %   (Table III, verbatim)
    "cbf-only": (7, 21.62, 0.29, 11.04, 88.60, 0.12),
    "backup-cbf": (8, 19.80, 0.21, 1.65, 59.60, 0.09),
    "pl-cbf": (9, 19.92, 0.16, 1.49, 55.20, 0.43),
    "apf": (1, 29.75, 0.29, 0.28, 29.60, 0.04),
    "dwa": (13, 12.32, 0.14, 0.88, 47.30, 1.42),
    "mppi": (9, 20.56, 0.27, 0.40, 42.85, 0.10),
    "big-cbf-noshared": (15, 11.79, 0.24, 0.60, 39.30, 0.18),
    "big-cbf": (15, 13.18, 0.29, 0.26, 26.9, 0.00),
}

#: The paper's hardware numbers per method (Table III): ``successes`` of ``trials`` as printed, and the columns in
#: our summary's keys (success as a percentage); collisions: none recorded for BIG-CBF (Sec. V: "without a
#: recorded contact event"), not reported for the others (None).
PAPER_TABLE_III: dict[str, dict[str, float | int | None]] = {
    m: {"successes": v[0], "trials": TABLE3_TRIALS, "success_pct": 100.0 * v[0] / TABLE3_TRIALS,
        **dict(zip(TABLE3_KEYS[1:], v[1:])), "collisions": 0 if m == "big-cbf" else None}
    for m, v in _T3.items()
}

#: The hardware scenes of Sec. V in the order of the paper's Fig. 7, (a)-(c): our lab-scale scenario names.
HARDWARE_SCENARIO_ORDER = ("lab_required_sidestepping", "lab_static_clutter", "lab_pedestrian_crossing")


# --- when our figures may stand beside the paper's -----------------------------------------------------------------

#: The paper's seeds per scene (Sec. IV-A: "the same 50 random seeds"; Table II: 450 episodes per method).
PAPER_SEEDS = 50


def paper_successes(pct: float, n: int) -> int:
    """The paper's successes out of its n episodes from the percentage it prints (Table II: k/450 to two decimals,
    e.g. 68.67 % -> 309; the text's per-scene figures: k/50 as whole percents)."""
    return int(round(pct * n / 100.0))


def summary_successes(s: dict) -> tuple[int, int]:
    """(successes, episodes) of a summary row (``report.summarize``: its success % of its ``ok`` episodes)."""
    n = int(s.get("ok") or 0)
    return (int(round(s["success_pct"] * n / 100.0)) if n and s.get("success_pct") is not None else 0), n


def paper_tests(per_method: dict, per_scene: dict, methods, scenes) -> dict:
    """Each method's success against the paper's by a two-sample test (issue 24): overall (ours: all our episodes
    of the nine; the paper's: Table II's rate of 450) and in each scene of ``scenes`` whose rate the paper's text
    quotes (its 50 episodes). Per method ``{"overall": stats.two_sample_difference(...), "scenes": {scene: ...}}``:
    ours minus the paper's in percentage points, Newcombe's 95 % interval, Fisher's exact p."""
    from .stats import two_sample_difference

    out = {}
    for m in methods:
        if m not in PAPER_TABLE_II or m not in per_method:
            continue
        k, n = summary_successes(per_method[m])
        n_paper = PAPER_SEEDS * len(SCENARIO_ORDER)
        row = {"overall": two_sample_difference(k, n, paper_successes(PAPER_TABLE_II[m]["success_pct"], n_paper),
                                                n_paper), "scenes": {}}
        for sc in scenes:
            theirs = PAPER_SCENARIO_SUCCESS.get(sc, {}).get(m)
            if theirs is None or sc not in per_scene.get(m, {}):
                continue
            ks, ns = summary_successes(per_scene[m][sc])
            row["scenes"][sc] = two_sample_difference(ks, ns, paper_successes(theirs, PAPER_SEEDS), PAPER_SEEDS)
        out[m] = row
    return out


def shipped_scene_keys(names) -> dict[str, str]:
    """The bench's scenario key (:func:`bigcbf.bench.tasks.scenario_key`: the file's text and its base robot
    profile's text) of each shipped scene among ``names``: a bench row whose ``scenario_sha`` equals it ran that very
    file, whatever the name; a user's copy with other content differs."""
    from ..scenario import all_scenario_files, base_profile_text
    from .tasks import scenario_key

    files = all_scenario_files()
    out = {}
    for n in names:
        if n in files:
            _, profile = base_profile_text(files[n])
            out[n] = scenario_key(files[n].read_text(), profile)
    return out


def comparability(rows, scenarios, seeds, suite: str | None, default_params_hash: str | None) -> dict:
    """Whether this bench's figures may be shown beside the paper's, and why not.

    Table II (and the per-scene success the paper's text quotes) compare with the paper's own benchmark: 50 seeds
    of each of the nine scenes, every method with the same defaults. Ours stand beside them only when the bench ran
    the shipped scene files -- matched by content (the episode key's scenario hash), not by name --, at the paper's
    50 seeds, with the default run configuration. Table III (the hardware suite) needs the three shipped lab scenes
    by content and the defaults of that suite (its own seed count: the paper's 15 trials are physical runs, which
    no seed count reproduces). Returns ``{"table_ii": {"comparable", "why"}, "scenes": [names whose quoted
    figures may be shown], "table_iii": {"comparable", "why"}}``."""
    scenarios, n_seeds = list(scenarios), len(list(seeds))
    keys = shipped_scene_keys(scenarios)
    ran = {}
    hashes = set()
    for r in rows:
        ran.setdefault(r["scenario"], set()).add(r.get("scenario_sha"))
        hashes.add(r.get("params_hash"))
    same = [s for s in scenarios if s in keys and ran.get(s) == {keys[s]}]
    default = default_params_hash is not None and hashes <= {default_params_hash}

    def verdict(wanted, need_seeds: bool) -> dict:
        why = []
        missing = [s for s in wanted if s not in scenarios]
        if missing:
            why.append(f"{len(missing)} of the paper's {len(wanted)} scenes not in this bench")
        edited = [s for s in wanted if s in scenarios and s not in same]
        if edited:
            why.append("not the shipped file (by content): " + ", ".join(edited))
        extra = [s for s in scenarios if s not in wanted]
        if extra:
            why.append("scenes the paper does not have: " + ", ".join(extra))
        if need_seeds and n_seeds != PAPER_SEEDS:
            why.append(f"{n_seeds} seed{'s' if n_seeds != 1 else ''} per scene, the paper's {PAPER_SEEDS}")
        if not default:
            why.append("a run configuration other than the defaults (--config/--profile/--route/--variant)")
        return {"comparable": not why, "why": "; ".join(why)}

    quoted = [s for s in same if s in PAPER_SCENARIO_SUCCESS] if n_seeds == PAPER_SEEDS and default else []
    return {"table_ii": verdict(SCENARIO_ORDER, True) if suite != "hardware" else
            {"comparable": False, "why": "the hardware suite compares with Table III"},
            "scenes": quoted,
            "table_iii": verdict(HARDWARE_SCENARIO_ORDER, False) if suite == "hardware" else
            {"comparable": False, "why": "only the hardware suite compares with Table III"}}
