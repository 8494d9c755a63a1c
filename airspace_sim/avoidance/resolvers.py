"""Conflict resolvers by name (issue 3; ``docs/dev/CONTRACTS.md``, "Resolvers").

``airspace_sim.registry.get("resolver", name)(**params)`` returns an object with

    resolve(own_velocity (N, 2), rel_position (N, K, 2), rel_velocity (N, K, 2),
            valid (N, K) bool, max_heading_change (N,) rad,
            mode_predictions=None, rel_covariance=None) -> ResolverOutput

``rel_*`` are intruder minus ownship in the world frame (m, m/s). ``heading_change`` is the
turn the ownship should make now, rad CCW positive (negative = right turn), with
``|heading_change| ≤ max_heading_change``. ``mode_predictions`` is used by
``"bands-probabilistic"`` only (format in :class:`ProbabilisticBandsResolver`);
``rel_covariance`` is accepted for the contract and ignored by the built-in resolvers.

The band resolvers judge a candidate as if the heading change were made at once; a caller
with a turn-rate limit can pass a wide ``max_heading_change`` (a target-heading search, as
DAIDALUS does) and turn toward the result at its own rate.

Names:

- ``"none"``: never turns; still reports ``conflict`` (CPA over the look-ahead) for metrics.
- ``"seed"``: the paper's rotation literally (§V): :func:`escape_angle` on the relative state,
  ``horizon`` steps of ``dt``, heading change ``= θ`` (the relative-frame reading). With
  several intruders the one whose predicted conflict comes first (then the nearest) governs.
- ``"seed-world"``: same detection and governing intruder, but the exact world-frame heading
  change of :func:`tangent_heading_change` (clamped; ``θ`` where the tangent is unreachable).
- ``"bands"``: the multi-intruder band search of :mod:`airspace_sim.avoidance.bands`
  (``left_penalty`` > 0, e.g. 10°, biases it toward right turns: on converging rings of 16
  aircraft that keeps every pair clear where the plain smallest-``|ψ|`` rule does not).
- ``"bands-probabilistic"``: bands over the intruders whose conflict probability
  (:mod:`airspace_sim.avoidance.probability`, from ``mode_predictions``) reaches
  ``threshold``; falls back to ``"bands"`` without ``mode_predictions``.

``r_safe`` defaults to 3000 m, the paper's ``R_safety`` (§VI), for every resolver; scenarios
set their own (e.g. 5 NM = 9260 m en route).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airspace_sim.avoidance.bands import DEFAULT_RESOLUTION, band_search
from airspace_sim.avoidance.escape import escape_angle, predicted_conflict
from airspace_sim.avoidance.heading import tangent_heading_change
from airspace_sim.avoidance.probability import conflict_probability, conflict_probability_bound
from airspace_sim.registry import register

#: The paper's safety radius R_safety, metres (§VI).
DEFAULT_R_SAFE = 3000.0


@dataclass
class ResolverOutput:
    """What a resolver decides for ``N`` ownships.

    heading_change : (N,) rad, CCW positive (negative = right turn).
    conflict : (N,) bool, a conflict is predicted at the current heading.
    candidates, band : (N, C) candidate heading changes (rad) and their clear flags, for
        rendering; ``None`` for resolvers without bands.
    probability : (N, K) conflict probability per intruder slot, or ``None``.
    min_ratio : (N, C) per candidate, minimum over intruders of CPA distance / clear radius
        (``-inf`` for unused slots), or ``None``; it may be given only on the rows where a
        side has no clear candidate (NaN elsewhere).
    first_clear : (N, 3) int, index in ``candidates`` of the first clear candidate with
        ``ψ ≤ 0``, ``ψ ≥ 0`` and ``ψ < 0`` (−1: none); best_blocked : (N, 2) int, on a side
        (``ψ ≤ 0``, ``ψ ≥ 0``) with no clear candidate, its candidate of largest minimum CPA
        ratio (−1 elsewhere). With ``candidates``, what a CDA policy needs to commit a turn
        side (resolvers with ``reports_band``).
    """

    heading_change: np.ndarray
    conflict: np.ndarray
    candidates: np.ndarray | None = None
    band: np.ndarray | None = None
    probability: np.ndarray | None = None
    min_ratio: np.ndarray | None = None
    first_clear: np.ndarray | None = None
    best_blocked: np.ndarray | None = None


def _arrays(own_velocity, rel_position, rel_velocity, valid, max_heading_change):
    vo = np.asarray(own_velocity, dtype=float).reshape(-1, 2)
    n = vo.shape[0]
    r = np.asarray(rel_position, dtype=float).reshape(n, -1, 2)
    v = np.asarray(rel_velocity, dtype=float).reshape(n, -1, 2)
    valid = np.asarray(valid, dtype=bool).reshape(n, -1)
    mx = np.broadcast_to(np.asarray(max_heading_change, dtype=float), (n,))
    return vo, r, v, valid, mx


class NoResolver:
    """Never turns; ``conflict`` is the CPA test of ``"bands"`` at the current heading."""

    prefilter = uses_mode_predictions = uses_turn_rate = reports_band = False

    def __init__(self, r_safe=DEFAULT_R_SAFE, lookahead_s=120.0, margin=0.0):
        self.r_safe, self.lookahead_s, self.margin = float(r_safe), float(lookahead_s), margin

    def resolve(
        self,
        own_velocity,
        rel_position,
        rel_velocity,
        valid,
        max_heading_change,
        mode_predictions=None,
        rel_covariance=None,
        turn_rate=None,
    ):
        vo, r, v, valid, mx = _arrays(
            own_velocity, rel_position, rel_velocity, valid, max_heading_change
        )
        res = band_search(
            vo,
            r,
            v,
            valid,
            np.zeros_like(mx),
            self.r_safe,
            self.lookahead_s,
            self.margin,
            exact_candidates=False,
        )
        return ResolverOutput(np.zeros(vo.shape[0]), res.conflict)


class SeedResolver:
    """The paper's escape rotation (§V), relative-frame reading: heading change = ``θ``.

    Parameters: ``r_safe`` (m, 3000), ``dt`` (prediction step, s; the seed preset's 0.1),
    ``horizon`` (steps, 3), ``max_angle`` (rad, π/4), ``world_frame`` (use the exact
    world-frame heading change instead of ``θ``).
    """

    prefilter = uses_mode_predictions = uses_turn_rate = reports_band = False

    def __init__(
        self, r_safe=DEFAULT_R_SAFE, dt=0.1, horizon=3, max_angle=np.pi / 4, world_frame=False
    ):
        self.r_safe, self.dt, self.horizon = float(r_safe), float(dt), int(horizon)
        self.max_angle, self.world_frame = float(max_angle), bool(world_frame)

    def resolve(
        self,
        own_velocity,
        rel_position,
        rel_velocity,
        valid,
        max_heading_change,
        mode_predictions=None,
        rel_covariance=None,
        turn_rate=None,
    ):
        vo, r, v, valid, mx = _arrays(
            own_velocity, rel_position, rel_velocity, valid, max_heading_change
        )
        n, k = valid.shape
        theta, pair_conflict = escape_angle(
            r, v, self.r_safe, self.dt, self.horizon, self.max_angle
        )
        pair_conflict &= valid
        # governing intruder: earliest predicted conflict step, then nearest
        first = np.full((n, k), self.horizon + 1.0)
        for j in range(self.horizon, 0, -1):  # small fixed horizon
            inside = predicted_conflict(r, v, self.r_safe, self.dt * j, 1)
            first = np.where(inside, float(j), first)
        dist = np.hypot(r[..., 0], r[..., 1])
        key = np.where(pair_conflict, first * 1e12 + dist, np.inf)
        conflict = pair_conflict.any(axis=-1)
        if k == 0:
            return ResolverOutput(np.zeros(n), conflict)
        gov = np.argmin(key, axis=-1)
        rows = np.arange(n)
        psi = theta[rows, gov]
        if self.world_frame:
            exact, ok = tangent_heading_change(vo, v[rows, gov] + vo, r[rows, gov], self.r_safe)
            psi = np.where(ok, np.clip(exact, -self.max_angle, self.max_angle), psi)
        psi = np.where(conflict, np.clip(psi, -mx, mx), 0.0)
        return ResolverOutput(psi, conflict)


class BandsResolver:
    """Multi-intruder band search (:func:`~airspace_sim.avoidance.bands.band_search`).

    Parameters: ``r_safe`` (m, 3000), ``lookahead_s`` (s, 120), ``margin`` (0.1: clear
    distance ``r_safe·(1+margin)``), ``resolution`` (rad, 1°), ``exact_candidates`` (True),
    ``left_penalty`` (rad, 0: left turns rank as ``|ψ| + left_penalty``, a right-turn bias),
    ``model_turn`` (False; True: when the caller passes ``turn_rate`` to :meth:`resolve`, each
    candidate is judged as flown, turning at that rate until reached, then straight; False:
    as if the heading changed at once), ``full_band`` (False; True: ``band`` and
    ``min_ratio`` of every candidate, for drawing or analysis; False: only what the choice
    needs, the same choice, much faster).
    """

    prefilter = uses_turn_rate = reports_band = True
    uses_mode_predictions = False

    def __init__(
        self,
        r_safe=DEFAULT_R_SAFE,
        lookahead_s=120.0,
        margin=0.1,
        resolution=DEFAULT_RESOLUTION,
        exact_candidates=True,
        left_penalty=0.0,
        model_turn=False,
        full_band=False,
    ):
        self.r_safe, self.lookahead_s, self.margin = float(r_safe), float(lookahead_s), margin
        self.resolution, self.exact_candidates = float(resolution), bool(exact_candidates)
        self.left_penalty = float(left_penalty)
        self.model_turn = bool(model_turn)
        self.full_band = bool(full_band)

    def _search(self, vo, r, v, valid, mx, r_safe, turn_rate=None):
        return band_search(
            vo,
            r,
            v,
            valid,
            mx,
            r_safe,
            self.lookahead_s,
            self.margin,
            self.resolution,
            self.exact_candidates,
            self.left_penalty,
            turn_rate if self.model_turn else None,
            full=self.full_band,
        )

    def resolve(
        self,
        own_velocity,
        rel_position,
        rel_velocity,
        valid,
        max_heading_change,
        mode_predictions=None,
        rel_covariance=None,
        turn_rate=None,
    ):
        vo, r, v, valid, mx = _arrays(
            own_velocity, rel_position, rel_velocity, valid, max_heading_change
        )
        res = self._search(vo, r, v, valid, mx, self.r_safe, turn_rate)
        return ResolverOutput(
            res.heading_change,
            res.conflict,
            res.candidates,
            res.band,
            min_ratio=res.min_ratio,
            first_clear=res.first_clear,
            best_blocked=res.best_blocked,
        )


class ProbabilisticBandsResolver(BandsResolver):
    """Bands over the intruders with ``P(conflict) ≥ threshold`` (paper §VI assumption 4).

    ``mode_predictions = (xs, Ps, mu)`` with ``xs`` (N, K, M, S, 2) mode-conditioned predicted
    relative positions (m), ``Ps`` (N, K, M, S, 2, 2) their covariances (m²), ``mu`` (N, K, M)
    mode probabilities. ``P(conflict)`` uses radius ``r_safe`` (no margin). Pairs below the
    threshold are ignored by the band search; ``conflict`` is "some valid pair reaches the
    threshold". Without ``mode_predictions`` it behaves as ``"bands"``. The output's
    ``probability`` is exact where a closed-form upper bound
    (:func:`~airspace_sim.avoidance.probability.conflict_probability_bound`) reaches the
    threshold, and that bound (below the threshold) elsewhere.
    """

    prefilter = False
    uses_mode_predictions = True

    def __init__(self, threshold=0.05, **params):
        super().__init__(**params)
        self.threshold = float(threshold)

    def resolve(
        self,
        own_velocity,
        rel_position,
        rel_velocity,
        valid,
        max_heading_change,
        mode_predictions=None,
        rel_covariance=None,
        turn_rate=None,
    ):
        if mode_predictions is None:
            return super().resolve(
                own_velocity,
                rel_position,
                rel_velocity,
                valid,
                max_heading_change,
                turn_rate=turn_rate,
            )
        vo, r, v, valid, mx = _arrays(
            own_velocity, rel_position, rel_velocity, valid, max_heading_change
        )
        xs, ps, mu = (np.asarray(a, dtype=float) for a in mode_predictions)
        xs = np.broadcast_to(xs, valid.shape + xs.shape[-3:])
        ps = np.broadcast_to(ps, valid.shape + ps.shape[-4:])
        mu = np.broadcast_to(mu, valid.shape + mu.shape[-1:])
        # the quadrature only where the closed-form upper bound can reach the threshold
        prob = np.where(valid, conflict_probability_bound(xs, ps, mu, self.r_safe), 0.0)
        need = valid & (prob >= self.threshold)
        if need.any():
            prob[need] = conflict_probability(xs[need], ps[need], mu[need], self.r_safe)
        threat = valid & (prob >= self.threshold)
        res = self._search(vo, r, v, threat, mx, self.r_safe, turn_rate)
        return ResolverOutput(
            res.heading_change,
            threat.any(axis=-1),
            res.candidates,
            res.band,
            prob,
            res.min_ratio,
            res.first_clear,
            res.best_blocked,
        )


register("resolver", "none")(NoResolver)
register("resolver", "seed")(SeedResolver)
register("resolver", "bands")(BandsResolver)
register("resolver", "bands-probabilistic")(ProbabilisticBandsResolver)


@register("resolver", "seed-world")
def _seed_world(**params):
    """``"seed"`` with the exact world-frame heading change (``world_frame=True``)."""
    return SeedResolver(world_frame=True, **params)
