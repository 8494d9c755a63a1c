"""Closest point of approach (CPA) over a look-ahead, for many ownships, candidates and intruders.

For ownship ``n`` turning its velocity by a candidate heading change ``ψ`` (own speed kept)
and intruder ``k`` flying straight, with ``r`` the relative position and
``v_rel(ψ) = v_i − R(ψ)·v_o``:

    t_cpa = clamp(−r·v_rel / |v_rel|², 0, T),   d = |r + t_cpa·v_rel|

and the *ratio* ``d / radius``. :func:`cpa_min_ratio` gives the minimum ratio over intruders
for every (ownship, candidate); the search kernels below answer the questions a band search
asks (the first clear candidate of each side, the best candidate of a blocked side) with the
same arithmetic but far fewer evaluations, and :func:`band_rows` runs them row by row right
after sorting the row's candidates by preference (:func:`_sort_row`, the kernel of
:func:`~airspace_sim.avoidance.bands.preferred_candidates`): the whole fast path of
:func:`~airspace_sim.avoidance.bands.band_search` but the boundary roots, in one pass and in
one module (numba's on-disk cache of a kernel does not see edits of helpers in other
modules). A candidate flown at a turn rate is judged in
:mod:`~airspace_sim.avoidance.cpa_turning`. Distances m, velocities m/s, times s, angles rad
CCW positive.
"""

from __future__ import annotations

import numpy as np
from numba import njit


def kernel_array(value, shape) -> np.ndarray:
    """``value`` (a float or an array) broadcast to ``shape`` as a C-contiguous, writable
    float64 array, the one array type the cached kernels are compiled for: numba types a
    read-only array (a broadcast view, a track view's column) apart, and a second
    specialisation would be compiled or loaded the first time a caller passed one."""
    return np.require(
        np.broadcast_to(np.asarray(value, dtype=float), shape), requirements=("C", "W")
    )


def cpa_min_ratio(own_velocity, rel_position, rel_velocity, valid, candidates, radius, lookahead_s):
    """Minimum over intruders of (CPA distance over ``[0, T]``) / radius, per candidate.

    A fused numba kernel (:func:`_cpa_kernel`) evaluates the ``(N, C, K)`` arithmetic without
    temporaries; :func:`cpa_min_ratio_numpy` is the same formula in numpy (the reference).

    Parameters
    ----------
    own_velocity : (N, 2) m/s; rel_position : (N, K, 2) m; rel_velocity : (N, K, 2) m/s
        (intruder minus ownship, world frame, at the current heading).
    valid : (N, K) bool, intruder slot in use.
    candidates : (N, C) heading changes, rad (NaN allowed: gives NaN rows).
    radius : float or (N, K) array, m (the clear distance ``r_safe·(1+margin)``).
    lookahead_s : float, T in seconds.

    Returns
    -------
    (N, C) array; ``inf`` where the ownship has no valid intruder.
    """
    vo = np.ascontiguousarray(own_velocity, dtype=float)
    valid = np.ascontiguousarray(valid, dtype=bool)
    r = np.ascontiguousarray(rel_position, dtype=float)
    v = np.ascontiguousarray(rel_velocity, dtype=float)
    psi = np.ascontiguousarray(candidates, dtype=float)
    radius = kernel_array(radius, valid.shape)
    return _cpa_kernel(vo, r, v, valid, psi, radius, float(lookahead_s))


def cpa_pair_ratios(
    own_velocity, rel_position, rel_velocity, valid, candidates, radius, lookahead_s
):
    """:func:`cpa_min_ratio` of each (ownship, intruder) pair on its own, ``(N, K, C)``:
    the ratio to intruder ``k`` alone (``inf`` for an invalid slot), each pair a row of
    the kernel. Arguments as there; ``radius`` a float or an array that broadcasts to
    ``(N, K)``, m."""
    valid = np.asarray(valid, dtype=bool)
    n, k = valid.shape
    rad = kernel_array(radius, (n, k)).reshape(n * k, 1)
    return cpa_min_ratio(
        np.repeat(own_velocity, k, axis=0),
        np.reshape(rel_position, (n * k, 1, 2)),
        np.reshape(rel_velocity, (n * k, 1, 2)),
        valid.reshape(n * k, 1),
        np.repeat(candidates, k, axis=0),
        rad,
        lookahead_s,
    ).reshape(n, k, np.shape(candidates)[-1])


