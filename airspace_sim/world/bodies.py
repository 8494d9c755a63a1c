"""The pymunk side of a world: aircraft bodies with sensor circles, and the pairs they form.

Three pair sets are kept, as sorted arrays of keys ``i·N + j`` (``i < j``):

======== ==================================================
set      pair in the set  ⇔
======== ==================================================
LOS      centre distance < r_safe      (loss of separation)
NMAC     centre distance < nmac        (near mid-air collision)
RANGE    centre distance < range       (in surveillance range)
======== ==================================================

Pymunk answers the spatial query, numba the exact test. Each aircraft is a KINEMATIC body
in one ``pymunk.Space`` carrying one sensor circle of radius ``(R + margin) / 2``, ``R`` the
largest of the three distances: two circles overlap exactly when the aircraft are closer
than ``R + margin``, the *candidate* pairs. The space is not stepped every world step: the
bodies stay where the candidates were last found, and the candidates are found again only
once the aircraft may have moved so far that a pair outside ``R + margin`` then could be
inside ``R`` now, i.e. once twice the largest distance flown since (summed per step)
exceeds the margin: positions in with one :mod:`pymunk.batch` call, one step (velocities
stay 0), the pairs with an arbiter out with another (collision persistence 1: right after
a step the arbiters are exactly the overlapping pairs; no Python callback per pair). In
between, a numba pass over the candidates gives the three exact sets every step, with the
arithmetic of chipmunk's circle test (``dx² + dy² < d²``), so the same pairs as circles of
the exact radii stepped every step would give; the pairs that entered a set are a merge
of its sorted keys with the previous step's.

Positions are integrated here as chipmunk integrates a kinematic body (``p ← p + v·dt``,
the same bits). Cost per step: O(N + candidates) in numba and numpy, plus pymunk's
broad phase and arbiters once every ``margin / (2·v_max·dt)`` steps (every 18 steps at the
benchmark's 40 km range and 230 m/s: margin = 20% of ``R``; 1.44 times the pairs in range
as candidates; on the 1000-aircraft benchmark traffic 3.0 ms CPU per step against 4.3 with
a 10% margin refreshed every 8 steps, ``docs/performance.md``).

Everything lives on the instance: several worlds in one process never share state.
"""

from __future__ import annotations

import math

import numpy as np
import pymunk
import pymunk.batch
from numba import njit

from airspace_sim.tracking.keymap import KeyMap

LOS, NMAC, RANGE = 1, 2, 3
SETS = (LOS, NMAC, RANGE)
_ARBITER_BODIES = pymunk.batch.ArbiterFields.BODY_A_ID | pymunk.batch.ArbiterFields.BODY_B_ID
#: refresh margin as a fraction of the largest pair distance
MARGIN_FRACTION = 0.2
#: the distance flown is compared with the margin less this fraction (float rounding)
_MARGIN_SLACK = 1e-6


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


@njit(cache=True)
def _exact_pairs(keys, ci, cj, positions, d2):  # pragma: no cover - compiled
    """The candidate ``keys`` (P,) sorted, ``i·n + j``, of aircraft ``ci``, ``cj`` (P,),
    whose centres (``positions`` (N, 2) m) are closer than each set's distance ``d2`` (3,)
    squared, m²: per set ``(keys, i, j)`` (sorted keys and their aircraft), in the order
    of ``d2``. ``dx² + dy² < d²`` as chipmunk's circle test computes it. (The aircraft
    come in, not from ``keys // n``: an integer division per candidate and step was a
    quarter of the pass.) Each candidate is written to every set's next row and the row
    kept by counting the test (no branch: the sensor-range test is true for seven in ten
    candidates and mispredicted often)."""
    out_k = np.empty((3, keys.size), dtype=np.int64)
    out_i = np.empty((3, keys.size), dtype=np.int64)
    out_j = np.empty((3, keys.size), dtype=np.int64)
    c0 = c1 = c2 = 0
    lim0, lim1, lim2 = d2[0], d2[1], d2[2]
    for p in range(keys.size):
        k = keys[p]
        i = ci[p]
        j = cj[p]
        dx = positions[j, 0] - positions[i, 0]
        dy = positions[j, 1] - positions[i, 1]
        dd = dx * dx + dy * dy
        out_k[0, c0], out_i[0, c0], out_j[0, c0] = k, i, j
        c0 += dd < lim0
        out_k[1, c1], out_i[1, c1], out_j[1, c1] = k, i, j
        c1 += dd < lim1
        out_k[2, c2], out_i[2, c2], out_j[2, c2] = k, i, j
        c2 += dd < lim2
    count = (c0, c1, c2)
    return [(out_k[t, : count[t]], out_i[t, : count[t]], out_j[t, : count[t]]) for t in range(3)]


