#!/usr/bin/env python3
"""Measure each switch of ``big-cbf-plus`` alone, through the switches themselves (issue 24, item 2).

    .venv/bin/python scripts/fidelity_ablations.py --out DIR [--workers 2] [--paper-seeds 3]
        [--worlds-per-family 2] [--only VARIANT ...] [--report-only] [--json FILE] [--markdown FILE]

The variants are run configurations, nothing else (no patching): ``big-cbf-plus`` with its defaults (``plus``);
each switch that is on by default turned off alone (``no_<switch>``); the speed governor, off by default, turned on
alone (``with_speed_governor``); and ``big-cbf`` (the paper as written, every switch off) as the anchor. Each
variant's ``[methods.big-cbf-plus]`` table is written to ``DIR/configs/VARIANT.toml`` and run as two
``bigcbf bench --config VARIANT.toml`` runs: the nine paper scenes at seeds 0..paper_seeds-1 into
``DIR/VARIANT/paper`` and the first ``worlds-per-family`` worlds of every family's **dev** split (written to
``DIR/worlds/dev/`` exactly as ``bigcbf bench --suite generated`` writes them; never the test split), episode
seed 0 as that suite runs them, into ``DIR/VARIANT/dev``. A bench resumes what it has already run, so rerunning
the command finishes an interrupted measurement, and a larger ``--paper-seeds`` or ``--worlds-per-family`` in the
same folder runs only the episodes it adds; the table always holds exactly the episodes the arguments name.

It then prints one Markdown table from the benches' ``episodes.csv``: per variant the successes (nine scenes,
dev worlds, both with the Wilson 95 % interval of ``bigcbf.bench.stats``), the paired difference in success
against ``plus`` over the same (scene or world, seed) episodes (Newcombe's interval and the exact McNemar p of
``bigcbf.bench.stats.paired_difference``), collisions (at fault / passive), E_CBF (mean per episode), CBF active
(% of control steps, pooled), QP infeasible (% of steps, pooled) and left/right mode reversals per episode. A
measurement tool: nothing in bigcbf imports it.
"""
from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

PLUS = "big-cbf-plus"
PAPER = "big-cbf"
REFERENCE = "plus"
SETS = ("paper", "dev")


@dataclass(frozen=True)
class Variant:
    name: str
    method: str
    switches: dict            # [methods.big-cbf-plus] keys set in its configuration (empty: the defaults)
    what: str


def variants() -> list[Variant]:
    """``plus``, each default-on switch off alone, each default-off switch on alone, and ``big-cbf``."""
    from bigcbf.params.stack import PlusRules
    out = [Variant(REFERENCE, PLUS, {}, "big-cbf-plus, its defaults")]
    for name, on in PlusRules().switches.items():
        if on:
            out.append(Variant(f"no_{name}", PLUS, {name: False}, f"big-cbf-plus with {name} off"))
        else:
            out.append(Variant(f"with_{name}", PLUS, {name: True}, f"big-cbf-plus with {name} on"))
    out.append(Variant("big-cbf", PAPER, {}, "big-cbf: the paper as written (every switch off)"))
    return out


def config_text(v: Variant) -> str:
    """The variant's run configuration (TOML): its ``[methods.big-cbf-plus]`` table, nothing else."""
    lines = [f"# scripts/fidelity_ablations.py, variant {v.name}: {v.what}", f"[methods.{PLUS}]"]
    lines += [f"{k} = {'true' if val else 'false'}" for k, val in v.switches.items()]
    return "\n".join(lines) + "\n"


def dev_worlds(out: Path, per_family: int) -> list[Path]:
    """The first ``per_family`` world seeds of every family's dev split, written to ``out/worlds/dev/`` as the
    generated suite writes them (``bigcbf.worlds.generate`` and ``write``)."""
    from bigcbf import worlds
    paths = []
    for k in range(per_family):
        for fam in worlds.FAMILIES.names():
            seeds = list(worlds.FAMILIES.get(fam).splits.get("dev", ()))
            if k < len(seeds):
                w = worlds.generate(fam, seeds[k])
                p = out / "worlds" / "dev" / f"{w.name}.toml"
                worlds.write(w, p)
                paths.append(p)
    return paths