def cpa_min_ratio_numpy(
    own_velocity, rel_position, rel_velocity, valid, candidates, radius, lookahead_s
):
    """:func:`cpa_min_ratio` in plain numpy, arrays ``(N, C, K)`` (reference for the kernel)."""
    vo = np.asarray(own_velocity, dtype=float)
    valid = np.asarray(valid, dtype=bool)
    r = np.where(valid[..., None], np.asarray(rel_position, dtype=float), 0.0)
    vrel0 = np.where(valid[..., None], np.asarray(rel_velocity, dtype=float), 0.0)
    psi = np.asarray(candidates, dtype=float)
    if valid.shape[-1] == 0:
        return np.full(psi.shape, np.inf)
    radius = np.broadcast_to(np.asarray(radius, dtype=float), valid.shape)
    with np.errstate(divide="ignore"):
        inv_r2 = (1.0 / (radius * radius))[:, None, :]  # (N, 1, K)
    vi = vrel0 + vo[:, None, :]  # (N, K, 2) intruder world velocity
    c, s = np.cos(psi), np.sin(psi)  # (N, C)
    rvx = (c * vo[:, 0:1] - s * vo[:, 1:2])[:, :, None]  # (N, C, 1)
    rvy = (s * vo[:, 0:1] + c * vo[:, 1:2])[:, :, None]
    rx, ry = r[:, None, :, 0], r[:, None, :, 1]  # (N, 1, K)
    r2 = rx * rx + ry * ry
    # (N, C, K) arrays, updated in place: relative velocity, r·v, |v|², t_cpa, d²
    vx = vi[:, None, :, 0] - rvx
    vy = vi[:, None, :, 1] - rvy
    dot = vx * rx
    dot += vy * ry
    vx *= vx
    vy *= vy
    v2 = vx
    v2 += vy
    t = np.negative(dot)
    t /= np.maximum(v2, 1e-300)  # v = 0 has r·v = 0: t = 0
    np.clip(t, 0.0, lookahead_s, out=t)
    # d² = |r + t v|² = r² + t (2 r·v + t |v|²)
    v2 *= t
    dot *= 2.0
    v2 += dot
    v2 *= t
    v2 += r2
    np.maximum(v2, 0.0, out=v2)
    v2 *= inv_r2
    np.copyto(v2, np.inf, where=~valid[:, None, :])
    return np.sqrt(v2.min(axis=-1))


@njit(inline="always", error_model="numpy")
def _cpa_d2(rx, ry, wx, wy, rvx, rvy, lookahead_s):  # pragma: no cover - compiled
    """(CPA distance over [0, T])², m², of an intruder at ``(rx, ry)`` m (relative)
    flying ``(wx, wy)`` m/s (world frame) against an own velocity turned to
    ``(rvx, rvy)`` m/s: the one formula every kernel here uses, so that they all give
    the same bits as :func:`cpa_min_ratio_numpy`. Scalar arguments only: an inline
    helper that takes arrays reference-counts them on every call (atomic operations in
    the scans' innermost loops)."""
    vx = wx - rvx
    vy = wy - rvy
    dot = vx * rx + vy * ry
    v2 = vx * vx + vy * vy
    t = -dot / max(v2, 1e-300)
    t = min(max(t, 0.0), lookahead_s)
    d2 = (t * v2 + 2.0 * dot) * t + (rx * rx + ry * ry)
    return max(d2, 0.0)


@njit(inline="always", error_model="numpy")
def _cpa_ratio2(rx, ry, wx, wy, rvx, rvy, lookahead_s, radius):  # pragma: no cover
    """(CPA distance over [0, T] / radius)²: :func:`_cpa_d2` over ``radius²`` m²."""
    return _cpa_d2(rx, ry, wx, wy, rvx, rvy, lookahead_s) * (1.0 / (radius * radius))


@njit(cache=True, error_model="numpy")
def _cpa_kernel(vo, r, v, valid, psi, radius, lookahead_s):  # pragma: no cover - compiled
    """Fused loop over ``(n, c, k)`` of :func:`cpa_min_ratio_numpy`'s formula, same operations."""
    n_own, n_cand = psi.shape
    n_int = valid.shape[1]
    out = np.full((n_own, n_cand), np.inf)
    for n in range(n_own):
        for c in range(n_cand):
            if np.isnan(psi[n, c]) and n_int > 0:
                out[n, c] = np.nan
                continue
            cs, sn = np.cos(psi[n, c]), np.sin(psi[n, c])
            rvx = cs * vo[n, 0] - sn * vo[n, 1]
            rvy = sn * vo[n, 0] + cs * vo[n, 1]
            best = np.inf
            for k in range(n_int):
                if not valid[n, k]:
                    continue
                wx, wy = v[n, k, 0] + vo[n, 0], v[n, k, 1] + vo[n, 1]
                q2 = _cpa_ratio2(
                    r[n, k, 0], r[n, k, 1], wx, wy, rvx, rvy, lookahead_s, radius[n, k]
                )
                best = min(best, q2)
            out[n, c] = np.sqrt(best)
    return out


