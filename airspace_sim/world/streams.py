"""Counter-based random numbers: one independent stream per aircraft (or pair), no state.

Every random number in a world is a pure function of (world seed, who, what, step): the
aircraft keys come from ``numpy.random.SeedSequence(seed).spawn``, and a draw for aircraft
``i`` at step ``k`` is ``splitmix64`` of its key mixed with ``(stream, k)``. So results do
not depend on the order in which aircraft or pairs are visited, nor on which other aircraft
exist, and nothing is shared between worlds (no module-level mutable state).

:func:`uniform` and :func:`normal` run as numba kernels built on the scalar functions
:func:`draw_uniform` and :func:`draw_normal`; :func:`uniform_numpy` and
:func:`normal_numpy` are the same arithmetic in numpy, the reference the tests compare
against bit for bit. The integer hash is exact; the normals' log and cos are libm's in
numba, so the reference takes them from :mod:`math` (libm's too), element by element:
numpy's own log and cos may be SIMD versions (numpy 2.4's log is on AVX-512 CPUs) that
differ from libm's in the last bit for a few inputs in a thousand.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_TWO_M53 = 2.0**-53

#: Stream numbers (the "what" of a draw).
MODE, DETECT, NOISE_X, NOISE_Y, INITIAL_MODE, SPARE = range(6)


def mix(z: np.ndarray) -> np.ndarray:
    """splitmix64 finaliser, elementwise on uint64 arrays (wrapping arithmetic)."""
    z = np.asarray(z, dtype=np.uint64)
    with np.errstate(over="ignore"):
        z = (z ^ (z >> _S30)) * _M1
        z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


def aircraft_keys(seed: int, n: int, stream: int = 0) -> np.ndarray:
    """(n,) uint64 keys, one per aircraft, from ``SeedSequence(seed)`` children.

    ``stream`` selects an independent family of keys (child ``stream`` of the root, whose
    ``n`` children give the keys).
    """
    root = np.random.SeedSequence(int(seed))
    family = root.spawn(stream + 1)[stream]
    if n == 0:
        return np.zeros(0, dtype=np.uint64)
    return np.array([c.generate_state(1, np.uint64)[0] for c in family.spawn(n)], dtype=np.uint64)


def pair_keys(keys: np.ndarray, owner: np.ndarray, intruder: np.ndarray) -> np.ndarray:
    """Keys of ordered pairs (owner, intruder) from per-aircraft keys, (P,) uint64."""
    with np.errstate(over="ignore"):
        return mix(keys[owner] ^ mix(keys[intruder] + _GOLDEN))


def directed_pairs(i, j, owners, present, keys):
    """The ordered pairs of the unordered pairs ``(i, j)`` (P,) int64 that an ownship
    measures, and their :func:`pair_keys`: ``(owner (D,), intruder (D,), pair keys (D,)
    uint64)``, first the pairs ``i → j`` then ``j → i``, each in the order of ``(i, j)``,
    kept where ``owners[owner] & present[owner] & present[intruder]`` ((N,) bool each);
    ``keys`` (N,) uint64 per aircraft. One pass, the keys hashed in it: the same arrays as
    concatenating, masking and :func:`pair_keys` in numpy."""
    i = np.ascontiguousarray(i, dtype=np.int64)
    j = np.ascontiguousarray(j, dtype=np.int64)
    return _directed_pairs_kernel(
        i,
        j,
        np.ascontiguousarray(owners, dtype=np.bool_),
        np.ascontiguousarray(present, dtype=np.bool_),
        np.ascontiguousarray(keys, dtype=np.uint64),
    )


def _counter_word(stream: int, step: int) -> np.uint64:
    word = (int(stream) * 0x100000001B3 + int(step) * 0x2545F4914F6CDD1D + 1) % (1 << 64)
    return mix(np.array([word], dtype=np.uint64))[0]


@njit(cache=True)
def _mix_scalar(z):  # pragma: no cover - compiled
    """:func:`mix` of one uint64 (numba wraps uint64 products like numpy)."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@njit(cache=True)
def _directed_pairs_kernel(i, j, owners, present, keys):  # pragma: no cover - compiled
    """:func:`directed_pairs` (checked arguments). The intruder's half of :func:`pair_keys`,
    ``mix(keys[t] + golden)``, is taken once per aircraft (N), not once per pair."""
    as_intruder = np.empty(keys.size, dtype=np.uint64)
    for t in range(keys.size):
        as_intruder[t] = _mix_scalar(keys[t] + _GOLDEN)
    p = i.size
    owner = np.empty(2 * p, dtype=np.int64)
    intruder = np.empty(2 * p, dtype=np.int64)
    pk = np.empty(2 * p, dtype=np.uint64)
    d = 0
    for direction in range(2):
        a, b = (i, j) if direction == 0 else (j, i)
        for q in range(p):
            o, t = a[q], b[q]
            if owners[o] and present[o] and present[t]:
                owner[d], intruder[d] = o, t
                pk[d] = _mix_scalar(keys[o] ^ as_intruder[t])
                d += 1
    return owner[:d], intruder[:d], pk[:d]


@njit(cache=True)
def draw_uniform(key, word):  # pragma: no cover - compiled
    """One :func:`uniform` number in [0, 1) from a uint64 key and a counter word
    (:func:`_counter_word` of the stream and step)."""
    z = _mix_scalar(_mix_scalar(key ^ word) + _GOLDEN)
    return np.float64(z >> _S11) * _TWO_M53


