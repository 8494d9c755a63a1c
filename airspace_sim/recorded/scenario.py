"""Recorded aircraft for a scenario: a ``[recorded]`` section turned into ``AircraftSpec`` s.

    [recorded]
    file = "traffic:switzerland"     # or a path (relative to the scenario file)
    start_s = 3600                   # world time 0 is one hour into the recording
    min_altitude_ft = 10000          # en-route traffic only

Every flight with data in ``[start_s, start_s + duration]`` becomes an aircraft flown by the
``"recorded"`` autopilot (:mod:`.autopilot`), its id the flight's
(:attr:`~airspace_sim.recorded.flights.Flight.id`), placed at its first recorded position
in the world. With ``track = true`` (the default) it tracks the others and runs the
detection, so its alerts count, but it never flies the advice. Hand-placed and generated
aircraft of the same scenario share the local frame (metres from the frame centre, which
``centre_lat_deg`` / ``centre_lon_deg`` fix; by default the data's centre).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

from airspace_sim.errors import UserError
from airspace_sim.recorded.autopilot import Recording
from airspace_sim.recorded.flights import FOOT_M, Flight, Flights


def resolve_file(file: str, source: str) -> Path:
    """The trajectory file of a ``[recorded] file`` value: ``traffic:NAME`` is a sample of
    the traffic wheel (:mod:`.samples`), a relative path is relative to the scenario file
    ``source`` when that file exists, else to the working directory."""
    if file.startswith("traffic:"):
        from airspace_sim.recorded import samples

        return samples.path(file[len("traffic:") :])
    p = Path(file).expanduser()
    if not p.is_absolute():
        base = Path(source).parent if Path(source).is_file() else Path.cwd()
        if (base / p).exists():
            p = base / p
    if not p.is_file():
        raise UserError(f"{source}: recorded.file: no such file, got {file!r}")
    return p


@functools.lru_cache(maxsize=8)
def _read_cached(
    path: str, mtime: float, centre, max_gap_s: float, velocity: str, keep_glitches: bool
) -> Flights:
    from airspace_sim.recorded.glitches import SPIKE_M
    from airspace_sim.recorded.readers import read

    glitch_m = None if keep_glitches else SPIKE_M
    return read(path, centre=centre, max_gap_s=max_gap_s, velocity=velocity, glitch_m=glitch_m)


def load_flights(spec, source: str = "<memory>") -> Flights:
    """The :class:`Flights` of a :class:`~airspace_sim.scenarios.schema.RecordedSpec`
    (read once per file, frame, gap, velocity source and glitch rule: Flights are
    immutable), with its
    ``flights``, altitude and ``max_gap_s`` selections applied. ``spec`` is one the scenario
    loader validated (:data:`airspace_sim.scenarios.loader.RANGES` and
    :func:`~airspace_sim.scenarios.loader.check_scenario` hold its rules); only what needs
    the file is checked here."""
    path = resolve_file(spec.file, source)
    centre = None
    if spec.centre_lat_deg is not None:
        centre = (float(spec.centre_lat_deg), float(spec.centre_lon_deg))
    flights = _read_cached(
        str(path.resolve()), path.stat().st_mtime, centre, spec.max_gap_s, spec.velocity,
        bool(spec.keep_glitches),
    )  # fmt: skip
    if spec.flights:
        wanted = set(spec.flights)
        flights = flights.select(lambda f: bool({f.id, f.icao24, f.callsign} & wanted))
        if not len(flights):
            raise UserError(
                f"{source}: recorded.flights: none of {sorted(wanted)[:3]} is in {path.name}"
            )
    lo, hi = spec.min_altitude_ft, spec.max_altitude_ft
    if lo is not None or hi is not None:
        lo_m = -math.inf if lo is None else lo * FOOT_M
        hi_m = math.inf if hi is None else hi * FOOT_M
        flights = flights.keep_samples(lambda f: ~((f.altitude_m < lo_m) | (f.altitude_m > hi_m)))
    return flights


def recorded_aircraft(scenario, taken=frozenset()) -> list:
    """``AircraftSpec`` s (autopilot ``"recorded"``) for the flights of ``scenario.recorded``
    with data during the scenario's duration; ids must not clash with ``taken``."""
    from airspace_sim.scenarios.schema import AircraftSpec

    spec = scenario.recorded
    flights = load_flights(spec, scenario.source)
    offset = flights.start_s + float(spec.start_s)  # flight time at world time 0
    end = offset + float(scenario.duration)
    out = []
    for f in flights:
        if f.end_s < offset or f.start_s > end:
            continue
        if f.id in taken:
            raise UserError(
                f"{scenario.source}: recorded flight {f.id!r} has the id of another aircraft"
            )
        out.append(_spec(AircraftSpec, f, offset, spec.track))
    return out


def _spec(AircraftSpec, f: Flight, offset: float, track: bool):
    i = int(np.argmax(np.isfinite(f.vx)))
    heading = math.degrees(math.atan2(f.vy[i], f.vx[i])) if np.isfinite(f.vx[i]) else 0.0
    speed = float(math.hypot(f.vx[i], f.vy[i])) if np.isfinite(f.vx[i]) else 0.0
    return AircraftSpec(
        id=f.id,
        position=(float(f.x_m[0]), float(f.y_m[0])),
        heading_deg=heading,
        speed=speed,
        autopilot="recorded",
        avoid=bool(track),
        recording=Recording(f, offset),
    )
