"""Closest point of approach (CPA) over a look-ahead, for many ownships, candidates and intruders.

For ownship ``n`` turning its velocity by a candidate heading change ``ψ`` (own speed kept)
and intruder ``k`` flying straight, with ``r`` the relative position and
``v_rel(ψ) = v_i − R(ψ)·v_o``:

    t_cpa = clamp(−r·v_rel / |v_rel|², 0, T),   d = |r + t_cpa·v_rel|

and the *ratio* ``d / radius``. :func:`cpa_min_ratio` gives the minimum ratio over intruders
for every (ownship, candidate); the search kernels below answer the questions a band search
asks (the first clear candidate of each side, the best candidate of a blocked side) with the
same arithmetic but far fewer evaluations. :func:`cpa_min_ratio_turning` judges a candidate
as flown at a turn rate. Distances m, velocities m/s, times s, angles rad CCW positive.
"""

from __future__ import annotations

import numpy as np
from numba import njit


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
    radius = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, dtype=float), valid.shape))
    return _cpa_kernel(vo, r, v, valid, psi, radius, float(lookahead_s))


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
def _pair_ratio2(vo, r, v, radius, n, k, rvx, rvy, lookahead_s):  # pragma: no cover
    """(CPA distance over [0, T] / radius)² of ownship ``n`` (velocity turned to
    ``(rvx, rvy)``) and intruder ``k``: the one formula every kernel here uses, so that
    they all give the same bits as :func:`cpa_min_ratio_numpy`."""
    rx, ry = r[n, k, 0], r[n, k, 1]
    vx = (v[n, k, 0] + vo[n, 0]) - rvx
    vy = (v[n, k, 1] + vo[n, 1]) - rvy
    dot = vx * rx + vy * ry
    v2 = vx * vx + vy * vy
    t = -dot / max(v2, 1e-300)
    t = min(max(t, 0.0), lookahead_s)
    d2 = (t * v2 + 2.0 * dot) * t + (rx * rx + ry * ry)
    return max(d2, 0.0) * (1.0 / (radius[n, k] * radius[n, k]))


@njit(inline="always", error_model="numpy")
def _ratio_now(r, radius, n, k):  # pragma: no cover - compiled
    """(Current distance / radius)² of ownship ``n`` and intruder ``k``, as
    :func:`_pair_ratio2` computes it at ``t = 0``: an upper bound of :func:`_pair_ratio2`
    for every heading, in floating point too. (With ``t > 0``, ``r·v < 0`` and
    ``t ≤ −r·v/|v|²`` (rounded), ``t·|v|² + 2 r·v`` rounds to a negative number, so
    ``d² ≤ r²``; rounding is monotone.)"""
    rx, ry = r[n, k, 0], r[n, k, 1]
    return max(rx * rx + ry * ry, 0.0) * (1.0 / (radius[n, k] * radius[n, k]))


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
                best = min(best, _pair_ratio2(vo, r, v, radius, n, k, rvx, rvy, lookahead_s))
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


@njit(inline="always", error_model="numpy")
def _turned(vo, n, p, g, cos_grid, sin_grid):  # pragma: no cover - compiled
    """Own velocity of ownship ``n`` turned by ``p`` rad; ``g`` ≥ 0: ``p`` is the grid's
    ``g``-th value, whose cos and sin are in the tables (the same bits)."""
    if g >= 0:
        cs, sn = cos_grid[g], sin_grid[g]
    else:
        cs, sn = np.cos(p), np.sin(p)
    return cs * vo[n, 0] - sn * vo[n, 1], sn * vo[n, 0] + cs * vo[n, 1]