@njit(cache=True)
def _kinematic_step(positions, velocities, live, dt, out):  # pragma: no cover - compiled
    """Chipmunk's kinematic update ``p ← p + v·dt`` of the aircraft ``live`` (N,) bool, in
    ``positions`` (N, 2) m and copied to ``out`` (N, 2), velocities (N, 2) m/s, dt s.
    Returns the largest speed ``√(vx² + vy²)`` of a live aircraft, m/s (NaN if one is NaN,
    as numpy's max; −1 if none is live)."""
    fastest = -1.0
    for i in range(live.size):
        if live[i]:
            vx, vy = velocities[i, 0], velocities[i, 1]
            positions[i, 0] = positions[i, 0] + vx * dt
            positions[i, 1] = positions[i, 1] + vy * dt
            out[i, 0], out[i, 1] = positions[i, 0], positions[i, 1]
            speed = np.sqrt(vx * vx + vy * vy)
            if speed > fastest or speed != speed:
                if fastest == fastest:  # the first NaN stays
                    fastest = speed
    return fastest


@njit(cache=True)
def _new_keys(now, before):  # pragma: no cover - compiled
    """The sorted keys of ``now`` (sorted, unique) that are not in ``before`` (sorted,
    unique): one merge."""
    out = np.empty(now.size, dtype=np.int64)
    k = 0
    j = 0
    for i in range(now.size):
        while j < before.size and before[j] < now[i]:
            j += 1
        if j >= before.size or before[j] != now[i]:
            out[k] = now[i]
            k += 1
    return out[:k]


