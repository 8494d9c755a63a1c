"""Mode-aware band search: each candidate heading judged against every likely IMM mode's path.

``"bands"`` predicts an intruder straight along its tracked velocity, so an intruder that is
turning (another ownship resolving, an autopilot manoeuvring) is seen where it would be had
it stopped turning; in dense traffic most losses of ``"bands"`` come from pairs that are both
manoeuvring (issue 13). The IMM already predicts each mode's path (paper §VI, 4: the policy
asks the tracker for mode-conditioned predictions when the resolver declares
``uses_mode_predictions``). ``"bands-modes"`` keeps ``"bands"``' search, preference order and
detection and adds, for every intruder mode whose probability reaches ``mode_threshold``,
the distance from the ownship, turned by the candidate ψ, to that mode's predicted path
(:func:`mode_path_min_ratio`); a candidate is clear only if it clears the straight
prediction *and* every likely mode's path. Detection (``conflict``) stays the straight CPA
test, so the world's prefilter holds and alerting is that of ``"bands"``.

It is :class:`~airspace_sim.avoidance.roundabout.RoundaboutBandsResolver` with every
intruder given way to (``parallel_angle = π/2``; the convention can be switched back on) and
that resolver's generic search. Angles radians CCW from east, distances metres, times
seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from airspace_sim import registry
from airspace_sim.avoidance.roundabout import RoundaboutBandsResolver
from airspace_sim.geometry import rotate
from airspace_sim.parts import param


def mode_path_min_ratio(own_velocity, rel_position, xs, times_s, use, psi, radius, rows=32):
    """(N, C) min over the used (intruder, mode) paths of the distance to the ownship turned
    by ``psi`` (N, C) rad at once, divided by ``radius`` (m); ``inf`` where none is used.

    Each path is the polyline through the relative position now, ``rel_position`` (N, K, 2)
    m, and the IMM's mode-conditioned predictions ``xs`` (N, K, M, S, 2) m at ``times_s``
    (S,) s (intruder minus an ownship flying straight, :func:`~airspace_sim.world.policy.
    mode_predictions`); turning the ownship adds ``(v_o − R(ψ)·v_o)·t``. Between samples
    the relative track is taken straight (exact for the straight mode; a chord of the
    turning modes' arcs). ``use`` (N, K, M) bool; own_velocity (N, 2) m/s.
    """
    vo = np.asarray(own_velocity, dtype=float)
    psi = np.asarray(psi, dtype=float)
    n, k, m = use.shape
    t = np.concatenate([[0.0], np.asarray(times_s, dtype=float)])  # (S + 1,)
    pts = np.concatenate(
        [np.broadcast_to(rel_position[:, :, None, None, :], (n, k, m, 1, 2)), xs], axis=3
    )  # (N, K, M, S + 1, 2)
    out = np.full(psi.shape, np.inf)
    for a in range(0, n, rows):
        sl = slice(a, a + rows)
        dv = vo[sl, None, :] - rotate(vo[sl, None, :], np.nan_to_num(psi[sl]))  # (n, C, 2)
        # (n, C, K, M, S + 1, 2): the path as flown against the turned ownship
        q = pts[sl, None] + dv[:, :, None, None, None, :] * t[:, None]
        p0, seg = q[..., :-1, :], np.diff(q, axis=-2)
        L2 = np.einsum("...i,...i->...", seg, seg)
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.clip(-np.einsum("...i,...i->...", p0, seg) / L2, 0.0, 1.0)
        u = np.where(L2 > 0, u, 0.0)
        d = np.hypot(p0[..., 0] + u * seg[..., 0], p0[..., 1] + u * seg[..., 1]).min(axis=-1)
        d = np.where(use[sl, None], d / radius, np.inf)  # (n, C, K, M)
        out[sl] = d.reshape(d.shape[0], d.shape[1], -1).min(axis=-1, initial=np.inf)
    return out


@registry.register("resolver", "bands-modes")
class ModeAwareBandsResolver(RoundaboutBandsResolver):
    """``"bands"`` whose candidates must also clear each likely intruder mode's predicted
    path (module docstring)."""

    uses_mode_predictions = True

    @dataclass(frozen=True)
    class Params(RoundaboutBandsResolver.Params):
        parallel_angle: float = param(
            math.pi / 2,
            unit="rad",
            doc="right-of-way convention off at π/2 (every intruder given way to)",
            ge=0,
            le=math.pi / 2,
        )
        mode_threshold: float = param(
            0.2, doc="mode probability from which a mode's path is judged", gt=0, le=1
        )
        #: the loader fills dt (the prediction times are whole steps)
        dt: float = param(1.0, unit="s", doc="world step (prediction times)", gt=0, le=60.0)

    def _mode_ratio(self, vo, r, considered, mode_predictions):
        if mode_predictions is None:
            return None
        xs, _, mu = (np.asarray(a, dtype=float) for a in mode_predictions)
        S = xs.shape[-2]
        # the policy's sample times when [resolver] probability_horizon_s is unset: S evenly
        # spaced times up to the look-ahead, rounded to whole steps (the predictions do not
        # carry their times; with coarse steps and many samples the rounding merges some)
        steps = np.maximum(
            1, np.rint(self.params.lookahead_s * np.arange(1, S + 1) / S / self.params.dt)
        )
        if np.unique(steps).size != S:
            steps = np.unique(steps)[:S]
        use = considered[:, :, None] & (mu >= self.params.mode_threshold)
        radius = self.params.r_safe * (1.0 + self.params.margin)
        t = steps * self.params.dt
        return lambda psi: mode_path_min_ratio(vo, r, xs, t, use, psi, radius)