@njit(cache=True, error_model="numpy")
def first_clear_search(
    vo, r, v, valid, psi, usable, radius, lookahead_s, origin, grid, threshold
):  # pragma: no cover
    """Per ownship, the first clear candidate of each side (columns of ``first_clear``).

    ``psi`` (N, C) sorted by preference; ``origin`` (N, C) its grid index or −1 (the cos
    and sin of the ``grid`` (G,) values are computed once, not per row). Each candidate is
    tested with the same arithmetic
    as :func:`_cpa_kernel`, intruder by intruder, stopping at the first one closer than
    ``threshold``; the scan of an ownship stops once every side has a clear candidate. So
    the work is about the blocked candidates before the first clear ones, not C·K. The
    last intruder that blocked a candidate on the same side (ψ ≤ 0 or ψ > 0) is tried
    first: neighbouring candidates on a side are usually blocked by the same one, and the
    preference order alternates between the sides (one blocker for both sides took 2.3
    times the pair evaluations on the 1000-aircraft benchmark traffic). An intruder already
    closer than ``threshold`` (:func:`_ratio_now`) blocks every heading: such a row (a
    quarter of them there) has no clear candidate and is not scanned.
    """
    n_own, n_cand = psi.shape
    n_int = valid.shape[1]
    out = np.full((n_own, 3), -1, dtype=np.int64)
    cos_grid, sin_grid = _grid_trig(grid)
    blockers = np.empty(2, dtype=np.int64)  # last blocking intruder of each side
    for n in range(n_own):
        inside = False
        for k in range(n_int):
            if valid[n, k] and not (np.sqrt(_ratio_now(r, radius, n, k)) >= threshold):
                inside = True
                break
        if inside:
            continue
        blockers[0] = blockers[1] = -1
        for c in range(n_cand):
            if not usable[n, c]:
                continue
            p = psi[n, c]
            want = (
                (p <= 0.0 and out[n, 0] < 0)
                or (p >= 0.0 and out[n, 1] < 0)
                or (p < 0.0 and out[n, 2] < 0)
            )
            if not want:
                if out[n, 0] >= 0 and out[n, 1] >= 0 and out[n, 2] >= 0:
                    break
                continue
            rvx, rvy = _turned(vo, n, p, origin[n, c], cos_grid, sin_grid)
            clear = True
            sd = 0 if p <= 0.0 else 1
            blocker = blockers[sd]
            for j in range(-1, n_int):
                k = blocker if j < 0 else j
                if k < 0 or (j >= 0 and k == blocker) or not valid[n, k]:
                    continue
                ratio2 = _pair_ratio2(vo, r, v, radius, n, k, rvx, rvy, lookahead_s)
                if not (np.sqrt(ratio2) >= threshold):
                    clear = False
                    blockers[sd] = k
                    break
            if clear:
                if p <= 0.0 and out[n, 0] < 0:
                    out[n, 0] = c
                if p >= 0.0 and out[n, 1] < 0:
                    out[n, 1] = c
                if p < 0.0 and out[n, 2] < 0:
                    out[n, 2] = c
    return out


@njit(cache=True, error_model="numpy")
def best_blocked_search(
    vo, r, v, valid, psi, usable, radius, lookahead_s, origin, grid, rows, side
):  # pragma: no cover
    """For ownship ``rows[i]``, the candidate on side ``side[i]`` (0: ψ ≤ 0, 1: ψ ≥ 0) of
    largest minimum CPA ratio (the first in order among equals): a max-min search that
    stops evaluating a candidate once its running minimum cannot beat the best so far.

    Each candidate first tries the intruder that ended (or minimised) the previous
    candidate's evaluation: neighbouring candidates are mostly stopped by the same one
    (on dense traffic this halves the pair evaluations against trying the best
    candidate's minimiser). The minimum is kept squared and its square root taken only
    when it falls (``sqrt`` is monotone: the same minimum bits). No candidate's minimum
    exceeds the smallest current distance ratio (:func:`_ratio_now`): the scan stops once
    the best reaches it. ``origin``, ``grid`` as in :func:`first_clear_search`. Same
    arithmetic as :func:`_cpa_kernel`, so the same choice as the full evaluation.
    """
    n_int = valid.shape[1]
    n_cand = psi.shape[1]
    out = np.full(rows.size, -1, dtype=np.int64)
    cos_grid, sin_grid = _grid_trig(grid)
    for i in range(rows.size):
        n = rows[i]
        best = -np.inf
        guess = -1
        top2 = np.inf  # the smallest current (distance / radius)²
        for k in range(n_int):
            if valid[n, k]:
                top2 = min(top2, _ratio_now(r, radius, n, k))
        top = np.sqrt(top2)
        for c in range(n_cand):
            if best >= top:
                break
            if not usable[n, c]:
                continue
            p = psi[n, c]
            if (side[i] == 0 and p > 0.0) or (side[i] == 1 and p < 0.0):
                continue
            rvx, rvy = _turned(vo, n, p, origin[n, c], cos_grid, sin_grid)
            m2 = np.inf
            m = np.inf
            arg = -1
            for j in range(-1, n_int):
                k = guess if j < 0 else j
                if k < 0 or (j >= 0 and k == guess) or not valid[n, k]:
                    continue
                q2 = _pair_ratio2(vo, r, v, radius, n, k, rvx, rvy, lookahead_s)
                if q2 < m2:
                    m2 = q2
                    m = np.sqrt(q2)
                    arg = k
                    if m <= best:
                        break
            if m > best:
                best = m
                out[i] = c
            guess = arg
    return out


#: Largest heading change, rad, flown along one straight chord when the turn is modelled
#: (:func:`cpa_min_ratio_turning`): 15° (the chord's sagitta at 230 m/s and 3°/s is ≈ 40 m).
TURN_SEGMENT = float(np.radians(15.0))


