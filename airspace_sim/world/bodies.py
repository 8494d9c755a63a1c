"""The pymunk side of a world: three ``pymunk.Space``\\ s of kinematic aircraft bodies with
sensor circles.

Each aircraft is a KINEMATIC body (its velocity is set every step; pymunk integrates
``p ← p + v·dt`` exactly) in each of three spaces, one per set, carrying one sensor circle:

======== ================= ==================================================
set      circle radius     two circles overlap  ⇔
======== ================= ==================================================
LOS      r_safe / 2        centre distance < r_safe      (loss of separation)
NMAC     nmac / 2          centre distance < nmac        (near mid-air collision)
RANGE    range / 2         centre distance < range       (in surveillance range)
======== ================= ==================================================

One space per set, rather than three circles per body in one space, so that the sets never
meet in the broad phase: in one shared index every small LoS / NMAC circle lies inside the
bounding boxes of the ~20 range circles around it, and every such pair would be found and
rejected by shape filter at every step. The three copies of a body get the same velocity
and start at the same position, so pymunk's integration gives them bit-identical positions.

``space.on_collision(t, t, begin=..., separate=...)`` handlers record pair events; the
current pairs of each set are kept as a sorted array of keys ``i·N + j`` (``i < j``).
Python runs only when a pair starts or stops overlapping, so the cost grows with the number
of pairs changing, never with N². Positions and velocities move in and out of pymunk in one
call per space with :mod:`pymunk.batch`; the pairs overlapping when a space is built are read
in one :func:`pymunk.batch.get_space_arbiters` call.

Everything lives on the instance: several worlds in one process never share state.
"""

from __future__ import annotations

import numpy as np
import pymunk
import pymunk.batch

LOS, NMAC, RANGE = 1, 2, 3
SETS = (LOS, NMAC, RANGE)
_ARBITER_BODIES = pymunk.batch.ArbiterFields.BODY_A_ID | pymunk.batch.ArbiterFields.BODY_B_ID


class _EventLog:
    """Collects (set, i, j, +1 | −1) contact events from pymunk callbacks."""

    def __init__(self):
        self.events: list[tuple[int, int, int, int]] = []

    def _record(self, arbiter, sign):
        a, b = arbiter.shapes
        if a.body is None or b.body is None:  # the space is being torn down
            return
        self.events.append((a.collision_type, a.body._aircraft, b.body._aircraft, sign))

    def begin(self, arbiter, space, data):
        self._record(arbiter, 1)

    def separate(self, arbiter, space, data):
        self._record(arbiter, -1)


def _insert_sorted(keys: np.ndarray, new: np.ndarray) -> np.ndarray:
    """``union1d(keys, new)`` for sorted unique (P,) ``keys`` and sorted unique (E,) ``new``
    with E ≪ P: one O(P) copy instead of sorting P + E keys every step."""
    if keys.size and new.size:
        at = np.minimum(np.searchsorted(keys, new), keys.size - 1)
        new = new[keys[at] != new]
    return np.insert(keys, np.searchsorted(keys, new), new) if new.size else keys


def _delete_sorted(keys: np.ndarray, gone: np.ndarray) -> np.ndarray:
    """``keys[~isin(keys, gone)]`` for sorted unique (P,) ``keys`` and any (E,) ``gone``."""
    at = np.searchsorted(keys, gone)
    inside = at < keys.size
    at = at[inside]
    return np.delete(keys, at[keys[at] == gone[inside]])


