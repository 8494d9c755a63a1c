"""The built-in conflict resolvers (paper §V; protocol :class:`airspace_sim.parts.Resolver`).

Each is a class registered by name, constructed as ``cls(params)`` with its ``Params``
dataclass (fields with units and valid ranges, validated by the scenario loader), and
declares its capabilities (``uses_mode_predictions``, ``uses_turn_rate``, ``prefilter``,
``reports_band``) instead of being recognised by name::

    resolve(own_velocity (N, 2), rel_position (N, K, 2), rel_velocity (N, K, 2),
            valid (N, K) bool, max_heading_change (N,) rad, *,
            mode_predictions=None, turn_rate=None) -> ResolverOutput

``rel_*`` are intruder minus ownship in the world frame (m, m/s). ``heading_change`` is the
turn the ownship should make now, rad CCW positive (negative = right turn), with
``|heading_change| ≤ max_heading_change``.

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
  (``left_penalty`` > 0 biases it toward right turns; see ``docs/tuning.md``).
- ``"bands-probabilistic"``: bands over the intruders whose conflict probability
  (:mod:`airspace_sim.avoidance.probability`, from ``mode_predictions``) reaches
  ``threshold``; falls back to ``"bands"`` without ``mode_predictions``.

``r_safe`` defaults to 3000 m, the paper's ``R_safety`` (§VI), for every resolver; scenarios
set their own (e.g. 5 NM = 9260 m en route). :func:`build_resolver` makes a scenario's
resolver.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airspace_sim import parts, registry
from airspace_sim.avoidance.bands import DEFAULT_RESOLUTION, band_search
from airspace_sim.avoidance.escape import escape_angle, predicted_conflict
from airspace_sim.avoidance.heading import tangent_heading_change
from airspace_sim.avoidance.probability import conflict_probability, conflict_probability_bound
from airspace_sim.parts import param

#: The paper's safety radius R_safety, metres (§VI).
DEFAULT_R_SAFE = 3000.0

#: Physically meaningful bounds shared by the resolvers' parameters.
MAX_R_SAFE_M = 1e6
MAX_LOOKAHEAD_S = 3600.0
MAX_MARGIN = 10.0


def _r_safe(default=DEFAULT_R_SAFE):
    return param(default, unit="m", doc="safety radius", gt=0, le=MAX_R_SAFE_M)


def _lookahead(default=120.0):
    return param(default, unit="s", doc="look-ahead of the CPA test", gt=0, le=MAX_LOOKAHEAD_S)


def _margin(default):
    return param(default, doc="extra fraction of r_safe kept clear", ge=0, le=MAX_MARGIN)


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
    speed_target : (N,) m/s, the ground speed to fly with ``heading_change`` (resolvers with
        ``advises_speed``; NaN: no speed advice), or ``None``; candidate_speed : (N, C) m/s,
        the ground speed to fly with each candidate (with ``reports_band``: the CDA policy
        takes the one of the candidate it commits), or ``None``.
    """

    heading_change: np.ndarray
    conflict: np.ndarray
    candidates: np.ndarray | None = None
    band: np.ndarray | None = None
    probability: np.ndarray | None = None
    min_ratio: np.ndarray | None = None
    first_clear: np.ndarray | None = None
    best_blocked: np.ndarray | None = None
    speed_target: np.ndarray | None = None
    candidate_speed: np.ndarray | None = None


def _arrays(own_velocity, rel_position, rel_velocity, valid, max_heading_change):
    vo = np.asarray(own_velocity, dtype=float).reshape(-1, 2)
    n = vo.shape[0]
    r = np.asarray(rel_position, dtype=float).reshape(n, -1, 2)
    v = np.asarray(rel_velocity, dtype=float).reshape(n, -1, 2)
    valid = np.asarray(valid, dtype=bool).reshape(n, -1)
    mx = np.broadcast_to(np.asarray(max_heading_change, dtype=float), (n,))
    return vo, r, v, valid, mx


