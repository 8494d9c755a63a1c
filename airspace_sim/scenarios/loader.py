"""Load a scenario: TOML file → :class:`~airspace_sim.scenarios.schema.Scenario`, validated.

The checks are derived from the dataclasses in :mod:`.schema`: every field's type comes from
its annotation (``float``, ``int``, ``str``, ``bool``, ``dict``, ``tuple[float, float]``,
``list[X]``, ``X | None`` and nested dataclasses), and :data:`RANGES` adds what a type cannot
say (positive time step, probabilities in [0, 1], names that must exist). A new schema field
is validated with no change here as long as its type is one of those.

Every problem becomes one :class:`~airspace_sim.errors.UserError` line naming the file, the
dotted key and the value::

    scenarios/head_on.toml: traffic.count: expected a non-negative integer, got -3
    --set traffic.count: expected an integer, got 'abc'
    scenarios/bad.toml: invalid TOML at line 4, column 9: Invalid value
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
import re
import tomllib
import types
import typing
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import airspace_sim
from airspace_sim.errors import UserError
from airspace_sim.scenarios import schema
from airspace_sim.scenarios.overrides import apply_overrides
from airspace_sim.scenarios.schema import Scenario

#: Fields set by the loader, never read from a file.
INTERNAL_FIELDS = {("Scenario", "source")}

#: Traffic patterns :func:`airspace_sim.scenarios.traffic.build_aircraft` knows.
TRAFFIC_PATTERNS = ("none", "ring", "random", "encounter")


class Invalid(Exception):
    """A validation failure at ``path`` (dotted key), before the source is prefixed."""

    def __init__(self, path: str, message: str):
        super().__init__(f"{path}: {message}" if path else message)
        self.path = path
        self.message = message


# --------------------------------------------------------------------------- range table
# A check takes the converted value and returns None if fine, else the expectation text
# ("expected ...") used in the error. ``what`` is what the value must be.


def _check(what: str, ok: Callable[[Any], bool]) -> Callable[[Any], str | None]:
    def check(value):
        # None is an unset optional field (``X | None``); its type check already passed
        return None if value is None or ok(value) else f"expected {what}"

    check.what = what
    return check


def _one_of_registry(kind: str, extra: tuple[str, ...] = ()) -> Callable[[Any], str | None]:
    """A registered name of ``kind`` (or one of ``extra``, names the world handles itself);
    skipped while nothing of that kind is registered yet (parts still being written)."""

    def check(value):
        from airspace_sim import registry

        registered = registry.names(kind)
        known = sorted(set(registered) | set(extra))
        if not registered or value in known:
            return None
        return f"expected a registered {kind} name ({', '.join(known)})"

    return check


def _one_of(choices: Callable[[], Iterable[str]] | Iterable[str]) -> Callable[[Any], str | None]:
    def check(value):
        options = list(choices() if callable(choices) else choices)
        return None if value in options else f"expected one of {', '.join(options)}"

    return check


def _preset_names():
    from airspace_sim.dynamics.presets import PRESETS

    return sorted(PRESETS)


POSITIVE = _check("a positive number", lambda v: v > 0)
NON_NEGATIVE = _check("a non-negative number", lambda v: v >= 0)
POSITIVE_INT = _check("a positive integer", lambda v: v >= 1)
NON_NEGATIVE_INT = _check("a non-negative integer", lambda v: v >= 0)
PROBABILITY = _check("a probability in [0, 1]", lambda v: 0.0 <= v <= 1.0)
NON_EMPTY = _check("a non-empty string", lambda v: bool(v.strip()))

#: Extra checks per ``"Class.field"`` beyond the annotated type.
RANGES: dict[str, Callable[[Any], str | None]] = {
    "Scenario.name": NON_EMPTY,
    "Scenario.seed": NON_NEGATIVE_INT,
    "Scenario.dt": POSITIVE,
    "Scenario.duration": POSITIVE,
    "Scenario.model": _one_of(_preset_names),
    "Separation.r_safe": POSITIVE,
    "Separation.nmac": POSITIVE,
    "SensorSpec.kind": _one_of_registry("sensor"),
    "SensorSpec.range": POSITIVE,
    "SensorSpec.sigma": NON_NEGATIVE,
    "SensorSpec.detection_probability": PROBABILITY,
    "SensorSpec.period": POSITIVE,
    "SensorSpec.drop_after_misses": POSITIVE_INT,
    "TrackerSpec.kind": _one_of_registry("tracker", extra=("truth",)),  # truth: no filter
    "TrackerSpec.model": _one_of(_preset_names),
    "ResolverSpec.kind": _one_of_registry("resolver"),
    "ResolverSpec.lookahead": POSITIVE,
    "ResolverSpec.margin": NON_NEGATIVE,
    "ResolverSpec.search_deg": _check("a number of degrees in (0, 180]", lambda v: 0 < v <= 180),
    "ResolverSpec.turn_preference": _one_of(("right", "nearest", "none")),
    "ResolverSpec.confirm_s": NON_NEGATIVE,
    "ResolverSpec.resume_margin": NON_NEGATIVE,
    "ResolverSpec.resume_decay_s": POSITIVE,
    "ResolverSpec.probability_horizon_s": POSITIVE,
    "ResolverSpec.probability_samples": POSITIVE_INT,
    "AircraftSpec.id": NON_EMPTY,
    "AircraftSpec.speed": POSITIVE,
    "AircraftSpec.autopilot": _one_of_registry("autopilot"),
    "AircraftSpec.max_turn_rate_deg": POSITIVE,
    "TrafficSpec.pattern": _one_of(TRAFFIC_PATTERNS),
    "TrafficSpec.count": NON_NEGATIVE_INT,
    "TrafficSpec.radius": POSITIVE,
    "TrafficSpec.sector": POSITIVE,
    "TrafficSpec.spawn_clear_s": NON_NEGATIVE,
    "TrafficSpec.speed": POSITIVE,
    "TrafficSpec.speed_spread": NON_NEGATIVE,
    "TrafficSpec.autopilot": _one_of_registry("autopilot"),
    "TrafficSpec.max_turn_rate_deg": POSITIVE,
    "TrafficSpec.controlled": NON_NEGATIVE_INT,
}


# --------------------------------------------------------------------------- conversion


def _show(value: Any) -> str:
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


def convert(value: Any, tp, path: str, check: Callable | None = None) -> Any:
    """``value`` as annotation ``tp`` (and passing ``check``), else :class:`Invalid`."""
    try:
        out = _convert(value, tp, path)
    except Invalid as exc:
        what = getattr(check, "what", None)
        if what and exc.path == path:
            raise _type_error(tp, value, path, check) from None
        raise
    if check is not None:
        problem = check(out)
        if problem:
            raise Invalid(path, f"{problem}, got {_show(value)}")
    return out


def _type_error(tp, value, path, check=None) -> Invalid:
    what = getattr(check, "what", None) or describe(tp)
    return Invalid(path, f"expected {what}, got {_show(value)}")


def _convert(value: Any, tp, path: str) -> Any:
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
                return _convert(value, arg, path)
            except Invalid:
                continue
        raise _type_error(tp, value, path)
    if tp is float:
        if not _is_number(value):
            raise _type_error(tp, value, path)
        if not math.isfinite(value):
            raise Invalid(path, f"expected a finite number, got {_show(value)}")
        return float(value)
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
            return {k: _convert(v, args[1], f"{path}.{k}") for k, v in value.items()}
        return dict(value)
    if dataclasses.is_dataclass(tp):
        return build_dataclass(tp, value, path)
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise _type_error(tp, value, path)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{path}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise _type_error(tp, value, path)
        return tuple(
            _convert(v, a, f"{path}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=True))
        )
    if origin is list or tp is list:
        if not isinstance(value, (list, tuple)):
            raise _type_error(tp, value, path)
        if not args:
            return list(value)
        return [_convert(v, args[0], f"{path}[{i}]") for i, v in enumerate(value)]
    raise TypeError(f"{path}: unsupported scenario field type {tp!r}")


def _hints(cls) -> dict:
    return typing.get_type_hints(cls, vars(schema))


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def build_dataclass(cls, table: Any, path: str = ""):
    """Build dataclass ``cls`` from a TOML table, checking keys, types and :data:`RANGES`."""
    if not isinstance(table, dict):
        raise Invalid(path, f"expected a table, got {_show(table)}")
    hints = _hints(cls)
    fields = {
        f.name: f
        for f in dataclasses.fields(cls)
        if f.init and (cls.__name__, f.name) not in INTERNAL_FIELDS
    }
    for key in table:
        if key not in fields:
            near = difflib.get_close_matches(str(key), list(fields), n=1)
            hint = f"did you mean {near[0]!r}? " if near else ""
            raise Invalid(
                _join(path, str(key)),
                f"unknown key, got {_show(table[key])} ({hint}known: {', '.join(fields)})",
            )
    kwargs = {}
    for name, f in fields.items():
        key_path = _join(path, name)
        if name not in table:
            required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
            if required:
                raise Invalid(key_path, f"missing (required: {describe(hints[name])})")
            continue
        kwargs[name] = convert(
            table[name], hints[name], key_path, RANGES.get(f"{cls.__name__}.{name}")
        )
    return cls(**kwargs)


# --------------------------------------------------------------------------- cross-field checks


def check_scenario(sc: Scenario) -> None:
    """Checks that involve several fields; raises :class:`Invalid`."""
    ids = [a.id for a in sc.aircraft]
    for i, aid in enumerate(ids):
        if aid in ids[:i]:
            raise Invalid(f"aircraft[{i}].id", f"duplicate aircraft id, got {aid!r}")
    if sc.dt > sc.duration:
        raise Invalid("duration", f"expected at least dt ({sc.dt:g} s), got {sc.duration:g}")
    ratio = sc.sensor.period / sc.dt
    if abs(ratio - round(ratio)) > 1e-6 * max(1.0, ratio) or round(ratio) < 1:
        raise Invalid(
            "sensor.period",
            f"expected a whole multiple of dt ({sc.dt:g} s), got {sc.sensor.period:g}",
        )
    if sc.separation.nmac >= sc.separation.r_safe:
        raise Invalid(
            "separation.nmac",
            f"expected less than separation.r_safe ({sc.separation.r_safe:g} m), "
            f"got {sc.separation.nmac:g}",
        )
    t = sc.traffic
    if t.controlled > t.count:
        raise Invalid(
            "traffic.controlled",
            f"expected at most traffic.count ({t.count}), got {t.controlled}",
        )
    if t.pattern != "none" and t.count == 0:
        raise Invalid(
            "traffic.count", f"expected a positive integer for pattern {t.pattern!r}, got 0"
        )
    if t.pattern == "none" and t.count > 0:
        raise Invalid(
            "traffic.pattern",
            f"expected ring, random or encounter with count {t.count}, got 'none'",
        )
    if t.speed_spread >= t.speed:
        raise Invalid(
            "traffic.speed_spread",
            f"expected less than traffic.speed ({t.speed:g} m/s), got {t.speed_spread:g}",
        )
    if t.pattern == "encounter" and not sc.aircraft:
        raise Invalid(
            "traffic.pattern",
            "expected an aircraft[0] (the ownship) for pattern 'encounter', got none",
        )


# --------------------------------------------------------------------------- files


def scenario_dirs() -> list[Path]:
    """Folders searched for scenario names: the repository's ``scenarios/``, then
    ``./scenarios``."""
    dirs = [
        Path(airspace_sim.__file__).resolve().parent.parent / "scenarios",
        Path.cwd() / "scenarios",
    ]
    out = []
    for d in dirs:
        if d.is_dir() and d.resolve() not in [o.resolve() for o in out]:
            out.append(d)
    return out


def available() -> list[str]:
    """Names of the shipped scenarios (file stems)."""
    return sorted({p.stem for d in scenario_dirs() for p in d.glob("*.toml")})


def resolve(name_or_path: str | os.PathLike) -> Path:
    """The file for a scenario name or path; :class:`UserError` if there is none."""
    text = os.fspath(name_or_path)
    path = Path(text)
    if path.is_file():
        return path
    looks_like_path = text.endswith(".toml") or os.sep in text or "/" in text
    if not looks_like_path:
        for d in scenario_dirs():
            candidate = d / f"{text}.toml"
            if candidate.is_file():
                return candidate
    known = ", ".join(available()) or "none"
    if looks_like_path:
        raise UserError(f"{text}: no such scenario file")
    raise UserError(f"unknown scenario {text!r} (known: {known}; or give a path to a .toml file)")


def display_path(path: Path) -> str:
    """``path`` relative to the working directory when it is below it."""
    try:
        return str(path.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


_LINE_COL = re.compile(r"\s*\(at line (\d+), column (\d+)\)")
_END = re.compile(r"\s*\(at end of document\)")


def parse_toml(text: str, source: str) -> dict:
    """Parse TOML; a syntax error becomes one line with file, line and column."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc)
        m = _LINE_COL.search(msg)
        if m:
            line, col = m.group(1), m.group(2)
            msg = _LINE_COL.sub("", msg)
        else:
            lines = text.split("\n")
            line, col = len(lines), len(lines[-1]) + 1
            msg = _END.sub("", msg) + " (at end of file)"
        raise UserError(f"{source}: invalid TOML at line {line}, column {col}: {msg}") from None


