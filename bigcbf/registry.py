"""Name -> object registries (methods, scenarios, ...). A duplicate name is an error."""
from __future__ import annotations

from typing import Generic, Iterator, TypeVar

from .errors import UserError

T = TypeVar("T")


class Registry(Generic[T]):
    def __init__(self, kind: str):
        self.kind = kind
        self._items: dict[str, T] = {}

    def register(self, name: str, obj: T | None = None):
        """``reg.register("x", obj)`` or as a decorator ``@reg.register("x")``."""
        def add(o: T) -> T:
            if name in self._items:
                raise ValueError(f"duplicate {self.kind} name {name!r}")
            self._items[name] = o
            return o
        return add(obj) if obj is not None else add

    def get(self, name: str) -> T:
        try:
            return self._items[name]
        except KeyError:
            raise UserError(f"unknown {self.kind} {name!r}; known: {', '.join(sorted(self._items))}") from None

    def names(self) -> list[str]:
        return list(self._items)

    def __contains__(self, name: str) -> bool:
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self._items)


def describe_object(obj) -> str:
    """What ``obj`` is, in a few words, for an error message (``a built-in function``, ``a module``, ``an int``)."""
    import inspect

    if inspect.ismodule(obj):
        return "a module"
    if inspect.isbuiltin(obj):
        return "a built-in function"
    if inspect.isclass(obj):
        return f"the class {obj.__qualname__}"
    if inspect.isfunction(obj):
        return f"the function {obj.__qualname__}"
    kind = type(obj).__name__
    return f"{'an' if kind[:1].lower() in 'aeiou' else 'a'} {kind} object"


def check_protocol_factory(obj, methods: tuple[str, ...], protocol: str, what: str, name: str) -> None:
    """Check, before anything is constructed or run, that ``obj`` (``name``, loaded from a user's module) can
    be a factory of objects with the callable ``methods`` of ``protocol``: a class that defines them all, or a
    Python function (``def`` or ``lambda``; what it returns is checked when it is called). Anything else (a
    built-in function such as ``os.system``, a module, a class without those methods, an instance) is a one-line
    UserError starting with ``what`` that says what ``obj`` is and what is missing."""
    import functools
    import inspect

    if inspect.isclass(obj):
        missing = [m for m in methods if not callable(getattr(obj, m, None))]
        if missing:
            raise UserError(f"{what}: {name} is {describe_object(obj)}, which is not a {protocol} (no "
                            f"{', '.join(missing)}; a {protocol} class defines {', '.join(methods)})")
        return
    if inspect.isfunction(obj) or isinstance(obj, functools.partial):
        return
    raise UserError(f"{what}: {name} is {describe_object(obj)}, not a {protocol} class (a class that defines "
                    f"{', '.join(methods)}) or a factory function that returns one")
