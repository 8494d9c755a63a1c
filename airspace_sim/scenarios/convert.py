"""Typed conversion: a TOML value into an annotated dataclass field, checked on the way.

Every field's type comes from its annotation (``float``, ``int``, ``str``, ``bool``,
``dict``, ``tuple[float, float]``, ``tuple[X, ...]``, ``list[X]``, ``X | None`` and nested
dataclasses); numbers must be finite. What a type cannot say (ranges, names that must
exist) is the caller's: :class:`Rules` gives each field its check, and which fields are
never read from a file. The scenario's own rules and their table are in :mod:`.loader`.

Every problem is an :class:`Invalid` naming the dotted key and the value, e.g.
``aircraft[1].speed: expected a number, got 'x'``; the loader prefixes the file.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import types
import typing
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


class Invalid(Exception):
    """A validation failure at ``path`` (dotted key), before the source is prefixed."""

    def __init__(self, path: str, message: str):
        super().__init__(f"{path}: {message}" if path else message)
        self.path = path
        self.message = message


@dataclass(frozen=True)
class Rules:
    """What a type cannot say. ``check(cls, field, tp)``: the value check of ``field`` (of
    annotation ``tp``) of dataclass ``cls``, a callable returning None when the converted
    value is fine, else the expectation ("expected ..."), or None for no check; its
    ``what`` attribute, if any, replaces the type's description in a type error.
    ``internal``: ``(class name, field name)`` pairs never read from a table."""

    check: Callable[[type, dataclasses.Field, Any], Callable | None] | None = None
    internal: frozenset = frozenset()


#: Types only: no value checks, every field read.
NO_RULES = Rules()


def show(value: Any) -> str:
    """A short, readable rendering of a value for an error message."""
    if isinstance(value, dict):
        text = "a table {" + ", ".join(map(str, value)) + "}"
    elif isinstance(value, bool):
        text = "true" if value else "false"
    else:
        text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def describe(tp) -> str:
    """What a value of annotation ``tp`` looks like, for messages ("a number", ...)."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is str:
        return "a string"
    if tp is bool:
        return "true or false"
    if tp is dict or origin is dict:
        return "a table"
    if tp is typing.Any:
        return "any value"
    if dataclasses.is_dataclass(tp):
        return "a table"
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_plural(args[0])}"
        if len(set(args)) == 1:
            return f"a list of {len(args)} {_plural(args[0])}"
        return f"a list of {len(args)} values"
    if origin is list:
        return f"a list of {_plural(args[0])}" if args else "a list"
    if origin in (typing.Union, types.UnionType):
        return " or ".join(describe(a) for a in args if a is not type(None))
    raise TypeError(f"unsupported scenario field type {tp!r}")


def _plural(tp) -> str:
    simple = {float: "numbers", int: "integers", str: "strings", bool: "booleans"}
    if tp in simple:
        return simple[tp]
    if dataclasses.is_dataclass(tp) or tp is dict or typing.get_origin(tp) is dict:
        return "tables"
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin is tuple and args and Ellipsis not in args and len(set(args)) == 1:
        return f"lists of {len(args)} {_plural(args[0])}"  # e.g. [x, y] points
    if origin in (tuple, list):
        return "lists"
    return describe(tp)


def convert(
    value: Any, tp, path: str, check: Callable | None = None, rules: Rules = NO_RULES
) -> Any:
    """``value`` as annotation ``tp`` (and passing ``check``), nested dataclasses built
    under ``rules``; else :class:`Invalid`."""
    try:
        out = _convert(value, tp, path, rules)
    except Invalid as exc:
        what = getattr(check, "what", None)
        if what and exc.path == path:
            raise _type_error(tp, value, path, check) from None
        raise
    if check is not None:
        problem = check(out)
        if problem:
            raise Invalid(path, f"{problem}, got {show(value)}")
    return out


def _type_error(tp, value, path, check=None) -> Invalid:
    what = getattr(check, "what", None) or describe(tp)
    return Invalid(path, f"expected {what}, got {show(value)}")


def _convert(value: Any, tp, path: str, rules: Rules) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if tp is typing.Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(value, arg, path, rules)
            except Invalid:
                continue
        raise _type_error(tp, value, path)
    if tp is float:
        if not _is_number(value):
            raise _type_error(tp, value, path)
        if not math.isfinite(value):
            raise Invalid(path, f"expected a finite number, got {show(value)}")
        return float(value) + 0.0  # -0.0 → 0.0: a signed zero means nothing here
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise _type_error(tp, value, path)
        return value
    if tp is bool or tp is str:
        if not isinstance(value, tp):
            raise _type_error(tp, value, path)
        return value
    if tp is dict or origin is dict:
        if not isinstance(value, dict):
            raise _type_error(tp, value, path)
        if origin is dict and args:
            return {k: _convert(v, args[1], f"{path}.{k}", rules) for k, v in value.items()}
        return dict(value)
    if dataclasses.is_dataclass(tp):
        return build_dataclass(tp, value, path, rules)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise _type_error(tp, value, path)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{path}[{i}]", rules) for i, v in enumerate(value))
        if len(value) != len(args):
            raise _type_error(tp, value, path)
        return tuple(
            _convert(v, a, f"{path}[{i}]", rules)
            for i, (v, a) in enumerate(zip(value, args, strict=True))
        )
    if origin is list or tp is list:
        if not isinstance(value, (list, tuple)):
            raise _type_error(tp, value, path)
        if not args:
            return list(value)
        return [_convert(v, args[0], f"{path}[{i}]", rules) for i, v in enumerate(value)]
    raise TypeError(f"{path}: unsupported scenario field type {tp!r}")


def hints(cls) -> dict:
    """Field name → resolved annotation of dataclass ``cls`` (in its own module)."""
    return typing.get_type_hints(cls)


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def build_dataclass(cls, table: Any, path: str = "", rules: Rules = NO_RULES):
    """Build dataclass ``cls`` from a TOML table at dotted ``path``: unknown keys (with the
    closest known one), missing required keys, every value's type and the check
    ``rules.check`` gives its field; nested dataclasses the same way."""
    if not isinstance(table, dict):
        raise Invalid(path, f"expected a table, got {show(table)}")
    tps = hints(cls)
    fields = {
        f.name: f
        for f in dataclasses.fields(cls)
        if f.init and (cls.__name__, f.name) not in rules.internal
    }
    for key in table:
        if key not in fields:
            near = difflib.get_close_matches(str(key), list(fields), n=1)
            hint = f"did you mean {near[0]!r}? " if near else ""
            raise Invalid(
                _join(path, str(key)),
                f"unknown key, got {show(table[key])} "
                f"({hint}known: {', '.join(fields) if fields else 'none, it takes no keys'})",
            )
    kwargs = {}
    for name, f in fields.items():
        key_path = _join(path, name)
        if name not in table:
            required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
            if required:
                raise Invalid(key_path, f"missing (required: {describe(tps[name])})")
            continue
        check = rules.check(cls, f, tps[name]) if rules.check is not None else None
        kwargs[name] = convert(table[name], tps[name], key_path, check, rules)
    return cls(**kwargs)