@registry.register("resolver", "none")
class NoResolver(parts.Resolver):
    """Never turns; ``conflict`` is the CPA test of ``"bands"`` at the current heading."""

    @dataclass(frozen=True)
    class Params:
        r_safe: float = _r_safe()
        lookahead_s: float = _lookahead()
        margin: float = _margin(0.0)

    def resolve(
        self,
        own_velocity,
        rel_position,
        rel_velocity,
        valid,
        max_heading_change,
        *,
        mode_predictions=None,
        turn_rate=None,
    ):
        p = self.params
        vo, r, v, valid, mx = _arrays(
            own_velocity, rel_position, rel_velocity, valid, max_heading_change
        )
        res = band_search(
            vo,
            r,
            v,
            valid,
            np.zeros_like(mx),
            p.r_safe,
            p.lookahead_s,
            p.margin,
            exact_candidates=False,
        )
        return ResolverOutput(np.zeros(vo.shape[0]), res.conflict)


@registry.register("resolver", "seed")
class SeedResolver(parts.Resolver):
    """The paper's escape rotation (§V), relative-frame reading: heading change = ``θ``."""

    #: use the exact world-frame heading change instead of ``θ`` (``"seed-world"``)
    world_frame = False

    @dataclass(frozen=True)
    class Params:
        r_safe: float = _r_safe()
        #: the seed preset's step; in a world the loader fills the world's dt
        dt: float = param(0.1, unit="s", doc="prediction step", gt=0, le=60.0)
        horizon: int = param(3, unit="steps", doc="look-ahead of the detector", ge=1, le=1000)
        max_angle: float = param(
            float(np.pi / 4), unit="rad", doc="bound on the rotation θ", gt=0, le=float(np.pi)
        )

    def resolve(
        self,
        own_velocity,
        rel_position,
        rel_velocity,
        valid,
        max_heading_change,
        *,
        mode_predictions=None,
        turn_rate=None,
    ):
        p = self.params
        vo, r, v, valid, mx = _arrays(
            own_velocity, rel_position, rel_velocity, valid, max_heading_change
        )
        n, k = valid.shape
        theta, pair_conflict = escape_angle(r, v, p.r_safe, p.dt, p.horizon, p.max_angle)
        pair_conflict &= valid
        # governing intruder: earliest predicted conflict step, then nearest
        first = np.full((n, k), p.horizon + 1.0)
        for j in range(p.horizon, 0, -1):  # small fixed horizon
            inside = predicted_conflict(r, v, p.r_safe, p.dt * j, 1)
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
            exact, ok = tangent_heading_change(vo, v[rows, gov] + vo, r[rows, gov], p.r_safe)
            psi = np.where(ok, np.clip(exact, -p.max_angle, p.max_angle), psi)
        psi = np.where(conflict, np.clip(psi, -mx, mx), 0.0)
        return ResolverOutput(psi, conflict)


@registry.register("resolver", "seed-world")
class SeedWorldResolver(SeedResolver):
    """``"seed"`` with the exact world-frame heading change onto the tangent
    (:func:`~airspace_sim.avoidance.heading.tangent_heading_change`, clamped to
    ``max_angle``; ``θ`` where the tangent is unreachable)."""

    world_frame = True


