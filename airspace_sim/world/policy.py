"""The world's conflict detection and avoidance (CDA) policy: one object, all of its state.

:class:`AvoidancePolicy` owns everything the CDA rotation (paper §V) needs between steps:
the advice and conflict flags of every aircraft, the committed turn side, the time since the
side was last needed, the time spent off the route and the encounters of the last
detection (for the resume check). The world calls it twice per step and nothing else
reaches into it:

- :meth:`AvoidancePolicy.override` (commands phase): an avoiding ownship in conflict turns
  by its advice; one that is clear turns back toward its autopilot's desired heading only if
  that turn keeps clear, else it holds its heading;
- :meth:`AvoidancePolicy.advise` (detection phase): the confirmed tracks of every tracking
  ownship are gathered into per-ownship arrays (:func:`.control.gather`), the resolver runs
  on them (asking the track table for mode predictions when the resolver uses them), and
  the turn side is committed.

Policy knobs live in ``scenario.resolver`` (``search_deg``, ``turn_preference``,
``confirm_s``, ``resume_margin``, ``resume_decay_s``, ``resume_margin_floor``,
``resume_rule``, ``resume_turn_s``,
``resume_turn_clear``, ``resume_off_course_deg``, ``route_side_off_course_deg``,
``side_memory_s``,
``probability_horizon_s``, ``probability_samples``); why they have the values they have is
in ``docs/tuning.md``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from airspace_sim.avoidance import resume_heading_change
from airspace_sim.avoidance.bands import CLEAR_TOLERANCE
from airspace_sim.avoidance.cpa import cpa_min_ratio, cpa_pair_ratios
from airspace_sim.avoidance.resolvers import build_resolver
from airspace_sim.avoidance.turn_paths import turned_path_min_ratio
from airspace_sim.geometry import wrap_angle
from airspace_sim.tracking.prediction import relative_positions
from airspace_sim.world.control import Encounters, gather, screen

#: rad: an autopilot turn smaller than this per step is "on course" (a route autopilot's
#: atan2 gives ~1e-16 rad/s on a straight leg, which must not count as turning back)
TURN_TOLERANCE = 1e-9

#: fractions of the autopilot's turn back tried by the "partial" and "no-worse" resume rules,
#: largest first; the last, 0, is holding the heading
RESUME_FRACTIONS = np.array([1.0, 0.5, 0.25, 0.0])
#: relative: a pair whose closest point over the look-ahead is within this of its current
#: distance is diverging (the "diverging" resume rule; absorbs rounding of the CPA kernel)
DIVERGING_TOLERANCE = 1e-9


#: rad: an aircraft's intent heading that moves by no more than this has held (1°)
INTENT_TOLERANCE = math.radians(1.0)


class AvoidancePolicy:
    """CDA for all N aircraft of a world (see the module docstring).

    Parameters
    ----------
    scenario : the validated :class:`~airspace_sim.scenarios.Scenario`.
    dt : world step, s.
    avoid : (N,) bool, aircraft that fly the advice (``AircraftSpec.avoid`` and not agents).
    tracking : (N,) bool, aircraft whose tracks are gathered and advised (avoiding
        ownships and RL agents, whose observation holds the advice).

    Attributes (read-only outside this class)
    -----------------------------------------
    advice : (N,) rad, heading change for the coming step (CCW positive).
    conflict : (N,) bool, a conflict is predicted at the current heading.
    side : (N,) committed turn side, −1 right, +1 left, 0 none.
    off_route_s : (N,) s since the aircraft last flew its autopilot without a pending turn
        back.
    following : (N,) bool, the aircraft flew the policy (advice or hold) in the last step.
    desired_heading : (N,) rad, the autopilots' desired headings given to the last
        :meth:`override` (NaN: none), read by the next detection's route side.
    held_heading : (N,) rad, the absolute heading advised at the last detection to an
        ownship in conflict (current heading + its chosen heading change), NaN elsewhere;
        given back to resolvers with ``uses_held_heading``.
    intent_heading : (N,) rad, the absolute heading each aircraft flying the policy steers
        to in the current step (its held advised heading while it follows the advice in
        conflict, its current heading while it holds or part-resumes, its autopilot's desired
        heading otherwise), NaN for aircraft that do not fly the policy or have no desired
        heading: the intent an equipped aircraft broadcasts, given (as each intruder slot's
        heading change from its track's heading) to resolvers with ``uses_intruder_intent``.
    intent_age_s : (N,) s, how long each aircraft's intent has held within
        :data:`INTENT_TOLERANCE` (0 when it changes, appears or goes).
    speed_target : (N,) m/s, the ground speed a resolver with ``advises_speed`` advised with
        the heading; set at each detection in conflict, kept while the aircraft flies the
        policy (advice or a held heading), NaN (its own speed) once it flies its autopilot
        again. The world flies it within the aircraft's acceleration limit.
    speed_limits : (N, 2) m/s, the lowest and highest ground speed each aircraft may be
        advised (equal: heading only); max_acceleration : (N,) m/s².
    r_safe, lookahead_s, margin : the resolver's clear radius ``r_safe·(1 + margin)`` and
        look-ahead, m, s, -.
    """

    PREFERENCES = ("right", "nearest", "none")

    def __init__(
        self, scenario, dt: float, avoid, tracking, speed_limits=None, max_acceleration=None
    ):
        spec = scenario.resolver
        self.resolver = build_resolver(scenario)
        self.dt = float(dt)
        # the resolver's geometry: the scenario's, unless resolver.params overrides it
        given = spec.params
        self.r_safe = float(given.get("r_safe", scenario.separation.r_safe))
        self.lookahead_s = float(given.get("lookahead_s", spec.lookahead))
        self.margin = float(given.get("margin", spec.margin))
        self.search_range = math.radians(float(spec.search_deg))
        self.resume_margin = float(spec.resume_margin)
        self.resume_decay_s = None if spec.resume_decay_s is None else float(spec.resume_decay_s)
        self.resume_margin_floor = float(spec.resume_margin_floor)
        self.resume_rule = spec.resume_rule
        self.resume_turn_s = float(spec.resume_turn_s)
        self.resume_turn_clear = bool(spec.resume_turn_clear)
        off = spec.resume_off_course_deg
        #: rad off the autopilot's heading from which the no-worse comparison is waived
        self.resume_off_course = None if off is None else math.radians(float(off))
        off = spec.route_side_off_course_deg
        #: rad off the autopilot's heading from which an ownship in conflict turns to the
        #: side of its route
        self.route_side_off_course = None if off is None else math.radians(float(off))
        self.confirm_steps = math.ceil(float(spec.confirm_s) / dt - 1e-9)
        self.preference = spec.turn_preference
        self.memory_steps = max(math.ceil(float(spec.side_memory_s) / dt - 1e-9), 1)
        horizon = (
            self.lookahead_s if spec.probability_horizon_s is None else spec.probability_horizon_s
        )
        S = int(spec.probability_samples)
        #: s ahead at which mode predictions are taken (resolvers that use them)
        self.prediction_times_s = float(horizon) * np.arange(1, S + 1) / S
        #: "none" only reports conflicts; every other resolver's advice is flown
        self.overrides = spec.kind != "none"

        self.avoid = np.asarray(avoid, dtype=bool)
        self.tracking = np.asarray(tracking, dtype=bool)
        n = self.avoid.size
        self.advice = np.zeros(n)
        self.conflict = np.zeros(n, dtype=bool)
        self.side = np.zeros(n)
        self.off_route_s = np.zeros(n)
        self.following = np.zeros(n, dtype=bool)
        self.held_heading = np.full(n, np.nan)
        self.desired_heading = np.full(n, np.nan)
        self.intent_heading = np.full(n, np.nan)
        self.intent_age_s = np.zeros(n)
        self.speed_target = np.full(n, np.nan)
        self.speed_limits = (
            np.zeros((n, 2)) if speed_limits is None else np.array(speed_limits, dtype=float)
        )
        self.max_acceleration = (
            np.zeros(n) if max_acceleration is None else np.array(max_acceleration, dtype=float)
        )
        self._clear_for = np.zeros(n, dtype=np.int64)
        self._encounters = Encounters.empty()

    def __setstate__(self, state):
        """Unpickle; a checkpoint from before ``held_heading``, ``resume_margin_floor``, speed
        advice, ``intent_heading``, ``resume_off_course`` and ``route_side_off_course``
        holds no held heading (NaN), a floor of 0, no speed advice, no intent (NaN), no
        off-course waiver and no route side (nor the autopilots' headings it reads)."""
        n = np.asarray(state["advice"]).size
        if "held_heading" not in state:
            state["held_heading"] = np.full(n, np.nan)
        state.setdefault("resume_margin_floor", 0.0)
        state.setdefault("resume_off_course", None)
        state.setdefault("route_side_off_course", None)
        if "desired_heading" not in state:
            state["desired_heading"] = np.full(n, np.nan)
        if "intent_heading" not in state:
            state["intent_heading"] = np.full(n, np.nan)
            state["intent_age_s"] = np.zeros(n)
        if "speed_target" not in state:
            state["speed_target"] = np.full(n, np.nan)
            state["speed_limits"] = np.zeros((n, 2))
            state["max_acceleration"] = np.zeros(n)
        self.__dict__.update(state)

    # ------------------------------------------------------------- commands
    def override(self, rate, desired, active, velocities, max_heading_change, avoid=None):
        """Commands phase: the autopilots' turn rates with the CDA policy applied.

        rate : (N,) rad/s from the autopilots; desired : (N,) rad, their desired headings
        (NaN: none); active : (N,) bool; velocities : (N, 2) m/s; max_heading_change : (N,)
        rad per step; avoid : (N,) bool, who flies the advice this step (default the
        ``avoid`` given at construction; the world adds RL agents that leave this step to
        the built-in pilot). Returns the new (N,) rad/s. Updates ``following`` and
        ``off_route_s`` and ``desired_heading``.
        """
        n = rate.size
        self.desired_heading = np.array(desired, dtype=float)
        follow = np.zeros(n, dtype=bool)
        resuming = np.zeros(n, dtype=bool)
        out = rate
        flying = (self.avoid if avoid is None else avoid) & active if self.overrides else None
        anyone = flying is not None and bool(flying.any())
        if anyone:
            follow = flying & self.conflict
            out = np.where(follow, self.advice / self.dt, rate)
            # resume toward the autopilot's heading only if that turn is clear
            resuming = (
                flying
                & ~self.conflict
                & np.isfinite(desired)
                & (np.abs(rate) * self.dt > TURN_TOLERANCE)
            )
            enc = self._encounters
            if resuming.any() and enc.owners.size:
                sub = enc.subset(resuming[enc.owners])
                if sub.owners.size:
                    turn = rate[sub.owners] * self.dt
                    if self.resume_rule == "hold":
                        clear = self._resume_clear(sub, velocities, turn, max_heading_change)
                        hold = sub.owners[~clear]
                        out[hold] = 0.0
                        follow[hold] = True
                    else:
                        frac = self._resume_fraction(
                            sub, velocities, turn, max_heading_change, desired[sub.owners]
                        )
                        part = frac < 1.0
                        cut = sub.owners[part]
                        out[cut] = np.where(frac[part] > 0.0, rate[cut] * frac[part], 0.0)
                        follow[cut] = True
        self.following = follow
        if anyone:
            heading = np.arctan2(velocities[:, 1], velocities[:, 0])
            steer = np.where(follow & self.conflict, self.held_heading, heading)
            intent = np.where(flying, np.where(follow, steer, desired), np.nan)
        else:
            intent = np.full(n, np.nan)
        same = np.abs(wrap_angle(intent - self.intent_heading)) <= INTENT_TOLERANCE
        self.intent_age_s = np.where(same, self.intent_age_s + self.dt, 0.0)
        self.intent_heading = intent
        # the advised speed is flown with the advice and the held heading, not the route
        self.speed_target[~follow] = np.nan
        if anyone:
            self.off_route_s = np.where(follow | resuming, self.off_route_s + self.dt, 0.0)
        else:  # nobody follows or resumes
            self.off_route_s = np.zeros(n)
        return out

    def _resume_extra(self, owners):
        """(n_own,) the resume clearance's extra fraction of r_safe for ``owners`` (n_own,)
        int: ``resume_margin``, shrinking linearly over ``resume_decay_s`` off the route to
        ``resume_margin_floor``."""
        extra = np.full(owners.size, self.resume_margin)
        if self.resume_decay_s is not None:
            left = np.clip(1.0 - self.off_route_s[owners] / self.resume_decay_s, 0.0, 1.0)
            floor = self.resume_margin_floor
            extra = floor + (extra - floor) * left
        return extra

    def _resume_clear(self, enc: Encounters, velocities, turn, max_heading_change):
        """(n_own,) bool: is the heading change ``turn`` (n_own,) rad clear for enc's
        ownships, by ``r_safe·(1 + margin + extra)`` (:meth:`_resume_extra`)."""
        vo = velocities[enc.owners]
        desired = np.arctan2(vo[:, 1], vo[:, 0]) + turn
        extra = self._resume_extra(enc.owners)
        _, clear = resume_heading_change(
            vo,
            desired,
            enc.rel_position,
            enc.rel_velocity,
            enc.valid,
            max_heading_change[enc.owners],
            r_safe=self.r_safe,
            lookahead_s=self.lookahead_s,
            margin=self.margin + extra,
        )
        return np.asarray(clear, dtype=bool)

    def _resume_fraction(self, enc: Encounters, velocities, turn, max_heading_change, desired=None):
        """(n_own,) fraction of the turn back ``turn`` (n_own,) rad, clipped to
        ``max_heading_change``, that enc's ownships fly under ``resume_rule`` (the largest
        of :data:`RESUME_FRACTIONS` that passes; 0 holds the heading). ``desired`` (n_own,)
        rad: their autopilots' headings (needed with ``resume_off_course_deg``).

        With R0 = r_safe·(1 + margin), R1 = r_safe·(1 + margin + extra) (``extra`` as in
        :meth:`_resume_clear`), ρ(ψ) the minimum CPA distance over the look-ahead divided by
        R1 (:func:`~airspace_sim.avoidance.cpa.cpa_min_ratio`, straight flight after the
        heading change ψ) and ρ_k(ψ) the same for intruder k alone:

        - "partial" passes ψ with ρ(ψ) ≥ 1 (the "hold" test on a smaller turn);
        - "no-worse" passes ψ with ρ(ψ)·R1 ≥ R0 (no conflict) and ρ_k(ψ) ≥ min(1, ρ_k(0))
          for every k: the turn keeps outside R1 every intruder that holding keeps outside
          it and brings none inside R1 closer than holding would, so an intruder already
          inside R1 and diverging no longer blocks the turn back for ever;
        - "diverging" is stricter: no conflict, and every intruder either outside R1 or
          diverging after the turn (its closest point is now: ρ_k(ψ) = |r_k|/R1);
        - "no-worse-turns" is "no-worse", and the same per-intruder test again for each
          intruder turning left and right at the ownship's turn limit for
          ``resume_turn_s`` (then straight), sampled every 2 s
          (:func:`~airspace_sim.avoidance.turn_paths.turned_path_min_ratio`): a neighbour
          that begins an avoidance turn now must not find the ownship closer than holding
          would have left it (capped at R1, or at R0 with ``resume_turn_clear``).

        With ``resume_off_course_deg`` set, an ownship at least that far off its autopilot's
        heading passes ψ under either "no-worse" rule on the no-conflict test alone.
        """
        vo = velocities[enc.owners]
        mx = max_heading_change[enc.owners]
        psi = np.clip(turn, -mx, mx)[:, None] * RESUME_FRACTIONS[None, :]
        extra = self._resume_extra(enc.owners)
        base = 1.0 + self.margin
        wide = base + extra
        radius = (self.r_safe * wide)[:, None]
        if self.resume_rule in ("no-worse", "diverging", "no-worse-turns"):
            # each (ownship, intruder) pair as its own row of the CPA kernel: (n, K, C)
            pair = cpa_pair_ratios(
                vo, enc.rel_position, enc.rel_velocity, enc.valid, psi, radius, self.lookahead_s
            )
            ratio = pair.min(axis=1, initial=np.inf)
            no_conflict = ratio * (wide / base)[:, None] >= 1.0 - CLEAR_TOLERANCE
            if self.resume_rule in ("no-worse", "no-worse-turns"):
                floor = np.minimum(pair[:, :, -1:], 1.0 - CLEAR_TOLERANCE)
            else:  # clear of R1, or closest now: the pair's current distance over R1
                now = np.hypot(enc.rel_position[..., 0], enc.rel_position[..., 1])
                now = now[:, :, None] / radius[:, :, None] * (1.0 - DIVERGING_TOLERANCE)
                floor = np.minimum(now, 1.0 - CLEAR_TOLERANCE)
            ok = no_conflict & (pair >= floor).all(axis=1)
            if self.resume_rule == "no-worse-turns":
                # the same judgement against each intruder turning left or right at the
                # ownship's own turn limit for resume_turn_s, sampled: (n, K, 3, C)
                paths = turned_path_min_ratio(
                    vo,
                    enc.rel_position,
                    enc.rel_velocity,
                    enc.valid,
                    psi,
                    radius[:, 0],
                    self.lookahead_s,
                    mx / self.dt,
                    self.resume_turn_s,
                )
                # capped at "hold"'s R1, or with resume_turn_clear at the clear radius R0
                cap = (base / wide)[:, None, None, None] if self.resume_turn_clear else 1.0
                worse = paths < np.minimum(paths[..., -1:], cap - CLEAR_TOLERANCE)
                ok &= ~worse.any(axis=(1, 2))
            if self.resume_off_course is not None and self.resume_rule != "diverging":
                if desired is None:
                    raise ValueError("resume_off_course_deg needs the autopilots' headings")
                # far off course, a turn back needs only to be conflict-free
                heading = np.arctan2(vo[:, 1], vo[:, 0])
                off = np.abs(wrap_angle(desired - heading)) >= self.resume_off_course
                ok |= no_conflict & off[:, None]
        else:
            ratio = cpa_min_ratio(
                vo, enc.rel_position, enc.rel_velocity, enc.valid, psi, radius, self.lookahead_s
            )
            ok = ratio >= 1.0 - CLEAR_TOLERANCE
        ok[:, -1] = True  # holding is always possible
        return RESUME_FRACTIONS[np.argmax(ok, axis=1)]

    # ------------------------------------------------------------ detection
    def advise(self, tracks, positions, velocities, active, max_heading_change):
        """Detection phase: the resolver on every tracking ownship's confirmed tracks.

        tracks : the world's :class:`~.trackers.TrackTable`; positions, velocities : (N, 2)
        true own states, m, m/s; active : (N,) bool; max_heading_change : (N,) rad per step.
        Sets and returns ``(advice (N,) rad, conflict (N,) bool)``.
        """
        n = self.advice.size
        view = tracks.view()
        ok = view.age >= self.confirm_steps  # a two-point track's first velocities are poor
        enc = gather(view.owner, view.x, positions, velocities, self.tracking & active, keep=ok)
        self._encounters = enc
        advice = np.zeros(n)
        conflict = np.zeros(n, dtype=bool)
        held = np.full(n, np.nan)
        res = self.resolver
        if enc.owners.size and res.prefilter:
            enc = self._prefilter(enc, velocities)
        if enc.owners.size:
            mx = max_heading_change[enc.owners]
            pred = None
            if res.uses_mode_predictions and tracks.predicts_modes:
                pred = mode_predictions(
                    tracks, view, enc, positions, velocities, self.dt, self.prediction_times_s
                )
            # a kept side needs only that side's best blocked candidate (see _commit)
            commits = res.uses_committed_side and res.reports_band and self.preference != "none"
            # the keyword arguments the resolver declares it takes (its capabilities)
            given = {"committed_side": self.side[enc.owners]} if commits else {}
            own_vo = velocities[enc.owners]
            heading = np.arctan2(own_vo[:, 1], own_vo[:, 0])
            if commits and res.uses_held_heading:
                given["held_heading_change"] = wrap_angle(self.held_heading[enc.owners] - heading)
            if res.uses_intruder_turn_rate:
                omega = view.x[np.maximum(enc.rows, 0), 4]
                given["intruder_turn_rate"] = np.where(enc.rows >= 0, np.nan_to_num(omega), 0.0)
            if res.uses_aircraft_ids or res.uses_intruder_intent:
                ids = np.where(enc.rows >= 0, view.intruder[np.maximum(enc.rows, 0)], -1)
            if res.uses_aircraft_ids:
                given["aircraft_ids"] = enc.owners
                given["intruder_ids"] = ids
            if res.uses_intruder_intent:
                at = np.maximum(ids, 0)
                vi = enc.rel_velocity + own_vo[:, None, :]
                target = np.where(ids >= 0, self.intent_heading[at], np.nan)
                change = wrap_angle(target - np.arctan2(vi[..., 1], vi[..., 0]))
                given["intruder_intent"] = np.where(np.isfinite(change), change, 0.0)
                given["intruder_turn_limit"] = np.where(
                    ids >= 0, max_heading_change[at] / self.dt, 0.0
                )
                given["intruder_intent_age_s"] = np.where(ids >= 0, self.intent_age_s[at], 0.0)
                given["own_intent_age_s"] = self.intent_age_s[enc.owners]
            if res.advises_speed:
                given["speed_limits"] = self.speed_limits[enc.owners]
                given["max_acceleration"] = self.max_acceleration[enc.owners]
            out = res.resolve(
                velocities[enc.owners],
                enc.rel_position,
                enc.rel_velocity,
                enc.valid,
                np.maximum(mx, self.search_range),
                mode_predictions=pred,
                turn_rate=mx / self.dt if res.uses_turn_rate else None,
                **given,
            )
            psi = np.asarray(out.heading_change, dtype=float)
            c = np.asarray(out.conflict, dtype=bool)
            if res.reports_band and self.preference != "none":
                psi, self.side[enc.owners] = self._commit(
                    psi,
                    c,
                    self.side[enc.owners],
                    np.asarray(out.candidates),
                    np.asarray(out.first_clear),
                    None if out.best_blocked is None else np.asarray(out.best_blocked),
                    self._route_side(enc.owners, heading),
                )
            advice[enc.owners] = np.clip(psi, -mx, mx)
            conflict[enc.owners] = c
            held[enc.owners] = np.where(c, heading + psi, np.nan)
            if res.advises_speed:
                speed = self._advised_speed(out, psi)
                self.speed_target[enc.owners] = np.where(c, speed, self.speed_target[enc.owners])
        conflict &= active
        # forget the committed side once clear for side_memory_s
        self._clear_for = np.where(conflict, 0, self._clear_for + 1)
        self.side[self._clear_for >= self.memory_steps] = 0.0
        self.advice, self.conflict = advice, conflict
        self.held_heading = np.where(conflict, held, np.nan)
        return advice, conflict

    @staticmethod
    def _advised_speed(out, psi):
        """(n,) m/s: the speed a resolver with ``advises_speed`` gives for the heading change
        ``psi`` (n,) rad the policy flies: its ``candidate_speed`` (n, C) at that candidate
        when it reports one (the committed side may pick another candidate than the
        resolver's own choice), else its ``speed_target``."""
        speed = np.asarray(out.speed_target, dtype=float)
        per = out.candidate_speed
        if per is None or out.candidates is None:
            return speed
        cand = np.asarray(out.candidates, dtype=float)
        gap = np.where(np.isfinite(cand), np.abs(cand - psi[:, None]), np.inf)
        at = np.argmin(gap, axis=1)
        rows = np.arange(psi.size)
        exact = gap[rows, at] <= 1e-12
        return np.where(exact, np.asarray(per, dtype=float)[rows, at], speed)

    def _prefilter(self, enc: Encounters, velocities) -> Encounters:
        """Only the ownships whose current heading fails the resolver's own CPA test, and on
        them only the intruders some heading could bring within the clear radius (one numba
        pass, :func:`.control.screen`)."""
        clear_radius = self.r_safe * (1.0 + self.margin)
        return screen(
            enc, velocities[enc.owners], clear_radius, self.lookahead_s, 1.0 - CLEAR_TOLERANCE
        )

    def _route_side(self, owners, heading):
        """(n_own,) the side of their routes (−1 right, +1 left) for ``owners`` (n_own,) int
        at ``heading`` (n_own,) rad at least ``route_side_off_course_deg`` off their
        autopilots' headings, 0 for the others (and for all without the knob)."""
        if self.route_side_off_course is None:
            return np.zeros(owners.size)
        error = wrap_angle(self.desired_heading[owners] - heading)
        far = np.abs(error) >= self.route_side_off_course  # False where NaN: no autopilot
        return np.where(far, np.where(error < 0.0, -1.0, 1.0), 0.0)

    def _commit(self, psi, conflict, side, cand, first_clear, best_blocked=None, toward=None):
        """Heading changes and sides under the turn preference.

        ``psi`` (n,) resolver choices, rad; ``conflict`` (n,) bool; ``side`` (n,) committed
        sides; ``cand`` (n, C) candidate heading changes sorted by the resolver's preference;
        ``first_clear`` (n, 3) index of the first clear candidate with ψ ≤ 0, ψ ≥ 0, ψ < 0
        (−1: none); ``best_blocked`` (n, 2) or None: on a side (ψ ≤ 0, ψ ≥ 0) without a
        clear candidate, the index of its best one (largest minimum CPA ratio). ``"right"``
        takes the nearest clear
        heading on the right if there is one within the search range (else on the left),
        ``"nearest"`` the resolver's choice; afterwards the committed side is kept while it
        has a clear heading. When it has none, a resolver that reports ``min_ratio`` gets
        the best heading on that side and the side is kept; otherwise the resolver's choice
        is used and the side follows it. Under ``"right"`` a left commitment is only the
        fallback: back to the right as soon as a strictly right heading is clear.
        ``toward`` (n,) or None: an ownship in conflict with a nonzero entry (the side of its
        route, :meth:`_route_side`) takes the first clear heading on that side and commits
        to it, instead of all of the above, when that side has one. Returns
        ``(psi (n,), side (n,))``.
        """
        has_best = best_blocked is not None
        if not has_best:
            best_blocked = np.zeros((psi.size, 2), dtype=np.int64)
        if toward is None:
            toward = np.zeros(psi.size)
        return _commit_kernel(
            np.ascontiguousarray(psi, dtype=np.float64),
            np.ascontiguousarray(conflict, dtype=np.bool_),
            np.ascontiguousarray(side, dtype=np.float64),
            np.ascontiguousarray(cand, dtype=np.float64),
            np.ascontiguousarray(first_clear, dtype=np.int64),
            np.ascontiguousarray(best_blocked, dtype=np.int64),
            has_best,
            self.preference == "right",
            np.ascontiguousarray(toward, dtype=np.float64),
        )


@njit(cache=True)
def _sign(x):
    """np.sign of a float (+0.0 at ±0, NaN stays NaN)."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0 if x == 0.0 else x


@njit(cache=True)
def _commit_kernel(psi, conflict, side, cand, first_clear, best_blocked, has_best, right, toward):
    """:meth:`AvoidancePolicy._commit` row by row (``right``: the ``"right"`` preference,
    else ``"nearest"``; ``has_best``: ``best_blocked`` is given; ``toward`` (n,) the route
    sides, 0: none); the same selections as :func:`commit_reference`, in one pass. Returns
    ``(psi (n,), side (n,))``."""
    n = psi.size
    out_psi = np.empty(n)
    out_side = np.empty(n)
    for r in range(n):
        p, s, c = psi[r], side[r], conflict[r]
        i_r, i_l, i_sr = first_clear[r, 0], first_clear[r, 1], first_clear[r, 2]
        has_r, pick_r = i_r >= 0, cand[r, max(i_r, 0)]
        has_l, pick_l = i_l >= 0, cand[r, max(i_l, 0)]
        t = toward[r]
        if c and t != 0.0 and (has_r if t < 0.0 else has_l):
            out_psi[r] = pick_r if t < 0.0 else pick_l
            out_side[r] = t
            continue
        new_side = s
        fresh = c and s == 0.0
        if right:
            if fresh and has_r:
                p = pick_r
            elif fresh and has_l:
                p = pick_l
            if fresh:
                new_side = -1.0 if has_r else (1.0 if has_l else _sign(p))
            if c and s > 0.0 and i_sr >= 0:  # back to the right
                s = -1.0
                new_side = -1.0
        elif fresh:
            new_side = _sign(p)
        kept = c and s != 0.0
        has_s = has_r if s < 0.0 else has_l
        if kept and has_s:
            p = pick_r if s < 0.0 else pick_l
        if has_best:
            best = best_blocked[r, 0] if s < 0.0 else best_blocked[r, 1]
            if kept and not has_s and best >= 0:
                p = cand[r, best]
        elif kept and not has_s:
            new_side = _sign(p)
        out_psi[r] = p
        out_side[r] = new_side if c else s
    return out_psi, out_side


def commit_reference(
    preference, psi, conflict, side, cand, first_clear, best_blocked=None, toward=None
):
    """The numpy statement of :meth:`AvoidancePolicy._commit` (``preference`` "right" or
    "nearest"), which :func:`_commit_kernel` computes row by row (tests compare them)."""
    rows = np.arange(psi.size)
    right, left, strict_right = first_clear[:, 0], first_clear[:, 1], first_clear[:, 2]
    has_r, pick_r = right >= 0, cand[rows, np.maximum(right, 0)]
    has_l, pick_l = left >= 0, cand[rows, np.maximum(left, 0)]

    new_side = side.copy()
    fresh = conflict & (side == 0)
    if preference == "right":
        psi = np.where(fresh & has_r, pick_r, np.where(fresh & ~has_r & has_l, pick_l, psi))
        new_side = np.where(
            fresh, np.where(has_r, -1.0, np.where(has_l, 1.0, np.sign(psi))), new_side
        )
        # one ownship turning left and one right can turn into each other
        back = conflict & (side > 0) & (strict_right >= 0)
        side = np.where(back, -1.0, side)
        new_side = np.where(back, -1.0, new_side)
    else:
        new_side = np.where(fresh, np.sign(psi), new_side)
    kept = conflict & (side != 0)
    has_s = np.where(side < 0, has_r, has_l)
    pick_s = np.where(side < 0, pick_r, pick_l)
    psi = np.where(kept & has_s, pick_s, psi)
    if best_blocked is not None:
        # two ownships flipping sides at once can turn into each other: keep the side
        best = np.where(side < 0, best_blocked[:, 0], best_blocked[:, 1])
        psi = np.where(kept & ~has_s & (best >= 0), cand[rows, np.maximum(best, 0)], psi)
    else:
        new_side = np.where(kept & ~has_s, np.sign(psi), new_side)
    new_side = np.where(conflict, new_side, side)
    if toward is not None:
        # far off course: the first clear heading toward the route, where there is one
        route = conflict & np.where(toward < 0, has_r, np.where(toward > 0, has_l, False))
        psi = np.where(route, np.where(toward < 0, pick_r, pick_l), psi)
        new_side = np.where(route, toward, new_side)
    return psi, new_side


def mode_predictions(
    tracks, view, enc: Encounters, positions, velocities, dt, times_s, chunk: int = 4096
):
    """Relative mode-conditioned predictions of the tracks in ``enc`` (paper §VI, 4).

    tracks : a :class:`~.trackers.TrackTable` whose tracker predicts modes; view : its
    :meth:`~.trackers.TrackTable.view` that ``enc.rows`` index; positions, velocities : (N, 2) own
    true states; dt : world step, s; times_s : (S,) s ahead, rounded to whole steps.
    Returns ``(xs, Ps, mu)``: (n_own, K, M, S', 2) intruder-minus-ownship positions, m, the
    ownship flying straight; (n_own, K, M, S', 2, 2) their covariances, m²; (n_own, K, M)
    mode probabilities; zeros in unused slots. S' is the number of distinct whole steps.
    Rows are predicted ``chunk`` at a time so memory stays bounded.
    """
    steps = np.unique(np.maximum(1, np.rint(np.asarray(times_s) / dt))).astype(np.int64)
    t = steps * dt
    n_own, K = enc.valid.shape
    M = tracks.n_modes
    xs = np.zeros((n_own, K, M, steps.size, 2))
    Ps = np.zeros((n_own, K, M, steps.size, 2, 2))
    mu = np.zeros((n_own, K, M))
    oi, ki = np.nonzero(enc.valid)
    rows = enc.rows[oi, ki]
    slots = view.slots[rows]
    for a in range(0, slots.size, chunk):
        sl = slice(a, a + chunk)
        own = enc.owners[oi[sl]]
        x, P = tracks.predict_modes_at(steps, slots[sl])
        xs[oi[sl], ki[sl]], Ps[oi[sl], ki[sl]] = relative_positions(
            x, P, t, positions[own], velocities[own]
        )
        mu[oi[sl], ki[sl]] = view.mu[rows[sl]]
    return xs, Ps, mu
