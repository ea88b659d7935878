"""bigcbf tune: the equal-budget tuning protocol (issue 24, item 4; docs/tuning.md), resumable."""
from __future__ import annotations

from .argtypes import float_in_range, path_arg

HELP = ("run the equal-budget tuning protocol (bigcbf/params/tuning/grid.toml: 8 configurations per method on 48 "
        "dev worlds) into DIR, resumable; write the results and the chosen configurations (DIR/tuned.toml)")


def add_arguments(p):
    from ..limits import MAX_TIME_LIMIT_S, MIN_TIME_LIMIT_S

    p.add_argument("--out", type=path_arg, required=True, metavar="DIR",
                   help="output directory: new, empty, or an earlier search's (the same DIR resumes)")
    p.add_argument("--methods", nargs="+", default=None, metavar="M",
                   help="only these methods of the grid (default: all; a slice is not for --write-shipped)")
    p.add_argument("--workers", default=None, metavar="K", help="parallel episodes (default: one per core)")
    p.add_argument("--grid", type=path_arg, default=None, metavar="GRID.toml",
                   help="the protocol (default: the shipped bigcbf/params/tuning/grid.toml)")
    p.add_argument("--configs", nargs="+", default=None, metavar="I",
                   help="only these configurations (0-7; 0 is the defaults) -- a slice, for tests and timing")
    p.add_argument("--families", nargs="+", default=None, metavar="F", help="only these families of the subset")
    p.add_argument("--world-seeds", nargs="+", default=None, metavar="S", help="only these world seeds of the subset")
    p.add_argument("--time-limit", default=None, metavar="S",
                   type=float_in_range(MIN_TIME_LIMIT_S, MAX_TIME_LIMIT_S, "a time limit in seconds"),
                   help="replace every world's time limit (a smoke run; its worlds get other names and keys)")
    p.add_argument("--write-shipped", action="store_true",
                   help="after a complete run of the whole protocol, copy DIR's tuned.toml and results to "
                        "bigcbf/params/tuning/ (tuned.toml, results.csv, results.json)")
    p.add_argument("--progress", choices=["auto", "on", "off"], default="auto",
                   help="progress bar (default: only on a terminal)")


def _ints(values, option: str) -> list[int] | None:
    from ..errors import UserError
    if values is None:
        return None
    try:
        return [int(v) for v in values]
    except ValueError:
        raise UserError(f"{option} expects whole numbers, got {' '.join(values)[:60]!r}") from None


def run(args) -> int:
    import os

    from ..bench.tuning import GRID, SHIPPED, load_grid, run_tuning, table_lines, write_shipped
    from ..outputs import check_distinct
    from .bench import MAX_WORKERS_PER_CORE, _int

    grid = load_grid(args.grid or GRID)
    workers = None if args.workers is None else _int(args.workers, "--workers", 1,
                                                     MAX_WORKERS_PER_CORE * (os.cpu_count() or 1))
    check_distinct({"--grid": grid.path}, {"--out": args.out, **({f"shipped {k}": v for k, v in SHIPPED.items()}
                                                                 if args.write_shipped else {})})
    res = run_tuning(grid, args.out, args.methods, workers, configs=_ints(args.configs, "--configs"),
                     progress={"auto": None, "on": True, "off": False}[args.progress], families=args.families,
                     world_seeds=_ints(args.world_seeds, "--world-seeds"), time_limit_s=args.time_limit)
    for line in table_lines(res):
        print(line)
    print(f"wrote {args.out}/tuning.csv, tuning.json, tuned.toml (bigcbf bench --config {args.out}/tuned.toml)")
    if args.write_shipped:
        for path in write_shipped(args.out, grid):
            print(f"wrote {path}")
    bad = any(s["errors"] or s["missing"] for r in res["methods"].values() for s in r["configs"])
    return 1 if bad else 0