@registry.register("resolver", "bands")
class BandsResolver(parts.Resolver):
    """Multi-intruder band search (:func:`~airspace_sim.avoidance.bands.band_search`).

    With ``model_turn`` and a ``turn_rate`` from the caller each candidate is judged as
    flown (turning at that rate until reached, then straight); otherwise as if the heading
    changed at once.
    """

    uses_turn_rate = True
    prefilter = True
    reports_band = True
    uses_committed_side = True

    @dataclass(frozen=True)
    class Params:
        r_safe: float = _r_safe()
        lookahead_s: float = _lookahead()
        margin: float = _margin(0.1)
        resolution: float = param(
            DEFAULT_RESOLUTION, unit="rad", doc="candidate spacing", gt=0, le=float(np.pi / 2)
        )
        exact_candidates: bool = param(True, doc="add the exact band edges as candidates")
        left_penalty: float = param(
            0.0, unit="rad", doc="left turns rank as |ψ| + left_penalty", ge=0, le=float(np.pi)
        )
        model_turn: bool = param(False, doc="judge candidates as flown at turn_rate")
        full_band: bool = param(
            False,
            doc="band and min_ratio of every candidate (for drawing or analysis); false: "
            "only what the choice needs, the same choice, much faster",
        )

    def _search(self, vo, r, v, valid, mx, r_safe, turn_rate=None, committed_side=None):
        p = self.params
        return band_search(
            vo,
            r,
            v,
            valid,
            mx,
            r_safe,
            p.lookahead_s,
            p.margin,
            p.resolution,
            p.exact_candidates,
            p.left_penalty,
            turn_rate if p.model_turn else None,
            full=p.full_band,
            committed_side=committed_side,
        )

    def resolve(
        self,
        own_velocity,
        rel_position,
        rel_velocity,
        valid,
        max_heading_change,
        *,
        mode_predictions=None,
        turn_rate=None,
        committed_side=None,
    ):
        vo, r, v, valid, mx = _arrays(
            own_velocity, rel_position, rel_velocity, valid, max_heading_change
        )
        res = self._search(vo, r, v, valid, mx, self.params.r_safe, turn_rate, committed_side)
        return ResolverOutput(
            res.heading_change,
            res.conflict,
            res.candidates,
            res.band,
            min_ratio=res.min_ratio,
            first_clear=res.first_clear,
            best_blocked=res.best_blocked,
        )


@registry.register("resolver", "bands-probabilistic")
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

    uses_mode_predictions = True
    #: the conflict test is on probabilities, not the CPA test alone
    prefilter = False

    @dataclass(frozen=True)
    class Params(BandsResolver.Params):
        threshold: float = param(
            0.05, doc="conflict probability at which an intruder counts", gt=0, le=1
        )

    def resolve(
        self,
        own_velocity,
        rel_position,
        rel_velocity,
        valid,
        max_heading_change,
        *,
        mode_predictions=None,
        turn_rate=None,
        committed_side=None,
    ):
        if mode_predictions is None:
            return super().resolve(
                own_velocity,
                rel_position,
                rel_velocity,
                valid,
                max_heading_change,
                turn_rate=turn_rate,
                committed_side=committed_side,
            )
        vo, r, v, valid, mx = _arrays(
            own_velocity, rel_position, rel_velocity, valid, max_heading_change
        )
        xs, ps, mu = (np.asarray(a, dtype=float) for a in mode_predictions)
        xs = np.broadcast_to(xs, valid.shape + xs.shape[-3:])
        ps = np.broadcast_to(ps, valid.shape + ps.shape[-4:])
        mu = np.broadcast_to(mu, valid.shape + mu.shape[-1:])
        # the quadrature only where the closed-form upper bound can reach the threshold
        r_safe, threshold = self.params.r_safe, self.params.threshold
        prob = np.where(valid, conflict_probability_bound(xs, ps, mu, r_safe), 0.0)
        need = valid & (prob >= threshold)
        if need.any():
            prob[need] = conflict_probability(xs[need], ps[need], mu[need], r_safe)
        threat = valid & (prob >= threshold)
        res = self._search(vo, r, v, threat, mx, r_safe, turn_rate, committed_side)
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


def build_resolver(scenario):
    """The scenario's resolver, constructed from its validated parameters (no checks here).

    The loader (:func:`airspace_sim.scenarios.loader.resolver_params`) fills the ``Params``
    fields ``r_safe``, ``lookahead_s``, ``margin`` and ``dt`` from the scenario when the
    resolver declares them, ``resolver.params`` on top, and has validated the result.
    """
    from airspace_sim.scenarios.loader import resolver_params

    return registry.build("resolver", scenario.resolver.kind, params=resolver_params(scenario))


# resolvers kept in their own modules: registered here so that importing this one is enough
from airspace_sim.avoidance.reciprocal import ReciprocalBandsResolver  # noqa: E402

registry.register("resolver", "bands-reciprocal")(ReciprocalBandsResolver)