@njit(cache=True)
def draw_normal(key, word1, word2):  # pragma: no cover - compiled
    """One :func:`normal` number from a uint64 key and the counter words of its two
    uniforms (streams ``2·stream + 1000`` and ``2·stream + 1001``)."""
    u1 = 1.0 - draw_uniform(key, word1)  # (0, 1]
    u2 = draw_uniform(key, word2)
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u2)


@njit(cache=True)
def _uniform_kernel(keys, word):  # pragma: no cover - compiled
    """(P,) uniforms of the (P,) uint64 keys."""
    out = np.empty(keys.size)
    for p in range(keys.size):
        out[p] = draw_uniform(keys[p], word)
    return out


@njit(cache=True)
def _normal_kernel(keys, word1, word2):  # pragma: no cover - compiled
    """(P,) standard normals of the (P,) uint64 keys."""
    out = np.empty(keys.size)
    for p in range(keys.size):
        out[p] = draw_normal(keys[p], word1, word2)
    return out


@njit(cache=True)
def _add_normals_kernel(z, keys, scale, w1x, w2x, w1y, w2y):  # pragma: no cover - compiled
    """``z[p, 0] += scale·normal_x[p]``, ``z[p, 1] += scale·normal_y[p]`` in place, z (P, 2),
    keys (P,) uint64; the normals of two streams (counter words ``w1x, w2x`` and
    ``w1y, w2y``), each ``√(−2 ln u1)·cos(2π u2)`` exactly as :func:`draw_normal`.

    One pass in key order. libm's cos branches on its argument's range, and over random
    arguments those branches are mispredicted; evaluating a chunk's cos sorted by argument
    (a counting sort per chunk of keys) was faster on one CPU and slower on another, where
    the extra passes cost more than the mispredictions (``docs/performance.md``).
    """
    zf = z.reshape(-1)  # normal of key p on an axis is at 2p + axis
    for p in range(keys.size):
        k = keys[p]
        for axis in range(2):
            w1 = w1x if axis == 0 else w1y
            w2 = w2x if axis == 0 else w2y
            u1 = 1.0 - draw_uniform(k, w1)  # (0, 1]
            u2 = draw_uniform(k, w2)
            zf[2 * p + axis] += scale * (np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u2))


def add_normals(
    z: np.ndarray, keys: np.ndarray, scale: float, stream_x: int, stream_y: int, step: int
) -> None:
    """Add ``scale·normal(keys, stream_x, step)`` to ``z[:, 0]`` and ``scale·normal(keys,
    stream_y, step)`` to ``z[:, 1]``, in place (the same numbers, one pass). ``z`` (P, 2)
    float64 C-contiguous, ``keys`` (P,) uint64, ``scale`` in z's unit."""
    k = np.ascontiguousarray(keys, dtype=np.uint64).reshape(-1)
    if z.shape != (k.size, 2) or z.dtype != np.float64 or not z.flags.c_contiguous:
        raise ValueError(f"add_normals: z must be C-contiguous float64 ({k.size}, 2)")
    w1x, w2x = _counter_word(2 * stream_x + 1000, step), _counter_word(2 * stream_x + 1001, step)
    w1y, w2y = _counter_word(2 * stream_y + 1000, step), _counter_word(2 * stream_y + 1001, step)
    _add_normals_kernel(z, k, float(scale), w1x, w2x, w1y, w2y)


def uniform(keys: np.ndarray, stream: int, step: int) -> np.ndarray:
    """Uniform numbers in [0, 1), one per key, for this (stream, step), shape of ``keys``."""
    k = np.ascontiguousarray(keys, dtype=np.uint64)
    return _uniform_kernel(k.reshape(-1), _counter_word(stream, step)).reshape(k.shape)


def normal(keys: np.ndarray, stream: int, step: int) -> np.ndarray:
    """Standard normal numbers, one per key (Box–Muller on two counter-based uniforms),
    shape of ``keys``."""
    k = np.ascontiguousarray(keys, dtype=np.uint64)
    w1 = _counter_word(2 * stream + 1000, step)
    w2 = _counter_word(2 * stream + 1001, step)
    return _normal_kernel(k.reshape(-1), w1, w2).reshape(k.shape)


def uniform_numpy(keys: np.ndarray, stream: int, step: int) -> np.ndarray:
    """:func:`uniform` in numpy (the reference for the kernel)."""
    with np.errstate(over="ignore"):
        z = mix(mix(np.asarray(keys, dtype=np.uint64) ^ _counter_word(stream, step)) + _GOLDEN)
    return (z >> _S11).astype(np.float64) * _TWO_M53


def normal_numpy(keys: np.ndarray, stream: int, step: int) -> np.ndarray:
    """:func:`normal` in numpy (the reference for the kernel); log and cos are libm's, from
    :mod:`math` (module docstring)."""
    u1 = 1.0 - uniform_numpy(keys, 2 * stream + 1000, step)  # (0, 1]
    u2 = uniform_numpy(keys, 2 * stream + 1001, step)
    log_u1 = np.array([math.log(u) for u in u1.reshape(-1)]).reshape(u1.shape)
    cos_u2 = np.array([math.cos(a) for a in (2.0 * np.pi * u2).reshape(-1)]).reshape(u2.shape)
    return np.sqrt(-2.0 * log_u1) * cos_u2