def from_dict(
    data: dict, source: str = "<memory>", overrides: Iterable[str] = (), name: str | None = None
) -> Scenario:
    """Validate a TOML-like dict (after applying ``overrides``) into a :class:`Scenario`."""
    import copy

    data = copy.deepcopy(data)
    set_paths = apply_overrides(data, overrides)
    if name is not None:
        data.setdefault("name", name)
    try:
        sc = build_dataclass(Scenario, data)
        sc.source = source
        check_scenario(sc)
    except Invalid as exc:
        raise UserError(_where(exc, source, set_paths)) from None
    return sc


def _where(exc: Invalid, source: str, set_paths: list[str]) -> str:
    """Prefix an error with ``--set`` when the failing key came from an override."""
    for p in set_paths:
        if exc.path == p or exc.path.startswith((p + ".", p + "[")):
            return f"--set {exc}"
    return f"{source}: {exc}"


def load(name_or_path: str | os.PathLike, overrides: Iterable[str] = ()) -> Scenario:
    """Load a scenario by name (a file stem in ``scenarios/``) or path, with ``--set`` overrides.

    Raises :class:`UserError` (one line: file, dotted key, value) on any problem.
    """
    path = resolve(name_or_path)
    source = display_path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{source}: cannot read: {exc}") from None
    data = parse_toml(text, source)
    return from_dict(data, source, overrides, name=path.stem)
