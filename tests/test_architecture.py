"""The import layers of bigcbf and twin, read from the source (every ``import`` statement, parsed with ast, those
inside functions marked lazy), against the rules of the design (/work/shared/DESIGN.md, docs/architecture.md):

1. a lower layer never imports a higher one at module level (a lazy import inside a function may reach up: the
   CLI's helpers, for instance, are loaded on first use);
2. the robot-side packages ``bigcbf.control`` and ``bigcbf.perception`` import no mujoco, dm_control, cv2 or
   ``bigcbf.sim``, not even lazily, and nothing they load at import time does;
3. no module of bigcbf imports twin, except the command line (``bigcbf.cli``), lazily;
4. MuJoCo is simulator business: within bigcbf and twin only the sim layer (``bigcbf.sim``, the robot registry
   ``bigcbf.robots`` and the robot folders' generators under ``bigcbf.assets``) imports mujoco or dm_control.

Every module must belong to a layer, so a new module is placed (here and in docs/architecture.md) on purpose.
Where the code breaks a rule today, the case is a strict xfail naming the module and the reason.
"""
import ast
from functools import lru_cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: the layers, lowest first: (name, module prefixes). A module belongs to the layer of its longest matching prefix.
LAYERS = [
    ("foundation", ["bigcbf", "bigcbf.errors", "bigcbf.types", "bigcbf.registry", "bigcbf.outputs", "bigcbf.progress",
                    "bigcbf.validate", "bigcbf.sanity", "bigcbf.cost", "bigcbf.limits"]),
    ("params", ["bigcbf.params"]),
    ("robot side and log I/O", ["bigcbf.control", "bigcbf.perception", "bigcbf.logio"]),
    ("ros2 robot side", ["bigcbf.ros2"]),
    ("sim", ["bigcbf.sim", "bigcbf.assets", "bigcbf.robots"]),
    ("scenario", ["bigcbf.scenario", "bigcbf.worlds"]),
    ("episode", ["bigcbf.episode", "bigcbf.config"]),
    ("on an episode", ["bigcbf.video", "bigcbf.episode_perf", "bigcbf.ros2.sim_node"]),
    ("bench and gym_env", ["bigcbf.bench", "bigcbf.gym_env"]),
    ("api", ["bigcbf.api"]),
    ("twin", ["twin"]),
    ("cli", ["bigcbf.cli"]),
]
ROBOT_SIDE = ("bigcbf.control", "bigcbf.perception", "bigcbf.ros2.filter_node", "bigcbf.ros2.stack",
              "bigcbf.ros2.transport", "bigcbf.ros2.wire", "bigcbf.ros2.cli_common")
SIM_ONLY = ("mujoco", "dm_control", "cv2")
MUJOCO = ("mujoco", "dm_control")

#: rule 4 as the code stands (reported, not weakened): module -> why it imports MuJoCo itself
KNOWN_MUJOCO_OUTSIDE_SIM: dict[str, str] = {}


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


@lru_cache(maxsize=None)
def modules() -> dict[str, Path]:
    found = {}
    for pkg in ("bigcbf", "twin"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            if "__pycache__" not in path.parts:
                found[_module_name(path)] = path
    return found


@lru_cache(maxsize=None)
def imports() -> tuple[tuple[str, str, bool], ...]:
    """(importer, imported module, lazy) for every import statement; ``from pkg import name`` names the submodule
    when ``name`` is one, else ``pkg``. Lazy: inside a function (or lambda), or under ``if TYPE_CHECKING``."""
    mods = modules()
    out = []
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"

        def target(node: ast.ImportFrom) -> str:
            if not node.level:
                return node.module
            base = name.split(".") if is_pkg else name.split(".")[:-1]
            base = base[:len(base) - (node.level - 1)]
            return ".".join(base + ([node.module] if node.module else []))

        def visit(node, lazy):
            for child in ast.iter_child_nodes(node):
                inner = lazy or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)) or (
                    isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test))
                if isinstance(child, ast.Import):
                    out.extend((name, alias.name, inner) for alias in child.names)
                elif isinstance(child, ast.ImportFrom):
                    base = target(child)
                    for alias in child.names:
                        sub = f"{base}.{alias.name}"
                        out.append((name, sub if sub in mods else base, inner))
                visit(child, inner)

        tree = ast.parse(path.read_text(encoding="utf-8"))
        visit(tree, False)
        for node in ast.walk(tree):      # importlib.import_module("literal"): always inside a function here
            if (isinstance(node, ast.Call) and ast.unparse(node.func).endswith("import_module") and node.args
                    and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)):
                out.append((name, node.args[0].value, True))
    return tuple(out)