class Airspace:
    """N aircraft as kinematic pymunk bodies with sensor circles, and their pair sets.

    Parameters
    ----------
    positions : (N, 2) initial positions, m.
    r_safe, nmac, sensor_range : the three distances of the table above, m.
    spatial_hash : index the space with pymunk's spatial hash (cell size ``R + margin``,
        4·N cells; the default, None, is True) or with its bounding-box tree (False); the
        same pairs either way. The hash finds the candidates in 10–25% less time on the
        benchmark traffic (1000–10,000 aircraft, ``docs/performance.md``).
    margin : m, the candidate circles' extra diameter (default :data:`MARGIN_FRACTION` of ``R``); a larger
        margin means more candidates and rarer refreshes, never other pairs.
    in_space : (N,) bool, optional: the aircraft that start in the space (default all; the
        others can come in later with :meth:`add`).

    Attributes
    ----------
    positions : (N, 2) m, current positions (removed aircraft keep their last one).
    pairs : dict set → (P,) int64 sorted keys ``i·N + j`` (``i < j``) of the pairs in it.
    began : dict set → (E, 2) int64 pairs (i < j) that entered the set in the last step.
    refreshes : int, how many times the candidates were found again (after the first).

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
        margin: float | None = None,
        in_space=None,
    ):
        positions = np.asarray(positions, dtype=float).reshape(-1, 2)
        self.n = n = positions.shape[0]
        self.distances = {LOS: float(r_safe), NMAC: float(nmac), RANGE: float(sensor_range)}
        reach = max(self.distances.values())
        self.margin = float(MARGIN_FRACTION * reach if margin is None else margin)
        self.spatial_hash = True if spatial_hash is None else bool(spatial_hash)
        self.in_space = np.ones(n, dtype=bool) if in_space is None else np.array(in_space, bool)
        self.positions = positions.copy()
        self.refreshes = 0
        self._velocities = np.zeros((n, 2))
        self._flown = 0.0  # largest distance any aircraft may have flown since the refresh
        self._build(positions)
        self.pairs = {t: np.zeros(0, dtype=np.int64) for t in SETS}
        self._update_sets(reset_began=True)  # the pairs in a set at the start all begin now

    # ---------------------------------------------------------------- helpers
    def _build(self, positions: np.ndarray) -> None:
        """Create the space and the bodies (all N, those in :attr:`in_space` added) at
        ``positions`` (N, 2) m and the batch buffers, and find the candidate pairs there
        (:attr:`_candidates`, one zero-velocity step: ``p + 0·dt = p`` exactly)."""
        n = self.n
        self._buf_get = pymunk.batch.Buffer()
        self._buf_set = pymunk.batch.Buffer()
        self._pbuf = np.zeros(0)
        radius = (max(self.distances.values()) + self.margin) / 2.0
        self.space = space = pymunk.Space()
        self.bodies: list[pymunk.Body] = []
        self.shapes: list[pymunk.Shape] = []
        for i in range(n):
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            body.position = (float(positions[i, 0]), float(positions[i, 1]))
            body._aircraft = i
            c = pymunk.Circle(body, radius)
            c.sensor = True
            if self.in_space[i]:
                space.add(body, c)
            self.bodies.append(body)
            self.shapes.append(c)
        # an arbiter not touched in a step is dropped at once: the arbiters after a step
        # are the overlapping pairs (sensors' arbiters hold no contacts worth keeping)
        space.collision_persistence = 1
        if self.spatial_hash and n:
            space.use_spatial_hash(float(2.0 * radius), 4 * n)
        ids = np.array([b.id for b in self.bodies], dtype=np.uintp)
        by_id = np.argsort(ids)
        self._ids_sorted = (ids[by_id], by_id)
        # body id → aircraft in a hash map when the ids fit its keys (ids are addresses,
        # far below 2⁶³): O(1) per arbiter body instead of a binary search
        self._id_map = None
        if n and int(ids.max()) < 2**63:
            self._id_map = KeyMap(n)
            self._id_map.put(ids.astype(np.int64), np.arange(n, dtype=np.int64))
        self._refresh_order()
        if self._order.size:
            space.step(1.0)  # every body has velocity 0 and keeps it
        self._set_candidates(self._arbiter_keys())

    def _refresh_order(self) -> None:
        """Aircraft index (B,) of each body in the space in pymunk's iteration order."""
        self._buf_get.clear()
        pymunk.batch.get_space_bodies(self.space, pymunk.batch.BodyFields.BODY_ID, self._buf_get)
        self._order = self._aircraft_of(np.frombuffer(self._buf_get.int_buf(), np.uintp))

    def _aircraft_of(self, body_ids: np.ndarray) -> np.ndarray:
        """Aircraft indices (K,) int64 of pymunk body ids (K,)."""
        if self._id_map is not None:
            return self._id_map.get(body_ids.astype(np.int64))
        ids, by_id = self._ids_sorted
        return by_id[np.searchsorted(ids, body_ids)].astype(np.int64)

    def _arbiter_keys(self) -> np.ndarray:
        """(P,) sorted keys of the pairs with an arbiter (right after a step: exactly the
        overlapping pairs, collision persistence being 1)."""
        self._buf_get.clear()
        pymunk.batch.get_space_arbiters(self.space, _ARBITER_BODIES, self._buf_get)
        ab = self._aircraft_of(np.frombuffer(self._buf_get.int_buf(), np.uintp)).reshape(-1, 2)
        n = max(self.n, 1)
        # one shape per body, so one arbiter per pair: sorting is np.unique, three times
        # faster (checked, np.unique if a key came twice)
        keys = np.sort(np.minimum(ab[:, 0], ab[:, 1]) * n + np.maximum(ab[:, 0], ab[:, 1]))
        if keys.size > 1 and (keys[1:] == keys[:-1]).any():
            keys = np.unique(keys)
        return keys

    def _refresh(self) -> None:
        """Find the candidates again at the current positions: bodies moved there in one
        batch call, one step (velocities stay 0), the arbiters read in another."""
        if self._order.size:
            p = np.ascontiguousarray(self.positions[self._order])
            self._pbuf = p  # keep the memory alive while pymunk reads it
            self._buf_set.set_float_buf(p.reshape(-1))
            pymunk.batch.set_space_bodies(
                self.space, pymunk.batch.BodyFields.POSITION, self._buf_set
            )
            self.space.step(1.0)
        self._set_candidates(self._arbiter_keys())
        self._flown = 0.0
        self.refreshes += 1

    def _update_sets(self, reset_began: bool = True) -> None:
        """The three exact sets from the candidates at :attr:`positions`; :attr:`began`
        their new keys (added to it unless ``reset_began``)."""
        sets = self._exact(self._candidates, self._cand_ij)
        n = max(self.n, 1)
        began = {}
        self._ij = {}
        for t, (keys, i, j) in zip(SETS, sets):
            new = _new_keys(keys, self.pairs[t])
            b = np.stack([new // n, new % n], axis=1)
            began[t] = b if reset_began else np.concatenate([self.began[t], b])
            self.pairs[t] = keys
            self._ij[t] = (i, j)
        self.began = began

    def _set_candidates(self, keys: np.ndarray) -> None:
        """:attr:`_candidates` ← ``keys`` (P,) sorted, and their aircraft ``_cand_ij``."""
        n = max(self.n, 1)
        i = keys // n
        self._candidates, self._cand_ij = keys, (i, keys - i * n)

    def _exact(self, candidates: np.ndarray, ij=None) -> list:
        """Per set (in :data:`SETS` order) ``(keys, i, j)`` of the ``candidates`` closer
        than its distance at :attr:`positions`; ``ij`` their aircraft (default: from the
        keys)."""
        d2 = np.array([self.distances[t] ** 2 for t in SETS])
        if ij is None:
            n = max(self.n, 1)
            ij = (candidates // n, candidates % n)
        return _exact_pairs(candidates, ij[0], ij[1], self.positions, d2)

    # ----------------------------------------------------------------- public
    def set_velocities(self, velocities: np.ndarray) -> None:
        """Set every body's velocity (N, 2) m/s (rows of removed aircraft are ignored)."""
        self._velocities = np.array(velocities, dtype=float).reshape(self.n, 2)

    def step(self, dt: float, out_positions: np.ndarray) -> None:
        """Advance ``dt`` seconds; write the new positions of the aircraft in the space into
        ``out_positions`` (N, 2) and update :attr:`pairs` / :attr:`began`."""
        fastest = _kinematic_step(
            self.positions, self._velocities, self.in_space, float(dt), out_positions
        )
        if fastest >= 0.0 or fastest != fastest:  # some aircraft in the space (NaN: a NaN speed)
            self._flown += fastest * abs(dt)
        if 2.0 * self._flown > self.margin * (1.0 - _MARGIN_SLACK):
            self._refresh()
        self._update_sets()

    def remove(self, indices) -> None:
        """Take aircraft out of the space (they leave every set at once)."""
        idx = [int(i) for i in np.atleast_1d(indices) if self.in_space[int(i)]]
        if not idx:
            return
        for i in idx:
            self.space.remove(self.bodies[i], self.shapes[i])
        self.in_space[idx] = False
        self._refresh_order()
        i, j = self._cand_ij
        keep = self.in_space[i] & self.in_space[j]
        self._candidates, self._cand_ij = self._candidates[keep], (i[keep], j[keep])
        self._update_sets(reset_began=False)

    def add(self, indices, positions) -> None:
        """Put aircraft (k,) that are outside back into the space at ``positions`` (k, 2) m;
        their pairs begin with the next :meth:`step`, which finds the candidates again."""
        idx = np.atleast_1d(np.asarray(indices, dtype=np.int64))
        pos = np.asarray(positions, dtype=float).reshape(-1, 2)
        new = [(int(i), p) for i, p in zip(idx, pos) if not self.in_space[int(i)]]
        if not new:
            return
        for i, p in new:
            body = self.bodies[i]
            body.position = (float(p[0]), float(p[1]))
            self.positions[i] = p
            self.space.add(body, self.shapes[i])
        self.in_space[[i for i, _ in new]] = True
        self._refresh_order()
        self._flown = math.inf  # the new bodies' candidates are unknown until a refresh

    def pair_arrays(self, kind: int) -> tuple[np.ndarray, np.ndarray]:
        """Current pairs of a set as (i, j) int64 arrays, i < j, sorted (read-only: the
        airspace's own, valid until its next step or removal)."""
        return self._ij[kind]

    # --------------------------------------------------------------- pickling
    def __getstate__(self) -> dict:
        """The airspace as plain data: distances, margin, positions (N, 2) m and velocities
        (N, 2) m/s, the bodies' positions (where the candidates were found), the distance
        flown since, membership, candidates, pair sets and the last step's began pairs.

        The pymunk objects are not pickled: the batch buffers are cffi memory, and pymunk's
        own ``Space`` pickling costs O(arbiters × shapes). :meth:`__setstate__` rebuilds
        the space instead.
        """
        return {
            "n": self.n,
            "distances": dict(self.distances),
            "margin": self.margin,
            "spatial_hash": self.spatial_hash,
            "in_space": self.in_space.copy(),
            "positions": self.positions.copy(),
            "velocities": self._velocities.copy(),
            "body_positions": np.array([tuple(b.position) for b in self.bodies], float).reshape(
                -1, 2
            ),
            "flown": self._flown,
            "refreshes": self.refreshes,
            "candidates": self._candidates.copy(),
            "pairs": {t: k.copy() for t, k in self.pairs.items()},
            "began": {t: b.copy() for t, b in self.began.items()},
        }

    def __setstate__(self, state: dict) -> None:
        """Rebuild the space from :meth:`__getstate__`'s data (see :meth:`_build`), and
        check the candidates it finds and the exact sets they give against the stored
        ones."""
        self.n = int(state["n"])
        self.distances = dict(state["distances"])
        self.margin = float(state["margin"])
        self.spatial_hash = bool(state["spatial_hash"])
        self.in_space = np.array(state["in_space"], dtype=bool)
        self.positions = np.array(state["positions"], dtype=float).reshape(-1, 2)
        self._velocities = np.array(state["velocities"], dtype=float).reshape(-1, 2)
        self._flown = float(state["flown"])
        self.refreshes = int(state["refreshes"])
        self._build(np.asarray(state["body_positions"], float).reshape(-1, 2))
        stored = np.array(state["candidates"], dtype=np.int64)
        self._check("candidates", self._candidates, stored)
        self.pairs = {t: np.array(k, dtype=np.int64) for t, k in state["pairs"].items()}
        self.began = {t: np.array(b, dtype=np.int64) for t, b in state["began"].items()}
        found = self._exact(stored)
        self._ij = {}
        for t, (keys, i, j) in zip(SETS, found):
            self._check(f"set {t}", keys, self.pairs[t])
            self._ij[t] = (i, j)

    @staticmethod
    def _check(what: str, found: np.ndarray, stored: np.ndarray) -> None:
        if not np.array_equal(found, stored):
            extra = np.setdiff1d(found, stored)
            missing = np.setdiff1d(stored, found)
            raise RuntimeError(
                f"Airspace: rebuilt contacts of {what} differ from the stored pairs "
                f"(extra keys {extra[:5].tolist()}, missing {missing[:5].tolist()})"
            )
