"""Load a scenario: TOML file → :class:`~airspace_sim.scenarios.schema.Scenario`, validated.

The checks are derived from the dataclasses in :mod:`.schema`: every field's type comes from
its annotation (``float``, ``int``, ``str``, ``bool``, ``dict``, ``tuple[float, float]``,
``list[X]``, ``X | None`` and nested dataclasses; the conversion is :mod:`.convert`), and
this module holds the scenario's rules: :data:`RANGES` adds what a type cannot
say (positive time step, probabilities in [0, 1], physically meaningful bounds, names that
must exist); :func:`check_scenario` adds the rules between fields. A new schema field is
validated with no change here as long as its type is one of those.

The parts' own parameters (``resolver.params``, ``sensor.params``, ``tracker.params``) are
validated the same way against the part's ``Params`` dataclass, whose fields declare their
ranges (:func:`airspace_sim.parts.param`; :func:`check_parts`, :func:`validate_params`).
This is the one validation pass: the world and its parts trust the resulting
:class:`Scenario` and check nothing again.

Every problem becomes one :class:`~airspace_sim.errors.UserError` line naming the file, the
dotted key and the value::

    scenarios/head_on.toml: traffic.count: expected a non-negative integer, got -3
    --set traffic.count: expected an integer, got 'abc'
    scenarios/bad.toml: invalid TOML at line 4, column 9: Invalid value
"""

from __future__ import annotations

import copy
import dataclasses
import os
import re
import tomllib
import typing
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import airspace_sim
from airspace_sim.errors import UserError
from airspace_sim.scenarios import convert as _conversion
from airspace_sim.scenarios import schema
from airspace_sim.scenarios.convert import Invalid, Rules, describe, hints, show
from airspace_sim.scenarios.overrides import apply_overrides
from airspace_sim.scenarios.schema import Scenario

#: Fields set by the loader, never read from a file.
INTERNAL_FIELDS = {("Scenario", "source"), ("AircraftSpec", "recording")}

#: Traffic patterns :func:`airspace_sim.scenarios.traffic.build_aircraft` knows.
TRAFFIC_PATTERNS = ("none", "ring", "random", "encounter")
#: Id prefix of the aircraft each pattern generates (``ring00``, ``ring01``, ...).
GENERATED_ID_PREFIX = {"ring": "ring", "random": "ac", "encounter": "intruder"}


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


def _velocity_sources():
    from airspace_sim.recorded.readers import VELOCITY_SOURCES

    return VELOCITY_SOURCES


def _range(
    lo: float | None = None,
    hi: float | None = None,
    *,
    lo_open: bool = False,
    unit: str = "",
    integer: bool = False,
) -> Callable[[Any], str | None]:
    """A number in ``[lo, hi]`` (``(lo, hi]`` with ``lo_open``); ``None`` = unbounded."""
    noun = "integer" if integer else "number"
    if (lo == 0 and lo_open) or (integer and lo == 1):
        what = f"a positive {noun}"
    elif lo == 0:
        what = f"a non-negative {noun}"
    elif lo is not None:
        what = f"{'an' if integer else 'a'} {noun} {'>' if lo_open else '≥'} {lo:g}"
    else:
        what = f"an {noun}" if integer else f"a {noun}"
    if hi is not None:
        what += f" up to {hi}" if integer else f" up to {hi:g}"
    if unit:
        what += f" ({unit})"

    def ok(v):
        if lo is not None and not (v > lo if lo_open else v >= lo):
            return False
        return hi is None or v <= hi

    return _check(what, ok)


def _points(limit: float) -> Callable[[Any], str | None]:
    """A point ``(x, y)`` or a list of points with every coordinate within ``±limit`` m."""

    def ok(v):
        pts = [v] if v and not isinstance(v[0], (tuple, list)) else v
        return all(abs(c) <= limit for pt in pts for c in pt)

    def check(value):
        return None if ok(value) else f"expected coordinates within ±{limit:g} m"

    check.limit = (
        f"coordinates within ±{limit:g} m"  # no ``what``: a wrong shape keeps its type message
    )
    return check


def _params_range(meta, tp) -> Callable[[Any], str | None] | None:
    """The check of a part's ``Params`` field of type ``tp`` from its
    :func:`airspace_sim.parts.param` metadata (bounds, choices); None without any."""
    from airspace_sim import parts

    what = parts.describe_range(meta)
    if what is None:
        return None
    if "choices" not in meta:
        what = f"{describe(tp)} {what}"
    return _check(what, lambda v: parts.in_range(meta, v))


