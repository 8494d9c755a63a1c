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

Choice: the clear candidate of smallest ``|ψ|``; ties go to the right turn (``ψ < 0``), then
to the lower candidate index (optionally left turns rank as ``|ψ| + left_penalty``). If none
is clear, the candidate that maximises the minimum over intruders of
``d / (r_safe·(1+margin))`` (for one common radius: of the CPA distance), tie-broken the same
way. The CPA arithmetic and its search kernels are in :mod:`.cpa`. Angles radians CCW
positive, distances metres, times seconds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airspace_sim.avoidance.cpa import (
    _preferred_kernel,
    band_rows,
    cpa_min_ratio,
)
from airspace_sim.avoidance.cpa_turning import cpa_min_ratio_turning
from airspace_sim.avoidance.heading import (
    boundary_heading_changes,
    boundary_roots_in_window,
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
        where the side has a clear candidate (or is not the row's ``committed_side``).
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


def first_clear_from_band(candidates, band):
    """(N, 3) :attr:`BandResult.first_clear` from a full ``band`` (N, C)."""
    out = np.full((band.shape[0], 3), -1, dtype=np.int64)
    for col, mask in enumerate((candidates <= 0, candidates >= 0, candidates < 0)):
        ok = band & mask
        out[:, col] = np.where(ok.any(axis=1), np.argmax(ok, axis=1), -1)
    return out


def wanted_sides(committed_side, n):
    """(n, 2) bool: the sides (ψ ≤ 0, ψ ≥ 0) whose best blocked candidate is wanted, all
    of them without a ``committed_side`` ((n,), −1 right, +1 left, 0 none)."""
    if committed_side is None:
        return np.ones((n, 2), dtype=bool)
    side = np.broadcast_to(np.asarray(committed_side, dtype=float), (n,))
    return np.stack([side <= 0, side >= 0], axis=1)


def at_once_ratios(
    own_velocity, rel_position, rel_velocity, valid, max_heading_change, params, radius=None
):
    """``"bands"``' candidates judged at once, for resolvers that judge them further.

    Arrays as :func:`band_search`'s, already shaped ((N, 2), (N, K, 2), (N, K, 2), (N, K),
    (N,)); ``params`` a ``"bands"`` :class:`~airspace_sim.avoidance.resolvers.BandsResolver`
    ``Params``; ``radius`` (N, K) m, the clear radius per slot (None: the padded radius
    ``r_safe·(1 + margin)``). Returns ``(radius, candidates, usable, ratio, conflict)``: the
    clear radius (m), the (N, C) candidates in preference order (NaN padding), where they
    are not padding, their minimum CPA ratio if flown at once (``-inf`` on padding) and the
    (N,) conflict flags of the straight test at ψ = 0.
    """
    vo, r, v, p = own_velocity, rel_position, rel_velocity, params
    if radius is None:
        radius = p.r_safe * (1.0 + p.margin)
    extra = None
    if p.exact_candidates and r.shape[1] > 0:
        extra = exact_boundary_candidates(vo, r, v, valid, radius, p.lookahead_s)
    cand = preferred_candidates(max_heading_change, p.resolution, extra, p.left_penalty)
    usable = ~np.isnan(cand)
    ratio = cpa_min_ratio(vo, r, v, valid, np.where(usable, cand, 0.0), radius, p.lookahead_s)
    ratio = np.where(usable, ratio, -np.inf)
    n = vo.shape[0]
    ratio0 = cpa_min_ratio(vo, r, v, valid, np.zeros((n, 1)), radius, p.lookahead_s)[:, 0]
    return radius, cand, usable, ratio, ~(ratio0 >= 1.0 - CLEAR_TOLERANCE)


def bands_from_ratio(candidates, ratio, usable, wanted):
    """``(band (N, C), first_clear (N, 3), best_blocked (N, 2))`` of :class:`BandResult`
    from every candidate's ``ratio`` (N, C) (``-inf`` where not ``usable``); ``wanted``
    (N, 2) bool: the sides whose best blocked candidate is asked for."""
    band = usable & (ratio >= 1.0 - CLEAR_TOLERANCE)
    first = first_clear_from_band(candidates, band)
    best = np.full((ratio.shape[0], 2), -1, dtype=np.int64)
    for col, mask in enumerate((candidates <= 0, candidates >= 0)):
        score = np.where(mask & usable, ratio, -np.inf)
        blocked = (first[:, col] < 0) & (mask & usable).any(axis=1) & wanted[:, col]
        best[:, col] = np.where(blocked, np.argmax(score, axis=1), -1)
    return band, first, best


def band_choice(first_clear, best_blocked, score):
    """(N,) index of the chosen candidate: the first clear one of either side, else the
    better of the two sides' best blocked (the earlier one among equals); ``score(idx)``
    gives (N,) ratios of the candidates at (N,) indices (−1: none, scored −inf)."""
    right, left = first_clear[:, RIGHT_OR_AHEAD], first_clear[:, LEFT_OR_AHEAD]
    first_any = np.where(right < 0, left, np.where(left < 0, right, np.minimum(right, left)))
    br, bl = best_blocked[:, 0], best_blocked[:, 1]
    none_clear = (right < 0) & (left < 0)
    fallback = np.zeros(first_clear.shape[0], dtype=np.int64)
    if none_clear.any():
        sr, sl = score(br), score(bl)
        fallback = np.where((sr > sl) | ((sr == sl) & (br >= 0) & ((bl < 0) | (br < bl))), br, bl)
    return np.where(none_clear, np.maximum(fallback, 0), first_any)


def _grid(max_heading_change, resolution):
    """The grid ``k·resolution`` (G,) rad, ``|k| ≤ floor(max(max_heading_change)/resolution)``."""
    mx = np.asarray(max_heading_change, dtype=float)
    top = float(np.nanmax(mx)) if mx.size else 0.0
    m = int(np.floor(top / resolution + 1e-9)) if np.isfinite(top) and top > 0 else 0
    return np.arange(-m, m + 1, dtype=float) * resolution


def candidate_grid(max_heading_change, resolution, extra=None):
    """Candidates ``(N, C)``: grid ``k·resolution``, the limits ``±max``, and ``extra`` (N, E).

    Entries outside ``±max_heading_change[n]`` (or NaN) are set to NaN.
    """
    mx = np.asarray(max_heading_change, dtype=float)
    grid = _grid(mx, resolution)
    parts = [np.broadcast_to(grid, (mx.shape[0], grid.size)), -mx[:, None], mx[:, None]]
    if extra is not None:
        parts.append(np.asarray(extra, dtype=float).reshape(mx.shape[0], -1))
    cand = np.concatenate(parts, axis=1)
    inside = np.abs(cand) <= mx[:, None] * (1 + 1e-12) + 1e-15
    return np.where(inside, cand, np.nan)


def sort_by_preference_numpy(candidates, left_penalty=0.0):
    """``candidates`` (N, C) rad sorted along each row by preference (the reference for
    :func:`preferred_candidates`): ``|ψ|`` (``+ left_penalty`` for ``ψ > 0``; NaN ranks as
    ``inf``), then right turn (``ψ ≤ 0``) first, then the original index."""
    cand = np.asarray(candidates, dtype=float)
    usable = ~np.isnan(cand)
    mag = np.where(usable, np.abs(cand) + np.where(cand > 0, left_penalty, 0.0), np.inf)
    idx = np.broadcast_to(np.arange(cand.shape[1]), cand.shape)
    order = np.lexsort((idx, cand > 0, mag), axis=-1)
    return np.take_along_axis(cand, order, axis=-1)


def preferred_candidates(max_heading_change, resolution, extra, left_penalty=0.0):
    """:func:`candidate_grid` sorted by :func:`sort_by_preference_numpy`'s order, (N, C) rad.

    ``max_heading_change`` (N,) rad, ``resolution`` rad, ``extra`` None or (N, E) rad. One
    numba pass per row (:func:`_preferred_kernel`): the same array.
    """
    mx = np.ascontiguousarray(max_heading_change, dtype=float)
    grid = _grid(mx, resolution)
    if extra is None:
        extra = np.empty((mx.shape[0], 0))
    extra = np.ascontiguousarray(np.asarray(extra, dtype=float).reshape(mx.shape[0], -1))
    if not np.all(np.diff(grid) > 0):  # the kernel needs an increasing grid
        return sort_by_preference_numpy(candidate_grid(mx, resolution, extra), left_penalty)
    return _preferred_kernel(grid, mx, extra, float(left_penalty))


def exact_boundary_candidates(own_velocity, rel_position, rel_velocity, valid, radius, lookahead_s):
    """Exact boundary heading changes of each intruder's clear set, ``(N, 6K)`` rad (NaN if none).

    Both tangents from :func:`~airspace_sim.avoidance.heading.tangent_heading_changes` (two
    roots each) and the two roots of ``|r + T·v_rel(ψ)| = radius``, intruder ``k`` in columns
    ``6k … 6k+5``; invalid slots NaN. Own velocity (N, 2) m/s, relative position and velocity
    (N, K, 2) m and m/s, valid (N, K), radius float or (N, K) m, ``lookahead_s`` s. One numba
    pass
    (:func:`~airspace_sim.avoidance.heading.boundary_heading_changes`);
    :func:`exact_boundary_candidates_numpy` is the reference.
    """
    vo = np.ascontiguousarray(own_velocity, dtype=float)
    r = np.ascontiguousarray(rel_position, dtype=float)
    vi = np.ascontiguousarray(np.asarray(rel_velocity, dtype=float) + vo[:, None, :])
    valid = np.ascontiguousarray(valid, dtype=bool)
    radius = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, dtype=float), r.shape[:-1]))
    out = boundary_heading_changes(vo, r, vi, valid, radius, float(lookahead_s))
    return out.reshape(out.shape[0], -1)