def bench(out: Path, v: Variant, config: Path, scenarios: list[str], seeds: list[int], workers: int) -> None:
    """One ``bigcbf bench`` of the variant's method with its configuration (resumes a bench already in ``out``)."""
    cmd = ["bench", "--out", str(out), "--methods", v.method, "--scenarios", *scenarios,
           "--seed-list", *map(str, seeds), "--workers", str(workers), "--config", str(config), "--progress", "off"]
    t = time.time()
    r = subprocess.run([sys.executable, "-c", "import sys; from bigcbf.cli import main; sys.exit(main(sys.argv[1:]))",
                        *cmd], cwd=ROOT)
    if r.returncode != 0:
        sys.exit(f"fidelity_ablations: bigcbf {' '.join(cmd)} exited with status {r.returncode}")
    print(f"# {v.name} {out.name}: {time.time() - t:.0f} s", file=sys.stderr, flush=True)


# --- the table --------------------------------------------------------------------------------------------------

def read_episodes(path: Path, method: str) -> dict[tuple[str, int], dict]:
    """(scenario, seed) -> the row of one bench's episodes.csv for ``method`` (a world file keyed by its name)."""
    rows = {}
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            if r["method"] != method:
                continue
            if r["status"] != "ok":
                raise SystemExit(f"fidelity_ablations: {path}: episode {r['scenario']} seed {r['seed']} "
                                 f"ended with {r['status']}: {r['error']}")
            rows[(Path(r["scenario"]).stem, int(r["seed"]))] = r
    return rows


def _b(x: str) -> bool:
    return x.strip().lower() == "true"


def summarize(eps: dict[tuple[str, str, int], dict]) -> dict:
    """Counts and means over episodes keyed (set, scenario, seed)."""
    from bigcbf.bench.stats import wilson_pct
    rows = list(eps.values())
    n = len(rows)
    steps = sum(int(r["control_steps"]) for r in rows)

    def succ(which):
        k = [r for (s, _, _), r in eps.items() if which in (None, s)]
        return sum(_b(r["success"]) for r in k), len(k)

    def mean(key):
        v = [float(r[key]) for r in rows if r[key] not in ("", None)]
        return sum(v) / len(v) if v else None

    out = {"episodes": n}
    for which, tag in ((None, "all"), ("paper", "paper"), ("dev", "dev")):
        k, m = succ(which)
        out[f"success_{tag}"] = k
        out[f"episodes_{tag}"] = m
        out[f"success_{tag}_ci95_pct"] = wilson_pct(k, m)
    out.update(
        collisions=sum(_b(r["collision"]) for r in rows),
        at_fault=sum(_b(r["at_fault_collision"]) for r in rows),
        passive=sum(_b(r["passive_collision"]) for r in rows),
        timeouts=sum(_b(r["timeout"]) for r in rows),
        e_cbf=mean("e_cbf"),
        active_pct=100 * sum(float(r["cbf_active_ratio"]) * int(r["control_steps"]) for r in rows) / max(steps, 1),
        infeasible_pct=100 * sum(float(r["qp_infeasible_ratio"]) * int(r["control_steps"]) for r in rows)
        / max(steps, 1),
        side_reversals=mean("side_reversals"))
    return out


def collect(out: Path, vs: list[Variant], wanted: dict[str, set] | None = None) -> dict[str, dict]:
    """Variant -> {(set, scenario, seed): episode row} from the benches' episodes.csv; ``wanted`` (set -> the
    (scenario, seed) keys to keep) leaves out episodes an earlier, larger run of the same folder recorded. A
    wanted episode that is missing stops the table."""
    data = {}
    for v in vs:
        eps = {}
        for s in SETS:
            p = out / v.name / s / "episodes.csv"
            if not p.is_file():
                raise SystemExit(f"fidelity_ablations: {p} is missing (run without --report-only)")
            got = read_episodes(p, v.method)
            keys = got.keys() if wanted is None else wanted[s]
            missing = sorted(set(keys) - set(got))
            if missing:
                raise SystemExit(f"fidelity_ablations: {p} lacks {len(missing)} episodes, e.g. {missing[0]} "
                                 f"(run without --report-only)")
            eps.update({(s, *key): got[key] for key in keys})
        data[v.name] = eps
    return data


def paired(mine: dict, ref: dict) -> dict:
    """The success difference mine - ref over the episodes both have (same set, scene or world, seed)."""
    from bigcbf.bench.stats import paired_difference
    keys = sorted(set(mine) & set(ref))
    return paired_difference([_b(mine[k]["success"]) for k in keys], [_b(ref[k]["success"]) for k in keys])


def _f(v, d=2):
    return "–" if v is None else f"{v:.{d}f}"