@njit(cache=True, error_model="numpy")
def _grid_trig(grid):  # pragma: no cover - compiled
    """(cos, sin) (G,) of the candidate grid (G,) rad, as the kernels compute them."""
    cs = np.empty(grid.size)
    sn = np.empty(grid.size)
    for g in range(grid.size):
        cs[g], sn[g] = np.cos(grid[g]), np.sin(grid[g])
    return cs, sn


def clear_ratio2(threshold: float) -> float:
    """The smallest ``x`` with ``np.sqrt(x) >= threshold``: the search kernels test a
    squared ratio ``q2`` as ``q2 >= clear_ratio2(t)``, which is ``np.sqrt(q2) >= t`` for
    every ``q2`` (NaN included) since the rounded square root is monotone, without a
    square root per pair (:func:`_sqrt_threshold`)."""
    return float(_sqrt_threshold(float(threshold)))


@njit(cache=True, error_model="numpy")
def _sqrt_threshold(t):  # pragma: no cover - compiled
    """:func:`clear_ratio2` in numba: ``t²`` moved by ulps to the edge of ``sqrt(x) >= t``."""
    if not t > 0.0:
        return -np.inf if t <= 0.0 else np.nan  # every x ≥ 0 passes; NaN: none does
    if t == np.inf:
        return np.inf
    y = t * t
    while y > 0.0 and np.sqrt(np.nextafter(y, 0.0)) >= t:
        y = np.nextafter(y, 0.0)
    while not np.sqrt(y) >= t:
        y = np.nextafter(y, np.inf)
    return y


@njit(inline="always", error_model="numpy")
def _pack_row(vo, r, v, valid, radius, n, px, py, wx, wy, inv_r2):  # pragma: no cover
    """Row ``n``'s valid intruders packed in slot order into the (K,) scratch arrays: the
    relative position ``px``, ``py`` (m), the intruder's world velocity ``wx``, ``wy``
    (m/s, ``v + vo``, the addition :func:`_cpa_kernel` makes per pair) and ``inv_r2 = 1 /
    radius²`` (the factor :func:`_cpa_ratio2` takes per pair), once per row: the same
    bits, and the scans' inner loops run over a few contiguous values without a test of
    ``valid`` (about half the slots of a padded row). Returns their number."""
    vox, voy = vo[n, 0], vo[n, 1]
    m = 0
    for k in range(valid.shape[1]):
        if valid[n, k]:
            px[m], py[m] = r[n, k, 0], r[n, k, 1]
            wx[m], wy[m] = v[n, k, 0] + vox, v[n, k, 1] + voy
            inv_r2[m] = 1.0 / (radius[n, k] * radius[n, k])
            m += 1
    return m


