"""bigcbf methods: the methods --method accepts (built-in and installed through entry points), each with the
parameters of its own (a run configuration's ``[methods.NAME]`` table) with their defaults and units;
``bigcbf methods NAME`` shows one method in full (for BIG-CBF and CBF-only, whose parameters are the stack's, every
``[stack]`` parameter)."""
from __future__ import annotations

import dataclasses
import inspect
import io
import math
import re
import textwrap
import tokenize

HELP = ("list the methods (built-in, and planners installed through the bigcbf.methods entry point group), each with "
        "its parameters, their defaults and units; 'bigcbf methods NAME' shows one in full")

#: the built-in methods whose factory is a lambda (no docstring of its own): what they are
_ABOUT = {
    "big-cbf": "BIG-CBF (the paper's method): behavior imagination with the shared uncertainty model, selection "
               "every T_B, the common CBF filter every T_C",
    "big-cbf-noshared": "BIG-CBF-NoShared (ablation): BIG-CBF whose imagination uses a fixed margin "
                        "(noshared_margin_m) instead of the shared uncertainty terms",
}
#: methods without a params_type take every parameter from the stack ([stack] of a run configuration)
_STACK_NOTE = "parameters: the stack's, [stack] (StackParams, paper Table I)"


def add_arguments(p):
    p.add_argument("name", nargs="?", default=None, metavar="NAME",
                   help="one method in full: a name from the list or package.module:Class")
    p.add_argument("--json", action="store_true", help="print one JSON object: method -> origin and parameters")


# --- the parameter table of a params dataclass ------------------------------------------------------------------

#: unit from a field name's suffix, when its comment gives none (longest suffix first)
_SUFFIX_UNITS = (("_radps_rthz", "rad/s/sqrt(Hz)"), ("_m3_per_s", "m^3/s"), ("_m2_per_s", "m^2/s"),
                 ("_radps2", "rad/s^2"), ("_mps2", "m/s^2"), ("_radps", "rad/s"), ("_per_s", "1/s"), ("_mps", "m/s"),
                 ("_deg", "deg"), ("_rad", "rad"), ("_hz", "Hz"), ("_ms", "ms"), ("_m2", "m^2"), ("_m", "m"),
                 ("_s", "s"))
_UNIT_WORD = re.compile(r"^(-|m|s|ms|rad|deg|Hz|[\w^]+/[\w^/()]+)$")


def field_comments(cls: type) -> dict[str, str]:
    """The comment on each field's line of a dataclass's source (``name: type = default  # comment``), over its
    bases too; {} where the source cannot be read (a class made at run time)."""
    out: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        if not dataclasses.is_dataclass(klass) or klass is object:
            continue
        try:
            src = textwrap.dedent(inspect.getsource(klass))
        except (OSError, TypeError):
            continue
        names = {f.name for f in dataclasses.fields(klass)}
        line_field: dict[int, str] = {}
        try:
            tokens = list(tokenize.generate_tokens(io.StringIO(src).readline))
        except (tokenize.TokenError, SyntaxError):
            continue
        for i, tok in enumerate(tokens[:-1]):
            # a field's declaration: NAME ':' at the class body's indentation, first on its line
            if (tok.type == tokenize.NAME and tok.string in names and tokens[i + 1].string == ":"
                    and tok.start[1] > 0 and tok.line[:tok.start[1]].strip() == ""):
                line_field.setdefault(tok.start[0], tok.string)
            elif tok.type == tokenize.COMMENT and tok.start[0] in line_field:
                out[line_field[tok.start[0]]] = tok.string.lstrip("#").strip()
    return out


def split_unit(name: str, comment: str) -> tuple[str, str]:
    """(unit, description) of a field from its comment: a trailing ``[unit]``, or a trailing ``(m/s, m/s, rad/s)``
    of units per axis; else the unit its name's suffix says (``_mps`` -> m/s); '' when neither tells."""
    m = re.search(r"\s*\[([^\[\]]*)\]\s*$", comment)
    if m:
        return m.group(1).strip(), comment[:m.start()].strip()
    for m in re.finditer(r"\s*\[([^\[\]]*)\]", comment):      # a unit inside the comment: "... [-] (1: ...)"
        if _UNIT_WORD.match(m.group(1).strip()):
            return m.group(1).strip(), (comment[:m.start()] + comment[m.end():]).strip()
    m = re.search(r"\s*\(([^()]*)\)\s*$", comment)
    if m and all(_UNIT_WORD.match(part.strip()) for part in m.group(1).split(",")):
        return m.group(1).strip(), comment[:m.start()].strip()
    for suffix, unit in _SUFFIX_UNITS:
        if name.endswith(suffix):
            return unit, comment
    return "", comment


def toml_value(v) -> str:
    """A default as it is written in a run configuration (TOML): 0.5, 9, true, [0.0, 0.25], "text"; a value that
    TOML cannot write (None: the field is unset) as ``unset``."""
    if v is None:
        return "unset"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return repr(v)


def parameter_rows(obj, prefix: str = "") -> list[dict]:
    """The fields of a params dataclass instance ``obj`` (its defaults: ``ParamsType()``), nested dataclasses
    flattened to dotted keys: [{key, default (TOML text), value, unit, about, range}] (range: the documented range
    a value must lie in, ``bigcbf.params.checks.ranged``, as text such as ``[2, 20000]``; '' when none)."""
    from ..params.checks import field_range
    rows = []
    comments = field_comments(type(obj))
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        key = prefix + f.name
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            rows.extend(parameter_rows(value, key + "."))
            continue
        unit, about = split_unit(f.name, comments.get(f.name, ""))
        unit = str(f.metadata.get("unit", unit))          # field(metadata={"unit": ..., "doc": ...}) wins
        about = str(f.metadata.get("doc", about))
        rng = field_range(f)
        rows.append({"key": key, "default": toml_value(value), "value": value, "unit": unit, "about": about,
                     "range": "" if rng is None else str(rng)})
    return rows


