"""bigcbf bench: the paper's benchmark (methods x scenarios x seeds), resumable, on local cores or Ray."""
from __future__ import annotations

import os
import re

from .argtypes import path_arg

HELP = ("run many episodes (methods x scenarios x seeds) into DIR/results.sqlite, resumable; "
        "write episodes.csv, summary.json/.md and figures")



def _suites_help() -> str:
    """Each registered suite with its description and default seed count (the registry is the one list)."""
    from ..bench.suites import SUITES
    return "; ".join(f"{n} ({SUITES.get(n).description}; {SUITES.get(n).default_seeds} seed"
                     f"{'s' if SUITES.get(n).default_seeds != 1 else ''})" for n in SUITES.names())


def _variants_help() -> str:
    """Each registered variant axis with its configuration path and values (the registry is the one list)."""
    from ..bench.variants import VARIANT_AXES
    return "; ".join(f"{n}={','.join(a.values)} ({a.path})" for n, a in VARIANT_AXES.items())


def _splits_help() -> str:
    from ..bench.suites import SUITES
    return "; ".join(f"{n}: {' or '.join(SUITES.get(n).splits)}" for n in SUITES.names() if SUITES.get(n).splits)


def add_arguments(p):
    p.add_argument("--out", type=path_arg, required=True, metavar="DIR",
                   help="output directory: new, empty, or an earlier bench's (rerunning with the same DIR resumes); "
                        "a folder holding other files is refused")
    p.add_argument("--methods", nargs="+", default=None, metavar="M",
                   help="methods to compare: names from 'bigcbf methods' or package.module:Class (importable by "
                        "every worker; default: every registered method)")
    p.add_argument("--suite", default="paper", metavar="NAME",
                   help="the scenarios of a named suite (default paper): " + _suites_help())
    p.add_argument("--scenarios", nargs="+", default=None, metavar="S",
                   help="scenario names or .toml files instead of the suite's")
    p.add_argument("--split", default=None, metavar="NAME",
                   help="only the suite's scenarios of this split (" + _splits_help() + "; default: all)")
    seeds = p.add_mutually_exclusive_group()
    seeds.add_argument("--seeds", default=None, metavar="N",
                       help="seeds 0..N-1, the same for every method (default: the suite's, 50 for paper; at most "
                            "10000)")
    seeds.add_argument("--seed-list", nargs="+", default=None, metavar="SEED", help="these seeds instead")
    p.add_argument("--world-seeds", nargs="+", default=None, metavar="A-B",
                   help="generated suite: every family's worlds at these world seeds (A-B inclusive, or single "
                        "seeds) instead of its splits', written to DIR/worlds/fresh/ and reported as split fresh: "
                        "worlds nobody tuned on (seeds of the dev and test splits are refused)")
    p.add_argument("--workers", default=None, metavar="K",
                   help="parallel episodes (default: one per core; with --engine ray: the cluster's CPUs)")
    p.add_argument("--engine", default="local", metavar="{local,ray}",
                   help="local process pool (default) or Ray tasks (pip install 'bigcbf[ray]')")
    p.add_argument("--ray-address", default=None, metavar="ADDR",
                   help="an existing Ray cluster (e.g. auto or ray://head:10001); default: a local Ray instance")
    p.add_argument("--config", type=path_arg, default=None, metavar="RUN.toml",
                   help="run configuration ([stack], [perception], [pedestrians], [methods.NAME]); the whole "
                        "configuration is part of the episode key")
    p.add_argument("--profile", type=path_arg, default=None,
                   help="stack parameters / uncertainty profile TOML over the configuration's [stack] (default: the "
                        "suite's; for paper, Table I with the twin-calibrated profile of the simulated X3); part of "
                        "the episode key")
    p.add_argument("--route", choices=["on", "off"], default=None,
                   help="every method under the route layer (on) or not (off: the paper's set-up), as the "
                        "configuration's [route] enabled (default: the configuration's, off); part of the key. "
                        "To compare all methods with it off and on in one report: --variant route=off,on")
    p.add_argument("--variant", action="append", default=None, metavar="NAME=V1,V2",
                   help="run every method under each of these values of a switch, on the same seeds, and report "
                        "them side by side with paired differences (repeatable: every combination runs; each "
                        "combination's configuration is part of the key): " + _variants_help())
    p.add_argument("--perception", default="lidar", metavar="{lidar,truth}",
                   help="obstacles from the LiDAR pipeline (default) or the simulator's truth; part of the key")
    p.add_argument("--report-only", action="store_true",
                   help="run nothing: rebuild the outputs from the episodes already in DIR/results.sqlite")
    p.add_argument("--docs", type=path_arg, default=None, metavar="PAGE",
                   help="also put the results into this Markdown page between its bench-results markers")
    p.add_argument("--progress", choices=["auto", "on", "off"], default="auto",
                   help="progress bar (default: only on a terminal)")


