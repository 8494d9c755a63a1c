"""Positions that are not reports: glitches far to the side of the track, and interpolations.

In the traffic samples' ``collections/switzerland`` about one 10 s position in a thousand lies
0.5–3 km to the side of a straight track while the recorded track angle does not move, and
the next position is back on it. Flown as recorded, such a report is a jump of kilometres and
back; smoothed into a tracker's truth, a jog of ±2–4 °/s over half a minute that no aircraft
flew (docs/tracking.md, "Glitches and segment ends"). :func:`despike` finds them by
:func:`track_residual`; :func:`airspace_sim.recorded.read` drops them unless told to keep
them. Some files also hold positions interpolated on a straight line between reports:
:func:`reported` tells them apart (for a tracker's truth, which should rest on the reports).
Plain numpy: no extra needed.
"""

from __future__ import annotations

import numpy as np

#: A recorded position farther than this (m) across the track from the path its neighbours
#: fly is a glitch (:func:`despike`).
SPIKE_M = 500.0
#: Positions are judged against their neighbours within runs without a longer silence (s).
RUN_GAP_S = 30.0


def track_residual(t, x, y):
    """How far each recorded position is across the track from the path its neighbours
    fly: (K,) m, NaN for the first and last two. t (K,) s increasing, x, y (K,) m.

    The least-squares quadratic in time through the two positions before and the two after
    gives the position expected at ``t_i`` and the direction of flight there; the residual
    is the distance across that direction. A turn at a steady rate leaves only its
    fourth-order term (4 v ω³ Δt⁴ / 24: 55 m for 3 °/s at 240 m/s, Δt = 10 s between
    reports), one begun at once 130 m; a timing error moves a position along the track, not
    across it."""
    t, x, y = (np.asarray(v, dtype=float) for v in (t, x, y))
    out = np.full(t.size, np.nan)
    if t.size < 5:
        return out
    i = np.arange(2, t.size - 2)
    nodes = i[:, None] + np.array([-2, -1, 1, 2])
    tau = t[nodes] - t[i, None]
    V = np.stack([np.ones_like(tau), tau, tau**2], axis=-1)  # (K-4, 4, 3)
    fit = np.linalg.pinv(V)  # (K-4, 3, 4): least-squares coefficients of the quadratic
    cx = np.einsum("kpj,kj->kp", fit, x[nodes])
    cy = np.einsum("kpj,kj->kp", fit, y[nodes])
    rx, ry = x[i] - cx[:, 0], y[i] - cy[:, 0]
    speed = np.maximum(np.hypot(cx[:, 1], cy[:, 1]), 1e-9)
    out[i] = np.abs(rx * cy[:, 1] - ry * cx[:, 1]) / speed
    return out


def local_peaks(r) -> np.ndarray:
    """(K,) bool: where ``r`` (K,) (NaN as 0) is the largest within two places either side."""
    v = np.nan_to_num(np.asarray(r, dtype=float))
    padded = np.pad(v, 2)
    top = np.ones(v.size, dtype=bool)
    for s in (-2, -1, 1, 2):
        top &= v >= padded[2 + s : 2 + s + v.size]
    return top


def despike(t, x, y, spike_m: float = SPIKE_M):
    """Indices (K',) of the recorded positions to keep: all but the glitches, positions
    over ``spike_m`` m across the track from the path of their neighbours
    (:func:`track_residual`), judged within runs without a silence over :data:`RUN_GAP_S`.
    A glitch also pulls its neighbours' paths, so only the largest residual within two
    positions either side (:func:`local_peaks`) is dropped, and the check is repeated until
    no glitch is left. Not judged: a run's first and last two positions; two glitches side by
    side on the same side (each pulls the other's path by two thirds)."""
    t, x, y = (np.asarray(v, dtype=float) for v in (t, x, y))
    cuts = np.flatnonzero(np.diff(t) > RUN_GAP_S) + 1
    kept = []
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, t.size]):
        keep = np.arange(a, b)
        while True:
            r = track_residual(t[keep], x[keep], y[keep])
            bad = (np.nan_to_num(r) > spike_m) & local_peaks(r)
            if not bad.any():
                break
            keep = keep[~bad]
        kept.append(keep)
    return np.concatenate(kept) if kept else np.zeros(0, dtype=int)


#: A position within this (m) of the straight-line interpolation of its neighbours, at its
#: time, is taken for an interpolated one (:func:`reported`).
INTERPOLATED_M = 0.5


def reported(t, x, y, max_gap_s: float = RUN_GAP_S) -> np.ndarray:
    """Indices (K',) of the positions to build a path through: the reports, and the
    interpolated positions of long straight stretches. t (K,) s increasing, x, y (K,) m.

    A position is *interpolated* when it lies, to within :data:`INTERPOLATED_M`, where the
    straight line between its neighbours puts it at its time. A run of such positions is
    dropped when the positions either side of it are at most ``max_gap_s`` apart (a path
    through the reports then rests on reports close in time), kept otherwise (a long
    straight stretch stays as recorded). The first and last positions are kept.

    Why: about half of the traffic samples' calibration positions (every 5 s) are such
    interpolations between reports 10–25 s apart. In a turn they make a polygon: straight
    chords at a constant step and corners, which a smoothed truth turns into rate spikes of
    8 °/s and speed dips of 30 m/s while the aircraft's reported track turns steadily
    (docs/tracking.md, "Reports and interpolated positions")."""
    t, x, y = (np.asarray(v, dtype=float) for v in (t, x, y))
    on_line = np.zeros(t.size, dtype=bool)
    if t.size > 2:
        w = (t[1:-1] - t[:-2]) / (t[2:] - t[:-2])
        ex = x[:-2] + w * (x[2:] - x[:-2]) - x[1:-1]
        ey = y[:-2] + w * (y[2:] - y[:-2]) - y[1:-1]
        on_line[1:-1] = np.hypot(ex, ey) <= INTERPOLATED_M
    keep = ~on_line
    starts = np.flatnonzero(on_line & ~np.r_[False, on_line[:-1]])
    ends = np.flatnonzero(on_line & ~np.r_[on_line[1:], False])
    for a, b in zip(starts, ends):  # the run a..b, between the kept a - 1 and b + 1
        if t[b + 1] - t[a - 1] > max_gap_s:
            keep[a : b + 1] = True
    return np.flatnonzero(keep)