def _interval(lo: float, hi: float, unit: str) -> Callable[[Any], str | None]:
    """A ``[low, high]`` range with ``lo ≤ low ≤ high ≤ hi``."""
    return _check(
        f"[low, high] with {lo:g} ≤ low ≤ high ≤ {hi:g} ({unit})",
        lambda v: lo <= v[0] <= v[1] <= hi,
    )


#: Physically meaningful limits (issue 11: beyond them the simulation overflows or runs
#: out of memory rather than failing cleanly).
MAX_DISTANCE_M = 1e7  #: ranges, radii, sectors: 10 000 km
MAX_COORDINATE_M = 1e8  #: positions and waypoints
MAX_SPEED = 1000.0  #: m/s (about Mach 3)
#: m/s: slower is not flight, and a speed of 5e-324 m/s made path metrics 0 / 0
MIN_SPEED = 1.0
MAX_SPEED_RANGE = 0.9  #: the advised speed stays at 10% of the aircraft's own or more
MAX_ACCELERATION = 100.0  #: m/s², about 10 g
MAX_TIME_S = 1e7  #: durations and time constants: about 4 months
MAX_LOOKAHEAD_S = 3600.0
MAX_STEPS = 10_000_000  #: duration / dt
#: aircraft in all: per-aircraft arrays are checked here; the track table, which grows with
#: the pairs in sensor range, is checked when it grows (:mod:`airspace_sim.resources`)
MAX_AIRCRAFT = 100_000
MAX_PROBABILITY_SAMPLES = 1000
MIN_DT_S = 1e-3  #: a shorter step only multiplies the work; 5e-324 overflowed duration / dt
MAX_HEADING_DEG = 360.0  #: headings within ±360° (one turn either way)

POSITIVE = _range(0, lo_open=True)
NON_NEGATIVE = _range(0)
POSITIVE_INT = _range(1, integer=True)
NON_NEGATIVE_INT = _range(0, integer=True)
PROBABILITY = _check("a probability in [0, 1]", lambda v: 0.0 <= v <= 1.0)
NON_EMPTY = _check("a non-empty string", lambda v: bool(v.strip()))
TURN_PREFERENCES = ("right", "nearest", "none")
RESUME_RULES = ("hold", "partial", "no-worse", "diverging", "no-worse-turns")

