"""Field checks shared by the contracts' declarations: :func:`checked` makes a frozen dataclass
refuse a keyword that is no field (naming the closest field) and a value that does not fit its
annotation (naming the field and the type it must have).
"""

from __future__ import annotations

import collections.abc
import dataclasses
import difflib
import functools
import re
import typing
from typing import Callable, Literal

from mcbench import BenchError

__all__ = ["SpecError", "checked", "field_names", "suggestion", "fits", "declaration"]


class SpecError(BenchError):
    """A declaration with an unknown field or a value of the wrong type."""


def checked(cls: type | None = None, *, elsewhere: dict[str, str] | None = None):
    """Class decorator for a frozen dataclass declaration: its ``__init__`` refuses unknown keywords
    with the closest field's name (or, for a key of ``elsewhere``, where that field goes), and every
    field's value is checked against its annotation (before the class's own ``__post_init__``)."""
    if cls is None:
        return functools.partial(checked, elsewhere=elsewhere)
    init, post_init = cls.__init__, getattr(cls, "__post_init__", None)

    def refusal(key: str) -> str:
        if elsewhere and key in elsewhere:
            return f"{cls.__name__} has no field '{key}': it goes in {elsewhere[key]}"
        return f"{cls.__name__} has no field '{key}'{suggestion(key, field_names(cls))}"

    @functools.wraps(init)
    def checked_init(self, *args, **fields):
        unknown = [key for key in fields if key not in field_names(cls)]
        if unknown:
            raise SpecError("; ".join(refusal(key) for key in unknown))
        missing = [name for name in _required(cls) if name not in fields]
        if missing and not args:
            raise SpecError(f"{cls.__name__} needs the field(s) {', '.join(missing)}")
        init(self, *args, **fields)
        if post_init is None:           # the generated __init__ calls __post_init__ only if the class has one
            check(self)

    def check(self) -> None:
        for name, hint in typing.get_type_hints(cls).items():
            value = getattr(self, name)
            if not fits(value, hint):
                raise SpecError(f"{cls.__name__} field '{name}' must be {_type_name(hint)}, got {value!r}")
        if post_init is not None:
            post_init(self)

    cls.__init__ = checked_init
    if post_init is not None:
        cls.__post_init__ = check
    return cls


@functools.cache
def _required(cls: type) -> tuple[str, ...]:
    """The fields of dataclass ``cls`` without a default."""
    return tuple(f.name for f in dataclasses.fields(cls)
                 if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING)


@functools.cache
def field_names(cls: type) -> tuple[str, ...]:
    """The fields of dataclass ``cls``, in declaration order."""
    return tuple(f.name for f in dataclasses.fields(cls))


def suggestion(key: str, names) -> str:
    """`` (did you mean 'x'?)`` for the name of ``names`` closest to ``key`` (case-insensitive), or ``""``."""
    lowered = {name.lower(): name for name in names}
    close = difflib.get_close_matches(key.lower(), lowered, n=1)
    return f" (did you mean '{lowered[close[0]]}'?)" if close else ""


def fits(value, hint) -> bool:
    """Whether ``value`` has the type ``hint``: ``Literal``, ``Optional``/unions, ``tuple[T, ...]``,
    ``dict`` or ``dict[K, V]``, ``Callable``, ``bool``, ``int`` (not bool), a class."""
    origin = typing.get_origin(hint)
    if origin is Literal:
        return value in typing.get_args(hint)
    if origin is typing.Union:
        return any(fits(value, arg) for arg in typing.get_args(hint))
    if hint is type(None):
        return value is None
    if origin is tuple:
        item = typing.get_args(hint)[0]
        return isinstance(value, tuple) and all(fits(v, item) for v in value)
    if origin is dict or hint is dict:
        key, item = typing.get_args(hint) or (object, object)
        return isinstance(value, dict) and all(fits(k, key) and fits(v, item) for k, v in value.items())
    if origin is collections.abc.Callable or hint is Callable:
        return callable(value)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return hint is object or isinstance(value, hint)


def _type_name(hint) -> str:
    """``hint`` as written in the dataclass: ``bool``, ``Optional[tuple[str, ...]]``, ..."""
    return hint.__name__ if isinstance(hint, type) else re.sub(r"\b(?:[a-z_]\w*\.)+(?=\w)", "", str(hint))


def declaration(module, attribute: str, cls: type, folder: str):
    """The declaration ``attribute`` (an instance of ``cls``) of plugin module ``module``; a
    :class:`mcbench.BenchError` naming ``<folder>/<name>.py`` when it has none or something else
    under that name."""
    from mcbench import BenchError

    spec = getattr(module, attribute, None)
    if not isinstance(spec, cls):
        name = module.__name__.rsplit(".", 1)[-1]
        found = "none" if spec is None else f"a {type(spec).__name__}"
        raise BenchError(f"{folder}/{name}.py: {attribute} must be a {cls.__module__}.{cls.__name__} "
                         f"(the {folder[:-1]}'s declaration), found {found}")
    return spec
