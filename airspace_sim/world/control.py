"""Tracks gathered into per-ownship arrays, the form every resolver takes (paper §V).

For the ownships that run the resolver, the confirmed tracks are gathered into padded
arrays ``(n_own, K, ·)`` (intruder slot ``k`` of ownship ``o``; ``valid`` marks used slots)
with ``rel_position = track position − own true position`` and ``rel_velocity = track
velocity − own true velocity`` (world frame, m and m/s). :class:`~.policy.AvoidancePolicy`
runs the resolver on them.

The per-step work is done by small numba kernels (:func:`_gather_kernel`,
:func:`_reachable_kernel`, :func:`_screen_kernel`); the numpy functions they replace are
kept as references (:func:`gather_numpy`, :func:`reachable_numpy`, :func:`screen_numpy`)
and the tests check that both give the same arrays bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from airspace_sim.avoidance.cpa import clear_ratio2, cpa_min_ratio


@dataclass
class Encounters:
    """Tracks of the resolver-running ownships as padded arrays.

    owners : (n_own,) aircraft index of each row; rows : (n_own, K) track row or −1;
    rel_position, rel_velocity : (n_own, K, 2) m, m/s; valid : (n_own, K) bool.
    """

    owners: np.ndarray
    rows: np.ndarray
    rel_position: np.ndarray
    rel_velocity: np.ndarray
    valid: np.ndarray

    @classmethod
    def empty(cls) -> Encounters:
        """No ownship."""
        z = np.zeros((0, 0, 2))
        return cls(
            np.zeros(0, np.int64), np.zeros((0, 0), np.int64), z, z.copy(), np.zeros((0, 0), bool)
        )

    def subset(self, mask: np.ndarray) -> Encounters:
        """The ownships with ``mask`` (n_own,) bool True (row gathers by ``np.take``,
        several times faster than boolean indexing of these (n_own, K, ·) arrays)."""
        rows = np.flatnonzero(mask)
        take = lambda a: np.take(a, rows, axis=0)
        return Encounters(
            take(self.owners),
            take(self.rows),
            take(self.rel_position),
            take(self.rel_velocity),
            take(self.valid),
        )

    def compact(self, keep: np.ndarray) -> Encounters:
        """Only the slots with ``keep`` (n_own, K) True, packed to the left, K shrunk."""
        keep = keep & self.valid
        n = self.owners.size
        K = int(keep.sum(axis=1).max(initial=0))
        order = np.argsort(~keep, axis=1, kind="stable")[:, :K]  # kept slots first
        take = lambda a: np.take_along_axis(a, order.reshape(n, K, *([1] * (a.ndim - 2))), axis=1)
        valid = take(keep)
        return Encounters(
            self.owners,
            np.where(valid, take(self.rows), -1),
            np.where(valid[..., None], take(self.rel_position), 0.0),
            np.where(valid[..., None], take(self.rel_velocity), 0.0),
            valid,
        )


def _sample_times(lookahead: float, step: float) -> np.ndarray:
    """(S,) s: ``0, step, 2·step, …`` with the last one clipped to ``lookahead``."""
    t = np.arange(0.0, lookahead + step, step)
    t[-1] = min(t[-1], lookahead)
    return t


def reachable(
    enc: Encounters, own_velocity, radius: float, lookahead: float, step: float = 10.0
) -> np.ndarray:
    """(n_own, K) bool: could the intruder come within ``radius`` during the look-ahead for
    SOME heading of the ownship (own speed kept, intruder straight)?

    ``|r + v_i t − v_o(ψ) t| ≥ |r + v_i t| − |v_o| t``; the right side is sampled every
    ``step`` seconds and lowered by its Lipschitz bound ``(|v_i| + |v_o|)·step/2``, so the
    test never drops an intruder that could matter (the band search's result is the same
    up to which exact boundary candidates it tries). own_velocity (n_own, 2) m/s, radius m,
    lookahead and step s. Numba kernel :func:`_reachable_kernel`; reference
    :func:`reachable_numpy`.
    """
    vo = np.ascontiguousarray(own_velocity, dtype=float).reshape(-1, 2)
    return _reachable_kernel(
        vo,
        np.ascontiguousarray(enc.rel_position, dtype=float),
        np.ascontiguousarray(enc.rel_velocity, dtype=float),
        np.ascontiguousarray(enc.valid, dtype=bool),
        _sample_times(float(lookahead), float(step)),
        float(radius),
        float(step),
    )


def reachable_numpy(
    enc: Encounters, own_velocity, radius: float, lookahead: float, step: float = 10.0
) -> np.ndarray:
    """:func:`reachable` in numpy over (n_own, K, S) arrays (the reference for the kernel)."""
    vo = np.asarray(own_velocity, dtype=float)[:, None, :]
    vi = enc.rel_velocity + vo
    so = np.hypot(vo[..., 0], vo[..., 1])  # (n, 1)
    t = _sample_times(float(lookahead), float(step))
    px = enc.rel_position[..., 0:1] + vi[..., 0:1] * t
    py = enc.rel_position[..., 1:2] + vi[..., 1:2] * t
    f = np.hypot(px, py) - so[..., None] * t
    slack = (np.hypot(vi[..., 0], vi[..., 1]) + so) * step / 2.0
    return (f.min(axis=-1) - slack < radius) & enc.valid


#: relative error bound, generous, of ``sqrt(x² + y²)`` against ``hypot`` as :func:`_reachable_slot`
#: uses it (both are within a few ulp, ~1e-15, of the exact value)
_SQRT_MARGIN = 1e-12


@njit(cache=True, error_model="numpy")
def _reachable_exact(rpx, rpy, vix, viy, so, t, slack):  # pragma: no cover - compiled
    """``min_j(|r + v_i t_j| − |v_o| t_j) − slack`` with numpy's operations (hypot; a NaN
    sample makes the minimum NaN)."""
    m = np.inf
    for j in range(t.size):
        f = np.hypot(rpx + vix * t[j], rpy + viy * t[j]) - so * t[j]
        if f < m:
            m = f
        elif np.isnan(f):
            return np.nan
    return m - slack


@njit(cache=True, error_model="numpy")
def _reachable_slot(rpx, rpy, vix, viy, so, t, radius, step):  # pragma: no cover - compiled
    """One slot of :func:`reachable`: relative position (m), intruder world velocity (m/s),
    own speed ``so`` m/s, sample times ``t`` (S,) s; the same decision as the numpy version.

    Rounding is monotone, so ``fl(min_j f_j − slack) < radius`` holds exactly when some
    ``fl(f_j − slack) < radius``: whether any sample passes, in any order. ``f_j`` and the
    slack are first taken with ``sqrt(x² + y²)`` (far cheaper than libm's hypot); only a
    sample within a margin far above their difference (:data:`_SQRT_MARGIN` of the
    magnitudes involved) is recomputed with hypot. The first pass over the samples only
    counts those below the margin band and those within or below it, without a branch
    per sample (an early exit mispredicts on half the slots): one below decides, none
    within decides the other way, and only a slot with a sample in the band takes the
    second, exact pass. Inputs that are not finite or so large that squares could
    overflow take :func:`_reachable_exact` (NaN semantics).
    """
    T = t[t.size - 1]
    vs = abs(vix) + abs(viy) + so
    scale = abs(rpx) + abs(rpy) + vs * (T + step) + abs(radius)
    if not scale < 1e150:
        slack = (np.hypot(vix, viy) + so) * step / 2.0
        return _reachable_exact(rpx, rpy, vix, viy, so, t, slack) < radius
    margin = _SQRT_MARGIN * scale
    slack = (np.sqrt(vix * vix + viy * viy) + so) * step / 2.0
    lo = radius - margin
    hi = radius + margin
    below = 0
    near = 0
    for j in range(t.size):
        px = rpx + vix * t[j]
        py = rpy + viy * t[j]
        g = (np.sqrt(px * px + py * py) - so * t[j]) - slack
        below += g < lo
        near += g <= hi
    if below:
        return True
    if near == 0:
        return False
    exact = (np.hypot(vix, viy) + so) * step / 2.0
    for j in range(t.size):
        px = rpx + vix * t[j]
        py = rpy + viy * t[j]
        g = (np.sqrt(px * px + py * py) - so * t[j]) - slack
        if g <= hi and (np.hypot(px, py) - so * t[j]) - exact < radius:
            return True
    return False


@njit(cache=True, error_model="numpy")
def _reachable_row(vox, voy, rp, rv, valid, t, radius, step, fs, js, out):
    """:func:`_reachable_slot` for the slots of one ownship (own velocity ``vox``, ``voy``
    m/s; rp, rv (K, 2) m, m/s; valid (K,)): ``out`` (K,) bool ← True where reachable (left
    as it is elsewhere); returns the number reachable. Scratch ``fs`` (7, K) float64,
    ``js`` (4, K) int64.

    The same decisions as slot by slot: the valid slots are packed into the scratch and
    the first pass runs sample by sample across them (an inner loop over the slots
    without a branch, which the compiler puts on vector registers: the same operations
    per element); a slot with a sample in the margin band, or inputs outside the sqrt
    path, is decided by :func:`_reachable_slot` itself."""
    so = np.hypot(vox, voy)
    T = t[t.size - 1]
    VX, VY, PX, PY, SL, LO, HI = fs[0], fs[1], fs[2], fs[3], fs[4], fs[5], fs[6]
    IDX, below, near, exact = js[0], js[1], js[2], js[3]
    m = 0
    for k in range(valid.size):
        if not valid[k]:
            continue
        rpx, rpy = rp[k, 0], rp[k, 1]
        vix = rv[k, 0] + vox
        viy = rv[k, 1] + voy
        # _reachable_slot's scale, margin and slack
        vs = abs(vix) + abs(viy) + so
        scale = abs(rpx) + abs(rpy) + vs * (T + step) + abs(radius)
        margin = _SQRT_MARGIN * scale
        VX[m], VY[m], PX[m], PY[m] = vix, viy, rpx, rpy
        SL[m] = (np.sqrt(vix * vix + viy * viy) + so) * step / 2.0
        LO[m] = radius - margin
        HI[m] = radius + margin
        IDX[m] = k
        exact[m] = not scale < 1e150
        below[m] = 0
        near[m] = 0
        m += 1
    for j in range(t.size):
        tj = t[j]
        st = so * tj
        for i in range(m):
            px = PX[i] + VX[i] * tj
            py = PY[i] + VY[i] * tj
            g = (np.sqrt(px * px + py * py) - st) - SL[i]
            below[i] += g < LO[i]
            near[i] += g <= HI[i]
    count = 0
    for i in range(m):
        if exact[i] or (near[i] > 0 and below[i] == 0):
            hit = _reachable_slot(PX[i], PY[i], VX[i], VY[i], so, t, radius, step)
        else:
            hit = below[i] > 0
        if hit:
            out[IDX[i]] = True
            count += 1
    return count


@njit(cache=True, error_model="numpy")
def _reachable_kernel(vo, rp, rv, valid, t, radius, step):  # pragma: no cover - compiled
    """(n_own, K) bool of :func:`reachable`; vo (n_own, 2) m/s, rp, rv (n_own, K, 2) m, m/s,
    valid (n_own, K), t (S,) s."""
    n_own, K = valid.shape
    out = np.zeros((n_own, K), dtype=np.bool_)
    fs = np.empty((7, K))
    js = np.empty((4, K), dtype=np.int64)
    for o in range(n_own):
        _reachable_row(vo[o, 0], vo[o, 1], rp[o], rv[o], valid[o], t, radius, step, fs, js, out[o])
    return out


def screen(
    enc: Encounters,
    own_velocity,
    radius: float,
    lookahead: float,
    threshold: float,
    step: float = 10.0,
) -> Encounters:
    """The resolver's prefilter in one pass: the ownships whose current heading fails the
    CPA test (minimum CPA ratio at ψ = 0 not ``≥ threshold``, as :func:`cpa_min_ratio`),
    and on them only the :func:`reachable` slots, packed to the left (K shrunk to the
    largest count). own_velocity (n_own, 2) m/s; radius m; lookahead, step s. Same arrays
    as :func:`screen_numpy` (CPA kernel, :meth:`Encounters.subset`, :meth:`~Encounters.compact`).
    """
    vo = np.ascontiguousarray(own_velocity, dtype=float).reshape(-1, 2)
    keep_rows, rows, rp, rv, valid = _screen_kernel(
        vo,
        np.ascontiguousarray(enc.rows, dtype=np.int64),
        np.ascontiguousarray(enc.rel_position, dtype=float),
        np.ascontiguousarray(enc.rel_velocity, dtype=float),
        np.ascontiguousarray(enc.valid, dtype=bool),
        _sample_times(float(lookahead), float(step)),
        float(radius),
        float(lookahead),
        float(threshold),
        clear_ratio2(float(threshold)),
        float(step),
    )
    return Encounters(enc.owners[keep_rows], rows, rp, rv, valid)


def screen_numpy(
    enc: Encounters,
    own_velocity,
    radius: float,
    lookahead: float,
    threshold: float,
    step: float = 10.0,
) -> Encounters:
    """:func:`screen` as separate steps (the reference for :func:`_screen_kernel`)."""
    ratio0 = cpa_min_ratio(
        own_velocity,
        enc.rel_position,
        enc.rel_velocity,
        enc.valid,
        np.zeros((enc.owners.size, 1)),
        radius,
        lookahead,
    )[:, 0]
    rows = ~(ratio0 >= threshold)
    enc = enc.subset(rows)
    vo = np.asarray(own_velocity, dtype=float)[rows]
    return enc.compact(reachable_numpy(enc, vo, radius, lookahead, step))


@njit(cache=True, error_model="numpy")
def _screen_kernel(
    vo, rows, rp, rv, valid, t, radius, lookahead, threshold, threshold2, step
):  # pragma: no cover - compiled
    """Arrays of :func:`screen`: ``(keep_rows (n_own,) bool, rows (n, K'), rel_position,
    rel_velocity (n, K', 2), valid (n, K'))`` for the n kept rows. The CPA ratio at ψ = 0
    is :func:`~airspace_sim.avoidance.cpa._pair_ratio2`'s arithmetic with cos 0 = 1, sin 0 = 0,
    written out here rather than called: numba's on-disk cache of this kernel would not
    notice an edit of a helper in another module (tests/test_control.py checks the bits).
    ``threshold2`` is :func:`~airspace_sim.avoidance.cpa.clear_ratio2` of ``threshold``:
    a pair with a squared ratio below it decides that the row is kept (the minimum can
    only fall further, ``sqrt`` is monotone, and a NaN minimum keeps the row too), so
    the row's other pairs are not evaluated.
    """
    n_own, K = valid.shape
    keep_rows = np.zeros(n_own, dtype=np.bool_)
    reach = np.zeros((n_own, K), dtype=np.bool_)
    counts = np.zeros(n_own, dtype=np.int64)
    fs = np.empty((7, K))
    js = np.empty((4, K), dtype=np.int64)
    inv_r2 = 1.0 / (radius * radius)
    cs, sn = np.cos(0.0), np.sin(0.0)
    n_keep = 0
    k_max = 0
    for o in range(n_own):
        rvx = cs * vo[o, 0] - sn * vo[o, 1]
        rvy = sn * vo[o, 0] + cs * vo[o, 1]
        best = np.inf
        for k in range(K):
            if not valid[o, k]:
                continue
            rx, ry = rp[o, k, 0], rp[o, k, 1]
            vx = (rv[o, k, 0] + vo[o, 0]) - rvx
            vy = (rv[o, k, 1] + vo[o, 1]) - rvy
            dot = vx * rx + vy * ry
            v2 = vx * vx + vy * vy
            tc = -dot / max(v2, 1e-300)
            tc = min(max(tc, 0.0), lookahead)
            d2 = (tc * v2 + 2.0 * dot) * tc + (rx * rx + ry * ry)
            q2 = max(d2, 0.0) * inv_r2
            best = min(best, q2)
            if q2 < threshold2:
                break
        if np.sqrt(best) >= threshold:
            continue
        keep_rows[o] = True
        n_keep += 1
        counts[o] = _reachable_row(
            vo[o, 0], vo[o, 1], rp[o], rv[o], valid[o], t, radius, step, fs, js, reach[o]
        )
        k_max = max(k_max, counts[o])
    out_rows = np.full((n_keep, k_max), -1, dtype=np.int64)
    out_rp = np.zeros((n_keep, k_max, 2))
    out_rv = np.zeros((n_keep, k_max, 2))
    out_valid = np.zeros((n_keep, k_max), dtype=np.bool_)
    i = 0
    for o in range(n_own):
        if not keep_rows[o]:
            continue
        s = 0
        for k in range(K):
            if reach[o, k]:
                out_rows[i, s] = rows[o, k]
                out_rp[i, s, 0] = rp[o, k, 0]
                out_rp[i, s, 1] = rp[o, k, 1]
                out_rv[i, s, 0] = rv[o, k, 0]
                out_rv[i, s, 1] = rv[o, k, 1]
                out_valid[i, s] = True
                s += 1
        i += 1
    return keep_rows, out_rows, out_rp, out_rv, out_valid


def gather(track_owner, track_x, positions, velocities, runs, keep=None) -> Encounters:
    """Padded per-ownship arrays of the tracks whose owner has ``runs[owner]`` True.

    track_owner (P,) int, track_x (P, 5) track states (world frame); positions, velocities
    (N, 2) true own states, m, m/s; runs (N,) bool; keep (P,) bool, optional: only these
    tracks. ``rows`` of the result index the P tracks given; owners ascending, and within
    an ownship its tracks in the order given. A counting sort by owner in numba
    (:func:`_gather_kernel`, O(P + N)); reference :func:`gather_numpy`.
    """
    track_owner = np.ascontiguousarray(track_owner, dtype=np.int64)
    if keep is None:
        keep = np.ones(track_owner.size, dtype=bool)
    owners, rows, rp, rv, valid = _gather_kernel(
        track_owner,
        np.asarray(track_x, dtype=float),
        np.asarray(positions, dtype=float),
        np.asarray(velocities, dtype=float),
        np.ascontiguousarray(runs, dtype=bool),
        np.ascontiguousarray(keep, dtype=bool),
    )
    return Encounters(owners, rows, rp, rv, valid)


@njit(cache=True)
def _gather_kernel(track_owner, track_x, positions, velocities, runs, keep):  # pragma: no cover
    """Arrays of :func:`gather`: ``(owners (n_own,), rows (n_own, K), rel_position,
    rel_velocity (n_own, K, 2) m, m/s, valid (n_own, K))``. Two passes over the P tracks:
    count per owner, then place each used track in its owner's next slot (stable)."""
    n = runs.size
    counts = np.zeros(n, dtype=np.int64)
    for p in range(track_owner.size):
        o = track_owner[p]
        if runs[o] and keep[p]:
            counts[o] += 1
    local = np.full(n, -1, dtype=np.int64)
    n_own = 0
    K = 0
    for o in range(n):
        if counts[o] > 0:
            local[o] = n_own
            n_own += 1
            K = max(K, counts[o])
    owners = np.empty(n_own, dtype=np.int64)
    for o in range(n):
        if local[o] >= 0:
            owners[local[o]] = o
    rows = np.full((n_own, K), -1, dtype=np.int64)
    rp = np.zeros((n_own, K, 2))
    rv = np.zeros((n_own, K, 2))
    valid = np.zeros((n_own, K), dtype=np.bool_)
    fill = np.zeros(n_own, dtype=np.int64)
    for p in range(track_owner.size):
        o = track_owner[p]
        if runs[o] and keep[p]:
            i = local[o]
            s = fill[i]
            fill[i] = s + 1
            rows[i, s] = p
            rp[i, s, 0] = track_x[p, 0] - positions[o, 0]
            rp[i, s, 1] = track_x[p, 2] - positions[o, 1]
            rv[i, s, 0] = track_x[p, 1] - velocities[o, 0]
            rv[i, s, 1] = track_x[p, 3] - velocities[o, 1]
            valid[i, s] = True
    return owners, rows, rp, rv, valid


def gather_numpy(track_owner, track_x, positions, velocities, runs, keep=None) -> Encounters:
    """:func:`gather` with numpy's stable argsort (the reference for the kernel)."""
    use = runs[track_owner] if track_owner.size else np.zeros(0, dtype=bool)
    if keep is not None:
        use = use & keep
    sel = np.flatnonzero(use)
    if sel.size == 0:
        return Encounters.empty()
    own = track_owner[sel]
    order = np.argsort(own, kind="stable")
    sel, own = sel[order], own[order]
    owners, start, counts = np.unique(own, return_index=True, return_counts=True)
    K = int(counts.max())
    local = np.repeat(np.arange(owners.size), counts)
    slot = np.arange(sel.size) - np.repeat(start, counts)
    rows = np.full((owners.size, K), -1, dtype=np.int64)
    rows[local, slot] = sel
    x = track_x[sel]
    rp = np.zeros((owners.size, K, 2))
    rv = np.zeros((owners.size, K, 2))
    rp[local, slot] = x[:, (0, 2)] - positions[own]
    rv[local, slot] = x[:, (1, 3)] - velocities[own]
    return Encounters(owners, rows, rp, rv, rows >= 0)