#: Extra checks per ``"Class.field"`` beyond the annotated type: every value rule of the
#: scenario lives here or in :func:`check_scenario` (cross-field), nowhere else.
RANGES: dict[str, Callable[[Any], str | None]] = {
    "Scenario.name": NON_EMPTY,
    "Scenario.seed": _range(0, 2**63 - 1, integer=True),
    "Scenario.dt": _range(MIN_DT_S, 60.0, unit="s"),
    "Scenario.duration": _range(0, MAX_TIME_S, lo_open=True, unit="s"),
    "Scenario.model": _one_of(_preset_names),
    "Separation.r_safe": _range(0, 1e6, lo_open=True, unit="m"),
    "Separation.nmac": _range(0, 1e6, lo_open=True, unit="m"),
    "SensorSpec.kind": _one_of_registry("sensor"),
    "SensorSpec.range": _range(0, MAX_DISTANCE_M, lo_open=True, unit="m"),
    "SensorSpec.sigma": _range(0, 1e5, unit="m"),
    "SensorSpec.detection_probability": PROBABILITY,
    "SensorSpec.period": _range(0, MAX_LOOKAHEAD_S, lo_open=True, unit="s"),
    "SensorSpec.drop_after_misses": _range(1, 1000, integer=True),
    "TrackerSpec.kind": _one_of_registry("tracker", extra=("truth",)),  # truth: no filter
    "TrackerSpec.model": _one_of(_preset_names),
    "ResolverSpec.kind": _one_of_registry("resolver"),
    "ResolverSpec.lookahead": _range(0, MAX_LOOKAHEAD_S, lo_open=True, unit="s"),
    "ResolverSpec.margin": _range(0, 10.0),
    "ResolverSpec.search_deg": _check("a number of degrees in (0, 180]", lambda v: 0 < v <= 180),
    "ResolverSpec.turn_preference": _one_of(TURN_PREFERENCES),
    "ResolverSpec.confirm_s": _range(0, MAX_LOOKAHEAD_S, unit="s"),
    "ResolverSpec.resume_margin": _range(0, 100.0),
    "ResolverSpec.resume_decay_s": _range(0, MAX_TIME_S, lo_open=True, unit="s"),
    "ResolverSpec.resume_margin_floor": _range(0, 100.0),
    "ResolverSpec.resume_rule": _one_of(RESUME_RULES),
    "ResolverSpec.resume_turn_s": _range(0, MAX_LOOKAHEAD_S, unit="s"),
    "ResolverSpec.resume_off_course_deg": _check(
        "a number of degrees in [0, 180]", lambda v: 0 <= v <= 180
    ),
    "ResolverSpec.route_side_off_course_deg": _check(
        "a number of degrees in [0, 180]", lambda v: 0 <= v <= 180
    ),
    "ResolverSpec.probability_horizon_s": _range(0, MAX_LOOKAHEAD_S, lo_open=True, unit="s"),
    "ResolverSpec.probability_samples": _range(1, MAX_PROBABILITY_SAMPLES, integer=True),
    "ResolverSpec.side_memory_s": _range(0, MAX_TIME_S, unit="s"),
    "AircraftSpec.id": NON_EMPTY,
    "AircraftSpec.position": _points(MAX_COORDINATE_M),
    "AircraftSpec.waypoints": _points(MAX_COORDINATE_M),
    "AircraftSpec.heading_deg": _range(-MAX_HEADING_DEG, MAX_HEADING_DEG, unit="deg"),
    "AircraftSpec.speed": _range(MIN_SPEED, MAX_SPEED, unit="m/s"),
    "AircraftSpec.autopilot": _one_of_registry("autopilot"),
    "AircraftSpec.max_turn_rate_deg": _range(0, 3600.0, unit="deg/s"),
    "AircraftSpec.speed_range": _range(0, MAX_SPEED_RANGE),
    "AircraftSpec.max_acceleration": _range(0, MAX_ACCELERATION, lo_open=True, unit="m/s²"),
    "RecordedSpec.start_s": _range(0, MAX_TIME_S, unit="s"),
    "RecordedSpec.centre_lat_deg": _range(-90.0, 90.0, unit="deg"),
    "RecordedSpec.centre_lon_deg": _range(-180.0, 180.0, unit="deg"),
    "RecordedSpec.min_altitude_ft": _range(-2000.0, 100_000.0, unit="ft"),
    "RecordedSpec.max_altitude_ft": _range(-2000.0, 100_000.0, unit="ft"),
    "RecordedSpec.max_gap_s": _range(0, MAX_TIME_S, lo_open=True, unit="s"),
    "RecordedSpec.velocity": _one_of(_velocity_sources),
    "TrafficSpec.pattern": _one_of(TRAFFIC_PATTERNS),
    "TrafficSpec.count": _range(0, MAX_AIRCRAFT, integer=True),
    "TrafficSpec.radius": _range(0, MAX_DISTANCE_M, lo_open=True, unit="m"),
    "TrafficSpec.sector": _range(0, MAX_DISTANCE_M, lo_open=True, unit="m"),
    "TrafficSpec.spawn_clear_s": _range(0, MAX_LOOKAHEAD_S, unit="s"),
    "TrafficSpec.speed": _range(MIN_SPEED, MAX_SPEED, unit="m/s"),
    "TrafficSpec.speed_spread": _range(0, MAX_SPEED, unit="m/s"),
    "TrafficSpec.autopilot": _one_of_registry("autopilot"),
    "TrafficSpec.max_turn_rate_deg": _range(0, 3600.0, unit="deg/s"),
    "TrafficSpec.speed_range": _range(0, MAX_SPEED_RANGE),
    "TrafficSpec.max_acceleration": _range(0, MAX_ACCELERATION, lo_open=True, unit="m/s²"),
    "TrafficSpec.controlled": NON_NEGATIVE_INT,
    "RandomiseSpec.radius": _interval(1.0, MAX_DISTANCE_M, "m"),
    "RandomiseSpec.phase_deg": _interval(-360.0, 360.0, "deg"),
    "RandomiseSpec.heading_deg": _interval(-180.0, 180.0, "deg"),
    "RandomiseSpec.speed": _interval(1.0, MAX_SPEED, "m/s"),
    "RandomiseSpec.start_s": _interval(0.0, MAX_LOOKAHEAD_S, "s"),
}


