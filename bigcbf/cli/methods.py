"""bigcbf methods: list the methods --method accepts (built-in and installed through entry points)."""
from __future__ import annotations

HELP = "list the methods (built-in, and planners installed through the bigcbf.methods entry point group)"


def add_arguments(p):
    pass


def run(args) -> int:
    from ..api import methods
    from ..control.methods import ENTRY_POINT_GROUP, method_params_type

    found = methods()
    width = max(map(len, found), default=0)
    for name, origin in found.items():
        ptype = method_params_type(name)
        own = f"; parameters [methods.{name}] ({ptype.__name__})" if ptype is not None else ""
        where = "built-in" if origin == "built-in" else f"entry point {ENTRY_POINT_GROUP}: {origin}"
        print(f"{name:<{width}}  {where}{own}")
    print("any other planner: --method package.module:Class (docs/extending.md)")
    return 0