@njit(cache=True, error_model="numpy")
def _first_clear_row(
    vox,
    voy,
    px,
    py,
    wx,
    wy,
    inv_r2,
    n_valid,
    clear2,
    lookahead_s,
    psi,
    usable,
    origin,
    n_scan,
    cos_grid,
    sin_grid,
    blockers,
    out,
):  # pragma: no cover - compiled
    """A row's first clear candidate of each side into ``out`` (3,) (the columns of
    ``first_clear``; −1: none). Own velocity ``vox``, ``voy`` m/s; the row's ``n_valid``
    intruders packed by :func:`_pack_row` (``px`` … ``inv_r2``).

    ``psi``, ``usable``, ``origin`` (C,): the row's candidates sorted by preference, usable
    (not NaN) and their grid index or −1 (the cos and sin of grid values come from the
    tables ``cos_grid``, ``sin_grid``, not libm per row); the first ``n_scan`` are
    scanned. Each candidate is tested with the arithmetic of :func:`_cpa_kernel`,
    intruder by intruder, stopping at the first one whose squared ratio is below
    ``clear2`` (:func:`clear_ratio2` of the threshold: no square root per pair;
    ``inv_r2`` from :func:`_pack_row`); the scan stops once every side has a clear
    candidate, so the work is about the blocked candidates before the first clear ones,
    not C·K. The last intruder that blocked a candidate on the same side (ψ ≤ 0 or ψ > 0,
    ``blockers`` (2,) scratch) is tried first: neighbouring candidates on a side are
    usually blocked by the same one, and the preference order alternates between the
    sides (one blocker for both sides costs far more pair evaluations; figures in
    ``docs/performance.md``, "Band search"). An intruder already closer than the threshold
    blocks every heading (for ``t > 0`` the computed ``t·|v|² + 2 r·v`` rounds negative,
    so the computed CPA distance never exceeds the current one, in floating point too):
    such a row has no clear candidate and is not scanned.
    """
    out[0] = out[1] = out[2] = -1
    for k in range(n_valid):
        rx, ry = px[k], py[k]
        # the current (distance / radius)², _cpa_d2 at t = 0
        if not (max(rx * rx + ry * ry, 0.0) * inv_r2[k] >= clear2):
            return
    blockers[0] = blockers[1] = -1
    for c in range(n_scan):
        if not usable[c]:
            continue
        p = psi[c]
        want = (p <= 0.0 and out[0] < 0) or (p >= 0.0 and out[1] < 0) or (p < 0.0 and out[2] < 0)
        if not want:
            if out[0] >= 0 and out[1] >= 0 and out[2] >= 0:
                break
            continue
        g = origin[c]
        if g >= 0:
            cs, sn = cos_grid[g], sin_grid[g]
        else:
            cs, sn = np.cos(p), np.sin(p)
        rvx, rvy = cs * vox - sn * voy, sn * vox + cs * voy
        clear = True
        sd = 0 if p <= 0.0 else 1
        blocker = blockers[sd]
        for j in range(-1, n_valid):
            k = blocker if j < 0 else j
            if k < 0 or (j >= 0 and k == blocker):
                continue
            if not (
                _cpa_d2(px[k], py[k], wx[k], wy[k], rvx, rvy, lookahead_s) * inv_r2[k] >= clear2
            ):
                clear = False
                blockers[sd] = k
                break
        if clear:
            if p <= 0.0 and out[0] < 0:
                out[0] = c
            if p >= 0.0 and out[1] < 0:
                out[1] = c
            if p < 0.0 and out[2] < 0:
                out[2] = c


@njit(cache=True, error_model="numpy")
def _best_blocked_row(
    vox,
    voy,
    px,
    py,
    wx,
    wy,
    inv_r2,
    n_valid,
    lookahead_s,
    psi,
    usable,
    origin,
    n_scan,
    side,
    cos_grid,
    sin_grid,
):  # pragma: no cover - compiled
    """Index of a row's candidate on ``side`` (0: ψ ≤ 0, 1: ψ ≥ 0) of largest minimum
    CPA ratio (the first in order among equals), −1 if the side has none; candidates as
    in :func:`_first_clear_row`. A max-min search that stops evaluating a candidate once
    its running minimum cannot beat the best so far.

    Each candidate first tries the intruder that ended (or minimised) the previous
    candidate's evaluation: neighbouring candidates are mostly stopped by the same one
    (on dense traffic this halves the pair evaluations against trying the best
    candidate's minimiser). The minimum is kept squared and its square root taken only
    when it falls (``sqrt`` is monotone: the same minimum bits). No candidate's minimum
    exceeds the smallest current distance ratio (see :func:`_first_clear_row`): the scan
    stops once the best reaches it. Same arithmetic as :func:`_cpa_kernel`, so the same
    choice as the full evaluation.
    """
    res = -1
    best = -np.inf
    guess = -1
    top2 = np.inf  # the smallest current (distance / radius)²
    for k in range(n_valid):
        rx, ry = px[k], py[k]
        top2 = min(top2, max(rx * rx + ry * ry, 0.0) * inv_r2[k])
    top = np.sqrt(top2)
    for c in range(n_scan):
        if best >= top:
            break
        if not usable[c]:
            continue
        p = psi[c]
        if (side == 0 and p > 0.0) or (side == 1 and p < 0.0):
            continue
        g = origin[c]
        if g >= 0:
            cs, sn = cos_grid[g], sin_grid[g]
        else:
            cs, sn = np.cos(p), np.sin(p)
        rvx, rvy = cs * vox - sn * voy, sn * vox + cs * voy
        m2 = np.inf
        m = np.inf
        arg = -1
        for j in range(-1, n_valid):
            k = guess if j < 0 else j
            if k < 0 or (j >= 0 and k == guess):
                continue
            q2 = _cpa_d2(px[k], py[k], wx[k], wy[k], rvx, rvy, lookahead_s) * inv_r2[k]
            if q2 < m2:
                m2 = q2
                m = np.sqrt(q2)
                arg = k
                if m <= best:
                    break
        if m > best:
            best = m
            res = c
        guess = arg
    return res