def ranges_table() -> str:
    """The markdown table of every number's range in :data:`RANGES`, by dotted key
    (``aircraft[].speed``): what scenarios/README.md shows (a test keeps them equal)."""
    rows = ["| key | range |", "| --- | --- |"]

    def walk(cls, prefix):
        tps = hints(cls)
        for f in dataclasses.fields(cls):
            if (cls.__name__, f.name) in INTERNAL_FIELDS:
                continue
            tp = tps[f.name]
            key = f"{prefix}{f.name}"
            inner = [a for a in typing.get_args(tp) if dataclasses.is_dataclass(a)]
            if dataclasses.is_dataclass(tp) or inner:
                walk(
                    tp if dataclasses.is_dataclass(tp) else inner[0],
                    key + ("[]." if inner else "."),
                )
                continue
            check = RANGES.get(f"{cls.__name__}.{f.name}")
            what = getattr(check, "what", None) or getattr(check, "limit", None)
            numeric = {float, int} & {tp, *typing.get_args(tp)} or "float" in repr(tp)
            if numeric and tp is not bool:
                rows.append(f"| `{key}` | {what or 'any'} |")

    walk(Scenario, "")
    return "\n".join(rows)


# --------------------------------------------------------------------------- conversion


def _field_check(cls, f, tp) -> Callable[[Any], str | None] | None:
    if cls.__module__ == schema.__name__:
        return RANGES.get(f"{cls.__name__}.{f.name}")
    return _params_range(f.metadata, tp)  # a part's Params: the range its field declares


#: The scenario's rules for :mod:`.convert`: :data:`RANGES` for the schema's fields, the
#: declared ranges for a part's ``Params``; :data:`INTERNAL_FIELDS` never read.
RULES = Rules(check=_field_check, internal=frozenset(INTERNAL_FIELDS))


def convert(value: Any, tp, path: str, check: Callable | None = None) -> Any:
    """``value`` as annotation ``tp`` (and passing ``check``), else :class:`Invalid`
    (:func:`airspace_sim.scenarios.convert.convert` under :data:`RULES`)."""
    return _conversion.convert(value, tp, path, check, RULES)


def build_dataclass(cls, table: Any, path: str = ""):
    """Build dataclass ``cls`` from a TOML table, checking keys, types and :data:`RANGES`
    (:func:`airspace_sim.scenarios.convert.build_dataclass` under :data:`RULES`)."""
    return _conversion.build_dataclass(cls, table, path, RULES)


# --------------------------------------------------------------------------- cross-field checks