#: the most seeds one bench runs (200 x the paper's 50; 720,000 episodes with the paper's 8 methods and 9 scenes)
MAX_SEEDS = 10_000
#: the most local worker processes per core (each holds a MuJoCo model and the stack, ~200 MB)
MAX_WORKERS_PER_CORE = 4
#: the most Ray tasks in flight / cluster CPUs one bench asks for
MAX_RAY_WORKERS = 10_000


def _int(value: str, option: str, minimum: int, maximum: int | None = None) -> int:
    from ..errors import UserError
    try:
        v = int(value)
    except (TypeError, ValueError):
        raise UserError(f"{option} expects a whole number, got {str(value)[:40]!r}") from None
    if v < minimum:
        raise UserError(f"{option} must be >= {minimum}, got {v}")
    if maximum is not None and v > maximum:
        raise UserError(f"{option} must be <= {maximum}, got {str(value)[:40]}")
    return v


def world_seeds_arg(tokens) -> list[int] | None:
    """``--world-seeds``' seeds: each token a seed N or a range A-B (inclusive, A <= B); at most MAX_SEEDS in all,
    each in [0, MAX_SEED]; a mistake is a UserError naming the option."""
    from ..errors import UserError
    from .argtypes import MAX_SEED

    if tokens is None:
        return None
    seeds: dict[int, None] = {}          # (in the order given, each once)
    for tok in tokens:
        m = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", str(tok))
        if m is None:
            raise UserError(f"--world-seeds expects seeds N or ranges A-B, got {str(tok)[:40]!r}")
        lo = _int(m.group(1), "--world-seeds", 0, MAX_SEED)
        hi = _int(m.group(2), "--world-seeds", 0, MAX_SEED) if m.group(2) is not None else lo
        if hi < lo:
            raise UserError(f"--world-seeds: the range {lo}-{hi} ends before it starts")
        if len(seeds) + hi - lo + 1 > MAX_SEEDS:
            raise UserError(f"--world-seeds: at most {MAX_SEEDS} world seeds in one bench")
        seeds.update(dict.fromkeys(range(lo, hi + 1)))
    return list(seeds)


def config_from_args(args):
    """A BenchConfig from parsed arguments (through :func:`bigcbf.api.bench_config`); every mistake is a UserError
    (one line, exit 2)."""
    from dataclasses import replace

    from ..api import bench_config
    from ..bench.suites import SUITES
    from ..bench.variants import parse_variants
    from ..errors import UserError
    from .argtypes import MAX_SEED
    from .run import config_note, with_route

    variants = parse_variants(args.variant)      # before the suite writes its worlds: a typo costs nothing
    if args.route is not None and any(name == "route" for name, _ in variants):
        raise UserError("--route and --variant route=... both set the route layer; give one of them")
    if args.seed_list is not None:
        if len(args.seed_list) > MAX_SEEDS:
            raise UserError(f"--seed-list: at most {MAX_SEEDS} seeds in one bench, got {len(args.seed_list)}")
        seeds = tuple(_int(s, "--seed-list", 0, MAX_SEED) for s in args.seed_list)
    elif args.seeds is not None:
        seeds = _int(args.seeds, "--seeds", 1, MAX_SEEDS)
    else:
        seeds = SUITES.get(args.suite).default_seeds
    max_workers = MAX_WORKERS_PER_CORE * (os.cpu_count() or 1) if args.engine == "local" else MAX_RAY_WORKERS
    workers = None if args.workers is None else _int(args.workers, "--workers", 1, max_workers)
    bc = bench_config(args.out, methods=args.methods, scenarios=args.scenarios, suite=args.suite, seeds=seeds,
                      workers=workers, engine=args.engine, ray_address=args.ray_address, config=args.config,
                      profile=args.profile, perception=args.perception, split=args.split,
                      notes=config_note, variants=args.variant, world_seeds=world_seeds_arg(args.world_seeds))
    return replace(bc, config=with_route(bc.config, args.route))


def run(args) -> int:
    from pathlib import Path

    from ..bench.report import check_docs_page, update_docs_page
    from ..bench.runner import OUTPUTS, check_bench_out, run_bench
    from ..outputs import check_distinct
    from ..scenario import resolve_path

    check_bench_out(args.out)            # new, empty or an earlier bench's: before a suite writes its worlds there
    config = config_from_args(args)
    inputs = {f"scenario {s}": resolve_path(s) for s in config.scenarios}
    inputs.update({"--config": args.config, "--profile": args.profile})
    outputs = {f"the bench's {name}": Path(config.out) / name for name in OUTPUTS}
    check_distinct(inputs, {**outputs, "--docs": args.docs})
    if args.docs is not None:            # before the bench: a page that cannot take the results fails now
        check_docs_page(args.docs)
    progress = {"auto": None, "on": True, "off": False}[args.progress]
    outcome = run_bench(config, progress=progress, report_only=args.report_only)
    if args.docs is not None:
        update_docs_page(args.docs, config.out)
        print(f"bench: updated {args.docs}")
    return 1 if outcome.errors else 0
