"""Recorded flights in a local metric frame: the :class:`Flights` container every reader returns.

A :class:`Flight` is one aircraft's cleaned trajectory, samples in time order, in the
project's conventions: x east and y north in metres in a local azimuthal equidistant frame
(:class:`Frame`), times in seconds since the collection's ``epoch``, velocities in m/s,
headings and turn rates counter-clockwise from east in radians (a right turn is negative).
Readers (:mod:`airspace_sim.recorded.readers`) have already dropped on-ground rows and
forward-filled repeats; gaps in coverage are kept as gaps (no sample is invented), so the
spacing of ``t_s`` is whatever the receiver gave. Users who need a regular grid call
:meth:`Flight.sample` with the times they want: NaN where the flight has no data.

    from airspace_sim.recorded import read
    flights = read("switzerland.json.gz")          # Flights
    f = flights[0]                                 # or flights["3c6444-DLH4AB-0"]
    f.t_s, f.x_m, f.y_m, f.vx, f.vy, f.turn_rate, f.altitude_m   # (n,) arrays
    x, y, vx, vy = f.sample(np.arange(f.t_s[0], f.t_s[-1], 1.0))  # 1 s grid, NaN in gaps
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from airspace_sim.errors import UserError
from airspace_sim.geometry import wrap_angle
from airspace_sim.recorded._extra import require

#: s: a longer silence between two samples of one flight is a gap (no interpolation across
#: it; the replay takes the aircraft out of the world for its duration). OpenSky's state
#: vectors come every 1-10 s; 60 s without one is a coverage hole, not sparse sampling.
MAX_GAP_S = 60.0
KNOT_MS = 1852.0 / 3600.0  #: m/s per knot
FOOT_M = 0.3048  #: m per foot


class Frame:
    """A local azimuthal equidistant projection (pyproj ``+proj=aeqd``) centred on
    ``(lat0_deg, lon0_deg)`` on the WGS84 ellipsoid: x east, y north, metres.

    Distances from the centre are exact and directions from it true; 130 km away
    the frame's distances between two nearby points err by ~0.02 % (an equirectangular
    projection errs by ~2 km there).
    """

    def __init__(self, lat0_deg: float, lon0_deg: float):
        pyproj = require("pyproj")

        self.lat0_deg = float(lat0_deg)
        self.lon0_deg = float(lon0_deg)
        crs = pyproj.CRS.from_proj4(
            f"+proj=aeqd +lat_0={self.lat0_deg} +lon_0={self.lon0_deg} +datum=WGS84 +units=m"
        )
        self._to = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
        self._from = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
        self._geod = pyproj.Geod(ellps="WGS84")

    def __repr__(self) -> str:
        return f"Frame(lat0_deg={self.lat0_deg:.6f}, lon0_deg={self.lon0_deg:.6f})"

    def forward(self, lat_deg, lon_deg):
        """(x_m, y_m) arrays of the points (lat_deg, lon_deg) (any equal shapes)."""
        x, y = self._to.transform(np.asarray(lon_deg, float), np.asarray(lat_deg, float))
        return np.asarray(x, float), np.asarray(y, float)

    def inverse(self, x_m, y_m):
        """(lat_deg, lon_deg) arrays of frame points (x_m, y_m)."""
        lon, lat = self._from.transform(np.asarray(x_m, float), np.asarray(y_m, float))
        return np.asarray(lat, float), np.asarray(lon, float)

    def velocity(self, lat_deg, lon_deg, speed_ms, track_deg):
        """(vx, vy) m/s in the frame of a ground speed ``speed_ms`` along the true track
        ``track_deg`` (degrees clockwise from true north, as ADS-B reports it) at each point.

        The frame's grid north is not true north away from the centre (about 1.9° at
        200 km east of a centre at 46° N), so the track is not rotated by a constant: the
        point one second ahead along the geodesic (``pyproj.Geod.fwd``) is projected and
        differenced. NaN where speed or track is missing.
        """
        lat = np.asarray(lat_deg, float)
        lon = np.asarray(lon_deg, float)
        speed = np.asarray(speed_ms, float)
        track = np.asarray(track_deg, float)
        ok = np.isfinite(speed) & np.isfinite(track)
        vx = np.full(lat.shape, np.nan)
        vy = np.full(lat.shape, np.nan)
        if ok.any():
            lon1, lat1, _ = self._geod.fwd(lon[ok], lat[ok], track[ok], speed[ok])
            x0, y0 = self.forward(lat[ok], lon[ok])
            x1, y1 = self.forward(lat1, lon1)
            vx[ok], vy[ok] = x1 - x0, y1 - y0
        return vx, vy


@dataclass(frozen=True, eq=False)
class Flight:
    """One recorded flight: n ≥ 2 samples with strictly increasing ``t_s``.

    Attributes (all (n,) float arrays, read-only)
    ----------------------------------------------
    t_s : s since :attr:`Flights.epoch_s`.
    x_m, y_m : position in the collection's :class:`Frame`, m (east, north).
    vx, vy : velocity from the recorded ground speed and track, m/s in the frame; NaN
        where the receiver gave none.
    turn_rate : rad/s CCW positive, from the recorded track: the central difference of
        the frame heading ``atan2(vy, vx)`` over the neighbouring samples (one-sided at the
        ends and next to gaps); NaN where no neighbour within :data:`MAX_GAP_S` has a track.
    altitude_m : barometric altitude, m (NaN where missing).
    id : unique in the collection, ``icao24-callsign-k`` (k counts the flights of one
        icao24 and callsign). icao24, callsign : as recorded (callsign may be "").
    max_gap_s : the gap threshold the flight was cut with (s).
    """

    id: str
    icao24: str
    callsign: str
    t_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    turn_rate: np.ndarray
    altitude_m: np.ndarray
    max_gap_s: float = MAX_GAP_S

    def __post_init__(self):
        for name in ("t_s", "x_m", "y_m", "vx", "vy", "turn_rate", "altitude_m"):
            a = np.array(getattr(self, name), dtype=float).reshape(-1)
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        n = self.t_s.size
        if n < 2 or any(
            getattr(self, k).size != n
            for k in ("x_m", "y_m", "vx", "vy", "turn_rate", "altitude_m")
        ):
            raise ValueError(f"flight {self.id}: needs ≥ 2 samples in equal-length arrays")
        if not np.all(np.diff(self.t_s) > 0):
            raise ValueError(f"flight {self.id}: t_s must increase strictly")

    def __len__(self) -> int:
        return self.t_s.size

    @property
    def start_s(self) -> float:
        return float(self.t_s[0])

    @property
    def end_s(self) -> float:
        return float(self.t_s[-1])

    @property
    def heading(self) -> np.ndarray:
        """(n,) rad CCW from east, from the recorded velocity (NaN where it is missing)."""
        return np.arctan2(self.vy, self.vx)

    @property
    def speed(self) -> np.ndarray:
        """(n,) ground speed, m/s."""
        return np.hypot(self.vx, self.vy)

    def gaps(self) -> np.ndarray:
        """(G, 2) s: the (start, end) of every silence longer than ``max_gap_s``."""
        cut = np.flatnonzero(np.diff(self.t_s) > self.max_gap_s)
        return np.stack([self.t_s[cut], self.t_s[cut + 1]], axis=1)

    def covered(self, t_s) -> np.ndarray:
        """Bool array (shape of ``t_s``): the flight has data at these times (within
        ``[start_s, end_s]`` and not inside a gap)."""
        t = np.asarray(t_s, dtype=float)
        i = np.clip(np.searchsorted(self.t_s, t, side="right"), 1, self.t_s.size - 1)
        inside = (t >= self.t_s[0]) & (t <= self.t_s[-1])
        on_sample = (t == self.t_s[i]) | (t == self.t_s[i - 1])  # the edges of a gap
        return inside & ((self.t_s[i] - self.t_s[i - 1] <= self.max_gap_s) | on_sample)

    def sample(self, t_s):
        """The trajectory at times ``t_s`` (any shape), s: ``(x_m, y_m, vx, vy)`` arrays.

        Between two samples the path is the cubic Hermite curve through both positions
        with both recorded velocities as end tangents (a straight-line interpolation would
        cut the corner of every turn; at 10 s sampling and 2°/s the chord lies ~40 m inside
        the arc); where a velocity is missing the segment is linear. NaN outside the flight
        and inside its gaps (:meth:`covered`).
        """
        t = np.asarray(t_s, dtype=float)
        shape = t.shape
        t = t.reshape(-1)
        ok = self.covered(t)
        i = np.clip(np.searchsorted(self.t_s, t, side="right") - 1, 0, self.t_s.size - 2)
        j = i + 1
        x, vx = hermite(
            t, self.t_s[i], self.t_s[j], self.x_m[i], self.x_m[j], self.vx[i], self.vx[j]
        )
        y, vy = hermite(
            t, self.t_s[i], self.t_s[j], self.y_m[i], self.y_m[j], self.vy[i], self.vy[j]
        )
        out = [np.where(ok, a, np.nan).reshape(shape) for a in (x, y, vx, vy)]
        return tuple(out)

    def turn_rate_at(self, t_s) -> np.ndarray:
        """Recorded turn rate (rad/s) at times ``t_s``, linear between samples; NaN where
        the flight has no data (:meth:`covered`)."""
        t = np.asarray(t_s, dtype=float)
        w = np.interp(t, self.t_s, self.turn_rate)
        return np.where(self.covered(t), w, np.nan)


def hermite(t, t0, t1, p0, p1, v0, v1):
    """Cubic Hermite interpolation of one coordinate: ``(position, velocity)`` at times
    ``t`` on segments from ``(t0, p0, v0)`` to ``(t1, p1, v1)`` (s, m, m/s; broadcast
    arrays, ``t1 > t0``), clamped to the segment. A segment with a NaN end velocity is the
    straight line between its positions, at constant velocity."""
    h = t1 - t0
    u = np.clip((t - t0) / h, 0.0, 1.0)
    linear = (p1 - p0) / h
    both = np.isfinite(v0) & np.isfinite(v1)
    m0 = np.where(both, v0, linear) * h
    m1 = np.where(both, v1, linear) * h
    u2, u3 = u * u, u * u * u
    pos = (2 * u3 - 3 * u2 + 1) * p0 + (u3 - 2 * u2 + u) * m0 + (-2 * u3 + 3 * u2) * p1
    pos = pos + (u3 - u2) * m1
    vel = (6 * u2 - 6 * u) * (p0 - p1) + (3 * u2 - 4 * u + 1) * m0 + (3 * u2 - 2 * u) * m1
    return pos, vel / h


class Timeline:
    """k flights sampled together at increasing times, with arrays, not a call per flight.

    flights : k :class:`Flight`; offsets_s : (k,) flight time at timeline time 0 (s). The
    samples are concatenated once; each flight keeps a pointer to the segment holding the
    last time asked, which only moves forward, so a query costs O(k) whatever the length
    of the flights. Times must not decrease from one call to the next.
    """

    def __init__(self, flights, offsets_s):
        flights = list(flights)
        n = np.array([len(f) for f in flights], dtype=np.int64)
        self.first = np.concatenate([[0], np.cumsum(n)[:-1]]).astype(np.int64)
        self.last = self.first + n - 1
        cat = lambda name: np.concatenate([getattr(f, name) for f in flights])  # noqa: E731
        self.t = cat("t_s") - np.repeat(np.asarray(offsets_s, dtype=float), n)
        self._columns = {k: cat(k) for k in _ARRAYS if k != "t_s"}
        self.max_gap = np.array([f.max_gap_s for f in flights], dtype=float)
        self.ptr = None
        self._t_last = -math.inf

    def _seek(self, t: float) -> None:
        if t < self._t_last:
            raise ValueError(f"Timeline: time went back from {self._t_last} to {t}")
        self._t_last = t
        if self.ptr is None:  # first call: one binary search per flight
            self.ptr = np.array(
                [
                    a
                    + min(
                        max(int(np.searchsorted(self.t[a : b + 1], t, "right")) - 1, 0), b - a - 1
                    )
                    for a, b in zip(self.first, self.last)
                ],
                dtype=np.int64,
            )
        while True:
            move = (self.ptr < self.last - 1) & (self.t[np.minimum(self.ptr + 1, self.last)] <= t)
            if not move.any():
                return
            self.ptr += move

    def present(self, t: float) -> np.ndarray:
        """(k,) bool: the flights with data at time ``t`` (as :meth:`Flight.covered`)."""
        self._seek(t)
        i, j = self.ptr, self.ptr + 1
        t0, t1 = self.t[i], self.t[j]
        inside = (t >= self.t[self.first]) & (t <= self.t[self.last])
        return inside & ((t1 - t0 <= self.max_gap) | (t == t0) | (t == t1))

    def at(self, t: float):
        """``(present (k,) bool, positions (k, 2) m, velocities (k, 2) m/s)`` at time
        ``t`` s, as :meth:`Flight.sample` (held at the ends, not NaN, where absent)."""
        present = self.present(t)
        i, j = self.ptr, self.ptr + 1
        c = self._columns
        t0, t1 = self.t[i], self.t[j]
        x, vx = hermite(t, t0, t1, c["x_m"][i], c["x_m"][j], c["vx"][i], c["vx"][j])
        y, vy = hermite(t, t0, t1, c["y_m"][i], c["y_m"][j], c["vy"][i], c["vy"][j])
        return present, np.stack([x, y], axis=1), np.stack([vx, vy], axis=1)

    def linear(self, t: float, name: str) -> np.ndarray:
        """(k,) column ``name`` (``"turn_rate"``, ``"altitude_m"``, ...) interpolated
        linearly at time ``t``; NaN where a flight is absent."""
        present = self.present(t)
        i, j = self.ptr, self.ptr + 1
        v = self._columns[name]
        u = np.clip((t - self.t[i]) / (self.t[j] - self.t[i]), 0.0, 1.0)
        return np.where(present, v[i] + u * (v[j] - v[i]), np.nan)


def derivative(t_s, values, max_gap_s: float = MAX_GAP_S, angle: bool = False) -> np.ndarray:
    """(n,) rate of change of ``values`` (n,) at each sample time ``t_s`` (n,) s.

    Central difference ``(v[i+1] − v[i−1]) / (t[i+1] − t[i−1])`` (differences wrapped to
    [−π, π) when ``angle``) where both neighbours are within ``max_gap_s`` and finite,
    one-sided where only one is, NaN where none is.
    """
    t = np.asarray(t_s, float)
    v = np.asarray(values, float)
    n = t.size
    if n < 2:
        return np.full(n, np.nan)
    dt = np.diff(t)
    dv = wrap_angle(np.diff(v)) if angle else np.diff(v)
    seg = np.where(dt <= max_gap_s, dv / dt, np.nan)  # rate over segment i → i+1, (n-1,)
    prev = np.concatenate([[np.nan], seg])
    nxt = np.concatenate([seg, [np.nan]])
    dt_prev = np.concatenate([[np.nan], dt])
    dt_next = np.concatenate([dt, [np.nan]])
    with np.errstate(invalid="ignore"):
        central = (prev * dt_prev + nxt * dt_next) / (dt_prev + dt_next)
    has_prev, has_next = np.isfinite(prev), np.isfinite(nxt)
    return np.where(
        has_prev & has_next, central, np.where(has_prev, prev, np.where(has_next, nxt, np.nan))
    )


def turn_rates(t_s, vx, vy, max_gap_s: float = MAX_GAP_S) -> np.ndarray:
    """(n,) rad/s: the rate of change of the heading ``atan2(vy, vx)`` at each sample
    (:func:`derivative` of the heading, differences wrapped). t_s, vx, vy (n,) s, m/s."""
    h = np.arctan2(np.asarray(vy, float), np.asarray(vx, float))
    return derivative(t_s, h, max_gap_s, angle=True)


def course_offset_deg(flight) -> float:
    """Median absolute angle (deg) between the recorded track and the course flown between
    samples (positions differenced); ~0 for consistent data. Some OpenSky samples carry a
    track ~100° off the positions for long stretches: read them with
    ``velocity="positions"``."""
    dt = np.diff(flight.t_s)
    ok = dt <= flight.max_gap_s
    course = np.arctan2(np.diff(flight.y_m), np.diff(flight.x_m))
    off = np.abs(wrap_angle(course - flight.heading[:-1]))[ok]
    off = off[np.isfinite(off)]
    return float(np.degrees(np.median(off))) if off.size else math.nan


@dataclass(eq=False)
class Flights:
    """Recorded flights of one file (or several), in one :class:`Frame`.

    flights : list of :class:`Flight`, ordered by start time then id.
    frame : the projection every flight's x_m, y_m use.
    epoch_s : POSIX time (s, UTC) of ``t_s = 0``: the earliest sample kept.
    source : where the data came from (file names), for messages.
    dropped : rows dropped while cleaning, by reason (``{"on_ground": 12, ...}``).
    """

    flights: list[Flight]
    frame: Frame
    epoch_s: float
    source: str = "<memory>"
    dropped: dict = field(default_factory=dict)

    def __post_init__(self):
        self.flights = sorted(self.flights, key=lambda f: (f.start_s, f.id))
        self._by_id = {f.id: i for i, f in enumerate(self.flights)}
        if len(self._by_id) != len(self.flights):
            raise ValueError(f"{self.source}: flight ids are not unique")

    def __len__(self) -> int:
        return len(self.flights)

    def __iter__(self):
        return iter(self.flights)

    def __getitem__(self, key) -> Flight:
        """A flight by position (int) or by :attr:`Flight.id` (str)."""
        if isinstance(key, str):
            try:
                return self.flights[self._by_id[key]]
            except KeyError:
                raise UserError(f"{self.source}: no flight {key!r}") from None
        return self.flights[key]

    @property
    def ids(self) -> list[str]:
        return [f.id for f in self.flights]

    @property
    def start_s(self) -> float:
        return min((f.start_s for f in self.flights), default=math.nan)

    @property
    def end_s(self) -> float:
        return max((f.end_s for f in self.flights), default=math.nan)

    def select(self, keep) -> Flights:
        """The flights for which ``keep(flight)`` is true, in the same frame and epoch."""
        return Flights(
            [f for f in self.flights if keep(f)],
            self.frame,
            self.epoch_s,
            self.source,
            self.dropped,
        )

    def window(self, start_s: float, end_s: float) -> Flights:
        """The flights overlapping ``[start_s, end_s]`` s, each cut to that window (flights
        left with fewer than 2 samples are dropped)."""
        return self.keep_samples(lambda f: (f.t_s >= start_s) & (f.t_s <= end_s))

    def keep_samples(self, keep) -> Flights:
        """Each flight with only the samples where ``keep(flight)`` ((n,) bool) is true
        (removed stretches longer than ``max_gap_s`` become gaps); flights left with fewer
        than 2 samples are dropped; turn rates are recomputed from what is kept."""
        out = []
        for f in self.flights:
            k = np.asarray(keep(f), dtype=bool)
            if k.all():
                out.append(f)
            elif k.sum() >= 2:
                arrays = [getattr(f, name)[k] for name in _ARRAYS]
                arrays[_ARRAYS.index("turn_rate")] = turn_rates(
                    f.t_s[k], f.vx[k], f.vy[k], f.max_gap_s
                )
                out.append(Flight(f.id, f.icao24, f.callsign, *arrays, max_gap_s=f.max_gap_s))
        return Flights(out, self.frame, self.epoch_s, self.source, self.dropped)

    def summary(self) -> dict:
        """Counts for a report: flights, samples, time span (s), median sample spacing (s),
        median over flights of :func:`course_offset_deg`."""
        spacing = [np.median(np.diff(f.t_s)) for f in self.flights]
        offsets = [course_offset_deg(f) for f in self.flights]
        return {
            "flights": len(self.flights),
            "samples": int(sum(len(f) for f in self.flights)),
            "span_s": float(self.end_s - self.start_s) if self.flights else 0.0,
            "median_spacing_s": float(np.median(spacing)) if spacing else math.nan,
            "track_vs_course_deg": float(np.nanmedian(offsets)) if offsets else math.nan,
            "dropped_rows": dict(self.dropped),
        }


_ARRAYS = ("t_s", "x_m", "y_m", "vx", "vy", "turn_rate", "altitude_m")
