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
        self.space = space = pymunk.Space()
        self._log = _EventLog()
        for t in SETS:
            space.on_collision(t, t, begin=self._log.begin, separate=self._log.separate)
        radii = {LOS: r_safe / 2.0, NMAC: nmac / 2.0, RANGE: sensor_range / 2.0}
        self.bodies: list[pymunk.Body] = []
        self.shapes: list[tuple[pymunk.Shape, ...]] = []
        for i in range(n):
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            body.position = (float(positions[i, 0]), float(positions[i, 1]))
            body._aircraft = i
            shapes = []
            for t in SETS:
                c = pymunk.Circle(body, radii[t])
                c.sensor = True
                c.collision_type = t
                c.filter = pymunk.ShapeFilter(categories=1 << t, mask=1 << t)
                shapes.append(c)
            space.add(body, *shapes)
            self.bodies.append(body)
            self.shapes.append(tuple(shapes))
        if spatial_hash is None:
            spatial_hash = n >= 200
        if spatial_hash and n:
            space.use_spatial_hash(float(sensor_range), 3 * n)
        self.in_space = np.ones(n, dtype=bool)
        self.pairs = {t: np.zeros(0, dtype=np.int64) for t in SETS}
        self.began = {t: np.zeros((0, 2), dtype=np.int64) for t in SETS}
        self._buf_get = pymunk.batch.Buffer()
        self._buf_set = pymunk.batch.Buffer()
        self._order = None  # aircraft index of each body in pymunk's iteration order
        self._refresh_order()
        # A zero-velocity step finds the pairs that overlap at the start (p + 0·dt = p).
        self.set_velocities(np.zeros((n, 2)))
        if n:
            space.step(1.0)
        self._drain()

    # ---------------------------------------------------------------- helpers
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