@njit(cache=True, error_model="numpy")
def _grid_order(grid, left_penalty):  # pragma: no cover - compiled
    """The whole grid (G,) (increasing) in preference order, as four (G,) arrays: value,
    key ``mag = |ψ| (+ left_penalty)``, ``ψ > 0``, grid index. Its right turns by
    decreasing index merged with its left turns by increasing index."""
    n_grid = grid.size
    split = 0  # grid[:split] ≤ 0 (right turns or ahead), grid[split:] > 0
    while split < n_grid and not grid[split] > 0.0:
        split += 1
    rv, rm, rl, ri = (
        np.empty(n_grid),
        np.empty(n_grid),
        np.empty(n_grid, np.bool_),
        np.empty(n_grid, np.int64),
    )
    lv, lm, ll, li = rv.copy(), rm.copy(), rl.copy(), ri.copy()
    ov, om, ol, oi = rv.copy(), rm.copy(), rl.copy(), ri.copy()
    nr = 0
    for j in range(split - 1, -1, -1):
        rv[nr], rm[nr], rl[nr], ri[nr] = grid[j], abs(grid[j]), False, j
        nr += 1
    nl = 0
    for j in range(split, n_grid):
        lv[nl], lm[nl], ll[nl], li[nl] = grid[j], abs(grid[j]) + left_penalty, True, j
        nl += 1
    i = j = o = 0
    while i < nr or j < nl:
        if j >= nl or (i < nr and _key_less(rm[i], rl[i], ri[i], lm[j], ll[j], li[j])):
            ov[o], om[o], ol[o], oi[o] = rv[i], rm[i], rl[i], ri[i]
            i += 1
        else:
            ov[o], om[o], ol[o], oi[o] = lv[j], lm[j], ll[j], li[j]
            j += 1
        o += 1
    return ov, om, ol, oi


@njit(inline="always")
def _key_less(am, al, ai, bm, bl, bi):  # pragma: no cover - compiled
    """The sort key ``(mag, ψ > 0, index)`` of ``a`` below that of ``b``."""
    return am < bm or (am == bm and (al < bl or (al == bl and ai < bi)))


