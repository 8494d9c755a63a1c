"""Stable slots: the free list and alive mask of a table of preallocated lanes.

A slot table holds up to ``capacity`` tracks in lanes ``0 .. capacity-1``; ``alive`` marks
the live ones. :meth:`Slots.take` hands out free lanes, :meth:`Slots.release` frees lanes;
no other lane changes, so both cost O(k) for k lanes (vectorised numpy, no sort). When no
lane is free the owner grows its arrays (:meth:`Slots.capacity_for` says to what size:
at least double, rounded up to whole chunks, so growth is amortised O(1) per lane) and
calls :meth:`Slots.grow`.

The free list is a stack: the lanes freed last are taken first (they sit in chunks that are
live anyway), and after a growth the new lanes are taken lowest first, so a table that only
grows fills its lanes in order ``0, 1, 2, …``. Which lanes a sequence of births and drops
gets is a pure function of that sequence (same run, same slots).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from airspace_sim.errors import UserError


class Slots:
    """Free list (a stack) and alive mask of ``capacity`` lanes, capacity a multiple of
    ``chunk`` (the owner's structure-of-arrays chunk width)."""

    def __init__(self, chunk: int = 1):
        self.chunk = int(chunk)
        #: (capacity,) bool: live lanes (owned here; read-only views are handed out)
        self.alive = np.zeros(0, dtype=bool)
        self._free = np.zeros(0, dtype=np.int64)  # stack: _free[:_n_free], top at the end
        self._n_free = 0

    @property
    def capacity(self) -> int:
        return int(self.alive.size)

    @property
    def n_live(self) -> int:
        return self.capacity - self._n_free

    def capacity_for(self, k: int) -> int:
        """The capacity needed to take ``k`` more lanes: the current one if enough are
        free, else at least twice it, in whole chunks."""
        if k <= self._n_free:
            return self.capacity
        need = max(self.n_live + k, 2 * self.capacity, self.chunk)
        return -(-need // self.chunk) * self.chunk

    def grow(self, capacity: int) -> None:
        """Add free lanes up to ``capacity`` (the owner has grown its arrays to it)."""
        old = self.capacity
        if capacity <= old:
            return
        if capacity % self.chunk:
            raise ValueError(f"Slots.grow: capacity {capacity} is not a multiple of {self.chunk}")
        alive = np.zeros(capacity, dtype=bool)
        alive[:old] = self.alive
        free = np.empty(capacity, dtype=np.int64)
        new = capacity - old
        # new lanes under the free ones (those are reused first), lowest new lane on top
        free[:new] = np.arange(capacity - 1, old - 1, -1)
        free[new : new + self._n_free] = self._free[: self._n_free]
        self.alive, self._free = alive, free
        self._n_free += new

    def take(self, k: int) -> np.ndarray:
        """Mark ``k`` free lanes live and return them (k,) int64 (call :meth:`grow` first
        if :meth:`capacity_for` asks for more)."""
        if k > self._n_free:
            raise ValueError(f"Slots.take: {k} lanes asked, {self._n_free} free")
        top = self._n_free
        slots = self._free[top - k : top][::-1].copy()
        self._n_free -= k
        self.alive[slots] = True
        return slots

    def release(self, slots, where: str = "drop") -> np.ndarray:
        """Free the live lanes ``slots`` (k,) int; return them as int64. A slot that is not
        live, out of range or repeated is a :class:`UserError` (nothing is freed then)."""
        s = np.asarray(slots)
        if s.size == 0:
            return np.zeros(0, dtype=np.int64)
        if not np.issubdtype(s.dtype, np.integer):
            raise UserError(f"{where}: slots must be integers, got dtype {s.dtype}")
        s = np.ascontiguousarray(s.reshape(-1), dtype=np.int64)
        error, at = _release(self.alive, self._free, self._n_free, s)
        if error == 1:
            raise UserError(f"{where}: slot {int(s[at])} out of range 0..{self.capacity - 1}")
        if error == 2:
            raise UserError(f"{where}: slot {int(s[at])} is not live")
        if error == 3:
            raise UserError(f"{where}: repeated slots in {s.tolist()}")
        self._n_free += s.size
        return s

    def live(self) -> np.ndarray:
        """The live slots in increasing order (L,) int64 (O(capacity))."""
        return np.flatnonzero(self.alive)


@njit(cache=True)
def _release(alive, free, n_free, s):  # pragma: no cover - compiled
    """:meth:`Slots.release` of ``s`` (k,) int64: ``(0, 0)`` after clearing ``alive`` and
    pushing ``s`` on the free stack ``free[n_free:]``, or with nothing changed ``(1, i)``
    (``s[i]`` is the first out of range), ``(2, i)`` (the first not live) or ``(3, 0)``
    (a slot repeated), checked in that order."""
    cap = alive.size
    for i in range(s.size):
        if s[i] < 0 or s[i] >= cap:
            return 1, i
    for i in range(s.size):
        if not alive[s[i]]:
            return 2, i
    for i in range(s.size):
        if not alive[s[i]]:  # live before this pass: cleared by an earlier entry
            for j in range(i):
                alive[s[j]] = True
            return 3, 0
        alive[s[i]] = False
    for i in range(s.size):
        free[n_free + i] = s[i]
    return 0, 0
