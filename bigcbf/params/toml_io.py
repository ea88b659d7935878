"""Frozen dataclasses <-> TOML, with errors that name the file and the field.

Supported field types: float, int, bool, str, tuples of floats (fixed or variable length), tuples of
tuples of floats (matrices), Optional of these, and nested frozen dataclasses (TOML tables).
Unknown keys are errors; missing keys take the dataclass default (which is documented in the class). A field
declared with a documented range (``bigcbf.params.checks.ranged``) is checked against it here, for every dataclass
alike: a value outside is a UserError naming the file and the field. Files are read with a size cap
(:data:`MAX_TOML_BYTES`): at most that many bytes plus one are ever read, so a device or a huge file is refused at
once.
"""
from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

try:
    import tomllib
except ModuleNotFoundError:      # Python 3.10 (a robot's ROS 2 Humble, bigcbf filter): tomli is the same parser
    import tomli as tomllib

import tomli_w

from ..errors import FieldError, UserError
from .checks import range_violation

T = TypeVar("T")


#: every number in a parameter or scenario file lies within +-MAX_ABS_NUMBER (no product of a few of them can
#: overflow a float; each class documents its own, tighter ranges)
MAX_ABS_NUMBER = 1e9


def _short(value: Any, limit: int = 60) -> str:
    """repr(value), cut to one short line (error messages stay one line for any input)."""
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", None) or str(tp).replace("typing.", "")


def _convert(tp: Any, value: Any, file: str | None, field: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        non_none = [a for a in args if a is not type(None)]
        return _convert(non_none[0], value, file, field)
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise UserError(f"expected a table, got {_short(value)}", file=file, field=field)
        return from_dict(tp, value, file=file, prefix=field)
    if tp is bool:
        if not isinstance(value, bool):
            raise UserError(f"expected true or false, got {_short(value)}", file=file, field=field)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise UserError(f"expected an integer, got {_short(value)}", file=file, field=field)
        if abs(value) > MAX_ABS_NUMBER:
            raise UserError(f"expected a number within +-{MAX_ABS_NUMBER:g}, got {_short(value)}", file=file,
                            field=field)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise UserError(f"expected a number, got {_short(value)}", file=file, field=field)
        if not math.isfinite(value):
            raise UserError(f"expected a finite number, got {value!r}", file=file, field=field)
        if abs(value) > MAX_ABS_NUMBER:
            raise UserError(f"expected a number within +-{MAX_ABS_NUMBER:g}, got {_short(value)}", file=file,
                            field=field)
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise UserError(f"expected a string, got {_short(value)}", file=file, field=field)
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise UserError(f"expected an array, got {_short(value)}", file=file, field=field)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, file, f"{field}[{j}]") for j, v in enumerate(value))
        if len(value) != len(args):
            raise UserError(f"expected an array of {len(args)} values, got {len(value)}", file=file, field=field)
        return tuple(_convert(a, v, file, f"{field}[{j}]") for j, (a, v) in enumerate(zip(args, value)))
    raise TypeError(f"unsupported field type {_type_name(tp)} for {field}")


@functools.lru_cache(maxsize=None)
def _fields(cls: type) -> tuple[dict, dict]:
    """A dataclass's resolved type hints and init fields (resolving hints is slow; classes do not change)."""
    return typing.get_type_hints(cls), {f.name: f for f in dataclasses.fields(cls) if f.init}


def from_dict(cls: type[T], data: dict, *, file: str | None = None, prefix: str = "") -> T:
    """Build the frozen dataclass ``cls`` from a TOML table; unknown keys and bad values raise UserError."""
    hints, fields = _fields(cls)
    kwargs = {}
    for key, value in data.items():
        name = f"{prefix}.{key}" if prefix else key
        if key not in fields:
            raise UserError(f"unknown key (known: {', '.join(sorted(fields))})", file=file, field=name)
        kwargs[key] = _convert(hints[key], value, file, name)
        problem = range_violation(fields[key], kwargs[key])      # the field's documented range (checks.ranged)
        if problem is not None:
            raise UserError(problem, file=file, field=name)
    for key, f in fields.items():
        if key not in kwargs and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise UserError("missing key", file=file, field=f"{prefix}.{key}" if prefix else key)
    try:
        return cls(**kwargs)
    except UserError:
        raise
    except FieldError as exc:               # __post_init__ validation that names its field
        raise UserError(str(exc), file=file, field=f"{prefix}.{exc.field}" if prefix else exc.field) from None
    except (ValueError, TypeError) as exc:  # __post_init__ validation
        raise UserError(str(exc), file=file, field=prefix or None) from None