@njit(cache=True, error_model="numpy")
def _grid_inside(lim, all_v, all_m, all_l, all_i, fv, fm, fl, fi, gstart):  # pragma: no cover
    """The grid entries with ``|ψ| ≤ lim``, in the grid's preference order
    (:func:`_grid_order`'s arrays), into ``fv``, ``fm``, ``fl``, ``fi``, and their
    buckets of key (:func:`_bucket`): ``gstart[b]`` (≥ nb + 1 entries) the first entry of
    bucket ``b`` or later. Returns ``(nf, inv_w, nb)``: their number and the buckets'
    scale and count. Rows of one limit share them (the callers keep the last limit's)."""
    nf = 0
    for q in range(all_v.size):
        if abs(all_v[q]) <= lim:
            fv[nf], fm[nf], fl[nf], fi[nf] = all_v[q], all_m[q], all_l[q], all_i[q]
            nf += 1
    # about two grid entries a bucket (±kΔ share a key without left_penalty)
    nb = max(nf // 2, 1)
    top = fm[nf - 1] if nf > 0 else 0.0
    inv_w = nb / top if top > 0.0 else 0.0
    if not inv_w < np.inf:  # an infinite key (left_penalty = inf) or a denormal top
        inv_w = 0.0
    q = 0
    for b in range(nb + 1):
        while q < nf and _bucket(fm[q], inv_w, nb) < b:
            q += 1
        gstart[b] = q
    return nf, inv_w, nb


@njit(inline="always")
def _bucket(m, inv_w, nb):  # pragma: no cover - compiled
    """Bucket ``0 … nb − 1`` of a sort key ``m`` (the ``mag`` of :func:`_key_less`, not
    NaN), for a finite scale ``inv_w`` ≥ 0: a non-decreasing function of ``m`` (the
    rounded product is monotone, and so are the truncation and the clamps), so an entry
    of a lower bucket has the smaller ``mag``."""
    x = m * inv_w
    if x < 1.0:
        return 0
    if x < nb:
        return int(x)
    return nb - 1


@njit(inline="always")
def _row_limit(mx_n):  # pragma: no cover - compiled
    """The limit ``|ψ| ≤`` this of a row's candidates (:func:`candidate_grid`'s test)."""
    return mx_n * (1 + 1e-12) + 1e-15


@njit(cache=True, error_model="numpy")
def _sort_row(
    mx_n,
    extra_row,
    n_used,
    left_penalty,
    fv,
    fm,
    fl,
    fi,
    nf,
    gstart,
    inv_w,
    nb,
    n_grid,
    out,
    origin,
    usable,
    xv,
    xm,
    xl,
    xi,
    xb,
    perm,
    count,
    tail,
    nt,
):  # pragma: no cover - compiled
    """One row of :func:`_preferred_kernel` into ``out`` (C,), with ``origin`` (C,) (grid
    index or −1) and ``usable`` (C,) (not NaN) up to the returned count. ``fv``, ``fm``, ``fl``, ``fi``: the first
    ``nf`` of them the entries of the ``n_grid`` grid inside the row's limit, in
    preference order, and ``gstart`` their ``nb`` buckets of scale ``inv_w``
    (:func:`_grid_inside`); the other arrays are scratch. Only the first ``n_used``
    extras are read, the others taken as NaN (the boundary roots packed by
    :func:`~airspace_sim.avoidance.heading.boundary_roots_in_window`). Returns the number
    of leading entries that hold every usable one.

    The limits and extras inside the limit are sorted by bucket of their key
    (:func:`_bucket`, a counting sort), then by the whole key within a bucket (an
    insertion sort that has nothing to move across buckets); each one's rank among the
    grid's run is the grid entries of lower buckets and those of its own bucket with a
    smaller key, and grid entry ``q`` moves up by the number of ranks ≤ ``q``: two
    straight loops instead of a merge's unpredictable branches (figures in
    ``docs/performance.md``). Every key differs (the index is part of it), so this is the
    one sorted order, the lexsort's.
    """
    n_extra = extra_row.size
    lim = _row_limit(mx_n)
    # the limits and extras of finite mag (inside the limit) to sort; the others into the
    # tail lists in listing order: (inf, right) — NaN ranks as mag = inf, right — (inf,
    # left), then the grid's NaN and NaN mag (a NaN left_penalty). An extra's roots are
    # finite, so its entries of the first list are all NaN: the unread ones go last.
    nx = 0
    nt[:] = 0
    count[: nb + 1] = 0
    for j in range(n_grid, n_grid + 2 + n_used):
        if j == n_grid:
            c = -mx_n
        elif j == n_grid + 1:
            c = mx_n
        else:
            c = extra_row[j - n_grid - 2]
        if not (abs(c) <= lim):
            c = np.nan
        left = c > 0.0
        g = np.inf if np.isnan(c) else abs(c) + (left_penalty if left else 0.0)
        if g < np.inf:
            b = _bucket(g, inv_w, nb)
            xv[nx], xm[nx], xl[nx], xi[nx], xb[nx] = c, g, left, j, b
            count[b + 1] += 1
            nx += 1
        else:
            q = (0 if g == np.inf else 2) + (1 if left else 0)
            tail[q, nt[q]] = c
            nt[q] += 1
    # counting sort by bucket (count[b] becomes the start of bucket b's entries) ...
    for b in range(nb):
        count[b + 1] += count[b]
    for x in range(nx):
        b = xb[x]
        perm[count[b]] = x
        count[b] += 1
    # ... then by the whole key inside each bucket (a lower bucket has the smaller key)
    for i in range(1, nx):
        p = perm[i]
        g, lf, ix = xm[p], xl[p], xi[p]
        k = i - 1
        while k >= 0:
            q = perm[k]
            if _key_less(xm[q], xl[q], xi[q], g, lf, ix):
                break
            perm[k + 1] = q
            k -= 1
        perm[k + 1] = p
    # each entry's place: after the grid's entries of lower buckets and the smaller ones
    # of its own (``rank``, the grid entries before it); grid entry q then has the
    # entries of rank ≤ q before it (``count`` reused for the ranks' histogram)
    count[: nf + 1] = 0
    for i in range(nx):
        p = perm[i]
        b = xb[p]
        g, lf, ix = xm[p], xl[p], xi[p]
        rank = gstart[b]
        end = gstart[b + 1]
        while rank < end and _key_less(fm[rank], fl[rank], fi[rank], g, lf, ix):
            rank += 1
        count[rank] += 1
        out[i + rank], origin[i + rank], usable[i + rank] = xv[p], -1, True
    before = 0
    for q in range(nf):
        before += count[q]
        out[q + before], origin[q + before], usable[q + before] = fv[q], fi[q], True
    o = nf + nx
    n_scan = o
    # the tail: NaN but for an infinite limit's ±inf, so origin and usable are written
    # only up to the last usable entry (the scans read no further)
    for t in range(4):
        if t == 1:
            out[o : o + n_extra - n_used] = np.nan
            o += n_extra - n_used
        elif t == 2:
            out[o : o + n_grid - nf] = np.nan
            o += n_grid - nf
        for e in range(nt[t]):
            c = tail[t, e]
            out[o] = c
            o += 1
            if not np.isnan(c):
                n_scan = o
    for e in range(nf + nx, n_scan):
        origin[e], usable[e] = -1, not np.isnan(out[e])
    return n_scan


@njit(cache=True)
def _sort_scratch(n_cand):  # pragma: no cover - compiled
    """The scratch arrays of :func:`_sort_row` for rows of ``n_cand`` candidates:
    ``usable`` (C,); the entries to sort: value (C,) rad, key (C,), ``ψ > 0`` (C,), index
    (C,), bucket (C,); their permutation (C,); the bucket counts (C + 2,); the four tail
    lists (4, C) and their lengths (4,); the grid's bucket starts (C + 2,)."""
    return (
        np.empty(n_cand, np.bool_),
        np.empty(n_cand),
        np.empty(n_cand),
        np.empty(n_cand, np.bool_),
        np.empty(n_cand, np.int64),
        np.empty(n_cand, np.int64),
        np.empty(n_cand, np.int64),
        np.empty(n_cand + 2, np.int64),
        np.empty((4, n_cand)),
        np.zeros(4, np.int64),
        np.empty(n_cand + 2, np.int64),
    )


@njit(cache=True, error_model="numpy")
def _preferred_kernel(grid, mx, extra, left_penalty):  # pragma: no cover - compiled
    """Rows of ``[grid (G,), −mx[n], mx[n], extra[n] (E,)]`` (NaN outside ``±mx[n]``), sorted.

    The order is the lexsort key ``(mag, ψ > 0, index)``, ``mag = |ψ| (+ left_penalty)``.
    The entries of finite ``mag`` form two runs already sorted by that key — the grid's
    (its order computed once for the whole grid, ``grid`` increasing, :func:`_grid_order`;
    a row keeps the entries inside its limit in that order) and the limits and extras
    sorted by bucket of key and then by the whole key (a few dozen per row), each placed
    among the grid's by its bucket (:func:`_sort_row`). The ``inf``
    and then NaN ``mag`` entries follow in the listing order, which is where the lexsort
    puts them (every NaN here is the same ``np.nan``). Returns the sorted rows (n_own, C).
    """
    n_own, n_extra = extra.shape
    n_cand = grid.size + 2 + n_extra
    out = np.empty((n_own, n_cand))
    origin = np.empty(n_cand, np.int64)  # scratch: _sort_row's grid indices, unused here
    all_v, all_m, all_l, all_i = _grid_order(grid, left_penalty)
    usable, xv, xm, xl, xi, xb, perm, count, tail, nt, gstart = _sort_scratch(n_cand)
    fv, fm, fl, fi = all_v.copy(), all_m.copy(), all_l.copy(), all_i.copy()
    nf, inv_w, nb, last = -1, 0.0, 1, np.nan
    for n in range(n_own):
        lim = _row_limit(mx[n])
        if nf < 0 or not lim == last:
            nf, inv_w, nb = _grid_inside(lim, all_v, all_m, all_l, all_i, fv, fm, fl, fi, gstart)
            last = lim
        _sort_row(
            mx[n],
            extra[n],
            n_extra,
            left_penalty,
            fv,
            fm,
            fl,
            fi,
            nf,
            gstart,
            inv_w,
            nb,
            grid.size,
            out[n],
            origin,
            usable,
            xv,
            xm,
            xl,
            xi,
            xb,
            perm,
            count,
            tail,
            nt,
        )
    return out


@njit(cache=True, error_model="numpy")
def band_rows(
    vo,
    r,
    v,
    valid,
    radius,
    lookahead_s,
    mx,
    extra,
    n_extra,
    grid,
    left_penalty,
    threshold,
    wanted,
):  # pragma: no cover - compiled
    """:func:`~airspace_sim.avoidance.bands.band_search`'s fast path (``full=False``) row
    by row in one pass: the ratio at ψ = 0 (as :func:`_cpa_kernel`), the row's candidates
    sorted (:func:`_sort_row`, as :func:`_preferred_kernel`), its first clear candidates
    (:func:`_first_clear_row`, clear: ratio ≥ ``threshold``) and, on the sides ``wanted``
    (N, 2) that have none, the best blocked one (:func:`_best_blocked_row`). ``vo`` (N, 2)
    m/s, ``r``, ``v`` (N, K, 2) m and m/s, ``valid`` (N, K), ``lookahead_s`` s, ``mx``
    (N,) rad, ``grid`` (G,) rad increasing; other arguments as there (``radius`` (N, K)
    m; ``extra`` (N, E) rad the boundary roots, of which row ``n`` uses the first
    ``n_extra[n]``, the others NaN).

    Returns ``(candidates (N, C), first_clear (N, 3), best_blocked (N, 2), ratio0 (N,))``,
    the arrays of those functions, without the (N, C) origin and usable arrays between
    them and with each row's sorted candidates still in cache when they are searched.
    """
    n_own, n_int = valid.shape
    n_cand = grid.size + 2 + extra.shape[1]
    cand = np.empty((n_own, n_cand))
    first = np.full((n_own, 3), -1, dtype=np.int64)
    best = np.full((n_own, 2), -1, dtype=np.int64)
    ratio0 = np.empty(n_own)
    all_v, all_m, all_l, all_i = _grid_order(grid, left_penalty)
    cos_grid, sin_grid = _grid_trig(grid)
    clear2 = _sqrt_threshold(threshold)
    origin = np.empty(n_cand, np.int64)
    usable, xv, xm, xl, xi, xb, perm, count, tail, nt, gstart = _sort_scratch(n_cand)
    blockers = np.empty(2, dtype=np.int64)
    # the row's intruders packed (_pack_row)
    px, py, wx, wy = np.empty(n_int), np.empty(n_int), np.empty(n_int), np.empty(n_int)
    inv_r2 = np.empty(n_int)
    cs, sn = np.cos(0.0), np.sin(0.0)
    fv, fm, fl, fi = all_v.copy(), all_m.copy(), all_l.copy(), all_i.copy()
    nf, inv_w, nb, last = -1, 0.0, 1, np.nan
    for n in range(n_own):
        vox, voy = vo[n, 0], vo[n, 1]
        n_valid = _pack_row(vo, r, v, valid, radius, n, px, py, wx, wy, inv_r2)
        # _cpa_kernel at ψ = 0, its operations in its order (inv_r2 is _cpa_ratio2's factor)
        rvx = cs * vox - sn * voy
        rvy = sn * vox + cs * voy
        b = np.inf
        for k in range(n_valid):
            q2 = _cpa_d2(px[k], py[k], wx[k], wy[k], rvx, rvy, lookahead_s) * inv_r2[k]
            b = min(b, q2)
        ratio0[n] = np.sqrt(b)
        lim = _row_limit(mx[n])
        if nf < 0 or not lim == last:
            nf, inv_w, nb = _grid_inside(lim, all_v, all_m, all_l, all_i, fv, fm, fl, fi, gstart)
            last = lim
        n_scan = _sort_row(
            mx[n],
            extra[n],
            n_extra[n],
            left_penalty,
            fv,
            fm,
            fl,
            fi,
            nf,
            gstart,
            inv_w,
            nb,
            grid.size,
            cand[n],
            origin,
            usable,
            xv,
            xm,
            xl,
            xi,
            xb,
            perm,
            count,
            tail,
            nt,
        )
        row = cand[n]
        _first_clear_row(
            vox,
            voy,
            px,
            py,
            wx,
            wy,
            inv_r2,
            n_valid,
            clear2,
            lookahead_s,
            row,
            usable,
            origin,
            n_scan,
            cos_grid,
            sin_grid,
            blockers,
            first[n],
        )
        for col in range(2):
            if first[n, col] < 0 and wanted[n, col]:
                best[n, col] = _best_blocked_row(
                    vox,
                    voy,
                    px,
                    py,
                    wx,
                    wy,
                    inv_r2,
                    n_valid,
                    lookahead_s,
                    row,
                    usable,
                    origin,
                    n_scan,
                    col,
                    cos_grid,
                    sin_grid,
                )
    return cand, first, best, ratio0