def format_rows(rows: list[dict], indent: str = "    ") -> list[str]:
    """One line a parameter: ``key = default  [unit]  in RANGE  what it is`` in aligned columns."""
    if not rows:
        return []
    wk = max(len(r["key"]) for r in rows)
    wd = min(max(len(r["default"]) for r in rows), 24)     # a longer default (a matrix) pushes its own row only
    wu = max(len(r["unit"]) for r in rows) + 2
    wr = max(len(r.get("range", "")) for r in rows)
    wr = wr + 3 if wr else 0

    def rng(r):
        return f"{'in ' + r['range'] if r.get('range') else '':<{wr}}  " if wr else ""
    return [f"{indent}{r['key']:<{wk}} = {r['default']:<{wd}}  {'[' + r['unit'] + ']':<{wu}}  {rng(r)}{r['about']}"
            .rstrip() for r in rows]


# --- one method -----------------------------------------------------------------------------------------------

def describe(name: str, origin: str) -> dict:
    """What ``bigcbf methods`` says about method ``name``: origin, what it is, its own parameters' table (the
    TOML table that sets them and the rows) or None when its parameters are the stack's."""
    from ..control.methods import ENTRY_POINT_GROUP, resolve_method
    from ..errors import UserError

    factory = resolve_method(name)
    ptype = getattr(factory, "params_type", None)
    doc = _ABOUT[name] if name in _ABOUT else inspect.getdoc(factory)
    where = {"built-in": "built-in", "module path": "module path"}.get(origin,
                                                                       f"entry point {ENTRY_POINT_GROUP}: {origin}")
    out = {"origin": where, "about": doc or "", "params_type": None, "table": None, "parameters": None}
    if ptype is not None:
        if not (isinstance(ptype, type) and dataclasses.is_dataclass(ptype)):
            raise UserError(f"method {name!r}: its params_type {ptype!r} is not a dataclass (docs/extending.md)")
        try:
            defaults = ptype()
        except Exception as exc:          # a user's dataclass without defaults or with failing checks
            raise UserError(f"method {name!r}: {ptype.__name__}() has no defaults ({exc})") from None
        out.update(params_type=ptype.__name__, table=f"methods.{_toml_key(name)}",
                   params_about=_own_doc(ptype), parameters=parameter_rows(defaults))
    return out


def _own_doc(cls: type) -> str:
    """A class's docstring, '' for the signature that @dataclass writes when the class has none."""
    doc = inspect.getdoc(cls) or ""
    return "" if doc.startswith(f"{cls.__name__}(") else doc


def _toml_key(name: str) -> str:
    return name if re.fullmatch(r"[A-Za-z0-9_-]+", name) else '"' + name + '"'


def stack_rows() -> list[dict]:
    """The stack's parameters as a run uses them by default: Table I with the simulated X3's stack profile."""
    from ..params.stack import default_stack_params
    return parameter_rows(default_stack_params())


def run(args) -> int:
    from ..api import methods
    from ..outputs import strict_json

    found = methods()
    if args.name is not None:
        found = {args.name: found.get(args.name, "module path")}
    info = {name: describe(name, origin) for name, origin in found.items()}
    if args.json:                        # the rows as printed (default as TOML text, unit, what it is)
        def plain(rows):
            return None if rows is None else [{k: v for k, v in r.items() if k != "value"} for r in rows]
        payload = {n: {**d, "parameters": plain(d["parameters"])} for n, d in info.items()}
        if args.name is not None and info[args.name]["parameters"] is None:
            payload[args.name]["stack"] = plain(stack_rows())
        print(strict_json(payload))
        return 0
    width = max(map(len, info), default=0)
    for name, d in info.items():
        full = args.name is not None
        own = (f"; parameters [{d['table']}] ({d['params_type']})" if d["table"] is not None
               else "; " + _STACK_NOTE)
        print(f"{name:<{width}}  {d['origin']}{own}")
        if d["about"]:
            about = d["about"] if full else d["about"].split("\n\n")[0].replace("\n", " ")
            print(textwrap.indent(about if full else textwrap.fill(about, 116), "  "))
        if d["parameters"] is not None:
            if full and d.get("params_about"):
                print(textwrap.indent(d["params_about"], "  "))
            print("\n".join(format_rows(d["parameters"])))
            if full:
                print(f"  set them in a run configuration (bigcbf run --config RUN.toml): a table [{d['table']}] "
                      "with key = value lines")
        elif full:
            print(textwrap.fill("the stack's parameters as a run uses them by default (Table I with the simulated "
                                "X3's stack profile, bigcbf/profiles/stack/x3_sim.toml); set them in [stack] of a "
                                "run configuration (bigcbf run --config RUN.toml), the uncertainty ones also with "
                                "--profile STACK.toml:", 116, initial_indent="  ", subsequent_indent="  "))
            print("\n".join(format_rows(stack_rows())))
    if args.name is None:
        print("any other planner: --method package.module:Class (docs/extending.md); "
              "'bigcbf methods NAME' shows one method in full")
    return 0