def check_scenario(sc: Scenario) -> None:
    """Checks that involve several fields; raises :class:`Invalid`."""
    n = len(sc.aircraft) + sc.traffic.count
    if n > MAX_AIRCRAFT:
        raise Invalid(
            "aircraft",
            f"expected at most {MAX_AIRCRAFT} aircraft in all, got {len(sc.aircraft)} "
            f"+ traffic.count {sc.traffic.count}",
        )
    ids = [a.id for a in sc.aircraft]
    for i, aid in enumerate(ids):
        if aid in ids[:i]:
            raise Invalid(f"aircraft[{i}].id", f"duplicate aircraft id, got {aid!r}")
    if sc.traffic.pattern in GENERATED_ID_PREFIX and sc.traffic.count:
        from airspace_sim.scenarios.traffic import _ids

        taken = set(ids)
        prefix = GENERATED_ID_PREFIX[sc.traffic.pattern]
        for gid in _ids(prefix, sc.traffic.count):
            if gid in taken:
                i = ids.index(gid)
                raise Invalid(
                    f"aircraft[{i}].id",
                    f"expected an id unlike the generated {sc.traffic.pattern} aircraft "
                    f"({prefix}00, {prefix}01, ...), got {gid!r}",
                )
    if sc.dt > sc.duration:
        raise Invalid("duration", f"expected at least dt ({sc.dt:g} s), got {sc.duration:g}")
    if sc.duration / sc.dt > MAX_STEPS:
        raise Invalid(
            "duration",
            f"expected at most {MAX_STEPS} steps of dt = {sc.dt:g} s, got {sc.duration:g} s",
        )
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
    if sc.resolver.resume_margin_floor > sc.resolver.resume_margin:
        raise Invalid(
            "resolver.resume_margin_floor",
            f"expected at most resolver.resume_margin ({sc.resolver.resume_margin:g}), "
            f"got {sc.resolver.resume_margin_floor:g}",
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
    if t.speed - t.speed_spread < MIN_SPEED:
        raise Invalid(
            "traffic.speed_spread",
            f"expected at most traffic.speed − {MIN_SPEED:g} m/s ({t.speed - MIN_SPEED:g} m/s: "
            f"generated speeds stay ≥ {MIN_SPEED:g} m/s), got {t.speed_spread:g}",
        )
    from airspace_sim.scenarios.traffic import randomise_problem

    problem = randomise_problem(sc)
    if problem:
        raise Invalid(*problem)
    if t.pattern == "encounter" and not sc.aircraft:
        raise Invalid(
            "traffic.pattern",
            "expected an aircraft[0] (the ownship) for pattern 'encounter', got none",
        )
    r = sc.recorded
    if (r.centre_lat_deg is None) != (r.centre_lon_deg is None):
        given, missing = ("lat", "lon") if r.centre_lon_deg is None else ("lon", "lat")
        raise Invalid(
            f"recorded.centre_{missing}_deg",
            f"expected it with recorded.centre_{given}_deg (the frame centre needs both, or "
            "neither for the data's centre), got none",
        )
    if None not in (r.min_altitude_ft, r.max_altitude_ft) and r.max_altitude_ft < r.min_altitude_ft:
        raise Invalid(
            "recorded.max_altitude_ft",
            f"expected at least recorded.min_altitude_ft ({r.min_altitude_ft:g} ft), "
            f"got {r.max_altitude_ft:g}",
        )


# --------------------------------------------------------------------------- part parameters

#: ``Params`` fields filled from the scenario when a resolver declares them:
#: field → (dotted scenario key, value). ``resolver.params`` overrides them.
RESOLVER_FILLED = {
    "r_safe": ("separation.r_safe", lambda sc: sc.separation.r_safe),
    "lookahead_s": ("resolver.lookahead", lambda sc: sc.resolver.lookahead),
    "margin": ("resolver.margin", lambda sc: sc.resolver.margin),
    "dt": ("dt", lambda sc: sc.dt),
}


def _field_names(Params) -> set[str]:
    return {f.name for f in dataclasses.fields(Params) if f.init}


def resolver_params(sc: Scenario) -> dict:
    """The keyword values of the scenario's resolver ``Params``: :data:`RESOLVER_FILLED`
    fields it declares, then ``resolver.params``. Validated by :func:`from_dict`; what
    :func:`airspace_sim.avoidance.resolvers.build_resolver` constructs from."""
    from airspace_sim import registry

    declared = _field_names(registry.params_class("resolver", sc.resolver.kind))
    out = {k: get(sc) for k, (_, get) in RESOLVER_FILLED.items() if k in declared}
    out.update(sc.resolver.params)
    return out


def _check_params(Params, table: dict, path: str, filled: dict | None = None) -> dict:
    """``table`` validated against dataclass ``Params`` (unknown keys, types, ranges of its
    :func:`airspace_sim.parts.param` fields); returns the converted values of its keys.

    ``filled`` maps keys taken from elsewhere in the scenario to their dotted key, named in
    the error instead of ``path.key`` when such a value does not fit.
    """
    filled = filled or {}
    try:
        built = build_dataclass(Params, table, path)
    except Invalid as exc:
        key = exc.path[len(path) + 1 :] if exc.path.startswith(path + ".") else None
        if key in filled:
            raise Invalid(filled[key], f"{exc.message} for {path}.{key}") from None
        raise
    return {k: getattr(built, k) for k in table}


def validate_params(Params, table: dict, where: str):
    """A ready ``Params`` instance from ``table``, for any kind of part; a one-line
    :class:`UserError` ``"<where>.<key>: ..."`` on an unknown key (listing the known ones),
    a wrong type or a value out of the field's declared range."""
    if not isinstance(table, dict):
        raise UserError(f"{where}: expected a table, got {show(table)}")
    try:
        return build_dataclass(Params, table, where)
    except Invalid as exc:
        raise UserError(str(exc)) from None


def check_parts(sc: Scenario) -> None:
    """Validate the parameters of the scenario's parts against their ``Params``; raises
    :class:`Invalid`. Replaces each ``*.params`` table by its converted values."""
    from airspace_sim import registry
    from airspace_sim.parts import NoParams

    Params = registry.params_class("resolver", sc.resolver.kind)
    declared = _field_names(Params)
    filled = {k: src for k, (src, _) in RESOLVER_FILLED.items() if k in declared}
    filled = {k: v for k, v in filled.items() if k not in sc.resolver.params}
    values = _check_params(Params, resolver_params(sc), "resolver.params", filled)
    sc.resolver.params = {k: values[k] for k in sc.resolver.params}
    sc.sensor.params = _check_params(
        registry.params_class("sensor", sc.sensor.kind), sc.sensor.params, "sensor.params"
    )
    tracker = NoParams
    if sc.tracker.kind in registry.names("tracker"):  # "truth" runs no filter
        tracker = registry.params_class("tracker", sc.tracker.kind)
    sc.tracker.params = _check_params(tracker, sc.tracker.params, "tracker.params")


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
    except RecursionError:
        raise UserError(f"{source}: invalid TOML: arrays or tables nested too deeply") from None
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
    data: dict,
    source: str = "<memory>",
    overrides: Iterable[str] = (),
    name: str | None = None,
    *,
    runnable: bool = False,
) -> Scenario:
    """Validate a TOML-like dict (after applying ``overrides``) into a :class:`Scenario`.

    With ``runnable`` (what :func:`load` asks for a scenario file) a table with no keys, or
    a scenario with no aircraft, no traffic and no recorded file, is refused: there is
    nothing to simulate.
    Without it such a scenario is a configuration code builds (defaults, a resolver's
    parameters)."""

    if runnable and not data:
        raise UserError(
            f"{source}: empty scenario: expected [[aircraft]] tables or a [traffic] table"
        )
    try:
        data = copy.deepcopy(data)
    except RecursionError:  # a dict built in Python; a file's nesting is caught by parse_toml
        raise UserError(f"{source}: values nested too deeply") from None
    overrides = [overrides] if isinstance(overrides, str) else list(overrides)
    _drop_params_of_replaced_kinds(data, overrides)
    set_paths = apply_overrides(data, overrides)
    _recorded_tracker_default(data)
    if name is not None:
        data.setdefault("name", name)
    try:
        sc = build_dataclass(Scenario, data)
        sc.source = source
        check_scenario(sc)
        check_parts(sc)
    except Invalid as exc:
        raise UserError(_where(exc, source, set_paths)) from None
    if runnable and not sc.aircraft and sc.traffic.count == 0 and not sc.recorded.file:
        raise UserError(
            f"{source}: aircraft: expected at least one aircraft ([[aircraft]] tables, "
            "[traffic] with a count or a [recorded] file), got none: nothing to simulate"
        )
    return sc


