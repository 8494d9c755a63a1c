"""Minimum distances to intruders that may start turning: straight, or a left or right turn at
a given rate for a while, then straight (the "no-worse-turns" resume rule of the world's CDA
policy, ``docs/resolvers.md`` "Resume rules").

An intruder flying straight now can begin an avoidance turn at any moment (on a crowded ring
most losses traced under the "no-worse" rule began that way: a neighbour turned into an
ownship that judged it straight). Its future positions under the three hypotheses, with
``p``, ``v`` its position and velocity now and ``ω`` the turn rate for ``t ≤ turn_s``:

    straight: p + v·t
    turning:  p + (R(ω·τ) − I)·J⁻¹·v / ω + R(ω·τ)·v·(t − τ),   τ = min(t, turn_s)

(the arc of a constant-rate turn, ``J`` the 90° rotation), and the ownship, turned by ψ now,
flies straight: ``R(ψ)·v_o·t``. The minimum over the look-ahead is taken on a time grid
(every ``step_s`` and at the look-ahead), not in closed form: the turned path has none.
Distances m, velocities m/s, times s, angles rad CCW positive.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from airspace_sim.avoidance.cpa import kernel_array

#: the three intruder hypotheses, in the order of the ``M`` axis
HYPOTHESES = ("straight", "left", "right")


def turned_path_min_ratio_numpy(
    own_velocity,
    rel_position,
    rel_velocity,
    valid,
    candidates,
    radius,
    lookahead_s: float,
    turn_rate,
    turn_s: float,
    step_s: float = 2.0,
):
    """:func:`turned_path_min_ratio` in numpy over (N, K, S) arrays (the kernel's reference).

    (N, K, 3, C) minimum over the sampled look-ahead of the distance to intruder k, over
    ``radius``, under each of :data:`HYPOTHESES`, the ownship turned by candidate c.

    own_velocity (N, 2) m/s; rel_position, rel_velocity (N, K, 2) m, m/s (intruder minus
    ownship, at the current heading); valid (N, K) bool (invalid slots give ``inf``);
    candidates (N, C) rad; radius (N,) or scalar m; turn_rate (N,) or scalar rad/s > 0, the
    intruders' turn rate; turn_s: s of turning before the intruder flies straight again;
    step_s: s between samples (``t = 0`` and ``t = lookahead_s`` always included).
    """
    vo = np.asarray(own_velocity, dtype=float)
    r = np.asarray(rel_position, dtype=float)
    vi = np.asarray(rel_velocity, dtype=float) + vo[:, None, :]  # (N, K, 2) world
    psi = np.asarray(candidates, dtype=float)
    n, k = r.shape[:2]
    radius = np.broadcast_to(np.asarray(radius, dtype=float), (n,))
    # a zero turn limit is the straight path (the arc's limit); kept finite for the division
    w = np.maximum(np.broadcast_to(np.asarray(turn_rate, dtype=float), (n,)), 1e-12)
    t = _sample_times(lookahead_s, step_s)  # (S,)
    tau = np.minimum(t, turn_s)
    # intruder displacement from now, (N, K, 3, S, 2), per hypothesis
    disp = np.empty((n, k, 3, t.size, 2))
    disp[:, :, 0] = vi[:, :, None, :] * t[None, None, :, None]
    for m, sign in ((1, 1.0), (2, -1.0)):
        a = (sign * w)[:, None] * tau[None, :]  # (N, S) turned angle
        c, s = np.cos(a), np.sin(a)
        ww = (sign * w)[:, None, None]  # (N, 1, 1)
        vx, vy = vi[..., 0][:, :, None], vi[..., 1][:, :, None]  # (N, K, 1)
        # arc: ∫0^τ R(ωu) v du = [sin(ωτ) v + (1 − cos(ωτ)) J v] / ω, J v = (−vy, vx)
        ax = (s[:, None] * vx - (1.0 - c[:, None]) * vy) / ww
        ay = (s[:, None] * vy + (1.0 - c[:, None]) * vx) / ww
        rest = (t - tau)[None, None, :]
        disp[:, :, m, :, 0] = ax + (c[:, None] * vx - s[:, None] * vy) * rest
        disp[:, :, m, :, 1] = ay + (s[:, None] * vx + c[:, None] * vy) * rest
    cp, sp = np.cos(psi), np.sin(psi)  # (N, C)
    out = np.empty((n, k, 3, psi.shape[1]))
    for j in range(psi.shape[1]):  # (N, K, S) arrays per candidate and hypothesis
        ox = (cp[:, j : j + 1] * vo[:, 0:1] - sp[:, j : j + 1] * vo[:, 1:2])[:, :, None] * t
        oy = (sp[:, j : j + 1] * vo[:, 0:1] + cp[:, j : j + 1] * vo[:, 1:2])[:, :, None] * t
        for m in range(3):
            dx = r[:, :, 0:1] + disp[:, :, m, :, 0] - ox
            dy = r[:, :, 1:2] + disp[:, :, m, :, 1] - oy
            out[:, :, m, j] = np.hypot(dx, dy).min(axis=-1, initial=np.inf)
    out /= radius[:, None, None, None]
    return np.where(np.asarray(valid, dtype=bool)[:, :, None, None], out, np.inf)


def _sample_times(lookahead_s: float, step_s: float) -> np.ndarray:
    """The sample times (S,) s: every ``step_s`` from 0, and ``lookahead_s``."""
    return np.unique(np.append(np.arange(0.0, lookahead_s, step_s), lookahead_s))


def turned_path_min_ratio(
    own_velocity,
    rel_position,
    rel_velocity,
    valid,
    candidates,
    radius,
    lookahead_s: float,
    turn_rate,
    turn_s: float,
    step_s: float = 2.0,
):
    """(N, K, 3, C) minimum over the sampled look-ahead of the distance to intruder k, over
    ``radius``, under each of :data:`HYPOTHESES`, the ownship turned by candidate c (a numba
    kernel, one pass without temporaries; the arguments and result of
    :func:`turned_path_min_ratio_numpy`, the reference it is tested against)."""
    vo = np.ascontiguousarray(own_velocity, dtype=float)
    n, k = np.shape(valid)
    return _turned_kernel(
        vo,
        np.ascontiguousarray(rel_position, dtype=float),
        np.ascontiguousarray(rel_velocity, dtype=float),
        np.ascontiguousarray(valid, dtype=np.bool_),
        np.ascontiguousarray(candidates, dtype=float),
        kernel_array(radius, (n,)),
        np.ascontiguousarray(
            np.maximum(np.broadcast_to(np.asarray(turn_rate, dtype=float), (n,)), 1e-12)
        ),
        _sample_times(float(lookahead_s), float(step_s)),
        float(turn_s),
    )


@njit(cache=True)
def _turned_kernel(vo, r, v, valid, psi, radius, w, t, turn_s):  # pragma: no cover - compiled
    """:func:`turned_path_min_ratio_numpy`'s formulas per (ownship, candidate, intruder,
    hypothesis), the minimum over the sample times ``t`` (S,) s kept as a scalar; ``w``
    (N,) rad/s > 0, ``radius`` (N,) m."""
    n, k = valid.shape
    c_n = psi.shape[1]
    out = np.full((n, k, 3, c_n), np.inf)
    for a in range(n):
        for j in range(c_n):
            cp, sp = math.cos(psi[a, j]), math.sin(psi[a, j])
            ovx = cp * vo[a, 0] - sp * vo[a, 1]
            ovy = sp * vo[a, 0] + cp * vo[a, 1]
            for b in range(k):
                if not valid[a, b]:
                    continue
                vx = v[a, b, 0] + vo[a, 0]
                vy = v[a, b, 1] + vo[a, 1]
                for m in range(3):
                    sign = 0.0 if m == 0 else (1.0 if m == 1 else -1.0)
                    ww = sign * w[a]
                    best = np.inf
                    for i in range(t.size):
                        ti = t[i]
                        if m == 0:
                            dx, dy = vx * ti, vy * ti
                        else:
                            tau = min(ti, turn_s)
                            ang = ww * tau
                            c, s = math.cos(ang), math.sin(ang)
                            rest = ti - tau
                            dx = (s * vx - (1.0 - c) * vy) / ww + (c * vx - s * vy) * rest
                            dy = (s * vy + (1.0 - c) * vx) / ww + (s * vx + c * vy) * rest
                        ex = r[a, b, 0] + dx - ovx * ti
                        ey = r[a, b, 1] + dy - ovy * ti
                        d = math.sqrt(ex * ex + ey * ey)
                        if d < best:
                            best = d
                    out[a, b, m, j] = best / radius[a]
    return out