def exact_boundary_candidates_in_window(
    own_velocity, rel_position, rel_velocity, valid, radius, lookahead_s, limit
):
    """The roots of :func:`exact_boundary_candidates` that may lie in ``|ψ| ≤ limit[n]``
    (rad), packed to the left: ``(roots (N, 6K) rad, count (N,))``, NaN after the first
    ``count[n]`` of row ``n``. Every root inside the window is there, in the same order
    and with the same bits; a root outside it is left out when a cheap cosine test shows
    it (:func:`~airspace_sim.avoidance.heading.boundary_roots_in_window`), which saves its
    ``atan2`` and ``acos``. The candidate sort gives the same rows from these as from all
    the roots."""
    vo = np.ascontiguousarray(own_velocity, dtype=float)
    r = np.ascontiguousarray(rel_position, dtype=float)
    v = np.ascontiguousarray(rel_velocity, dtype=float)  # the kernel adds vo
    valid = np.ascontiguousarray(valid, dtype=bool)
    radius = np.ascontiguousarray(np.broadcast_to(np.asarray(radius, dtype=float), r.shape[:-1]))
    limit = np.ascontiguousarray(np.broadcast_to(np.asarray(limit, dtype=float), vo.shape[:1]))
    return boundary_roots_in_window(vo, r, v, valid, radius, float(lookahead_s), limit)


