"""bigcbf perf: speed benchmarks of every layer (a benchmark, never a timed test).

Every timing figure ``X_ms`` is also given as ``X_steps``: its ratio to the bare physics step of the same run
(``physics_step_us``: ``bigcbf.sim.perf``, the robot alone stepping; measured here when ``--only`` leaves that
provider out), so figures from a loaded or a slower machine compare: ``imagination_p95_steps``,
``perception_steps``, ``cbf_qp_p95_steps``; ``episode_physics_ratio`` (the episode's real-time factor over the bare
physics of its own model, ``bigcbf.episode_perf``) and ``episode_replay_ratio`` (over its own physics replayed
without the stack) are ratios already. ``by_method`` puts these five figures of
each method in :data:`SIDE_BY_SIDE` side by side; a method without its own figures says why ("not available"),
never a number it did not measure.
"""
from __future__ import annotations

import importlib
import math

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
    "bigcbf.ros2.perf:bench",
]

#: The figures ``by_method`` compares, in step ratios (module docstring).
RATIO_FIGURES = ("imagination_p95_steps", "perception_steps", "cbf_qp_p95_steps", "episode_physics_ratio",
                 "episode_replay_ratio")

#: The methods reported side by side in ``by_method``, each with where its figures come from: None for the
#: providers above (they measure big-cbf), else "module:function" -> function(quick) -> dict with the same
#: ``*_ms`` figures and ``episode_physics_ratio`` for that method. big-cbf-plus: its own selection cycle, filter,
#: perception and an episode with its route layer on (``bigcbf.control.perf.bench_big_cbf_plus``).
SIDE_BY_SIDE = {"big-cbf": None, "big-cbf-plus": "bigcbf.control.perf:bench_big_cbf_plus"}


def add_arguments(p):
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.add_argument("--quick", action="store_true", help="fewer repetitions (noisier figures)")
    p.add_argument("--only", nargs="*", default=None, metavar="PROVIDER",
                   help="run only these providers (module names, e.g. bigcbf.sim.perf)")


def step_ratios(figures: dict, physics_step_us: float) -> dict:
    """``X_steps`` = ``X_ms`` / the physics step, for every finite number ``X_ms`` in ``figures``."""
    out = {}
    for k, v in figures.items():
        if k.endswith("_ms") and isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v):
            out[k[:-3] + "_steps"] = round(1e3 * v / physics_step_us, 3)
    return out


def _method_figures(name: str, spec: str | None, out: dict, quick: bool, physics_step_us: float):
    """The RATIO_FIGURES of one method (those this run measured), or a "not available: ..." line."""
    from ..control.methods import METHODS
    if name not in METHODS:
        return f"not available: method {name!r} is not registered"
    if spec is None:
        figures = out
    else:
        mod_name, fn_name = spec.split(":")
        try:
            fn = getattr(importlib.import_module(mod_name), fn_name)
        except (ImportError, AttributeError):
            return f"not available: no perf provider {spec} for method {name!r}"
        raw = fn(quick=quick)
        figures = {**raw, **step_ratios(raw, physics_step_us)}
    return {k: figures[k] for k in RATIO_FIGURES if k in figures}


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
    if "physics_step_us" not in out:
        from ..sim.perf import bare_steps_per_s
        out["physics_step_us"] = round(1e6 / bare_steps_per_s(args.quick)[0], 3)
    out.update(step_ratios(out, out["physics_step_us"]))
    out["by_method"] = {name: _method_figures(name, spec, out, args.quick, out["physics_step_us"])
                        for name, spec in SIDE_BY_SIDE.items()}
    if args.json:
        from ..outputs import strict_json
        print(strict_json(out, sort_keys=True))
    else:
        flat = {k: v for k, v in out.items() if k != "by_method"}
        for name, figs in out["by_method"].items():
            if isinstance(figs, dict):
                flat.update({f"by_method.{name}.{k}": v for k, v in figs.items()})
            else:
                flat[f"by_method.{name}"] = figs
        width = max(map(len, flat), default=0)
        for k in sorted(flat):
            v = flat[k]
            print(f"{k:<{width}}  {v:.4g}" if isinstance(v, float) else f"{k:<{width}}  {v}")
    return 0
