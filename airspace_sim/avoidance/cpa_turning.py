"""CPA over a look-ahead with the ownship *turning* to a candidate heading change at a turn
rate (an arc, as chords, then straight) and the intruder straight: the turned-flight variant of
:mod:`~airspace_sim.avoidance.cpa`, which flies candidates as instantaneous heading changes.
Its kernel and the helper it calls are kept in this one module (numba's on-disk cache of a
kernel does not see edits of helpers in other modules). Distances m, velocities m/s, times s,
angles rad CCW positive.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from airspace_sim.avoidance.cpa import kernel_array

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
    """:func:`~airspace_sim.avoidance.cpa.cpa_min_ratio` with the ownship turning at
    ``turn_rate`` until ``ψ`` is reached.

    The ownship flies an arc of radius ``|v_o|/ω`` from its current heading to ``heading + ψ``
    (taking ``|ψ|/ω`` seconds), then straight; the intruder flies straight. The arc is
    replaced by chords of at most ``segment`` rad whose end points lie on it, so the relative
    track is piecewise straight and the minimum distance over ``[0, T]`` is the minimum of
    each piece's clamped CPA. ``turn_rate`` (N,) rad/s (``inf`` or ≤ 0: instantaneous, the
    same numbers as :func:`~airspace_sim.avoidance.cpa.cpa_min_ratio`).
    """
    vo = np.ascontiguousarray(own_velocity, dtype=float)
    valid = np.ascontiguousarray(valid, dtype=bool)
    r = np.ascontiguousarray(rel_position, dtype=float)
    v = np.ascontiguousarray(rel_velocity, dtype=float)
    psi = np.ascontiguousarray(candidates, dtype=float)
    radius = kernel_array(radius, valid.shape)
    w = kernel_array(turn_rate, (vo.shape[0],))
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
