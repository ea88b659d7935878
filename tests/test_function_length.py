"""No function over 60 lines without a reason in its docstring (issue 22, item 5).

A function in bigcbf/ or twin/ longer than ``MAX_LINES`` (``end_lineno - lineno + 1``, docstring included) must say
why it is one function in a docstring line that starts with ``Length:`` (e.g. "Length: a numba kernel ...", or
"Length: to be split (issue 22)" where there is no good reason yet).
"""
from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("bigcbf", "twin")
MAX_LINES = 60


def long_functions_without_reason(source: str, label: str) -> list[str]:
    """``label:line name (n lines)`` for each function in ``source`` over MAX_LINES whose docstring has no line
    starting with ``Length:``."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        n = node.end_lineno - node.lineno + 1
        if n <= MAX_LINES:
            continue
        doc = ast.get_docstring(node) or ""
        if not any(line.strip().startswith("Length:") for line in doc.splitlines()):
            out.append(f"{label}:{node.lineno} {node.name} ({n} lines)")
    return out


def test_long_functions_state_why():
    files = sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))
    assert len(files) > 50, f"found only {len(files)} source files under {PACKAGES}"
    bad = []
    for p in files:
        bad += long_functions_without_reason(p.read_text(encoding="utf-8"), str(p.relative_to(ROOT)))
    assert not bad, (f"{len(bad)} function(s) over {MAX_LINES} lines without a 'Length:' line in the docstring "
                     "(state why it is one function, or 'Length: to be split (issue 22)'):\n" + "\n".join(bad))


def test_the_check_sees_a_long_function():
    body = "".join(f"    x{i} = {i}\n" for i in range(MAX_LINES))
    plain = f'def f():\n    """Doc."""\n{body}'
    reason = f'def f():\n    """Doc.\n\n    Length: a reason.\n    """\n{body}'
    short = 'def f():\n    """Doc."""\n    return 1\n'
    nested = f'class C:\n    def m(self):\n        def g():\n{"".join("    " * 2 + ln + chr(10) for ln in body.splitlines())}'
    assert long_functions_without_reason(plain, "x.py") == [f"x.py:1 f ({MAX_LINES + 2} lines)"]
    assert long_functions_without_reason(reason, "x.py") == []
    assert long_functions_without_reason(short, "x.py") == []
    assert sorted(long_functions_without_reason(nested, "x.py")) == [
        f"x.py:2 m ({MAX_LINES + 2} lines)", f"x.py:3 g ({MAX_LINES + 1} lines)"]
