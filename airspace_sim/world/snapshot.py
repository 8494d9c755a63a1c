"""A world's state at one instant, as a typed, read-only value: :class:`Snapshot`.

    from airspace_sim.world.snapshot import snapshot
    s = snapshot(world)          # or world.snapshot(); a Snapshot
    s.positions[s.active]        # (n_active, 2) m
    s.tracks.x[s.tracks.owner == 0]

The renderer (:mod:`airspace_sim.rendering`), the ``run`` command's frames and any other
observer read a :class:`Snapshot` only, never the world's internals. A snapshot is built
once per frame; its arrays are copies of the world's, marked read-only, so it stays valid
(and unchanged) while the world goes on stepping. Units SI: metres, seconds, radians CCW
from east.

What the track arrays come from is read in :func:`live_tracks` only (one place to change
when the track table changes its layout).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from airspace_sim.geometry import coordinated_turn_positions

#: Predicted points per track in :func:`snapshot` (at lookahead·k/S s, k = 1..S).
PREDICTION_POINTS = 6


def _frozen(a, dtype, shape, what: str) -> np.ndarray:
    """``a`` as a read-only array view of ``dtype``; ``shape`` entries None match any size."""
    a = np.asarray(a, dtype=dtype)
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"Snapshot.{what}: expected shape {want}, got {a.shape}")
    v = a.view()
    v.flags.writeable = False
    return v


@dataclass(frozen=True, eq=False)
class Tracks:
    """The live tracks of every ownship, one row per (ownship, intruder) pair (P rows, M
    tracker modes). Estimates are in the WORLD frame.

    =============  ============  ======================================================
    field          shape         meaning
    =============  ============  ======================================================
    ``owner``      (P,) int      aircraft index of the ownship that keeps the track
    ``intruder``   (P,) int      aircraft index of the tracked aircraft
    ``x``          (P, 5)        ``[x, vx, y, vy, Ω]`` estimate: m, m/s, m, m/s, rad/s
    ``P``          (P, 5, 5)     its covariance, in the units of ``x`` squared
    ``mu``         (P, M)        mode probabilities (NaN for the ``truth`` tracker)
    ``misses``     (P,) int      consecutive missed scans
    ``age``        (P,) int      world steps since the track started
    =============  ============  ======================================================
    """

    owner: np.ndarray
    intruder: np.ndarray
    x: np.ndarray
    P: np.ndarray
    mu: np.ndarray
    misses: np.ndarray
    age: np.ndarray

    def __post_init__(self):
        n = len(np.asarray(self.owner))
        for name, dtype, shape in (
            ("owner", np.int64, (n,)),
            ("intruder", np.int64, (n,)),
            ("x", float, (n, 5)),
            ("P", float, (n, 5, 5)),
            ("mu", float, (n, None)),
            ("misses", np.int64, (n,)),
            ("age", np.int64, (n,)),
        ):
            object.__setattr__(
                self, name, _frozen(getattr(self, name), dtype, shape, f"tracks.{name}")
            )

    @classmethod
    def _of_view(cls, *arrays) -> Tracks:
        """Tracks of a :class:`~.trackers.TrackView`'s arrays, in field order, read-only and
        of the field dtypes (the caller checks), the view's shapes: not checked again (the
        env reads them every step)."""
        t = object.__new__(cls)
        for name, a in zip(_TRACK_FIELDS, arrays):
            object.__setattr__(t, name, a)
        return t

    def __len__(self) -> int:
        return int(self.owner.size)

    def copy(self) -> Tracks:
        """The same tracks in arrays of their own."""
        return Tracks(**{f.name: np.array(getattr(self, f.name)) for f in fields(self)})


@dataclass(frozen=True, eq=False)
class Snapshot:
    """The world at one instant (N aircraft, P tracks, M tracker modes, S predicted points,
    L pairs in loss of separation, Q pairs in NMAC). Arrays are read-only.

    =====================  ============  ================================================
    field                  shape         meaning
    =====================  ============  ================================================
    ``time``               float         simulated time, s
    ``step``               int           steps taken
    ``dt``                 float         world step, s
    ``ids``                (N,) str      aircraft ids (a tuple)
    ``positions``          (N, 2)        true positions, m
    ``velocities``         (N, 2)        true velocities, m/s (0 for inactive aircraft)
    ``headings``           (N,)          true headings, rad CCW from east
    ``speeds``             (N,)          ground speeds, m/s
    ``turn_rates``         (N,)          turn rate flown in the last step, rad/s
    ``max_turn_rate``      (N,)          turn-rate limits, rad/s
    ``active``             (N,) bool     still flying
    ``controlled``         (N,) bool     RL agents
    ``avoid``              (N,) bool     runs the resolver
    ``true_modes``         (N,) int      true Markov mode over the last step, −1 if none
    ``in_los``             (N,) bool     within r_safe of another aircraft
    ``nmac``               (N,) bool     within the NMAC distance of another aircraft
    ``conflict``           (N,) bool     resolver predicts a conflict at current heading
    ``advice``             (N,)          resolver heading change for the next step, rad
    ``r_safe``             float         protected-zone radius, m
    ``nmac_distance``      float         NMAC distance, m
    ``sensor_range``       float         surveillance range, m
    ``lookahead``          float         resolver look-ahead, s
    ``mode_names``         (M,) str      tracker mode names, e.g. straight, left, right
    ``tracks``             Tracks        the live tracks (see :class:`Tracks`), P rows
    ``predicted``          (P, S, 2)     track positions extrapolated as coordinated turns
                                         at the estimated Ω, at lookahead·k/S s,
                                         k = 1..S, m
    ``los_pairs``          (L, 2) int    aircraft index pairs (i < j) in loss of separation
    ``nmac_pairs``         (Q, 2) int    aircraft index pairs (i < j) in NMAC
    =====================  ============  ================================================
    """

    time: float
    step: int
    dt: float
    ids: tuple[str, ...]
    positions: np.ndarray
    velocities: np.ndarray
    headings: np.ndarray
    speeds: np.ndarray
    turn_rates: np.ndarray
    max_turn_rate: np.ndarray
    active: np.ndarray
    controlled: np.ndarray
    avoid: np.ndarray
    true_modes: np.ndarray
    in_los: np.ndarray
    nmac: np.ndarray
    conflict: np.ndarray
    advice: np.ndarray
    r_safe: float
    nmac_distance: float
    sensor_range: float
    lookahead: float
    mode_names: tuple[str, ...]
    tracks: Tracks
    predicted: np.ndarray
    los_pairs: np.ndarray
    nmac_pairs: np.ndarray

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "ids", tuple(str(i) for i in self.ids))
        set_(self, "mode_names", tuple(str(m) for m in self.mode_names))
        for name in ("time", "dt", "r_safe", "nmac_distance", "sensor_range", "lookahead"):
            set_(self, name, float(getattr(self, name)))
        set_(self, "step", int(self.step))
        if not isinstance(self.tracks, Tracks):
            raise ValueError(f"Snapshot.tracks: expected Tracks, got {type(self.tracks).__name__}")
        n, p = len(self.ids), len(self.tracks)
        for name, dtype, shape in (
            ("positions", float, (n, 2)),
            ("velocities", float, (n, 2)),
            ("headings", float, (n,)),
            ("speeds", float, (n,)),
            ("turn_rates", float, (n,)),
            ("max_turn_rate", float, (n,)),
            ("active", bool, (n,)),
            ("controlled", bool, (n,)),
            ("avoid", bool, (n,)),
            ("true_modes", np.int64, (n,)),
            ("in_los", bool, (n,)),
            ("nmac", bool, (n,)),
            ("conflict", bool, (n,)),
            ("advice", float, (n,)),
            ("predicted", float, (p, None, 2)),
            ("los_pairs", np.int64, (None, 2)),
            ("nmac_pairs", np.int64, (None, 2)),
        ):
            set_(self, name, _frozen(getattr(self, name), dtype, shape, name))

    @property
    def n(self) -> int:
        """Number of aircraft N (active or not)."""
        return len(self.ids)


def live_tracks(world) -> Tracks:
    """The world's live tracks as :class:`Tracks` (read-only views, not copies).

    The only place that reads the world's track table; the env's observations read it
    here too.
    """
    table = world.tracks
    v = table.view()
    arrays = (v.owner, v.intruder, v.x, v.P, v.mu, v.misses, v.age)
    # the table's kept views are the same array objects while its track count holds
    # (trackers.TrackView): the Tracks of the last call, if made of exactly these arrays
    last = table.__dict__.get("_tracks_of_view")
    if last is not None and all(a is b for a, b in zip(arrays, last[0])):
        return last[1]
    if [a.dtype for a in arrays] == _TRACK_DTYPES and not any(a.flags.writeable for a in arrays):
        tracks = Tracks._of_view(*arrays)
        table._tracks_of_view = (arrays, tracks)
        return tracks
    return Tracks(*arrays)


#: dtypes of the :class:`Tracks` fields, in field order
_TRACK_DTYPES = [np.dtype(d) for d in (np.int64, np.int64, float, float, float, np.int64, np.int64)]


_TRACK_FIELDS = tuple(f.name for f in fields(Tracks))


def _pairs(i, j) -> np.ndarray:
    return np.stack([np.asarray(i, np.int64), np.asarray(j, np.int64)], axis=1).reshape(-1, 2)


def snapshot(world, prediction_points: int = PREDICTION_POINTS) -> Snapshot:
    """A :class:`Snapshot` of ``world`` now, with ``prediction_points`` (S) predicted
    positions per track over the resolver look-ahead."""
    from airspace_sim.world.bodies import LOS, NMAC

    tracks = live_tracks(world).copy()
    look = float(world.lookahead)
    S = int(prediction_points)
    times = look * np.arange(1, S + 1) / S
    return Snapshot(
        time=world.time,
        step=world.step_count,
        dt=world.dt,
        ids=tuple(world.ids),
        positions=world.positions.copy(),
        velocities=world.velocities.copy(),
        headings=world.headings.copy(),
        speeds=world.speeds.copy(),
        turn_rates=world.turn_rates.copy(),
        max_turn_rate=world.max_turn_rate.copy(),
        active=world.active.copy(),
        controlled=world.controlled.copy(),
        avoid=world.avoid.copy(),
        true_modes=world.modes.copy(),
        in_los=world.in_los.copy(),
        nmac=world.nmac.copy(),
        conflict=world.conflict.copy(),
        advice=world.advice.copy(),
        r_safe=world.r_safe,
        nmac_distance=world.nmac_distance,
        sensor_range=world.sensor_range,
        lookahead=look,
        mode_names=tuple(world.tracks.mode_names),
        tracks=tracks,
        predicted=coordinated_turn_positions(tracks.x, times),
        los_pairs=_pairs(*world.airspace.pair_arrays(LOS)),
        nmac_pairs=_pairs(*world.airspace.pair_arrays(NMAC)),
    )