def _recorded_tracker_default(data: dict) -> None:
    """A scenario that replays recorded traffic and names no tracker model gets
    :data:`~airspace_sim.dynamics.presets.RECORDED_TRACKER` (in place): a tracker chosen on
    real flights, where ``realistic``'s known-rate modes are the simulated traffic's."""
    from airspace_sim.dynamics.presets import RECORDED_TRACKER

    recorded = data.get("recorded")
    if not (isinstance(recorded, dict) and recorded.get("file")):
        return
    tracker = data.setdefault("tracker", {})
    if isinstance(tracker, dict):  # anything else is refused by the validation
        tracker.setdefault("model", RECORDED_TRACKER)


#: the scenario tables whose ``params`` belong to their ``kind``
PARTS_WITH_PARAMS = ("resolver", "sensor", "tracker")


def _kind_of(data: dict, part: str):
    table = data.get(part)
    return table.get("kind") if isinstance(table, dict) else None


def _drop_params_of_replaced_kinds(data: dict, overrides: list[str]) -> None:
    """Where ``overrides`` change a part's kind (``--set resolver.kind=...``), remove the
    file's ``params`` of that part from ``data`` (in place): they were written for the file's
    kind (a ``bands-flown`` table would be refused by ``bands`` as unknown keys), so the new
    kind starts from its defaults plus any ``PART.params`` the overrides set."""
    trial = copy.deepcopy(data)
    apply_overrides(trial, overrides)
    for part in PARTS_WITH_PARAMS:
        if _kind_of(trial, part) != _kind_of(data, part) and isinstance(data.get(part), dict):
            data[part].pop("params", None)


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
    return from_dict(data, source, overrides, name=path.stem, runnable=True)
