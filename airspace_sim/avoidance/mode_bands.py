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


def mode_path_min_ratio(own_velocity, rel_position, xs, times_s, use, psi, radius, chunk=2048):
    """(N, C) min over the used (intruder, mode) paths of the distance to the ownship turned
    by ``psi`` (N, C) rad at once, divided by ``radius`` (m); ``inf`` where none is used.

    Each path is the polyline through the relative position now, ``rel_position`` (N, K, 2)
    m, and the IMM's mode-conditioned predictions ``xs`` (N, K, M, S, 2) m at ``times_s``
    (S,) s (intruder minus an ownship flying straight, :func:`~airspace_sim.world.policy.
    mode_predictions`); turning the ownship adds ``(v_o − R(ψ)·v_o)·t``. Between samples
    the relative track is taken straight (exact for the straight mode; a chord of the
    turning modes' arcs). ``use`` (N, K, M) bool; own_velocity (N, 2) m/s.

    A path that no heading change can bring within ``radius`` (``|x_s| − 2|v_o|·t_s >
    radius`` at every sample, ``|v_o − R(ψ)v_o| ≤ 2|v_o|``) is left out: it reports ``inf``
    instead of its ratio, which is above 1 for every candidate (so every clear/blocked
    verdict and every blocked candidate's ratio is the exact one). The rest are evaluated
    ``chunk`` paths at a time (memory ~ chunk·C·S).
    """
    vo = np.asarray(own_velocity, dtype=float)
    psi = np.asarray(psi, dtype=float)
    xs = np.asarray(xs, dtype=float)
    r = np.asarray(rel_position, dtype=float)
    t = np.asarray(times_s, dtype=float)
    out = np.full(psi.shape, np.inf)
    reach = 2.0 * np.hypot(vo[:, 0], vo[:, 1])[:, None, None, None] * t  # (N, 1, 1, S)
    near = (np.hypot(xs[..., 0], xs[..., 1]) - reach <= radius).any(axis=-1)
    near |= (np.hypot(r[..., 0], r[..., 1]) <= radius)[..., None]
    own, kk, mm = np.nonzero(np.asarray(use, dtype=bool) & near)
    t0 = np.concatenate([[0.0], t])  # (S + 1,)
    for a in range(0, own.size, chunk):
        o, k, m = own[a : a + chunk], kk[a : a + chunk], mm[a : a + chunk]
        pts = np.concatenate([r[o, k][:, None, :], xs[o, k, m]], axis=1)  # (P, S + 1, 2)
        dv = vo[o, None, :] - rotate(vo[o, None, :], np.nan_to_num(psi[o]))  # (P, C, 2)
        q = pts[:, None] + dv[:, :, None, :] * t0[:, None]  # (P, C, S + 1, 2)
        p0, seg = q[..., :-1, :], np.diff(q, axis=-2)
        L2 = np.einsum("...i,...i->...", seg, seg)
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.clip(-np.einsum("...i,...i->...", p0, seg) / L2, 0.0, 1.0)
        u = np.where(L2 > 0, u, 0.0)
        d = np.hypot(p0[..., 0] + u * seg[..., 0], p0[..., 1] + u * seg[..., 1]).min(axis=-1)
        np.minimum.at(out, o, d / radius)  # (P, C) into the owners' rows
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
        mode_horizon_s: float | None = param(
            None,
            unit="s",
            doc="judge the mode paths only this far ahead (unset: the whole look-ahead)",
            gt=0,
            le=3600.0,
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
        if self.params.mode_horizon_s is not None:
            # a turn mode predicts the turn going on for ever; manoeuvres end: near term only
            keep = t <= self.params.mode_horizon_s + 1e-9
            xs, t = xs[..., keep, :], t[keep]
            if t.size == 0:
                return None
        return lambda psi: mode_path_min_ratio(vo, r, xs, t, use, psi, radius)
