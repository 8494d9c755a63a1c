"""Minimum distance over a look-ahead with the ownship turning to a candidate heading (as
:mod:`~airspace_sim.avoidance.cpa_turning`) *and* each intruder turning at its own estimated
rate for a while, then straight: the intruder's manoeuvre in the ownship's prediction.

Both paths are coordinated-turn arcs followed by straight flight, in closed form; while
either turns they are evaluated every ``step_s`` seconds and the relative track between
samples is taken as straight, so the minimum over each piece is a clamped CPA; once both fly
straight the rest of the look-ahead is one exact straight piece. At 230 m/s and
3°/s a one-second chord departs from its arc by under 2 m. Its kernel and the helpers it calls
are kept in this one module (numba's on-disk cache of a kernel does not see edits of helpers in
other modules). Distances m, velocities m/s, times s, angles rad CCW positive.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from airspace_sim.avoidance.cpa import kernel_array

#: s between the samples of both paths (:func:`cpa_min_ratio_intruder_turning`)
SAMPLE_STEP_S = 1.0


def cpa_min_ratio_intruder_turning(
    own_velocity,
    rel_position,
    rel_velocity,
    valid,
    candidates,
    radius,
    lookahead_s,
    turn_rate,
    intruder_turn_rate,
    intruder_turn_s,
    step_s=SAMPLE_STEP_S,
):
    """(N, C) minimum over intruders of (minimum distance over ``[0, lookahead_s]``) / radius.

    own_velocity (N, 2) m/s; rel_position, rel_velocity (N, K, 2) intruder minus ownship, m,
    m/s; valid (N, K) bool; candidates (N, C) heading changes ψ, rad (NaN: none, NaN out);
    radius m, scalar or (N, K); turn_rate (N,) rad/s, the ownship's (``inf`` or ≤ 0: it takes
    ψ at once); intruder_turn_rate (N, K) rad/s, each intruder's turn rate, flown for
    ``intruder_turn_s`` s (scalar or (N, K); 0: straight), then straight. The ownship flies
    an arc of radius ``|v_o|/ω`` to ``heading + ψ`` (``|ψ|/ω`` s), then straight (as
    :func:`~airspace_sim.avoidance.cpa_turning.cpa_min_ratio_turning`).
    """
    vo = np.ascontiguousarray(own_velocity, dtype=float)
    valid = np.ascontiguousarray(valid, dtype=bool)
    r = np.ascontiguousarray(rel_position, dtype=float)
    v = np.ascontiguousarray(rel_velocity, dtype=float)
    psi = np.ascontiguousarray(candidates, dtype=float)
    radius = kernel_array(radius, valid.shape)
    w = kernel_array(turn_rate, (vo.shape[0],))
    wi = kernel_array(intruder_turn_rate, valid.shape)
    turn_s = kernel_array(intruder_turn_s, valid.shape)
    return _kernel(
        vo,
        r,
        v,
        valid,
        psi,
        radius,
        float(lookahead_s),
        w,
        wi,
        turn_s,
        float(step_s),
    )


@njit(cache=True, error_model="numpy")
def _arc_then_straight(speed, h0, rate, turn_s, t):  # pragma: no cover - compiled
    """Displacement (x, y) after ``t`` s of a path that starts at heading ``h0`` with
    ``speed``, turns at ``rate`` (signed, rad/s) for ``turn_s`` s, then flies straight."""
    tt = min(t, turn_s)
    if abs(rate) * tt > 1e-9:
        h1 = h0 + rate * tt
        x = speed / rate * (np.sin(h1) - np.sin(h0))
        y = speed / rate * (np.cos(h0) - np.cos(h1))
    else:
        h1 = h0
        x = speed * tt * np.cos(h0)
        y = speed * tt * np.sin(h0)
    rest = t - tt
    return x + rest * speed * np.cos(h1), y + rest * speed * np.sin(h1)


@njit(cache=True, error_model="numpy")
def _seg_min(rx, ry, vx, vy, dt):  # pragma: no cover - compiled
    """min over t in [0, dt] of |r + t v|²."""
    dot = vx * rx + vy * ry
    v2 = vx * vx + vy * vy
    t = -dot / max(v2, 1e-300)
    t = min(max(t, 0.0), dt)
    return max((t * v2 + 2.0 * dot) * t + (rx * rx + ry * ry), 0.0)


@njit(cache=True, error_model="numpy")
def _samples_until(until_s, step_s, n_s):  # pragma: no cover - compiled
    """Index of the first sample at or after ``until_s`` s (capped at the last, ``n_s``)."""
    return min(int(np.ceil(until_s / step_s - 1e-9)), n_s)


@njit(cache=True, error_model="numpy")
def _kernel(vo, r, v, valid, psi, radius, lookahead_s, w, wi, turn_s, step_s):  # pragma: no cover
    n_own, n_cand = psi.shape
    n_int = valid.shape[1]
    n_s = max(int(np.ceil(lookahead_s / step_s - 1e-9)), 1)
    times = np.empty(n_s + 1)
    for s in range(n_s + 1):
        times[s] = min(s * step_s, lookahead_s)
    out = np.full((n_own, n_cand), np.inf)
    own_x = np.empty(n_s + 1)
    own_y = np.empty(n_s + 1)
    # the ownship's arc left and right, shared by every candidate while it still turns
    arc_x = np.empty((2, n_s + 1))
    arc_y = np.empty((2, n_s + 1))
    # the intruders' sampled positions relative to the ownship's start, once per ownship
    int_x = np.empty((n_int, n_s + 1))
    int_y = np.empty((n_int, n_s + 1))
    if n_int == 0:
        return out
    for n in range(n_own):
        speed = np.hypot(vo[n, 0], vo[n, 1])
        h0 = np.arctan2(vo[n, 1], vo[n, 0])
        turns = w[n] > 0.0 and np.isfinite(w[n])
        # only the samples up to the end of both turns, and the last, are ever read: the
        # longest own turn over the candidates, the longest intruder turn over the slots
        own_turn_max = 0.0
        if turns:
            for c in range(n_cand):
                if not np.isnan(psi[n, c]):
                    own_turn_max = max(own_turn_max, abs(psi[n, c]) / w[n])
        int_turn_max = 0.0
        for k in range(n_int):
            if valid[n, k] and wi[n, k] != 0.0:
                int_turn_max = max(int_turn_max, turn_s[n, k])
        if turns:
            # a sample at t ≤ τ is the same point of the arc for every τ (t − min(t, τ) = 0)
            arc_end = _samples_until(own_turn_max, step_s, n_s)
            for side in range(2):
                rate = w[n] if side == 0 else -w[n]
                for s in range(arc_end + 1):
                    arc_x[side, s], arc_y[side, s] = _arc_then_straight(
                        speed, h0, rate, own_turn_max, times[s]
                    )
        for k in range(n_int):
            if not valid[n, k]:
                continue
            vix = v[n, k, 0] + vo[n, 0]
            viy = v[n, k, 1] + vo[n, 1]
            si, hi = np.hypot(vix, viy), np.arctan2(viy, vix)
            turn_k = turn_s[n, k] if wi[n, k] != 0.0 else 0.0
            needed = _samples_until(max(own_turn_max, turn_k), step_s, n_s)
            for s in range(needed + 1):
                ix, iy = _arc_then_straight(si, hi, wi[n, k], turn_s[n, k], times[s])
                int_x[k, s] = r[n, k, 0] + ix
                int_y[k, s] = r[n, k, 1] + iy
            ix, iy = _arc_then_straight(si, hi, wi[n, k], turn_s[n, k], times[n_s])
            int_x[k, n_s] = r[n, k, 0] + ix
            int_y[k, n_s] = r[n, k, 1] + iy
        for c in range(n_cand):
            p = psi[n, c]
            if np.isnan(p):
                out[n, c] = np.nan
                continue
            if turns:
                rate, tau, h_start = (w[n] if p > 0 else -w[n]), abs(p) / w[n], h0
            else:  # the heading change at once
                rate, tau, h_start = 0.0, 0.0, h0 + p
            needed = _samples_until(max(tau, int_turn_max), step_s, n_s)
            side = 0 if rate > 0 else 1
            for s in range(needed + 1):
                if turns and times[s] <= tau:
                    own_x[s], own_y[s] = arc_x[side, s], arc_y[side, s]
                else:
                    own_x[s], own_y[s] = _arc_then_straight(speed, h_start, rate, tau, times[s])
            own_x[n_s], own_y[n_s] = _arc_then_straight(speed, h_start, rate, tau, times[n_s])
            best = np.inf
            for k in range(n_int):
                if not valid[n, k]:
                    continue
                # once both turns are over the relative track is straight: one segment
                # from the first sample after both to the look-ahead is exact
                turn_end = max(tau, turn_s[n, k] if wi[n, k] != 0.0 else 0.0)
                last = _samples_until(turn_end, step_s, n_s)
                px = int_x[k, 0] - own_x[0]
                py = int_y[k, 0] - own_y[0]
                d2 = px * px + py * py
                for s in range(1, last + 1):
                    qx = int_x[k, s] - own_x[s]
                    qy = int_y[k, s] - own_y[s]
                    dt = times[s] - times[s - 1]
                    if dt > 0.0:
                        d2 = min(d2, _seg_min(px, py, (qx - px) / dt, (qy - py) / dt, dt))
                    px, py = qx, qy
                dt = times[n_s] - times[last]
                if dt > 0.0:
                    qx = int_x[k, n_s] - own_x[n_s]
                    qy = int_y[k, n_s] - own_y[n_s]
                    d2 = min(d2, _seg_min(px, py, (qx - px) / dt, (qy - py) / dt, dt))
                best = min(best, d2 * (1.0 / (radius[n, k] * radius[n, k])))
            out[n, c] = np.sqrt(best)
    return out
