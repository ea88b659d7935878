"""bigcbf scenarios: list the scenarios with one line each; ``generate`` writes a procedural world."""
from __future__ import annotations

from pathlib import Path

from .argtypes import nonneg_int

HELP = ("list the benchmark scenarios (scenarios/*.toml), one line each; "
        "'bigcbf scenarios generate FAMILY --seed N --out FILE' writes a procedural world")


def add_arguments(p):
    sub = p.add_subparsers(dest="action", metavar="ACTION")
    g = sub.add_parser("generate", help="write one procedural world (a scenario TOML file) of a family and seed",
                       description="Write one procedural world of FAMILY for --seed as an ordinary scenario TOML "
                                   "file (run it with 'bigcbf run FILE'). '--list' lists the families and the "
                                   "ranges their parameters are drawn from.")
    g.add_argument("family", nargs="?", metavar="FAMILY", help="the family (see --list)")
    g.add_argument("--seed", type=nonneg_int, default=0, help="the world's seed (default 0)")
    g.add_argument("--out", type=Path, default=None, metavar="FILE",
                   help="write the world here (default: print it)")
    g.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    g.add_argument("--list", action="store_true", help="list the families with their parameter ranges")


def _list_families() -> None:
    from ..worlds import FAMILIES, SPLITS

    def seeds(splits: dict[str, range]) -> str:
        return " and ".join(f"{r.start}-{r.stop - 1} ({split})" for split, r in splits.items())

    for fam in FAMILIES.values():
        print(f"{fam.name}: {fam.summary}")
        for r in fam.ranges:
            print(f"    {r}")
        if fam.splits != SPLITS:
            print(f"    generated suite: seeds {seeds(fam.splits)}")
    print("The generated bench suite ('bigcbf bench --suite generated') holds, per family, the worlds of seeds "
          + seeds(SPLITS) + (" unless listed above." if any(f.splits != SPLITS for f in FAMILIES.values()) else "."))


def _generate(args) -> int:
    from ..errors import UserError
    from ..outputs import check_distinct, check_output_file, write_text
    from ..worlds import FAMILIES, family, generate, parse

    if args.list:
        _list_families()
        return 0
    if args.family is None:
        raise UserError(f"name a family: {', '.join(FAMILIES)} (or --list)")
    family(args.family)
    out = args.out
    if out is not None:
        if out.is_dir():
            raise UserError("--out is a directory; give a file name", file=str(out))
        if out.exists() and not args.force:
            raise UserError("the file exists (use --force to overwrite it)", file=str(out))
        if not out.parent.is_dir():
            raise UserError("the folder does not exist", file=str(out.parent))
        from ..scenario import all_scenario_files
        # a shipped scenario is never overwritten, --force or not (the package's own files are its inputs)
        check_distinct({f"shipped scenario {n}": p for n, p in all_scenario_files().items()}, {"--out": out})
        check_output_file(out, "world")
    world = generate(args.family, args.seed)
    parse(world.toml)                     # what we write, the loader reads
    if out is None:
        print(world.toml, end="")
        return 0
    write_text(out, world.toml, "world")
    print(f"wrote {out}: {world.name}, time limit {world.time_limit_s:.0f} s, shortest route "
          f"{world.path_length_m:.2f} m, {len(world.draft.pedestrians)} pedestrians")
    return 0


def run(args) -> int:
    if getattr(args, "action", None) == "generate":
        return _generate(args)
    from ..scenario import describe, scenario_files

    files = scenario_files()
    width = max(map(len, files), default=0)
    for name, path in files.items():
        print(f"{name:<{width}}  {describe(path)}")
    return 0