def layer(module: str) -> int | None:
    best = None
    for i, (_, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            if module == p or (p != "bigcbf" and module.startswith(p + ".")):
                if best is None or len(p) > best[1]:
                    best = (i, len(p))
    return None if best is None else best[0]


def ours(module: str) -> bool:
    return module.split(".")[0] in ("bigcbf", "twin")


def test_the_graph_is_read():
    """The parser sees the package: the known edges, module-level and lazy, are there."""
    edges = set(imports())
    assert len(modules()) > 80
    assert ("bigcbf.episode", "bigcbf.sim.world", False) in edges
    assert any(a == "bigcbf.cli.calibrate" and b.startswith("twin.") and lazy for a, b, lazy in edges)
    assert any(a.startswith("bigcbf.sim") and b == "mujoco" and not lazy for a, b, lazy in edges)


def test_every_module_has_a_layer():
    missing = [m for m in modules() if layer(m) is None]
    assert not missing, f"place these in LAYERS and in docs/architecture.md: {missing}"


def test_a_lower_layer_never_imports_a_higher_one_at_module_level():
    bad = [f"{a} ({LAYERS[layer(a)][0]}) imports {b} ({LAYERS[layer(b)][0]})"
           for a, b, lazy in imports()
           if not lazy and ours(b) and layer(b) is not None and layer(a) is not None and layer(b) > layer(a)]
    assert not bad, "\n".join(bad)


def test_robot_side_packages_never_import_the_simulator():
    """Directly, at any level (lazy included), and through what they load at import time (module-level closure)."""
    edges = imports()
    module_level: dict[str, set[str]] = {}
    for a, b, lazy in edges:
        if not lazy:
            module_level.setdefault(a, set()).add(b)
    bad = []
    for a, b, lazy in edges:
        if a.startswith(ROBOT_SIDE) and (b.split(".")[0] in SIM_ONLY or b.startswith("bigcbf.sim")):
            bad.append(f"{a} imports {b}" + (" (lazily)" if lazy else ""))
    start = [m for m in modules() if m.startswith(ROBOT_SIDE)]
    seen, todo = set(start), list(start)
    while todo:
        m = todo.pop()
        for b in module_level.get(m, ()):
            # a submodule import loads its packages' __init__ first
            chain = [".".join(b.split(".")[:k]) for k in range(1, b.count(".") + 2)]
            for c in chain:
                if c.split(".")[0] in SIM_ONLY or c.startswith("bigcbf.sim"):
                    bad.append(f"{m} loads {c} at import time (reached from the robot side)")
                elif c in modules() and c not in seen:
                    seen.add(c)
                    todo.append(c)
    assert not bad, "\n".join(sorted(set(bad)))


def test_only_the_cli_imports_twin_and_only_lazily():
    bad = [f"{a} imports {b}" + (" at module level" if not lazy else "")
           for a, b, lazy in imports()
           if a.startswith("bigcbf") and b.split(".")[0] == "twin" and not (a.startswith("bigcbf.cli") and lazy)]
    assert not bad, "\n".join(bad)
    assert any(a.startswith("bigcbf.cli") and b.startswith("twin") for a, b, _ in imports())


SIM_LAYER = [i for i, (name, _) in enumerate(LAYERS) if name == "sim"][0]


def _mujoco_importers() -> set[str]:
    return {a for a, b, _ in imports() if b.split(".")[0] in MUJOCO and layer(a) != SIM_LAYER}


@pytest.mark.parametrize("module", [
    pytest.param(m, marks=pytest.mark.xfail(strict=True, reason=KNOWN_MUJOCO_OUTSIDE_SIM[m]))
    if m in KNOWN_MUJOCO_OUTSIDE_SIM else m
    for m in sorted(set(KNOWN_MUJOCO_OUTSIDE_SIM) | {"bigcbf.episode", "bigcbf.video", "bigcbf.gym_env",
                                                      "twin.record", "twin.calibrate",
                                                      "twin.model_fit", "twin.replay", "bigcbf.episode_perf"})])
def test_mujoco_only_in_sim(module):
    """DESIGN.md: "sim  MuJoCo only here". Checked per module; the known exceptions are strict xfails."""
    assert module in modules()
    assert module not in _mujoco_importers()


def test_no_other_module_imports_mujoco():
    """Every importer of mujoco or dm_control outside the sim layer is one of the known exceptions above."""
    assert _mujoco_importers() <= set(KNOWN_MUJOCO_OUTSIDE_SIM), _mujoco_importers() - set(KNOWN_MUJOCO_OUTSIDE_SIM)


def test_the_model_fits_mujoco_side_is_in_sim():
    """Issue 27: twin.model_fit reaches MuJoCo only through bigcbf.sim.sysid, which it loads on first use."""
    edges = set(imports())
    assert ("twin.model_fit", "bigcbf.sim.sysid", True) in edges
    assert not any(a == "twin.model_fit" and b == "bigcbf.sim.sysid" and not lazy for a, b, lazy in edges)
    assert any(a == "bigcbf.sim.sysid" and b.split(".")[0] == "mujoco" for a, b, _ in edges)
