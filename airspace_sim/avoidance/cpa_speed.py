"""Minimum distance over a look-ahead with the ownship turning to a candidate heading *and*
changing its ground speed to a candidate speed, the intruders straight: the speed axis of the
as-flown band search (:mod:`~airspace_sim.avoidance.speed_bands`).

The ownship turns at its turn rate ω until the heading change ψ is flown (``|ψ|/ω`` s) and
accelerates at ``a`` until the target speed is reached (``|s₁ − s₀|/a`` s), both at once from
the start, then flies straight at the target speed. Each piece of that path (both changing,
one, none) has a closed-form displacement: with ``θ(u) = h + ωu`` and speed ``s + αu``,

    ∫₀ᵈ (s + αu) e^{iθ(u)} du = −(i/ω)·(s (z₁ − z₀) + α d z₁) + α (z₁ − z₀)/ω²,
    z₀ = e^{ih}, z₁ = e^{i(h + ωd)},

and its expansion to second order in ω for ``|ωd| < 10⁻⁴`` (where the closed form loses
digits to the 1/ω² terms; the expansion's error is ~ s·d·(ωd)³/24, under 10⁻⁹ m).
The path is evaluated at knots and the relative track between knots is taken as straight, so
the minimum over each piece is a clamped CPA. Once the manoeuvre is over the relative track is
straight, and one piece to the look-ahead is exact. During it the knots are spaced so that the
path departs from its chords by at most ``tolerance_m``: a path of acceleration of magnitude
``g`` lies within ``g·Δt²/8`` of the chord of ``Δt`` s, with ``g² = (s·ω)² + a²`` (at 230 m/s
and 3°/s, 2 m: 1.2 s while turning; at 0.5 m/s² alone: 5.7 s), and a knot is put at the end of
the turn and of the speed change. The kernel and its
helpers are kept in this one module (numba's on-disk cache of a kernel does not see edits of
helpers in other modules). Distances m, velocities m/s, times s, angles rad CCW positive.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from airspace_sim.avoidance.cpa import kernel_array

#: m, the largest distance of the ownship's path from its chords (:func:`cpa_min_ratio_speed`)
CHORD_TOLERANCE_M = 2.0
#: |ω·d| under which a piece of the path is integrated by its midpoint heading
_SMALL_TURN = 1e-4


def cpa_min_ratio_speed(
    own_velocity,
    rel_position,
    rel_velocity,
    valid,
    candidates,
    speeds,
    radius,
    lookahead_s,
    turn_rate,
    acceleration,
    tolerance_m=CHORD_TOLERANCE_M,
):
    """(N, C, P) minimum over intruders of (minimum distance over ``[0, lookahead_s]``) / radius,
    for every heading change and target speed.

    own_velocity (N, 2) m/s; rel_position, rel_velocity (N, K, 2) intruder minus ownship, m,
    m/s; valid (N, K) bool; candidates (N, C) heading changes ψ, rad (NaN: none, NaN out);
    speeds (N, P) target ground speeds, m/s (> 0); radius m, scalar or (N, K); turn_rate (N,)
    rad/s (``inf`` or ≤ 0: ψ at once); acceleration (N,) m/s², the ownship's along-track
    limit (``inf`` or ≤ 0: the target speed at once); tolerance_m > 0 the chords' largest
    distance from the path (module docstring). Intruders fly straight at their tracked
    velocities. Without valid intruders the entry is +inf.
    """
    vo = np.ascontiguousarray(own_velocity, dtype=float)
    valid = np.ascontiguousarray(valid, dtype=bool)
    r = np.ascontiguousarray(rel_position, dtype=float)
    v = np.ascontiguousarray(rel_velocity, dtype=float)
    psi = np.ascontiguousarray(candidates, dtype=float)
    n = vo.shape[0]
    sp = kernel_array(speeds, (n, np.asarray(speeds).shape[-1]))
    radius = kernel_array(radius, valid.shape)
    w = kernel_array(turn_rate, (n,))
    acc = kernel_array(acceleration, (n,))
    tol = float(tolerance_m)
    if not tol > 0.0:
        raise ValueError(f"tolerance_m must be > 0 m, got {tolerance_m!r}")
    size = _knot_bound(vo, sp, w, acc, float(lookahead_s), tol)
    return _kernel(vo, r, v, valid, psi, sp, radius, float(lookahead_s), w, acc, tol, size)


def _knot_bound(vo, speeds, turn_rate, acceleration, lookahead_s, tol):
    """An upper bound on the knots of any path of the call (:func:`_knots`): the steps over the
    look-ahead at the largest path acceleration of the call, one more per phase, the first
    knot and the look-ahead."""
    s_max = max(_largest(np.hypot(vo[:, 0], vo[:, 1])), _largest(speeds))
    g = math.hypot(s_max * _largest(turn_rate), _largest(acceleration))
    steps = math.ceil(lookahead_s / math.sqrt(8.0 * tol / g)) if g > 0.0 else 0
    return steps + 4


def _largest(x):
    """The largest finite positive entry of ``x`` (a turn rate or acceleration that is flown,
    not taken at once), 0 if none."""
    x = np.asarray(x, dtype=float)
    return float(np.max(x[np.isfinite(x) & (x > 0.0)], initial=0.0))


@njit(cache=True, error_model="numpy")
def _piece(s, h, w, a, d):  # pragma: no cover - compiled
    """Displacement (x, y) over ``d`` s from heading ``h`` and speed ``s``, turning at ``w``
    rad/s and accelerating at ``a`` m/s² (module docstring)."""
    if abs(w * d) < _SMALL_TURN:
        # e^{ih}·(L + iωM − ω²N/2), L, M, N the moments ∫(s + αu)uʲ du, j = 0, 1, 2
        d2 = d * d
        length = s * d + 0.5 * a * d2
        m1 = w * (0.5 * s * d2 + a * d2 * d / 3.0)
        n2 = 0.5 * w * w * (s * d2 * d / 3.0 + 0.25 * a * d2 * d2)
        c, sn = np.cos(h), np.sin(h)
        return (length - n2) * c - m1 * sn, (length - n2) * sn + m1 * c
    c0, s0 = np.cos(h), np.sin(h)
    c1, s1 = np.cos(h + w * d), np.sin(h + w * d)
    # −(i/ω)(A + iB) = (B − iA)/ω with A + iB = s (z1 − z0) + a d z1
    ar = s * (c1 - c0) + a * d * c1
    ai = s * (s1 - s0) + a * d * s1
    x = ai / w + a * (c1 - c0) / (w * w)
    y = -ar / w + a * (s1 - s0) / (w * w)
    return x, y


@njit(cache=True, error_model="numpy")
def _displacement(s0, h0, w, tau_h, a, tau_s, t):  # pragma: no cover - compiled
    """Displacement (x, y) after ``t`` s: turning at ``w`` for ``tau_h`` s and accelerating at
    ``a`` for ``tau_s`` s, both from the start, then straight at constant speed."""
    t1 = min(tau_h, tau_s, t)
    x, y = _piece(s0, h0, w, a, t1)
    h, s = h0 + w * t1, s0 + a * t1
    t2 = min(max(tau_h, tau_s), t)
    if t2 > t1:
        wi = w if tau_h > t1 else 0.0
        ai = a if tau_s > t1 else 0.0
        dx, dy = _piece(s, h, wi, ai, t2 - t1)
        x += dx
        y += dy
        h, s = h + wi * (t2 - t1), s + ai * (t2 - t1)
    if t > t2:
        x += s * (t - t2) * np.cos(h)
        y += s * (t - t2) * np.sin(h)
    return x, y


@njit(cache=True, error_model="numpy")
def _seg_min(rx, ry, vx, vy, dt):  # pragma: no cover - compiled
    """min over t in [0, dt] of |r + t v|²."""
    dot = vx * rx + vy * ry
    v2 = vx * vx + vy * vy
    t = -dot / max(v2, 1e-300)
    t = min(max(t, 0.0), dt)
    return max((t * v2 + 2.0 * dot) * t + (rx * rx + ry * ry), 0.0)


@njit(cache=True, error_model="numpy")
def _knots(s0, s1, rate, tau_h, a, tau_s, lookahead_s, tol, out):  # pragma: no cover - compiled
    """Fill ``out`` with the knot times, s, of one path (module docstring); return how many:
    0, then steps of at most ``sqrt(8·tol/g)`` to the ends of the turn and of the speed change,
    then the look-ahead."""
    t_end = min(max(tau_h, tau_s), lookahead_s)
    s_max = max(s0, s1)
    m = 0
    out[m] = 0.0
    m += 1
    t = 0.0
    while t < t_end:
        turning = t < tau_h
        ramping = t < tau_s
        g2 = (s_max * rate) ** 2 if turning else 0.0
        g2 += a * a if ramping else 0.0
        stop = t_end
        if turning and tau_h < stop:
            stop = tau_h
        if ramping and tau_s < stop:
            stop = tau_s
        step = np.sqrt(8.0 * tol / np.sqrt(g2)) if g2 > 0.0 else stop - t
        n_steps = max(int(np.ceil((stop - t) / step - 1e-9)), 1)
        dt = (stop - t) / n_steps
        for j in range(1, n_steps):
            out[m] = t + j * dt
            m += 1
        out[m] = stop
        m += 1
        t = stop
    if lookahead_s > t_end:
        out[m] = lookahead_s
        m += 1
    return m


@njit(cache=True, error_model="numpy")
def _kernel(vo, r, v, valid, psi, sp, radius, lookahead_s, w, acc, tol, size):  # pragma: no cover
    n_own, n_cand = psi.shape
    n_speed = sp.shape[1]
    n_int = valid.shape[1]
    out = np.full((n_own, n_cand, n_speed), np.inf)
    times = np.empty(size)
    own_x = np.empty(size)
    own_y = np.empty(size)
    for n in range(n_own):
        s0 = np.hypot(vo[n, 0], vo[n, 1])
        h0 = np.arctan2(vo[n, 1], vo[n, 0])
        turns = w[n] > 0.0 and np.isfinite(w[n])
        ramps = acc[n] > 0.0 and np.isfinite(acc[n])
        for c in range(n_cand):
            p = psi[n, c]
            if np.isnan(p):
                if n_int > 0:
                    out[n, c, :] = np.nan
                continue
            if turns:
                rate, tau_h, h_start = (w[n] if p > 0 else -w[n]), abs(p) / w[n], h0
            else:
                rate, tau_h, h_start = 0.0, 0.0, h0 + p
            for q in range(n_speed):
                s1 = sp[n, q]
                if ramps:
                    a, tau_s, s_start = (acc[n] if s1 > s0 else -acc[n]), abs(s1 - s0) / acc[n], s0
                else:
                    a, tau_s, s_start = 0.0, 0.0, s1
                m = _knots(s_start, s1, rate, tau_h, a, tau_s, lookahead_s, tol, times)
                for s in range(m):
                    own_x[s], own_y[s] = _displacement(
                        s_start, h_start, rate, tau_h, a, tau_s, times[s]
                    )
                best = np.inf
                for k in range(n_int):
                    if not valid[n, k]:
                        continue
                    vix = v[n, k, 0] + vo[n, 0]
                    viy = v[n, k, 1] + vo[n, 1]
                    px = r[n, k, 0] - own_x[0]
                    py = r[n, k, 1] - own_y[0]
                    d2 = px * px + py * py
                    for s in range(1, m):
                        qx = r[n, k, 0] + vix * times[s] - own_x[s]
                        qy = r[n, k, 1] + viy * times[s] - own_y[s]
                        dt = times[s] - times[s - 1]
                        if dt > 0.0:
                            d2 = min(d2, _seg_min(px, py, (qx - px) / dt, (qy - py) / dt, dt))
                        px, py = qx, qy
                    best = min(best, d2 * (1.0 / (radius[n, k] * radius[n, k])))
                out[n, c, q] = np.sqrt(best)
    return out
