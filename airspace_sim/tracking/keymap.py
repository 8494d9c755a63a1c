"""A hash map from non-negative int64 keys to int64 values, with batched numba operations.

The track table's index from a pair key ``owner·N + intruder`` to the track's slot: a
lookup of D keys costs O(D) (no sort), inserting or deleting k keys O(k), memory O(live
keys). Open addressing with linear probing in a power-of-two table kept at most half full
(Fibonacci hashing of the key), deletion by backward shift (no tombstones, so probe
sequences never degrade however many inserts and deletes a long run makes). Each entry is
a (key, value) row of one (size, 2) array: a lookup that misses the cache misses it once,
not once in a key array and again in a value array (at 10,000 aircraft the track index
holds 490,000 keys in a 32 MB table).
"""

from __future__ import annotations

import numpy as np
from numba import njit

_EMPTY = -1
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


@njit(cache=True)
def _home(key, shift):
    return np.int64((np.uint64(key) * _GOLDEN) >> np.uint64(shift))


@njit(cache=True)
def _find(t, key, shift):
    mask = t.shape[0] - 1
    i = _home(key, shift)
    while True:
        k = t[i, 0]
        if k == key or k == _EMPTY:
            return i
        i = (i + 1) & mask


@njit(cache=True)
def _lookup(t, query, shift, out):
    for q in range(query.size):
        i = _find(t, query[q], shift)
        out[q] = t[i, 1] if t[i, 0] == query[q] else -1


@njit(cache=True)
def _insert(t, keys, vals, shift):
    """Insert (or overwrite); returns the number of new keys."""
    new = 0
    for q in range(keys.size):
        i = _find(t, keys[q], shift)
        if t[i, 0] == _EMPTY:
            new += 1
        t[i, 0] = keys[q]
        t[i, 1] = vals[q]
    return new


@njit(cache=True)
def _delete(t, keys, shift):
    """Delete keys (absent ones are ignored); returns the number deleted."""
    mask = t.shape[0] - 1
    gone = 0
    for q in range(keys.size):
        i = _find(t, keys[q], shift)
        if t[i, 0] == _EMPTY:
            continue
        gone += 1
        # backward shift: move later entries of the probe run into the hole when their
        # home position is not in (hole, entry]
        j = i
        while True:
            j = (j + 1) & mask
            if t[j, 0] == _EMPTY:
                break
            h = _home(t[j, 0], shift)
            if (j > i and (h <= i or h > j)) or (j < i and (h <= i and h > j)):
                t[i, 0] = t[j, 0]
                t[i, 1] = t[j, 1]
                i = j
        t[i, 0] = _EMPTY
    return gone


class KeyMap:
    """int64 key (≥ 0) → int64 value; :meth:`get` gives −1 for absent keys."""

    def __init__(self, capacity: int = 0):
        self._alloc(max(16, 1 << int(2 * max(capacity, 1) - 1).bit_length()))
        self.size = 0

    def _alloc(self, table_size: int) -> None:
        self._t = np.zeros((table_size, 2), dtype=np.int64)  # rows (key, value)
        self._t[:, 0] = _EMPTY
        self._shift = 64 - (table_size.bit_length() - 1)

    def __setstate__(self, state: dict) -> None:
        """Unpickle; a map pickled with separate key and value arrays (``_k``, ``_v``, an
        older checkpoint) gets its rows from them (same table size, same positions)."""
        if "_t" not in state:
            state["_t"] = np.stack([state.pop("_k"), state.pop("_v")], axis=1)
        self.__dict__.update(state)

    def __len__(self) -> int:
        return self.size

    def get(self, query) -> np.ndarray:
        """Values of ``query`` (D,) int keys, −1 where absent."""
        q = np.ascontiguousarray(query, dtype=np.int64)
        out = np.empty(q.size, dtype=np.int64)
        if q.size:
            _lookup(self._t, q, self._shift, out)
        return out

    def put(self, keys, values) -> None:
        """Insert or overwrite ``keys`` (k,) → ``values`` (k,)."""
        keys = np.ascontiguousarray(keys, dtype=np.int64)
        values = np.ascontiguousarray(values, dtype=np.int64)
        if keys.size and keys.min() < 0:
            raise ValueError("KeyMap keys must be non-negative")
        if 2 * (self.size + keys.size) > self._t.shape[0]:  # keep at most half full
            live = self._t[:, 0] != _EMPTY
            old_k, old_v = self._t[live, 0], self._t[live, 1]
            self._alloc(1 << int(4 * (self.size + keys.size) - 1).bit_length())
            _insert(self._t, old_k, old_v, self._shift)
        self.size += int(_insert(self._t, keys, values, self._shift))

    def delete(self, keys) -> None:
        """Remove ``keys`` (k,) (absent keys are ignored)."""
        keys = np.ascontiguousarray(keys, dtype=np.int64)
        if keys.size:
            self.size -= int(_delete(self._t, keys, self._shift))
