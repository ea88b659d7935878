"""bigcbf perf: speed benchmarks of every layer (a benchmark, never a timed test)."""
from __future__ import annotations

import importlib

HELP = "measure speed: physics, LiDAR, perception, planners, CBF-QP, episodes (prints one JSON object with --json)"

#: Benchmark providers: "module:function" -> function(quick: bool) -> dict of figures.
BENCHES = [
    "bigcbf.sim.perf:bench",
    "bigcbf.perception.perf:bench",
    "bigcbf.control.perf:bench",
    "bigcbf.control.baselines.perf:bench",
    "bigcbf.episode_perf:bench",
    "twin.perf:bench",
    "bigcbf.bench.perf:bench",
]


def add_arguments(p):
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--quick", action="store_true", help="fewer repetitions (noisier figures)")
    p.add_argument("--only", nargs="*", default=None, metavar="PROVIDER",
                   help="run only these providers (module names, e.g. bigcbf.sim.perf)")


def run(args) -> int:
    from ..errors import UserError
    known = [spec.split(":")[0] for spec in BENCHES]
    unknown = sorted(set(args.only or ()) - set(known))
    if unknown:
        raise UserError(f"--only: unknown provider(s) {', '.join(unknown)}; known: {', '.join(known)}")
    out: dict = {}
    for spec in BENCHES:
        mod_name, fn_name = spec.split(":")
        if args.only and mod_name not in args.only:
            continue
        fn = getattr(importlib.import_module(mod_name), fn_name)
        out.update(fn(quick=args.quick))
    if args.json:
        from ..outputs import strict_json
        print(strict_json(out, sort_keys=True))
    else:
        width = max(map(len, out), default=0)
        for k in sorted(out):
            v = out[k]
            print(f"{k:<{width}}  {v:.4g}" if isinstance(v, float) else f"{k:<{width}}  {v}")
    return 0
