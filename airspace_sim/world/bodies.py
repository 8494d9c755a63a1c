"""The pymunk side of a world: one ``pymunk.Space``, kinematic aircraft bodies, sensor shapes.

Each aircraft is a KINEMATIC body (its velocity is set every step; pymunk integrates
``p ← p + v·dt`` exactly) carrying three sensor circles, each in its own collision type and
shape-filter category so that a set only ever touches the same set:

======== ================= ==================================================
set      circle radius     two circles overlap  ⇔
======== ================= ==================================================
LOS      r_safe / 2        centre distance < r_safe      (loss of separation)
NMAC     nmac / 2          centre distance < nmac        (near mid-air collision)
RANGE    range / 2         centre distance < range       (in surveillance range)
======== ================= ==================================================

``space.on_collision(t, t, begin=..., separate=...)`` handlers record pair events; the
current pairs of each set are kept as a sorted array of keys ``i·N + j`` (``i < j``).
Python runs only when a pair starts or stops overlapping, so the cost grows with the number
of neighbours in range, never with N². Positions and velocities move in and out of pymunk in
one call each with :mod:`pymunk.batch`.

Everything lives on the instance: several worlds in one process never share state.
"""

from __future__ import annotations

import numpy as np
import pymunk
import pymunk.batch

LOS, NMAC, RANGE = 1, 2, 3
SETS = (LOS, NMAC, RANGE)


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


