"""Multi-intruder heading bands (DAIDALUS-style: NASA DAIDALUS heading bands).

For each ownship ``n`` (``N`` of them) with ``K`` intruder slots, candidate heading changes
``ψ`` within ``±max_heading_change[n]`` are scored by the closest point of approach (CPA)
over the look-ahead ``[0, T]`` under straight-line relative motion:

    v_rel(ψ) = v_i − R(ψ)·v_o,  t_cpa = clamp(−r·v_rel / |v_rel|², 0, T),  d = |r + t_cpa·v_rel|

all as arrays ``(N, C, K)``. A candidate is *clear* when ``d ≥ r_safe·(1 + margin)`` for every
valid intruder (to a relative tolerance :data:`CLEAR_TOLERANCE`, so the exact boundary
candidates below count as clear). The band is the clear set over the candidates.

Candidates: a grid ``k·resolution`` inside the limit, the limits ``±max_heading_change[n]``,
and (``exact_candidates=True``) the exact boundaries of each intruder's clear set from
:mod:`airspace_sim.avoidance.heading` with radius ``r_safe·(1 + margin)``: both tangents
(CPA inside the look-ahead) and ``d(T) = radius`` (CPA at the end of the look-ahead).

Choice: the clear candidate of smallest ``|ψ|``; ties go to the right turn (``ψ < 0``), then to
the lower candidate index (optionally left turns rank as ``|ψ| + left_penalty``). If none is clear, the candidate that maximises the minimum over
intruders of ``d / (r_safe·(1+margin))`` (for one common radius: of the CPA distance), tie-broken
the same way. Angles radians CCW positive, distances metres, times seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from airspace_sim.avoidance.heading import (
    range_at_time_heading_changes,
    tangent_heading_changes,
    wrap_angle,
)

#: Relative tolerance of the clear test ``d ≥ radius·(1 − CLEAR_TOLERANCE)``.
CLEAR_TOLERANCE = 1e-9
#: Default candidate grid step, rad (1°).
DEFAULT_RESOLUTION = float(np.radians(1.0))


@dataclass
class BandResult:
    """Result of :func:`band_search` (``N`` ownships, ``C`` candidates).

    heading_change : (N,) chosen heading change, rad, CCW positive.
    conflict : (N,) bool, the current heading (``ψ = 0``) is not clear.
    candidates : (N, C) candidate heading changes, rad, sorted by preference
        (``|ψ|``, right turn first); NaN for unused slots.
    band : (N, C) bool, candidate is clear (the band to draw); False for unused slots.
        ``None`` from ``band_search(..., full=False)``.
    min_ratio : (N, C) minimum over intruders of CPA distance / radius (``inf`` with no
        intruder, ``-inf`` for unused slots); ``None`` from ``band_search(..., full=False)``.
    first_clear : (N, 3) int, index in ``candidates`` of the first clear candidate with
        ``ψ ≤ 0``, with ``ψ ≥ 0`` and with ``ψ < 0`` (−1: none).
    best_blocked : (N, 2) int, on a side (``ψ ≤ 0``, ``ψ ≥ 0``) without a clear candidate,
        the index of its candidate of largest ``min_ratio`` (the first among equals); −1
        where the side has a clear candidate.
    """

    heading_change: np.ndarray
    conflict: np.ndarray
    candidates: np.ndarray
    band: np.ndarray | None
    min_ratio: np.ndarray
    first_clear: np.ndarray
    best_blocked: np.ndarray


#: Columns of :attr:`BandResult.first_clear`.
RIGHT_OR_AHEAD, LEFT_OR_AHEAD, STRICT_RIGHT = 0, 1, 2


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
                rx, ry = r[n, k, 0], r[n, k, 1]
                vx = (v[n, k, 0] + vo[n, 0]) - rvx
                vy = (v[n, k, 1] + vo[n, 1]) - rvy
                dot = vx * rx + vy * ry
                v2 = vx * vx + vy * vy
                t = -dot / max(v2, 1e-300)
                t = min(max(t, 0.0), lookahead_s)
                d2 = (t * v2 + 2.0 * dot) * t + (rx * rx + ry * ry)
                ratio2 = max(d2, 0.0) * (1.0 / (radius[n, k] * radius[n, k]))
                best = min(best, ratio2)
            out[n, c] = np.sqrt(best)
    return out


@njit(cache=True, error_model="numpy")
def _first_clear_kernel(
    vo, r, v, valid, psi, usable, radius, lookahead_s, threshold
):  # pragma: no cover
    """Per ownship, the first clear candidate of each side (columns of ``first_clear``).

    ``psi`` (N, C) sorted by preference. Each candidate is tested with the same arithmetic
    as :func:`_cpa_kernel`, intruder by intruder, stopping at the first one closer than
    ``threshold`` (the last blocking intruder is tried first: neighbouring candidates are
    usually blocked by the same one); the scan of an ownship stops once every side has a
    clear candidate. So the work is about the blocked candidates before the first clear
    ones, not C·K.
    """
    n_own, n_cand = psi.shape
    n_int = valid.shape[1]
    out = np.full((n_own, 3), -1, dtype=np.int64)
    for n in range(n_own):
        blocker = -1
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
            cs, sn = np.cos(p), np.sin(p)
            rvx = cs * vo[n, 0] - sn * vo[n, 1]
            rvy = sn * vo[n, 0] + cs * vo[n, 1]
            clear = True
            for j in range(-1, n_int):
                k = blocker if j < 0 else j
                if k < 0 or (j >= 0 and k == blocker) or not valid[n, k]:
                    continue
                rx, ry = r[n, k, 0], r[n, k, 1]
                vx = (v[n, k, 0] + vo[n, 0]) - rvx
                vy = (v[n, k, 1] + vo[n, 1]) - rvy
                dot = vx * rx + vy * ry
                v2 = vx * vx + vy * vy
                t = -dot / max(v2, 1e-300)
                t = min(max(t, 0.0), lookahead_s)
                d2 = (t * v2 + 2.0 * dot) * t + (rx * rx + ry * ry)
                ratio2 = max(d2, 0.0) * (1.0 / (radius[n, k] * radius[n, k]))
                if not (np.sqrt(ratio2) >= threshold):
                    clear = False
                    blocker = k
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
def _best_blocked_kernel(
    vo, r, v, valid, psi, usable, radius, lookahead_s, rows, side
):  # pragma: no cover
    """For ownship ``rows[i]``, the candidate on side ``side[i]`` (0: ψ ≤ 0, 1: ψ ≥ 0) of
    largest minimum CPA ratio (the first in order among equals): a max-min search that
    stops evaluating a candidate once its running minimum cannot beat the best so far.
    Same arithmetic as :func:`_cpa_kernel`, so the same choice as the full evaluation."""
    n_int = valid.shape[1]
    n_cand = psi.shape[1]
    out = np.full(rows.size, -1, dtype=np.int64)
    for i in range(rows.size):
        n = rows[i]
        best = -np.inf
        blocker = -1
        for c in range(n_cand):
            if not usable[n, c]:
                continue
            p = psi[n, c]
            if (side[i] == 0 and p > 0.0) or (side[i] == 1 and p < 0.0):
                continue
            cs, sn = np.cos(p), np.sin(p)
            rvx = cs * vo[n, 0] - sn * vo[n, 1]
            rvy = sn * vo[n, 0] + cs * vo[n, 1]
            m = np.inf
            arg = -1
            for j in range(-1, n_int):
                k = blocker if j < 0 else j
                if k < 0 or (j >= 0 and k == blocker) or not valid[n, k]:
                    continue
                rx, ry = r[n, k, 0], r[n, k, 1]
                vx = (v[n, k, 0] + vo[n, 0]) - rvx
                vy = (v[n, k, 1] + vo[n, 1]) - rvy
                dot = vx * rx + vy * ry
                v2 = vx * vx + vy * vy
                t = -dot / max(v2, 1e-300)
                t = min(max(t, 0.0), lookahead_s)
                d2 = (t * v2 + 2.0 * dot) * t + (rx * rx + ry * ry)
                q = np.sqrt(max(d2, 0.0) * (1.0 / (radius[n, k] * radius[n, k])))
                if q < m:
                    m = q
                    arg = k
                if m <= best:
                    break
            if m > best:
                best = m
                out[i] = c
                blocker = arg
    return out


def first_clear_from_band(candidates, band):
    """(N, 3) :attr:`BandResult.first_clear` from a full ``band`` (N, C)."""
    out = np.full((band.shape[0], 3), -1, dtype=np.int64)
    for col, mask in enumerate((candidates <= 0, candidates >= 0, candidates < 0)):
        ok = band & mask
        out[:, col] = np.where(ok.any(axis=1), np.argmax(ok, axis=1), -1)
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


def candidate_grid(max_heading_change, resolution, extra=None):
    """Candidates ``(N, C)``: grid ``k·resolution``, the limits ``±max``, and ``extra`` (N, E).

    Entries outside ``±max_heading_change[n]`` (or NaN) are set to NaN.
    """
    mx = np.asarray(max_heading_change, dtype=float)
    top = float(np.nanmax(mx)) if mx.size else 0.0
    m = int(np.floor(top / resolution + 1e-9)) if np.isfinite(top) and top > 0 else 0
    grid = np.arange(-m, m + 1, dtype=float) * resolution
    parts = [np.broadcast_to(grid, (mx.shape[0], grid.size)), -mx[:, None], mx[:, None]]
    if extra is not None:
        parts.append(np.asarray(extra, dtype=float).reshape(mx.shape[0], -1))
    cand = np.concatenate(parts, axis=1)
    inside = np.abs(cand) <= mx[:, None] * (1 + 1e-12) + 1e-15
    return np.where(inside, cand, np.nan)


def exact_boundary_candidates(own_velocity, rel_position, rel_velocity, valid, radius, lookahead_s):
    """Exact boundary heading changes of each intruder's clear set, ``(N, 6K)`` (NaN if none).

    Both tangents from :func:`~airspace_sim.avoidance.heading.tangent_heading_changes` (two
    roots each) and the two roots of ``|r + T·v_rel(ψ)| = radius``.
    """
    vo = np.asarray(own_velocity, dtype=float)[:, None, :]
    r = np.asarray(rel_position, dtype=float)
    vi = np.asarray(rel_velocity, dtype=float) + vo
    radius = np.broadcast_to(np.asarray(radius, dtype=float), r.shape[:-1])
    parts = [
        tangent_heading_changes(vo, vi, r, radius, -1.0),
        tangent_heading_changes(vo, vi, r, radius, 1.0),
        range_at_time_heading_changes(vo, vi, r, radius, np.full(r.shape[:-1], lookahead_s)),
    ]
    out = np.concatenate(parts, axis=-1)  # (N, K, 6)
    out = np.where(np.asarray(valid, dtype=bool)[..., None], out, np.nan)
    return out.reshape(out.shape[0], -1)


def band_search(
    own_velocity,
    rel_position,
    rel_velocity,
    valid,
    max_heading_change,
    r_safe=3000.0,
    lookahead_s=120.0,
    margin=0.1,
    resolution=DEFAULT_RESOLUTION,
    exact_candidates=True,
    left_penalty=0.0,
    turn_rate=None,
    full=True,
):
    """Choose each ownship's heading change against all its intruders at once.

    Parameters
    ----------
    own_velocity : (N, 2) m/s, world frame.
    rel_position, rel_velocity : (N, K, 2) intruder minus ownship, m and m/s.
    valid : (N, K) bool.
    max_heading_change : (N,) rad, ``|ψ| ≤`` this.
    r_safe : float or (N, K) m; margin : float (clear distance ``r_safe·(1+margin)``).
    lookahead_s : float, s; resolution : grid step, rad; exact_candidates : bool.
    left_penalty : rad, ≥ 0. Left turns (``ψ > 0``) are ranked as if ``|ψ| + left_penalty``
        (a rules-of-the-air bias toward right turns; 0 = the plain smallest-``|ψ|`` rule).
    turn_rate : None, float or (N,) rad/s. ``None``: a candidate is judged as if the heading
        changed at once; else as flown: turning at ``turn_rate`` until ``ψ`` is reached,
        then straight (:func:`cpa_min_ratio_turning`).
    full : bool. True: ``band`` and ``min_ratio`` for every candidate. False (straight
        candidates only, ``turn_rate`` None): only what a choice needs — the first clear
        candidate of each side, and ``min_ratio`` on the rows where a side has none — the
        same choice, ``first_clear`` and (on those rows) ``min_ratio`` as ``full=True``.

    Returns
    -------
    :class:`BandResult`
    """
    vo = np.asarray(own_velocity, dtype=float).reshape(-1, 2)
    n = vo.shape[0]
    r = np.asarray(rel_position, dtype=float).reshape(n, -1, 2)
    v = np.asarray(rel_velocity, dtype=float).reshape(n, -1, 2)
    valid = np.asarray(valid, dtype=bool).reshape(n, -1)
    mx = np.broadcast_to(np.asarray(max_heading_change, dtype=float), (n,))
    radius = np.asarray(r_safe, dtype=float) * (1.0 + margin)
    extra = None
    if exact_candidates and r.shape[1] > 0:
        extra = exact_boundary_candidates(vo, r, v, valid, radius, lookahead_s)
    cand = candidate_grid(mx, resolution, extra)
    # sort by preference: |ψ| (+ left_penalty for left turns), then right turn (ψ ≤ 0)
    # first, then original index
    usable = ~np.isnan(cand)
    mag = np.where(usable, np.abs(cand) + np.where(cand > 0, left_penalty, 0.0), np.inf)
    idx = np.broadcast_to(np.arange(cand.shape[1]), cand.shape)
    order = np.lexsort((idx, cand > 0, mag), axis=-1)
    cand = np.take_along_axis(cand, order, axis=-1)
    usable = np.take_along_axis(usable, order, axis=-1)
    rows = np.arange(n)
    safe = np.where(usable, cand, 0.0)
    ratio0 = cpa_min_ratio(vo, r, v, valid, np.zeros((n, 1)), radius, lookahead_s)[:, 0]
    conflict = ~(ratio0 >= 1.0 - CLEAR_TOLERANCE)
    if full or turn_rate is not None:
        if turn_rate is None:
            ratio = cpa_min_ratio(vo, r, v, valid, safe, radius, lookahead_s)
        else:
            ratio = cpa_min_ratio_turning(vo, r, v, valid, safe, radius, lookahead_s, turn_rate)
        ratio = np.where(usable, ratio, -np.inf)
        band = usable & (ratio >= 1.0 - CLEAR_TOLERANCE)
        first = first_clear_from_band(cand, band)
        best = np.full((n, 2), -1, dtype=np.int64)
        for col, mask in enumerate((cand <= 0, cand >= 0)):
            score = np.where(mask & usable, ratio, -np.inf)
            blocked = (first[:, col] < 0) & (mask & usable).any(axis=1)
            best[:, col] = np.where(blocked, np.argmax(score, axis=1), -1)
    else:
        band = ratio = None
        args = (
            np.ascontiguousarray(vo),
            np.ascontiguousarray(r),
            np.ascontiguousarray(v),
            np.ascontiguousarray(valid),
            np.ascontiguousarray(safe),
            np.ascontiguousarray(usable),
            np.ascontiguousarray(np.broadcast_to(radius, valid.shape)),
            float(lookahead_s),
        )
        first = _first_clear_kernel(*args, 1.0 - CLEAR_TOLERANCE)
        best = np.full((n, 2), -1, dtype=np.int64)
        blocked = first[:, :2] < 0
        blocked &= np.stack(
            [(usable & (cand <= 0)).any(axis=1), (usable & (cand >= 0)).any(axis=1)], axis=1
        )
        who, col = np.nonzero(blocked)
        if who.size:
            best[who, col] = _best_blocked_kernel(*args, who.astype(np.int64), col.astype(np.int64))
    right, left = first[:, RIGHT_OR_AHEAD], first[:, LEFT_OR_AHEAD]
    first_any = np.where(right < 0, left, np.where(left < 0, right, np.minimum(right, left)))
    # nothing clear: the better of the two sides' best (the earlier one among equals)
    br, bl = best[:, 0], best[:, 1]
    if ratio is None:
        score = lambda idx: np.where(  # noqa: E731
            idx >= 0,
            cpa_min_ratio(
                vo, r, v, valid, safe[rows, np.maximum(idx, 0)][:, None], radius, lookahead_s
            )[:, 0],
            -np.inf,
        )
    else:
        score = lambda idx: np.where(idx >= 0, ratio[rows, np.maximum(idx, 0)], -np.inf)  # noqa: E731
    none_clear = (right < 0) & (left < 0)
    fallback = np.zeros(n, dtype=np.int64)
    if none_clear.any():
        sr, sl = score(br), score(bl)
        fallback = np.where((sr > sl) | ((sr == sl) & (br >= 0) & ((bl < 0) | (br < bl))), br, bl)
    choice = np.where(none_clear, np.maximum(fallback, 0), first_any)
    heading_change = cand[rows, choice]
    return BandResult(heading_change, conflict, cand, band, ratio, first, best)


def resume_heading_change(
    own_velocity,
    desired_heading,
    rel_position,
    rel_velocity,
    valid,
    max_heading_change,
    r_safe=3000.0,
    lookahead_s=120.0,
    margin=0.1,
):
    """Heading change back toward ``desired_heading`` if that turn is clear.

    The turn is ``wrap(desired − current)`` limited to ``±max_heading_change``; it is applied
    only where it is clear of every valid intruder (same test as :func:`band_search`).

    Parameters
    ----------
    own_velocity : (N, 2) m/s; desired_heading : (N,) rad (world heading, ``atan2(vy, vx)``).
    rel_position, rel_velocity, valid, max_heading_change, r_safe, lookahead_s:
        as in :func:`band_search`.
    margin : float or (N,), fraction of ``r_safe`` kept clear on top of it.

    Returns
    -------
    heading_change : (N,) rad, the limited turn where clear, else 0.
    clear : (N,) bool, that turn is clear.
    """
    vo = np.asarray(own_velocity, dtype=float).reshape(-1, 2)
    n = vo.shape[0]
    mx = np.broadcast_to(np.asarray(max_heading_change, dtype=float), (n,))
    heading = np.arctan2(vo[:, 1], vo[:, 0])
    delta = np.clip(wrap_angle(np.asarray(desired_heading, dtype=float) - heading), -mx, mx)
    r = np.asarray(rel_position, dtype=float).reshape(n, -1, 2)
    v = np.asarray(rel_velocity, dtype=float).reshape(n, -1, 2)
    valid = np.asarray(valid, dtype=bool).reshape(n, -1)
    radius = np.asarray(r_safe, dtype=float) * (1.0 + np.asarray(margin, dtype=float))
    if radius.ndim == 1:  # one per ownship
        radius = radius[:, None]
    ratio = cpa_min_ratio(vo, r, v, valid, delta[:, None], radius, lookahead_s)[:, 0]
    clear = ratio >= 1.0 - CLEAR_TOLERANCE
    return np.where(clear, delta, 0.0), clear