class Airspace:
    """Three pymunk spaces (one per set) holding N aircraft as kinematic bodies with sensor
    circles.

    Parameters
    ----------
    positions : (N, 2) initial positions, m.
    r_safe, nmac, sensor_range : the three radii of the table above, m.
    in_space : (N,) bool, optional: the aircraft that start in the spaces (default all; the
        others can come in later with :meth:`add`).
    spatial_hash : index the RANGE space with pymunk's spatial hash (cell size
        ``sensor_range``, 4·N cells) instead of the default bounding-box tree. The LoS and
        NMAC spaces always use the tree. Either gives the same pairs and events; the cost
        of the RANGE space is in its arbiters (one per pair in range), not the broad phase.

    Attributes
    ----------
    pairs : dict set → (P,) int64 sorted keys ``i·N + j`` (``i < j``) of overlapping pairs.
    began : dict set → (E, 2) int64 pairs (i < j) that began overlapping in the last step.

    An ``Airspace`` pickles and deep-copies (see :meth:`__getstate__`); the copy steps
    bit-identically to the original, pair events included.
    """

    def __init__(
        self,
        positions,
        r_safe: float,
        nmac: float,
        sensor_range: float,
        spatial_hash: bool | None = None,
        in_space=None,
    ):
        positions = np.asarray(positions, dtype=float).reshape(-1, 2)
        self.n = n = positions.shape[0]
        self.radii = {LOS: r_safe / 2.0, NMAC: nmac / 2.0, RANGE: sensor_range / 2.0}
        self.spatial_hash = bool(spatial_hash)
        self.in_space = np.ones(n, dtype=bool) if in_space is None else np.array(in_space, bool)
        self.pairs = {t: np.zeros(0, dtype=np.int64) for t in SETS}
        self.began = {t: np.zeros((0, 2), dtype=np.int64) for t in SETS}
        primed = self._build(positions, np.zeros((n, 2)))
        self.pairs = primed  # the pairs that overlap at the start all begin now
        nn = max(n, 1)
        self.began = {t: np.stack([k // nn, k % nn], axis=1) for t, k in primed.items()}

    # ---------------------------------------------------------------- helpers
    def _build(self, positions: np.ndarray, velocities: np.ndarray) -> dict:
        """Create the spaces, the bodies (all N in each, those in :attr:`in_space` added),
        the handlers and the batch buffers, with an arbiter for every pair overlapping at
        ``positions`` (N, 2) m; leave the body velocities at ``velocities`` (N, 2) m/s.

        A zero-velocity step (``p + 0·dt = p`` exactly) makes pymunk create an arbiter for
        every overlapping pair, so that the next step fires ``separate`` for a pair that
        stops overlapping and no second ``begin`` for one that still overlaps. The ``begin``
        handler is installed after that step: its ~25k begins at 1000 aircraft would be as
        many Python calls; the arbiters are read in one batch call instead.

        Returns set → (P,) sorted keys of the overlapping pairs.
        """
        n = self.n
        self._log = log = _EventLog()
        self.spaces: dict[int, pymunk.Space] = {}
        self.bodies: dict[int, list[pymunk.Body]] = {}
        self.shapes: dict[int, list[pymunk.Shape]] = {}
        self._order: dict[int, np.ndarray] = {}
        self._ids_sorted: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # body ids, sorted
        self._buf_get = pymunk.batch.Buffer()
        self._buf_set = pymunk.batch.Buffer()
        self._vbuf = np.zeros(0)
        primed = {}
        for t in SETS:
            space = pymunk.Space()
            bodies, shapes = [], []
            for i in range(n):
                body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
                body.position = (float(positions[i, 0]), float(positions[i, 1]))
                body._aircraft = i
                c = pymunk.Circle(body, self.radii[t])
                c.sensor = True
                c.collision_type = t
                if self.in_space[i]:
                    space.add(body, c)
                bodies.append(body)
                shapes.append(c)
            # An arbiter keeps the handler it was created with: ``separate`` must be in
            # place before the priming step, ``begin`` only after it (same handler struct).
            space.on_collision(t, t, separate=log.separate)
            if t == RANGE and self.spatial_hash and n:
                space.use_spatial_hash(float(2.0 * self.radii[RANGE]), 4 * n)
            self.spaces[t], self.bodies[t], self.shapes[t] = space, bodies, shapes
            ids = np.array([b.id for b in bodies], dtype=np.uintp)
            by_id = np.argsort(ids)
            self._ids_sorted[t] = (ids[by_id], by_id)
            self._refresh_order(t)
            if self._order[t].size:
                self._set_velocities(t, np.zeros((n, 2)))
                space.step(1.0)
            primed[t] = self._arbiter_keys(t)
            space.on_collision(t, t, begin=log.begin)
            self._set_velocities(t, velocities)
            for i in np.flatnonzero(~self.in_space):  # bodies outside the space keep theirs
                bodies[i].velocity = (float(velocities[i, 0]), float(velocities[i, 1]))
        return primed

    def _refresh_order(self, t: int) -> None:
        """Aircraft index (B,) of each body of space ``t`` in pymunk's iteration order."""
        self._buf_get.clear()
        pymunk.batch.get_space_bodies(
            self.spaces[t], pymunk.batch.BodyFields.BODY_ID, self._buf_get
        )
        self._order[t] = self._aircraft_of(t, np.frombuffer(self._buf_get.int_buf(), np.uintp))

    def _aircraft_of(self, t: int, body_ids: np.ndarray) -> np.ndarray:
        """Aircraft indices (K,) int64 of pymunk body ids (K,) of space ``t``."""
        ids, by_id = self._ids_sorted[t]
        return by_id[np.searchsorted(ids, body_ids)].astype(np.int64)

    def _arbiter_keys(self, t: int) -> np.ndarray:
        """(P,) sorted keys of the pairs with an arbiter in space ``t`` (right after a step
        of a new space: exactly the overlapping pairs)."""
        self._buf_get.clear()
        pymunk.batch.get_space_arbiters(self.spaces[t], _ARBITER_BODIES, self._buf_get)
        ab = self._aircraft_of(t, np.frombuffer(self._buf_get.int_buf(), np.uintp)).reshape(-1, 2)
        n = max(self.n, 1)
        return np.unique(ab.min(axis=1) * n + ab.max(axis=1))

    def _set_velocities(self, t: int, velocities: np.ndarray) -> None:
        v = np.ascontiguousarray(np.asarray(velocities, dtype=float)[self._order[t]])
        self._vbuf = v  # keep the memory alive while pymunk reads it
        self._buf_set.set_float_buf(v.reshape(-1))
        pymunk.batch.set_space_bodies(
            self.spaces[t], pymunk.batch.BodyFields.VELOCITY, self._buf_set
        )

    def _drain(self, reset_began: bool = True) -> None:
        """Fold the recorded events into the pair sets (and :attr:`began`)."""
        events = self._log.events
        self._log.events = []
        n = max(self.n, 1)
        ev = np.array(events, dtype=np.int64).reshape(-1, 4)
        keys = np.minimum(ev[:, 1], ev[:, 2]) * n + np.maximum(ev[:, 1], ev[:, 2])
        for t in SETS:
            mine = ev[:, 0] == t
            b = np.unique(keys[mine & (ev[:, 3] > 0)])
            e = keys[mine & (ev[:, 3] < 0)]
            k = self.pairs[t]
            if e.size:
                k = _delete_sorted(k, e)
            if b.size:
                k = _insert_sorted(k, b)
            self.pairs[t] = k
            new = np.stack([b // n, b % n], axis=1)
            self.began[t] = new if reset_began else np.concatenate([self.began[t], new])

    # ----------------------------------------------------------------- public
    def set_velocities(self, velocities: np.ndarray) -> None:
        """Set every body's velocity (N, 2) m/s (rows of removed aircraft are ignored)."""
        for t in SETS:
            self._set_velocities(t, velocities)

    def step(self, dt: float, out_positions: np.ndarray) -> None:
        """Advance ``dt`` seconds; write the new positions of bodies in the space into
        ``out_positions`` (N, 2) and update :attr:`pairs` / :attr:`began`."""
        for t in SETS:
            if self._order[t].size:
                self.spaces[t].step(dt)
        if self._order[RANGE].size:  # the three copies of a body are at the same place
            self._buf_get.clear()
            pymunk.batch.get_space_bodies(
                self.spaces[RANGE], pymunk.batch.BodyFields.POSITION, self._buf_get
            )
            out_positions[self._order[RANGE]] = np.frombuffer(self._buf_get.float_buf()).reshape(
                -1, 2
            )
        self._drain()

    def remove(self, indices) -> None:
        """Take aircraft out of the spaces (they stop touching anything at once)."""
        idx = [int(i) for i in np.atleast_1d(indices) if self.in_space[int(i)]]
        if not idx:
            return
        for t in SETS:
            for i in idx:
                self.spaces[t].remove(self.bodies[t][i], self.shapes[t][i])
        self.in_space[idx] = False
        for t in SETS:
            self._refresh_order(t)
        self._drain(reset_began=False)

    def add(self, indices, positions) -> None:
        """Put aircraft (k,) that are outside back into the spaces at ``positions`` (k, 2) m;
        their pairs begin with the next :meth:`step`."""
        idx = np.atleast_1d(np.asarray(indices, dtype=np.int64))
        pos = np.asarray(positions, dtype=float).reshape(-1, 2)
        new = [(int(i), p) for i, p in zip(idx, pos) if not self.in_space[int(i)]]
        if not new:
            return
        for t in SETS:
            for i, p in new:
                body = self.bodies[t][i]
                body.position = (float(p[0]), float(p[1]))
                body.velocity = (0.0, 0.0)
                self.spaces[t].add(body, self.shapes[t][i])
        self.in_space[[i for i, _ in new]] = True
        for t in SETS:
            self._refresh_order(t)

    def pair_arrays(self, kind: int) -> tuple[np.ndarray, np.ndarray]:
        """Current overlapping pairs of a set as (i, j) int64 arrays, i < j, sorted."""
        k = self.pairs[kind]
        n = max(self.n, 1)
        return k // n, k % n

    # --------------------------------------------------------------- pickling
    def __getstate__(self) -> dict:
        """The airspace as plain data: radii, positions (N, 2) m and velocities (N, 2) m/s of
        all bodies, membership, pair sets and pending events.

        The pymunk objects are not pickled: the batch buffers are cffi memory, and pymunk's
        own ``Space`` pickling restores cached arbiters that no longer fire ``separate`` (a
        copy misses the end of every pair that overlapped when it was saved) and costs
        O(arbiters × shapes). :meth:`__setstate__` rebuilds the spaces instead.
        """
        bodies = self.bodies[RANGE]
        return {
            "n": self.n,
            "radii": dict(self.radii),
            "spatial_hash": self.spatial_hash,
            "in_space": self.in_space.copy(),
            "positions": np.array([tuple(b.position) for b in bodies], float).reshape(-1, 2),
            "velocities": np.array([tuple(b.velocity) for b in bodies], float).reshape(-1, 2),
            "pairs": {t: k.copy() for t, k in self.pairs.items()},
            "began": {t: b.copy() for t, b in self.began.items()},
            "events": list(self._log.events),
        }

    def __setstate__(self, state: dict) -> None:
        """Rebuild the spaces from :meth:`__getstate__`'s data, with an arbiter for every
        pair that overlaps (see :meth:`_build`), and check that those pairs are the stored
        ones.

        The stored pair sets stay authoritative; the contacts the rebuilt spaces find at
        the same positions must equal them, or the copy would fire other events than the
        original from the next step on.
        """
        self.n = int(state["n"])
        self.radii = dict(state["radii"])
        self.spatial_hash = bool(state["spatial_hash"])
        self.in_space = np.array(state["in_space"], dtype=bool)
        found = self._build(
            np.asarray(state["positions"], float), np.asarray(state["velocities"], float)
        )
        self._log.events = list(state["events"])
        self.pairs = {t: np.array(k, dtype=np.int64) for t, k in state["pairs"].items()}
        self.began = {t: np.array(b, dtype=np.int64) for t, b in state["began"].items()}
        for t in SETS:
            if not np.array_equal(found[t], self.pairs[t]):
                extra = np.setdiff1d(found[t], self.pairs[t])
                missing = np.setdiff1d(self.pairs[t], found[t])
                raise RuntimeError(
                    f"Airspace: rebuilt contacts of set {t} differ from the stored pairs "
                    f"(extra keys {extra[:5].tolist()}, missing {missing[:5].tolist()})"
                )