def exact_boundary_candidates_numpy(
    own_velocity, rel_position, rel_velocity, valid, radius, lookahead_s
):
    """:func:`exact_boundary_candidates` from the numpy functions of
    :mod:`~airspace_sim.avoidance.heading` (the reference for the kernel), ``(N, 6K)``."""
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
    committed_side=None,
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
    committed_side : None or (N,), −1 (right), +1 (left), 0 (none): the turn side each
        ownship's CDA policy keeps. On a row with a side, ``best_blocked`` is searched on
        that side only (−1 in the other column), so where nothing is clear the choice is
        the best candidate of that side (what the policy flies there, whatever the other
        side holds); half the max-min searches of a dense airspace.

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
    wanted = wanted_sides(committed_side, n)
    grid = _grid(mx, resolution)
    # the fast path's kernel needs an increasing grid (always so for a resolution > 0)
    fast = not full and turn_rate is None and bool(np.all(np.diff(grid) > 0))
    rows = np.arange(n)
    if fast:
        extra, n_extra = np.empty((n, 0)), np.zeros(n, dtype=np.int64)
        if exact_candidates and r.shape[1] > 0:
            # only the roots that can lie within ±max_heading_change (the others are not
            # candidates): the same sorted rows
            extra, n_extra = exact_boundary_candidates_in_window(
                vo, r, v, valid, radius, lookahead_s, mx
            )
        cand, first, best, ratio0 = band_rows(
            np.ascontiguousarray(vo),
            np.ascontiguousarray(r),
            np.ascontiguousarray(v),
            np.ascontiguousarray(valid),
            np.ascontiguousarray(np.broadcast_to(radius, valid.shape)),
            float(lookahead_s),
            np.ascontiguousarray(mx),
            extra,
            n_extra,
            grid,
            float(left_penalty),
            1.0 - CLEAR_TOLERANCE,
            np.ascontiguousarray(wanted),
        )
        band = ratio = None
        radius_rows = np.broadcast_to(radius, valid.shape)

        def score(idx):  # the ratio of the candidates idx (−1: −inf), on the rows with one
            out = np.full(n, -np.inf)
            sel = np.flatnonzero(idx >= 0)
            if sel.size:
                psi = cand[sel, idx[sel]][:, None]
                out[sel] = cpa_min_ratio(
                    vo[sel], r[sel], v[sel], valid[sel], psi, radius_rows[sel], lookahead_s
                )[:, 0]
            return out

    else:
        extra = None
        if exact_candidates and r.shape[1] > 0:
            extra = exact_boundary_candidates(vo, r, v, valid, radius, lookahead_s)
        # sorted by preference: |ψ| (+ left_penalty for left turns), then right turn
        # (ψ ≤ 0) first, then original index
        cand = preferred_candidates(mx, resolution, extra, left_penalty)
        usable = ~np.isnan(cand)
        safe = np.where(usable, cand, 0.0)
        ratio0 = cpa_min_ratio(vo, r, v, valid, np.zeros((n, 1)), radius, lookahead_s)[:, 0]
        if turn_rate is None:
            ratio = cpa_min_ratio(vo, r, v, valid, safe, radius, lookahead_s)
        else:
            ratio = cpa_min_ratio_turning(vo, r, v, valid, safe, radius, lookahead_s, turn_rate)
        ratio = np.where(usable, ratio, -np.inf)
        band, first, best = bands_from_ratio(cand, ratio, usable, wanted)
        score = lambda idx: np.where(idx >= 0, ratio[rows, np.maximum(idx, 0)], -np.inf)  # noqa: E731
        if not (full or turn_rate is not None):
            band = ratio = None
    conflict = ~(ratio0 >= 1.0 - CLEAR_TOLERANCE)
    choice = band_choice(first, best, score)
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