class Airspace:
    """A pymunk space holding N aircraft as kinematic bodies with sensor circles.

    Parameters
    ----------
    positions : (N, 2) initial positions, m.
    r_safe, nmac, sensor_range : the three radii of the table above, m.
    spatial_hash : use pymunk's spatial hash with cell size ``sensor_range`` (faster than the
        default bounding-box tree for hundreds of aircraft with large range circles).

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
    ):
        positions = np.asarray(positions, dtype=float).reshape(-1, 2)
        self.n = n = positions.shape[0]
        self.radii = {LOS: r_safe / 2.0, NMAC: nmac / 2.0, RANGE: sensor_range / 2.0}
        self.spatial_hash = bool(n >= 200 if spatial_hash is None else spatial_hash)
        self.in_space = np.ones(n, dtype=bool)
        self.pairs = {t: np.zeros(0, dtype=np.int64) for t in SETS}
        self.began = {t: np.zeros((0, 2), dtype=np.int64) for t in SETS}
        self._build(positions, np.zeros((n, 2)))
        self._drain()  # the pairs that overlap at the start

    # ---------------------------------------------------------------- helpers
    def _build(self, positions: np.ndarray, velocities: np.ndarray) -> None:
        """Create the space, the bodies (all N, those in :attr:`in_space` added), the
        handlers and the batch buffers, and record the contacts at ``positions`` (N, 2) m:
        a zero-velocity step (``p + 0·dt = p`` exactly) makes pymunk create an arbiter for
        every overlapping pair and fire its ``begin``, so that the next step fires
        ``separate`` for a pair that stops overlapping and no second ``begin`` for one that
        still overlaps. Leaves the body velocities at ``velocities`` (N, 2) m/s and those
        events in the log."""
        n = self.n
        self.space = space = pymunk.Space()
        self._log = _EventLog()
        for t in SETS:
            space.on_collision(t, t, begin=self._log.begin, separate=self._log.separate)
        self.bodies: list[pymunk.Body] = []
        self.shapes: list[tuple[pymunk.Shape, ...]] = []
        for i in range(n):
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            body.position = (float(positions[i, 0]), float(positions[i, 1]))
            body._aircraft = i
            shapes = []
            for t in SETS:
                c = pymunk.Circle(body, self.radii[t])
                c.sensor = True
                c.collision_type = t
                c.filter = pymunk.ShapeFilter(categories=1 << t, mask=1 << t)
                shapes.append(c)
            if self.in_space[i]:
                space.add(body, *shapes)
            self.bodies.append(body)
            self.shapes.append(tuple(shapes))
        if self.spatial_hash and n:
            space.use_spatial_hash(float(2.0 * self.radii[RANGE]), 3 * n)
        self._buf_get = pymunk.batch.Buffer()
        self._buf_set = pymunk.batch.Buffer()
        self._refresh_order()  # aircraft index of each body in pymunk's iteration order
        if self._order.size:
            self.set_velocities(np.zeros((n, 2)))
            space.step(1.0)
        self.set_velocities(velocities)
        for i in np.flatnonzero(~self.in_space):  # bodies outside the space keep theirs too
            self.bodies[i].velocity = (float(velocities[i, 0]), float(velocities[i, 1]))

    def _refresh_order(self) -> None:
        ids = {b.id: i for i, b in enumerate(self.bodies)}
        self._buf_get.clear()
        pymunk.batch.get_space_bodies(self.space, pymunk.batch.BodyFields.BODY_ID, self._buf_get)
        body_ids = np.frombuffer(self._buf_get.int_buf(), dtype=np.uintp)
        self._order = np.array([ids[int(b)] for b in body_ids], dtype=np.int64)

    def _drain(self, reset_began: bool = True) -> None:
        """Fold the recorded events into the pair sets (and :attr:`began`)."""
        events = self._log.events
        self._log.events = []
        n = max(self.n, 1)
        began = {t: [] for t in SETS}
        ended = {t: [] for t in SETS}
        for t, i, j, sign in events:
            key = min(i, j) * n + max(i, j)
            (began if sign > 0 else ended)[t].append(key)
        for t in SETS:
            b = np.array(began[t], dtype=np.int64)
            e = np.array(ended[t], dtype=np.int64)
            keys = self.pairs[t]
            if e.size:
                keys = keys[~np.isin(keys, e)]
            if b.size:
                keys = np.union1d(keys, b)
            self.pairs[t] = keys
            b = np.unique(b)
            new = np.stack([b // n, b % n], axis=1) if b.size else np.zeros((0, 2), np.int64)
            self.began[t] = new if reset_began else np.concatenate([self.began[t], new])

    # ----------------------------------------------------------------- public
    def set_velocities(self, velocities: np.ndarray) -> None:
        """Set every body's velocity (N, 2) m/s (rows of removed aircraft are ignored)."""
        v = np.ascontiguousarray(np.asarray(velocities, dtype=float)[self._order])
        self._vbuf = v  # keep the memory alive while pymunk reads it
        self._buf_set.set_float_buf(v.reshape(-1))
        pymunk.batch.set_space_bodies(self.space, pymunk.batch.BodyFields.VELOCITY, self._buf_set)

    def step(self, dt: float, out_positions: np.ndarray) -> None:
        """Advance ``dt`` seconds; write the new positions of bodies in the space into
        ``out_positions`` (N, 2) and update :attr:`pairs` / :attr:`began`."""
        if self._order.size:
            self.space.step(dt)
            self._buf_get.clear()
            pymunk.batch.get_space_bodies(
                self.space, pymunk.batch.BodyFields.POSITION, self._buf_get
            )
            out_positions[self._order] = np.frombuffer(self._buf_get.float_buf()).reshape(-1, 2)
        self._drain()

    def remove(self, indices) -> None:
        """Take aircraft out of the space (they stop touching anything at once)."""
        idx = [int(i) for i in np.atleast_1d(indices) if self.in_space[int(i)]]
        if not idx:
            return
        for i in idx:
            self.space.remove(self.bodies[i], *self.shapes[i])
            self.in_space[i] = False
        self._refresh_order()
        self._drain(reset_began=False)

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
        O(arbiters × shapes). :meth:`__setstate__` rebuilds the space instead.
        """
        return {
            "n": self.n,
            "radii": dict(self.radii),
            "spatial_hash": self.spatial_hash,
            "in_space": self.in_space.copy(),
            "positions": np.array([tuple(b.position) for b in self.bodies], float).reshape(-1, 2),
            "velocities": np.array([tuple(b.velocity) for b in self.bodies], float).reshape(-1, 2),
            "pairs": {t: k.copy() for t, k in self.pairs.items()},
            "began": {t: b.copy() for t, b in self.began.items()},
            "events": list(self._log.events),
        }

    def __setstate__(self, state: dict) -> None:
        """Rebuild the space from :meth:`__getstate__`'s data, with an arbiter for every pair
        that overlaps (see :meth:`_build`), and check that those pairs are the stored ones.

        The stored pair sets stay authoritative; the contacts the rebuilt space finds at the
        same positions must equal them, or the copy would fire other events than the
        original from the next step on.
        """
        self.n = int(state["n"])
        self.radii = dict(state["radii"])
        self.spatial_hash = bool(state["spatial_hash"])
        self.in_space = np.array(state["in_space"], dtype=bool)
        self._build(np.asarray(state["positions"], float), np.asarray(state["velocities"], float))
        primed, self._log.events = self._log.events, list(state["events"])
        self.pairs = {t: np.array(k, dtype=np.int64) for t, k in state["pairs"].items()}
        self.began = {t: np.array(b, dtype=np.int64) for t, b in state["began"].items()}
        n = max(self.n, 1)
        found = {t: set() for t in SETS}
        for t, i, j, sign in primed:
            if sign > 0:
                found[t].add(min(i, j) * n + max(i, j))
        for t in SETS:
            if found[t] != set(self.pairs[t].tolist()):
                extra = sorted(found[t] - set(self.pairs[t].tolist()))
                missing = sorted(set(self.pairs[t].tolist()) - found[t])
                raise RuntimeError(
                    f"Airspace: rebuilt contacts of set {t} differ from the stored pairs "
                    f"(extra keys {extra[:5]}, missing {missing[:5]})"
                )
