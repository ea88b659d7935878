"""Frozen dataclasses <-> TOML, with errors that name the file and the field.

Supported field types: float, int, bool, str, tuples of floats (fixed or variable length), tuples of
tuples of floats (matrices), Optional of these, and nested frozen dataclasses (TOML tables).
Unknown keys are errors; missing keys take the dataclass default (which is documented in the class).
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import tomli_w

from ..errors import UserError

T = TypeVar("T")


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
            raise UserError(f"expected a table, got {value!r}", file=file, field=field)
        return from_dict(tp, value, file=file, prefix=field)
    if tp is bool:
        if not isinstance(value, bool):
            raise UserError(f"expected true or false, got {value!r}", file=file, field=field)
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise UserError(f"expected an integer, got {value!r}", file=file, field=field)
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise UserError(f"expected a number, got {value!r}", file=file, field=field)
        if not math.isfinite(value):
            raise UserError(f"expected a finite number, got {value!r}", file=file, field=field)
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise UserError(f"expected a string, got {value!r}", file=file, field=field)
        return value
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise UserError(f"expected an array, got {value!r}", file=file, field=field)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, file, f"{field}[{j}]") for j, v in enumerate(value))
        if len(value) != len(args):
            raise UserError(f"expected an array of {len(args)} values, got {len(value)}", file=file, field=field)
        return tuple(_convert(a, v, file, f"{field}[{j}]") for j, (a, v) in enumerate(zip(args, value)))
    raise TypeError(f"unsupported field type {_type_name(tp)} for {field}")


def from_dict(cls: type[T], data: dict, *, file: str | None = None, prefix: str = "") -> T:
    """Build the frozen dataclass ``cls`` from a TOML table; unknown keys and bad values raise UserError."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    kwargs = {}
    for key, value in data.items():
        name = f"{prefix}.{key}" if prefix else key
        if key not in fields:
            raise UserError(f"unknown key (known: {', '.join(sorted(fields))})", file=file, field=name)
        kwargs[key] = _convert(hints[key], value, file, name)
    for key, f in fields.items():
        if key not in kwargs and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise UserError("missing key", file=file, field=f"{prefix}.{key}" if prefix else key)
    try:
        return cls(**kwargs)
    except UserError:
        raise
    except (ValueError, TypeError) as exc:  # __post_init__ validation
        raise UserError(str(exc), file=file, field=prefix or None) from None


def load_toml(path: str | Path) -> dict:
    """Read a TOML file; a missing or malformed file is a UserError naming it."""
    p = Path(path)
    try:
        with p.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise UserError("file not found", file=str(p)) from None
    except IsADirectoryError:
        raise UserError("is a directory, expected a TOML file", file=str(p)) from None
    except tomllib.TOMLDecodeError as exc:
        raise UserError(f"not valid TOML: {exc}", file=str(p)) from None


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
    """Write a dataclass as TOML (never overwrites silently a directory; parents are created)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    text = tomli_w.dumps(to_dict(obj))
    if header:
        text = "".join(f"# {line}\n" for line in header.splitlines()) + text
    p.write_text(text)