#: deepest nesting of tables and arrays accepted in a TOML file (the shipped files use 3; deeper is a mistake, and
#: Python's TOML parser would exhaust its recursion limit on a few thousand levels)
MAX_TOML_DEPTH = 32


def _depth(node, limit: int) -> int:
    """Nesting depth of parsed TOML (stops counting past ``limit``)."""
    stack, deepest = [(node, 0)], 0
    while stack:
        n, d = stack.pop()
        deepest = max(deepest, d)
        if deepest > limit:
            break
        if isinstance(n, dict):
            stack.extend((v, d + 1) for v in n.values())
        elif isinstance(n, list):
            stack.extend((v, d + 1) for v in n)
    return deepest


def parse_toml(text: str, file: str | None = None) -> dict:
    """Parse TOML text; a syntax error, too deep a nesting or a text longer than :data:`MAX_TOML_BYTES` is a
    UserError naming ``file``."""
    if len(text) > MAX_TOML_BYTES:
        raise UserError(f"larger than the {MAX_TOML_BYTES:,} bytes a TOML file may have; is it the right file?",
                        file=file)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"not valid TOML: {exc}", file=file) from None
    except RecursionError:
        raise UserError(f"tables or arrays nested deeper than {MAX_TOML_DEPTH} levels", file=file) from None
    if _depth(data, MAX_TOML_DEPTH) > MAX_TOML_DEPTH:
        raise UserError(f"tables or arrays nested deeper than {MAX_TOML_DEPTH} levels", file=file)
    return data


#: largest parameter, scenario or configuration file read [bytes] (1 MiB; the largest shipped one is ~4 KiB, a
#: generated world of 1000 walls ~100 KiB)
MAX_TOML_BYTES = 1 << 20


def read_capped(path: str | Path, cap: int, what: str = "file") -> bytes:
    """The bytes of ``path``, reading at most ``cap`` + 1 of them: a longer file (or an endless device such as
    /dev/zero) is a UserError naming it, after reading no more than that. OSErrors propagate."""
    with open(path, "rb") as fh:
        raw = fh.read(cap + 1)
    if len(raw) > cap:
        raise UserError(f"larger than the {cap:,} bytes a {what} may have; is it the right file?", file=str(path))
    return raw


def load_toml(path: str | Path) -> dict:
    """Read a TOML file (UTF-8, as TOML requires; at most :data:`MAX_TOML_BYTES`); a missing, unreadable, binary,
    too large or malformed file is a UserError naming it."""
    p = Path(path)
    try:
        raw = read_capped(p, MAX_TOML_BYTES, "TOML file")
    except FileNotFoundError:
        raise UserError("file not found", file=str(p)) from None
    except IsADirectoryError:
        raise UserError("is a directory, expected a TOML file", file=str(p)) from None
    except OSError as exc:
        raise UserError(f"cannot read the file ({exc.strerror or exc})", file=str(p)) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise UserError(f"not a UTF-8 text file (byte 0x{raw[exc.start]:02x} on line {line}); TOML files are "
                        "UTF-8: re-save it as UTF-8", file=str(p)) from None
    return parse_toml(text, str(p))


def load(cls: type[T], path: str | Path, *, table: str | None = None) -> T:
    """Load ``cls`` from a TOML file (optionally from one of its tables)."""
    data = load_toml(path)
    if table is not None:
        data = data.get(table, {})
    return from_dict(cls, data, file=str(path), prefix=table or "")


def to_dict(obj: Any) -> dict:
    """The TOML table of a dataclass (tuples become arrays; None fields are left out)."""
    out = {}
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if v is None:
            continue
        if dataclasses.is_dataclass(v):
            out[f.name] = to_dict(v)
        elif isinstance(v, tuple):
            out[f.name] = [list(x) if isinstance(x, tuple) else x for x in v]
        else:
            out[f.name] = v
    return out


def save(obj: Any, path: str | Path, *, header: str = "") -> None:
    """Write a dataclass as TOML, atomically (a temporary file renamed over ``path``; parents are created)."""
    from ..outputs import write_text
    text = tomli_w.dumps(to_dict(obj))
    if header:
        text = "".join(f"# {line}\n" for line in header.splitlines()) + text
    write_text(path, text, "TOML file")