def _ci(k, n, ci):
    return f"{k}/{n}" if ci is None else f"{k}/{n} [{ci[0]:.0f}, {ci[1]:.0f}]"


def table(data: dict[str, dict], vs: list[Variant]) -> tuple[str, list[dict]]:
    lines = ["| variant | nine scenes: success [95 % CI, %] | dev worlds: success | all: success | "
             "vs plus: paired diff. (pp) [95 % CI], McNemar p | collisions (at fault / passive) | timeouts | "
             "E_CBF | active (%) | QP infeasible (%) | L/R reversals |",
             "|:---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    rows = []
    for v in vs:
        s = summarize(data[v.name])
        pd = paired(data[v.name], data[REFERENCE]) if v.name != REFERENCE else None
        rows.append({"variant": v.name, "method": v.method, "switches": v.switches, **s, "paired_vs_plus": pd})
        diff = "–" if pd is None else (f"{pd['diff_pct']:+.1f} [{pd['ci95_pct'][0]:+.1f}, {pd['ci95_pct'][1]:+.1f}], "
                                       f"p = {pd['mcnemar_p']:.2g} ({pd['b']} only it, {pd['c']} only plus)")
        lines.append(
            f"| {v.name} | {_ci(s['success_paper'], s['episodes_paper'], s['success_paper_ci95_pct'])} | "
            f"{_ci(s['success_dev'], s['episodes_dev'], s['success_dev_ci95_pct'])} | "
            f"{_ci(s['success_all'], s['episodes_all'], s['success_all_ci95_pct'])} | {diff} | "
            f"{s['collisions']} ({s['at_fault']} / {s['passive']}) | {s['timeouts']} | {_f(s['e_cbf'])} | "
            f"{_f(s['active_pct'], 1)} | {_f(s['infeasible_pct'])} | {_f(s['side_reversals'])} |")
    return "\n".join(lines) + "\n", rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder for the configurations, worlds and benches")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--paper-seeds", type=int, default=3, help="the nine scenes at seeds 0..N-1 (default 3)")
    ap.add_argument("--worlds-per-family", type=int, default=2,
                    help="the first N world seeds of each family's dev split (default 2)")
    ap.add_argument("--only", nargs="+", default=None, metavar="VARIANT",
                    help=f"run and report these variants (and {REFERENCE}, the reference)")
    ap.add_argument("--report-only", action="store_true",
                    help="run nothing; tabulate the episodes these arguments name from the benches in --out")
    ap.add_argument("--json", type=Path, default=None, help="also write the rows as JSON here")
    ap.add_argument("--markdown", type=Path, default=None, help="also write the table here")
    args = ap.parse_args()

    from bigcbf.bench.paper import SCENARIO_ORDER
    from bigcbf.outputs import check_output_dir, strict_json, write_text
    vs = variants()
    known = [v.name for v in vs]
    if args.only:
        bad = [n for n in args.only if n not in known]
        if bad:
            sys.exit(f"fidelity_ablations: --only: unknown variant {', '.join(bad)} (known: {', '.join(known)})")
        vs = [v for v in vs if v.name == REFERENCE or v.name in args.only]
    if args.paper_seeds < 1 or args.worlds_per_family < 1 or args.workers < 1:
        sys.exit("fidelity_ablations: --paper-seeds, --worlds-per-family and --workers must be at least 1")
    out = check_output_dir(args.out, "measurement folder")
    worlds = [str(p) for p in dev_worlds(out, args.worlds_per_family)]
    wanted = {"paper": {(s, k) for s in SCENARIO_ORDER for k in range(args.paper_seeds)},
              "dev": {(Path(w).stem, 0) for w in worlds}}
    if not args.report_only:
        for v in vs:
            write_text(out / "configs" / f"{v.name}.toml", config_text(v), "run configuration")
        t = time.time()
        for v in vs:
            cfg = out / "configs" / f"{v.name}.toml"
            bench(out / v.name / "paper", v, cfg, list(SCENARIO_ORDER), list(range(args.paper_seeds)), args.workers)
            bench(out / v.name / "dev", v, cfg, worlds, [0], args.workers)
        print(f"# all benches: {(time.time() - t) / 60:.1f} min", file=sys.stderr)
    text, rows = table(collect(out, vs, wanted), vs)
    print(text, end="")
    if args.markdown:
        write_text(args.markdown, text, "table")
    if args.json:
        write_text(args.json, strict_json(rows, indent=1) + "\n", "JSON rows")


if __name__ == "__main__":
    main()
