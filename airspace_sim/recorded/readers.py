"""Readers for recorded trajectories: OpenSky state vectors and the ``traffic`` library's files.

:func:`read` takes CSV (``.csv``, ``.csv.gz``), Parquet (``.parquet``) or pandas JSON records
(``.json``, ``.json.gz``, a list of row objects, as ``traffic`` writes them) in either of
two column schemas, recognised by their column names:

=============  ==========================================  =================================
quantity       ``traffic`` (and its OpenSky samples)         OpenSky state vectors (Impala)
=============  ==========================================  =================================
time           ``timestamp`` (datetime, ISO text or ms)      ``time`` (POSIX s)
aircraft       ``icao24``, ``callsign``, ``flight_id``?      ``icao24``, ``callsign``
position       ``latitude``, ``longitude`` (deg)             ``lat``, ``lon`` (deg)
altitude       ``altitude`` (ft, barometric)                 ``baroaltitude`` (m)
ground speed   ``groundspeed`` (kt)                          ``velocity`` (m/s)
track          ``track`` (deg clockwise from true north)     ``heading`` (deg, the same)
on ground      ``onground``? (bool)                          ``onground`` (bool)
position time  ``last_position``? (ms or s)                  ``lastposupdate`` (s)
=============  ==========================================  =================================

Cleaning, in this order: rows without a position or time are dropped (OpenSky reports
aircraft it has no position for); on-ground rows are dropped; forward-filled repeats are
dropped (a row whose position time, or without that column whose latitude and longitude,
equal the previous row's of the same aircraft: OpenSky repeats the last position every 10 s
until a new one comes); repeated timestamps keep their first row. Each aircraft's rows are
cut into flights at silences longer than ``split_gap_s`` (``flight_id`` if the file has
one); shorter gaps stay in the flight as gaps (:attr:`Flight.max_gap_s`). Last, glitches are
dropped: single positions over ``glitch_m`` (500 m) across the track from the path of their
neighbours (:mod:`airspace_sim.recorded.glitches`).

A value that is not a number, a time or a boolean, or a position off the globe, is a
:class:`~airspace_sim.errors.UserError` naming the file, the data row (1-based; for CSV
also the line) and the column.
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np

from airspace_sim.errors import UserError
from airspace_sim.recorded._extra import require
from airspace_sim.recorded.flights import FOOT_M as FOOT
from airspace_sim.recorded.flights import KNOT_MS as KNOT
from airspace_sim.recorded.flights import (
    MAX_GAP_S,
    Flight,
    Flights,
    Frame,
    derivative,
    turn_rates,
)
from airspace_sim.recorded.glitches import SPIKE_M, despike

#: s: a longer silence starts a new flight of the same aircraft (``traffic``'s own default
#: for ``Traffic.assign_id``/``Flight.split``)
SPLIT_GAP_S = 600.0

#: where flight velocities come from (:func:`read`'s ``velocity``)
VELOCITY_SOURCES = ("reported", "positions")

#: column names → (quantity, unit factor to SI) per schema
SCHEMAS = {
    "traffic": {
        "time": "timestamp",
        "lat": "latitude",
        "lon": "longitude",
        "alt": ("altitude", FOOT),
        "speed": ("groundspeed", KNOT),
        "track": "track",
        "onground": "onground",
        "last_position": "last_position",
    },
    "opensky": {
        "time": "time",
        "lat": "lat",
        "lon": "lon",
        "alt": ("baroaltitude", 1.0),
        "speed": ("velocity", 1.0),
        "track": "heading",
        "onground": "onground",
        "last_position": "lastposupdate",
    },
}


def _suffix(path: Path) -> str:
    name = path.name.lower()
    for s in (".csv.gz", ".json.gz", ".parquet", ".csv", ".json", ".jsonl"):
        if name.endswith(s):
            return s
    raise UserError(
        f"{path}: unknown file type (expected .csv, .csv.gz, .parquet, .json or .json.gz)"
    )


def _load_table(path: Path):
    """The file as a pandas DataFrame with a 0..n-1 index (row numbers for messages)."""
    pd = require("pandas")

    if not path.is_file():
        raise UserError(f"{path}: no such file")
    kind = _suffix(path)
    try:
        if kind in (".csv", ".csv.gz"):
            df = pd.read_csv(path, dtype={"icao24": str, "callsign": str}, low_memory=False)
        elif kind == ".parquet":
            df = pd.read_parquet(path)
        else:
            df = pd.read_json(
                path,
                orient="records",
                lines=kind == ".jsonl",
                dtype={"icao24": str, "callsign": str},
            )
    except UserError:
        raise
    except Exception as exc:  # noqa: BLE001 - any parser's complaint, as one line
        text = " ".join(str(exc).split())[:200]
        raise UserError(f"{path}: cannot read as {kind} ({type(exc).__name__}: {text})") from None
    return df.reset_index(drop=True)


def _where(path: Path, row: int) -> str:
    line = f" (line {row + 2})" if _suffix(path) in (".csv", ".csv.gz") else ""
    return f"{path}: row {row + 1}{line}"


def _numbers(df, col: str, path: Path, lo=None, hi=None) -> np.ndarray:
    """Column ``col`` as float (NaN where empty); a non-number or a value outside
    ``[lo, hi]`` is a UserError at its first row."""
    pd = require("pandas")

    raw = df[col]
    vals = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=float)
    bad = np.isnan(vals) & raw.notna().to_numpy()
    if bad.any():
        r = int(np.flatnonzero(bad)[0])
        raise UserError(f"{_where(path, r)}, column {col!r}: not a number: {raw.iloc[r]!r}")
    out = np.zeros(vals.shape, bool)
    if lo is not None:
        out |= vals < lo
    if hi is not None:
        out |= vals > hi
    out |= np.isinf(vals)
    if out.any():
        r = int(np.flatnonzero(out)[0])
        rng = f"in [{lo:g}, {hi:g}]" if lo is not None and hi is not None else f"≥ {lo:g}"
        raise UserError(f"{_where(path, r)}, column {col!r}: {float(vals[r])!r} is not {rng}")
    return vals


def _times(df, col: str, path: Path) -> np.ndarray:
    """POSIX seconds (float) of a time column: datetimes, ISO text, or numbers in s or ms
    (numbers above 1e11 are milliseconds: 1e11 s is the year 5138)."""
    pd = require("pandas")

    raw = df[col]
    if pd.api.types.is_datetime64_any_dtype(raw):
        ts = raw if raw.dt.tz is not None else raw.dt.tz_localize("UTC")
        out = (ts.dt.tz_convert("UTC") - pd.Timestamp(0, tz="UTC")).dt.total_seconds()
        return out.to_numpy(dtype=float)
    num = pd.to_numeric(raw, errors="coerce")
    if num.notna().sum() == raw.notna().sum():
        v = num.to_numpy(dtype=float)
        return np.where(np.abs(v) > 1e11, v / 1000.0, v)
    parsed = pd.to_datetime(raw, errors="coerce", utc=True, format="mixed")
    bad = parsed.isna().to_numpy() & raw.notna().to_numpy()
    if bad.any():
        r = int(np.flatnonzero(bad)[0])
        raise UserError(f"{_where(path, r)}, column {col!r}: not a time: {raw.iloc[r]!r}")
    return (parsed - pd.Timestamp(0, tz="UTC")).dt.total_seconds().to_numpy(dtype=float)


def _booleans(df, col: str, path: Path) -> np.ndarray:
    raw = df[col]
    if raw.dtype == bool:
        return raw.to_numpy()
    words = {"true": True, "false": False, "1": True, "0": False, "1.0": True, "0.0": False}
    out = np.zeros(len(raw), bool)
    for r, v in enumerate(raw.tolist()):
        if v is None or (isinstance(v, float) and math.isnan(v)):
            continue
        if isinstance(v, (bool, np.bool_)):
            out[r] = bool(v)
            continue
        key = str(v).strip().lower()
        if key not in words:
            raise UserError(f"{_where(path, r)}, column {col!r}: not a boolean: {v!r}")
        out[r] = words[key]
    return out


def _schema(df, path: Path) -> dict:
    cols = set(df.columns)
    for name, schema in SCHEMAS.items():
        if {schema["time"], schema["lat"], schema["lon"]} <= cols:
            need = [schema["speed"][0], schema["track"], "icao24"]
            missing = [c for c in need if c not in cols]
            if missing:
                raise UserError(
                    f"{path}: {name} columns found but no column {missing[0]!r} "
                    f"(columns: {', '.join(map(str, df.columns))})"
                )
            return schema
    raise UserError(
        f"{path}: no column 'timestamp'/'latitude'/'longitude' (traffic) or "
        f"'time'/'lat'/'lon' (OpenSky state vectors); columns: {', '.join(map(str, df.columns))}"
    )


def _table(path: Path) -> dict:
    """One file as cleaned columns (numpy arrays, SI units) plus drop counts."""
    df = _load_table(path)
    s = _schema(df, path)
    n = len(df)
    t = _times(df, s["time"], path)
    lat = _numbers(df, s["lat"], path, -90.0, 90.0)
    lon = _numbers(df, s["lon"], path, -180.0, 180.0)
    speed_col, speed_unit = s["speed"]
    speed = _numbers(df, speed_col, path, 0.0) * speed_unit
    track = _numbers(df, s["track"], path, -360.0, 720.0)
    alt_col, alt_unit = s["alt"]
    alt = _numbers(df, alt_col, path) * alt_unit if alt_col in df else np.full(n, np.nan)
    icao = df["icao24"].astype(str).str.strip().str.lower().to_numpy()
    if "callsign" in df:
        callsign = df["callsign"].fillna("").astype(str).str.strip().to_numpy()
    else:
        callsign = np.full(n, "", dtype=object)
    ground = _booleans(df, s["onground"], path) if s["onground"] in df else np.zeros(n, bool)
    last = _times(df, s["last_position"], path) if s["last_position"] in df else None
    fid = df["flight_id"].astype(str).to_numpy() if "flight_id" in df else None

    dropped = Counter()
    keep = np.isfinite(t) & np.isfinite(lat) & np.isfinite(lon)
    dropped["no_position"] += int((~keep).sum())
    dropped["on_ground"] += int((keep & ground).sum())
    keep &= ~ground
    cols = {
        "t": t, "lat": lat, "lon": lon, "speed": speed, "track": track, "alt": alt,
        "icao24": icao, "callsign": callsign,
    }  # fmt: skip
    cols["key"] = fid if fid is not None else icao
    if last is not None:
        cols["last"] = last
    cols = {k: v[keep] for k, v in cols.items()}
    order = np.lexsort((cols["t"], cols["key"]))
    cols = {k: v[order] for k, v in cols.items()}
    same = np.concatenate([[False], cols["key"][1:] == cols["key"][:-1]])
    if "last" in cols:
        stale = same & np.concatenate([[False], cols["last"][1:] == cols["last"][:-1]])
    else:
        stale = same & np.concatenate(
            [[False], (cols["lat"][1:] == cols["lat"][:-1]) & (cols["lon"][1:] == cols["lon"][:-1])]
        )
    dup = same & np.concatenate([[False], cols["t"][1:] == cols["t"][:-1]]) & ~stale
    dropped["repeated_position"] += int(stale.sum())
    dropped["repeated_time"] += int(dup.sum())
    keep = ~(stale | dup)
    cols = {k: v[keep] for k, v in cols.items()}
    cols["by_id"] = fid is not None
    return cols, dropped


def read(
    paths,
    *,
    centre: tuple[float, float] | None = None,
    split_gap_s: float = SPLIT_GAP_S,
    max_gap_s: float = MAX_GAP_S,
    min_samples: int = 2,
    velocity: str = "reported",
    glitch_m: float | None = SPIKE_M,
) -> Flights:
    """Read one file or a list of files of recorded trajectories into :class:`Flights`.

    paths : a path or a list of paths (CSV, Parquet or JSON records; the module docstring).
    centre : (lat_deg, lon_deg) of the local frame; default the centre of the data's
        latitude and longitude ranges.
    split_gap_s : s, a longer silence of one aircraft starts a new flight (ignored when the
        file has ``flight_id``).
    max_gap_s : s, shorter silences inside a flight are interpolated over by
        :meth:`Flight.sample`, longer ones are gaps.
    min_samples : flights with fewer samples are dropped (counted in ``dropped``).
    velocity : ``"reported"`` (from the ground speed and track columns) or ``"positions"``
        (central differences of the projected positions, :func:`derivative`), for data
        whose track disagrees with its positions (``Flights.summary()["track_vs_course_deg"]``).
    glitch_m : m, a position this far across the track from the path of its neighbours is a
        glitch and is dropped (:func:`airspace_sim.recorded.glitches.despike`; counted in
        ``dropped["glitch"]``); None keeps every position.
    """
    if velocity not in VELOCITY_SOURCES:
        raise UserError(f"recorded: velocity must be one of {VELOCITY_SOURCES}, got {velocity!r}")
    if glitch_m is not None and not (math.isfinite(glitch_m) and glitch_m > 0):
        raise UserError(f"recorded: glitch_m must be a distance > 0 m or None, got {glitch_m!r}")
    if isinstance(paths, (str, Path)):
        paths = [paths]
    paths = [Path(p) for p in paths]
    if not paths:
        raise UserError("recorded: no file given")
    tables, dropped = [], Counter()
    for p in paths:
        cols, d = _table(p)
        tables.append(cols)
        dropped.update(d)
    lat = np.concatenate([c["lat"] for c in tables])
    lon = np.concatenate([c["lon"] for c in tables])
    source = ", ".join(map(str, paths))
    if lat.size == 0:
        raise UserError(f"{source}: no airborne position in the file")
    if centre is None:
        centre = (0.5 * (lat.min() + lat.max()), 0.5 * (lon.min() + lon.max()))
    frame = Frame(*centre)
    epoch = math.floor(min(float(c["t"].min()) for c in tables if c["t"].size))
    flights, counts = [], Counter()
    for c in tables:
        if not c["t"].size:
            continue
        x, y = frame.forward(c["lat"], c["lon"])
        vx, vy = frame.velocity(c["lat"], c["lon"], c["speed"], c["track"])
        t = c["t"] - epoch
        key = c["key"]
        cut = np.flatnonzero(key[1:] != key[:-1]) + 1
        if not c["by_id"]:
            cut = np.union1d(cut, np.flatnonzero(np.diff(t) > split_gap_s) + 1)
        bounds = np.concatenate([[0], cut, [t.size]]).astype(int)
        for a, b in zip(bounds[:-1], bounds[1:]):
            if b - a < max(min_samples, 2):
                dropped["short_flight"] += int(b - a)
                continue
            sign = [s for s in c["callsign"][a:b] if s and s.lower() != "nan"]
            callsign = Counter(sign).most_common(1)[0][0] if sign else ""
            icao = str(c["icao24"][a])
            base = str(key[a]) if c["by_id"] else f"{icao}-{callsign or 'none'}"
            k = counts[base]
            counts[base] += 1
            fid = base if c["by_id"] and k == 0 else f"{base}-{k}"
            sl = np.arange(a, b)
            if glitch_m is not None:
                sl = sl[despike(t[a:b], x[a:b], y[a:b], glitch_m)]
                if sl.size < b - a:
                    dropped["glitch"] += int(b - a - sl.size)
            fvx, fvy = vx[sl], vy[sl]
            if velocity == "positions":
                fvx = derivative(t[sl], x[sl], max_gap_s)
                fvy = derivative(t[sl], y[sl], max_gap_s)
            rate = turn_rates(t[sl], fvx, fvy, max_gap_s)
            flights.append(
                Flight(
                    fid,
                    icao,
                    callsign,
                    t[sl],
                    x[sl],
                    y[sl],
                    fvx,
                    fvy,
                    rate,
                    c["alt"][sl],
                    max_gap_s,
                )
            )
    if not flights:
        raise UserError(f"{source}: no flight with at least {max(min_samples, 2)} samples")
    return Flights(flights, frame, float(epoch), source, dict(dropped))