def cpa_min_ratio_turning(
    own_velocity,
    rel_position,
    rel_velocity,
    valid,
    candidates,
    radius,
    lookahead_s,
    turn_rate,
    segment=TURN_SEGMENT,
):
    """:func:`cpa_min_ratio` with the ownship turning at ``turn_rate`` until ``ψ`` is reached.

    The ownship flies an arc of radius ``|v_o|/ω`` from its current heading to ``heading + ψ``
    (taking ``|ψ|/ω`` seconds), then straight; the intruder flies straight. The arc is
    replaced by chords of at most ``segment`` rad whose end points lie on it, so the relative
    track is piecewise straight and the minimum distance over ``[0, T]`` is the minimum of
    each piece's clamped CPA. ``turn_rate`` (N,) rad/s (``inf`` or ≤ 0: instantaneous, the
    same numbers as :func:`cpa_min_ratio`).
    """
    vo = np.ascontiguousarray(own_velocity, dtype=float)
    valid = np.ascontiguousarray(valid, dtype=bool)
    r = np.ascontiguousarray(rel_position, dtype=float)
    v = np.ascontiguousarray(rel_velocity, dtype=float)
    psi = np.ascontiguousarray(candidates, dtype=float)
    radius = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, dtype=float), valid.shape))
    w = np.ascontiguousarray(np.broadcast_to(np.asarray(turn_rate, dtype=float), (vo.shape[0],)))
    return _cpa_turn_kernel(vo, r, v, valid, psi, radius, float(lookahead_s), w, float(segment))


@njit(cache=True, error_model="numpy")
def _seg_min(rx, ry, vx, vy, t0, t1):  # pragma: no cover - compiled
    """min over t in [0, t1 − t0] of |r + t v|² (r at the segment start)."""
    dot = vx * rx + vy * ry
    v2 = vx * vx + vy * vy
    t = -dot / max(v2, 1e-300)
    t = min(max(t, 0.0), t1 - t0)
    return max((t * v2 + 2.0 * dot) * t + (rx * rx + ry * ry), 0.0)


@njit(cache=True, error_model="numpy")
def _cpa_turn_kernel(vo, r, v, valid, psi, radius, lookahead_s, w, segment):  # pragma: no cover
    n_own, n_cand = psi.shape
    n_int = valid.shape[1]
    out = np.full((n_own, n_cand), np.inf)
    pts_t = np.empty(64)
    pts_x = np.empty(64)
    pts_y = np.empty(64)
    for n in range(n_own):
        speed = np.hypot(vo[n, 0], vo[n, 1])
        h0 = np.arctan2(vo[n, 1], vo[n, 0])
        for c in range(n_cand):
            p = psi[n, c]
            if np.isnan(p) and n_int > 0:
                out[n, c] = np.nan
                continue
            # ownship break points (time, displacement) along the arc, then the end velocity
            tau = abs(p) / w[n] if (w[n] > 0.0 and np.isfinite(w[n])) else 0.0
            tau = min(tau, lookahead_s)
            m = 0
            if tau > 0.0:
                m = min(int(np.ceil(abs(p) / segment - 1e-9)), 62)
                m = max(m, 1)
            sgn = 1.0 if p > 0 else -1.0
            pts_t[0], pts_x[0], pts_y[0] = 0.0, 0.0, 0.0
            for j in range(1, m + 1):
                tj = tau * j / m
                if w[n] > 0.0 and np.isfinite(w[n]):
                    rad = speed / w[n]
                    hj = h0 + sgn * w[n] * tj
                    pts_x[j] = sgn * rad * (np.sin(hj) - np.sin(h0))
                    pts_y[j] = sgn * rad * (np.cos(h0) - np.cos(hj))
                pts_t[j] = tj
            cs, sn = np.cos(h0 + p), np.sin(h0 + p)
            ovx, ovy = speed * cs, speed * sn  # velocity after the turn
            best = np.inf
            for k in range(n_int):
                if not valid[n, k]:
                    continue
                vix = v[n, k, 0] + vo[n, 0]
                viy = v[n, k, 1] + vo[n, 1]
                d2 = np.inf
                for j in range(m):
                    t0, t1 = pts_t[j], pts_t[j + 1]
                    ax = r[n, k, 0] + vix * t0 - pts_x[j]
                    ay = r[n, k, 1] + viy * t0 - pts_y[j]
                    bx = r[n, k, 0] + vix * t1 - pts_x[j + 1]
                    by = r[n, k, 1] + viy * t1 - pts_y[j + 1]
                    dt = t1 - t0
                    d2 = min(d2, _seg_min(ax, ay, (bx - ax) / dt, (by - ay) / dt, t0, t1))
                ts = pts_t[m]
                ax = r[n, k, 0] + vix * ts - pts_x[m]
                ay = r[n, k, 1] + viy * ts - pts_y[m]
                d2 = min(d2, _seg_min(ax, ay, vix - ovx, viy - ovy, ts, lookahead_s))
                best = min(best, d2 * (1.0 / (radius[n, k] * radius[n, k])))
            out[n, c] = np.sqrt(best)
    return out
