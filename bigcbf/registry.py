"""Name -> object registries with metadata: methods, world families, faults, suites. A duplicate name is an error.

An object that carries its own ``name`` (a world family, a fault, a suite) registers with ``reg.add(obj)``, so its
name is written once, in the object; its ``tags`` (e.g. a suite's splits, a fault's levels) come with it, as
dm_control's tagged suites and Gymnasium's ``register`` keep metadata beside the name.
"""
from __future__ import annotations

from typing import Callable, Generic, Iterable, Iterator, TypeVar

from .errors import UserError

T = TypeVar("T")


class Registry(Generic[T]):
    def __init__(self, kind: str):
        self.kind = kind
        self._items: dict[str, T] = {}
        self._tags: dict[str, tuple[str, ...]] = {}

    def register(self, name: str, obj: T | None = None, *, tags: Iterable[str] = ()):
        """``reg.register("x", obj)`` or as a decorator ``@reg.register("x")``; ``tags``: the entry's labels."""
        def add(o: T) -> T:
            if not isinstance(name, str) or not name:
                raise ValueError(f"a {self.kind} name is a non-empty string, got {name!r}")
            if name in self._items:
                raise ValueError(f"duplicate {self.kind} name {name!r}")
            self._items[name] = o
            self._tags[name] = tuple(tags)
            return o
        return add(obj) if obj is not None else add

    def add(self, obj: T) -> T:
        """Register ``obj`` under its own ``name`` attribute; its tags are its ``tags`` attribute (if any), read
        when asked (a suite whose splits follow the registered world families stays current)."""
        return self.register(obj.name, obj)

    def remove(self, name: str) -> T:
        """Take ``name`` out (the undo of a temporary registration: a test's toy entry)."""
        self._tags.pop(name, None)
        return self._items.pop(name)

    def sort(self, key: Callable[[T], object]) -> None:
        """Put the entries in the order of ``key`` (the order ``names()`` and iteration list them)."""
        ordered = sorted(self._items.items(), key=lambda item: key(item[1]))
        self._items.clear()
        self._items.update(ordered)

    def get(self, name: str) -> T:
        try:
            return self._items[name]
        except KeyError:
            raise UserError(f"unknown {self.kind} {name!r}; known: {', '.join(sorted(self._items))}") from None

    def tags(self, name: str) -> tuple[str, ...]:
        """The tags ``name`` was registered with, else its object's ``tags`` (UserError for an unknown name)."""
        obj = self.get(name)
        return self._tags.get(name) or tuple(getattr(obj, "tags", ()))

    def tagged(self, tag: str) -> list[str]:
        """The names with ``tag`` among their tags, in registration order."""
        return [n for n in self._items if tag in self.tags(n)]

    def names(self) -> list[str]:
        return list(self._items)

    def values(self) -> list[T]:
        return list(self._items.values())

    def items(self) -> list[tuple[str, T]]:
        return list(self._items.items())

    def __getitem__(self, name: str) -> T:
        return self._items[name]

    def __len__(self) -> int:
        return len(self._items)

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
