"""Model presets: the numbers of a jump-Markov aircraft model, as data.

A :class:`Preset` holds everything needed to generate truth (:mod:`.truth`) and to build a
matched IMM (:meth:`Preset.imm_arguments`): time step, per-mode turn rates, mode chain,
process and measurement noise, initial speeds. Presets differ only in their numbers.

- ``seed``: the paper's numbers as ``docs/paper-notes.md`` reads them: ΔT = 0.1 s,
  modes (straight, left, right) with ω = π/4 rad/s, the paper's Π per step, ``Q = v``
  (§VI), ``R = 50² I``, speeds in [V_cruise, 2 V_cruise], V_cruise = 285.841 m/s.
- ``realistic``: ΔT = 1 s, standard-rate 3°/s turns, white-noise-acceleration Q, mode
  sojourn times of tens of seconds (Π = expm(ΛΔT)), airliner speeds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from airspace_sim.dynamics import markov, models
from airspace_sim.errors import UserError

V_CRUISE = 285.841  # m/s, the paper's nominal cruise speed (§VI)


@dataclass(frozen=True)
class Preset:
    """Numbers of one jump-Markov model. All units SI (metres, seconds, radians).

    Attributes
    ----------
    dt : time step ΔT in seconds.
    turn_rates : per-mode turn rate ω_q in rad/s, counter-clockwise positive, shape (M,).
    transition_matrix : Π, (M, M), row i = Pr(next mode | mode i), per step of ``dt``.
    process_noise : Q used by the truth generator, (5, 5), added each step.
    filter_process_noise : Q used by the matched IMM's mode filters, (5, 5).
    measurement_sigma : position measurement noise σ in metres (R = σ² I₂).
    speed_range : initial ground speed range in m/s.
    pin_turn_rate : if true, each mode filter sets Ω to its own mode's rate every step
        (transition row of Ω zeroed, offset ω_q), so the combined Ω estimate is the
        mode-weighted turn rate; if false Ω is carried as a random walk.
    initial_mode_probabilities : (M,) or None for the chain's stationary law.
    sojourn_s, switch_probabilities : optional continuous-time mode chain (mean sojourn
        times in seconds, where a mode goes when it leaves). When given, the per-step
        ``transition_matrix`` is ``expm(Λ dt)`` and :meth:`with_` rebuilds it when ``dt``
        changes, so the aircraft behave the same in seconds whatever the step.
    sigma_accel, filter_sigma_accel : optional white-noise-acceleration σ_a (m/s²) of the
        truth and of the filters; when given, :meth:`with_` rebuilds ``process_noise`` /
        ``filter_process_noise`` for a new ``dt``. ``sigma_turn_rate`` (rad/s per step) is
        their Ω entry.
    estimated_turn_rate : optional (M,) bools: the filter's modes whose turn rate is the
        state's own Ω (an EKF coordinated turn, :mod:`airspace_sim.tracking.coordinated_turn`)
        instead of the mode's known rate; their Ω is a random walk with
        ``ct_sigma_turn_rate`` (rad/s per √s) in the filter (Q_ΩΩ = σ² dt). The truth
        generator flies such a mode at its ``turn_rates`` entry.
    filter_mode_sigma_accel : optional (M,) white-noise-acceleration σ_a (m/s²) of each
        filter mode (e.g. a quiet and a manoeuvring constant-velocity mode); replaces
        ``filter_process_noise`` in :meth:`imm_arguments`, rebuilt for every ``dt``.
    filter_mode_sigma_turn_rate : optional (M,) σ_Ω (rad/s per √s) of each estimated-rate
        mode's Ω random walk, replacing ``ct_sigma_turn_rate`` for that mode (e.g. a
        steady turn and a roll-in/roll-out turn whose rate changes fast); entries of
        known-rate modes are not used.
    along_track_acceleration : optional (M,) bools: the filter's modes that are a
        coordinated turn at the estimated rate *with the along-track acceleration in the
        state* (:mod:`airspace_sim.tracking.along_track`); the filter's state is then
        ``[x, vx, y, vy, Ω, a]`` for every mode (:attr:`n_state` 6), the other modes carry
        ``a`` pinned at 0 (with ``pin_turn_rate``; else as a constant). Such a mode's Ω is
        estimated as for ``estimated_turn_rate`` and its ``a`` is a random walk of
        ``filter_mode_sigma_along_track`` (m/s² per √s; Q_aa = σ² dt). The truth generator
        flies such a mode at its ``turn_rates`` entry, at constant speed.
    filter_mode_sigma_along_track : optional (M,) σ (m/s² per √s) of each along-track
        mode's acceleration random walk (entries of other modes are not used).
    tracker : optional preset, the model the tracker assumes (:meth:`filter_model`) when it
        is not the traffic's: the traffic flies this preset's modes, and the world's and
        the recorded-flight trackers run ``tracker``'s (its own modes, Π, Q), at this
        preset's ``dt`` and ``measurement_sigma``. :meth:`imm_arguments` stays this
        preset's own matched IMM (the simulated experiments' matched filter).

    Presets without the continuous-time fields (``seed``) hold per-step numbers, as the
    paper does: changing ``dt`` alone keeps Π and Q per step.
    """

    name: str
    dt: float
    turn_rates: tuple
    transition_matrix: tuple
    process_noise: tuple
    filter_process_noise: tuple
    measurement_sigma: float = 50.0
    speed_range: tuple = (V_CRUISE, 2 * V_CRUISE)
    pin_turn_rate: bool = True
    initial_mode_probabilities: tuple = field(default=None)
    sojourn_s: tuple = None
    switch_probabilities: tuple = None
    sigma_accel: float = None
    filter_sigma_accel: float = None
    sigma_turn_rate: float = 0.0
    estimated_turn_rate: tuple = None
    ct_sigma_turn_rate: float = 0.0
    filter_mode_sigma_accel: tuple = None
    filter_mode_sigma_turn_rate: tuple = None
    tracker: Preset = None
    along_track_acceleration: tuple = None
    filter_mode_sigma_along_track: tuple = None

    def __post_init__(self):
        where = f"preset {self.name!r}"
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        dt = float(self.dt)
        if not (math.isfinite(dt) and dt > 0):
            raise UserError(f"{where}: dt must be a positive number of seconds, got {self.dt!r}")
        set_("dt", dt)
        rates = np.asarray(self.turn_rates, dtype=float).reshape(-1)
        if rates.size == 0 or not np.all(np.isfinite(rates)):
            raise UserError(f"{where}: turn_rates must be finite rad/s, got {rates.tolist()}")
        set_("turn_rates", tuple(rates.tolist()))
        M = rates.size
        Pi = markov.validate_transition_matrix(
            self.transition_matrix, f"{where}: transition_matrix"
        )
        if Pi.shape != (M, M):
            raise UserError(f"{where}: transition_matrix is {Pi.shape}, expected ({M}, {M})")
        set_("transition_matrix", _tup(Pi))
        for key in ("process_noise", "filter_process_noise"):
            set_(key, _tup(_check_covariance(getattr(self, key), f"{where}: {key}")))
        sigma = float(self.measurement_sigma)
        if not (math.isfinite(sigma) and sigma > 0):
            raise UserError(f"{where}: measurement_sigma must be positive metres, got {sigma!r}")
        set_("measurement_sigma", sigma)
        lo, hi = (float(v) for v in self.speed_range)
        if not (0 <= lo <= hi < math.inf):
            raise UserError(
                f"{where}: speed_range must be 0 <= low <= high m/s, got {self.speed_range!r}"
            )
        set_("speed_range", (lo, hi))
        if self.initial_mode_probabilities is not None:
            mu = np.asarray(self.initial_mode_probabilities, dtype=float).reshape(-1)
            if mu.shape != (M,) or np.any(~np.isfinite(mu) | (mu < 0)) or abs(mu.sum() - 1) > 1e-9:
                raise UserError(
                    f"{where}: initial_mode_probabilities must be {M} non-negative numbers "
                    f"summing to 1, got {mu.tolist()}"
                )
            set_("initial_mode_probabilities", tuple(mu.tolist()))
        if self.sojourn_s is not None:
            set_("sojourn_s", tuple(np.asarray(self.sojourn_s, dtype=float).reshape(-1).tolist()))
        if self.switch_probabilities is not None:
            set_("switch_probabilities", _tup(self.switch_probabilities))
        if self.estimated_turn_rate is not None:
            ct = tuple(bool(v) for v in np.asarray(self.estimated_turn_rate).reshape(-1))
            if len(ct) != M:
                raise UserError(f"{where}: estimated_turn_rate must have {M} flags, got {len(ct)}")
            set_("estimated_turn_rate", ct)
        if self.along_track_acceleration is not None:
            at = tuple(bool(v) for v in np.asarray(self.along_track_acceleration).reshape(-1))
            if len(at) != M:
                raise UserError(
                    f"{where}: along_track_acceleration must have {M} flags, got {len(at)}"
                )
            set_("along_track_acceleration", at)
        if self.filter_mode_sigma_along_track is not None:
            st = np.asarray(self.filter_mode_sigma_along_track, dtype=float).reshape(-1)
            if st.shape != (M,) or not np.all(np.isfinite(st) & (st >= 0)):
                raise UserError(
                    f"{where}: filter_mode_sigma_along_track must be {M} non-negative m/s² per "
                    f"√s, got {st.tolist()}"
                )
            set_("filter_mode_sigma_along_track", tuple(st.tolist()))
        if self.filter_mode_sigma_accel is not None:
            sa = np.asarray(self.filter_mode_sigma_accel, dtype=float).reshape(-1)
            if sa.shape != (M,) or not np.all(np.isfinite(sa) & (sa >= 0)):
                raise UserError(
                    f"{where}: filter_mode_sigma_accel must be {M} non-negative m/s², "
                    f"got {sa.tolist()}"
                )
            set_("filter_mode_sigma_accel", tuple(sa.tolist()))
        if self.filter_mode_sigma_turn_rate is not None:
            so = np.asarray(self.filter_mode_sigma_turn_rate, dtype=float).reshape(-1)
            if so.shape != (M,) or not np.all(np.isfinite(so) & (so >= 0)):
                raise UserError(
                    f"{where}: filter_mode_sigma_turn_rate must be {M} non-negative rad/s per "
                    f"√s, got {so.tolist()}"
                )
            set_("filter_mode_sigma_turn_rate", tuple(so.tolist()))
        if self.tracker is not None and not isinstance(self.tracker, Preset):
            raise UserError(f"{where}: tracker must be a Preset, got {self.tracker!r}")

    @property
    def n_modes(self) -> int:
        return len(self.turn_rates)

    def estimated(self) -> np.ndarray:
        """(M,) bool: the filter's estimated-rate (EKF coordinated-turn) modes, with or
        without along-track acceleration."""
        est = np.zeros(self.n_modes, dtype=bool)
        if self.estimated_turn_rate is not None:
            est |= np.asarray(self.estimated_turn_rate, dtype=bool)
        return est | self.along_track()

    def along_track(self) -> np.ndarray:
        """(M,) bool: the filter's modes with the along-track acceleration in the state."""
        if self.along_track_acceleration is None:
            return np.zeros(self.n_modes, dtype=bool)
        return np.asarray(self.along_track_acceleration, dtype=bool)

    @property
    def n_state(self) -> int:
        """The filter's state size: 5 (``[x, vx, y, vy, Ω]``), or 6 with an along-track
        mode (``[x, vx, y, vy, Ω, a]``)."""
        return 6 if self.along_track().any() else models.N_STATE

    def turning_modes(self) -> np.ndarray:
        """(M,) bool: the modes that model a turn (a non-zero known rate, or estimated)."""
        return (np.asarray(self.turn_rates) != 0.0) | self.estimated()

    def mode_names(self) -> tuple:
        """Names of the modes: ``straight``, ``left 3°/s``, ``right 1.5°/s`` (CCW positive),
        ``turn`` for an estimated-rate mode; modes alike but for their σ_a get it appended
        (``straight 0.3 m/s²``)."""
        names = []
        for w, est in zip(self.turn_rates, self.estimated()):
            deg = math.degrees(abs(w))
            side = "left" if w > 0 else "right"
            names.append("turn" if est else "straight" if w == 0 else f"{side} {deg:.3g}°/s")
        names = [f"{v} + speed" if at else v for v, at in zip(names, self.along_track())]
        if len(set(names)) < len(names) and self.filter_mode_sigma_accel is not None:
            # modes alike but for their noise (a quiet and a manoeuvring CV mode)
            names = [f"{v} {sa:g} m/s²" for v, sa in zip(names, self.filter_mode_sigma_accel)]
        if len(set(names)) < len(names) and self.filter_mode_sigma_turn_rate is not None:
            # estimated-rate modes alike but for their σ_Ω (a steady and a roll-in turn)
            names = [
                f"{v} {math.degrees(so):.3g}°/s/√s" if est else v
                for v, so, est in zip(names, self.filter_mode_sigma_turn_rate, self.estimated())
            ]
        return tuple(names)

    def transitions(self) -> np.ndarray:
        """Per-mode transition matrices ``A_q``, shape (M, 5, 5)."""
        est = self.estimated()
        F = models.transition(np.where(est, 0.0, np.asarray(self.turn_rates)), self.dt)
        if self.pin_turn_rate:
            F[~est, 4, 4] = 0.0
        return F

    def turn_rate_offsets(self) -> np.ndarray:
        """Per-mode additive offsets ``u_q`` (M, 5): ``X(k+1) = A_q X(k) + u_q``."""
        u = np.zeros((self.n_modes, models.N_STATE))
        if self.pin_turn_rate:
            u[:, models.TURN_RATE] = np.where(self.estimated(), 0.0, self.turn_rates)
        return u

    def mu0(self) -> np.ndarray:
        """Initial mode probabilities (M,): the given ones, else the chain's stationary law
        (:func:`~airspace_sim.dynamics.markov.stationary_law`)."""
        if self.initial_mode_probabilities is not None:
            return np.asarray(self.initial_mode_probabilities, dtype=float)
        return markov.stationary_law(self.transition_matrix)

    def filter_model(self) -> Preset:
        """The model the tracker assumes: :attr:`tracker` at this preset's ``dt`` and
        ``measurement_sigma`` if given, else this preset (its own matched filter)."""
        if self.tracker is None:
            return self
        t = self.tracker
        if t.dt == self.dt and t.measurement_sigma == self.measurement_sigma:
            return t
        return t.with_(dt=self.dt, measurement_sigma=self.measurement_sigma)

    def imm_arguments(self) -> dict:
        """Keyword arguments for :class:`~airspace_sim.tracking.IMM` except x0, P0, mu0
        (``estimated_turn_rate`` and ``dt`` only for a preset with estimated-rate modes):
        this preset's own modes (the tracker's, if it has one, are
        ``filter_model().imm_arguments()``)."""
        est = self.estimated()
        if self.filter_mode_sigma_accel is None:
            Q = np.broadcast_to(np.asarray(self.filter_process_noise), (self.n_modes, 5, 5))
            Q = Q.copy()
        else:
            Q = np.stack(
                [
                    models.white_noise_acceleration(sa, self.dt, self.sigma_turn_rate)
                    for sa in self.filter_mode_sigma_accel
                ]
            )
        sigma_omega = np.full(self.n_modes, self.ct_sigma_turn_rate)
        if self.filter_mode_sigma_turn_rate is not None:
            sigma_omega = np.asarray(self.filter_mode_sigma_turn_rate)
        Q[est, 4, 4] = sigma_omega[est] ** 2 * self.dt
        # the estimated-rate flags and dt only when there are such modes, so the arguments
        # of a linear model stay those of any linear-Gaussian IMM (filterpy's included)
        extra = dict(estimated_turn_rate=est, dt=self.dt) if est.any() else {}
        F, H, U = self.transitions(), models.position_measurement_matrix(), self.turn_rate_offsets()
        at = self.along_track()
        if at.any():
            F, Q, H, U = self._with_along_track(F, Q, H, U, at)
            extra["along_track_acceleration"] = at
        return dict(
            **extra,
            transitions=F,
            process_noise=Q,
            measurement_matrix=H,
            measurement_noise=models.measurement_noise(self.measurement_sigma),
            transition_matrix=np.asarray(self.transition_matrix, dtype=float),
            offsets=U,
        )

    def _with_along_track(self, F, Q, H, U, at):
        """The 5-state F (M, 5, 5), Q (M, 5, 5), H (2, 5), U (M, 5) in the 6-state layout
        ``[x, vx, y, vy, Ω, a]``: ``a`` pinned at 0 in the other modes (with
        ``pin_turn_rate``; else carried unchanged), a random walk of
        ``filter_mode_sigma_along_track`` in the along-track modes (whose F is not used)."""
        M, n = self.n_modes, 6
        F6 = np.zeros((M, n, n))
        F6[:, :5, :5] = F
        F6[:, 5, 5] = 0.0 if self.pin_turn_rate else 1.0
        F6[at, 5, 5] = 1.0
        sigma = np.zeros(M)
        if self.filter_mode_sigma_along_track is not None:
            sigma = np.asarray(self.filter_mode_sigma_along_track)
        Q6 = np.zeros((M, n, n))
        Q6[:, :5, :5] = Q
        Q6[:, 5, 5] = np.where(at, sigma**2 * self.dt, 0.0)
        H6 = np.zeros((H.shape[0], n))
        H6[:, :5] = H
        U6 = np.zeros((M, n))
        U6[:, :5] = U
        return F6, Q6, H6, U6

    def with_(self, **changes) -> Preset:
        """A copy with some fields changed (e.g. ``preset.with_(dt=0.5)``).

        Per-step numbers that come from continuous-time fields are rebuilt for the new
        values: Π from ``sojourn_s`` (if set) and Q from ``sigma_accel`` /
        ``filter_sigma_accel`` (if set), unless the change gives them explicitly. Giving a
        per-step Π or Q explicitly drops the continuous-time field it came from, so a later
        ``dt`` change keeps it per step.
        """
        changes = dict(changes)
        if "transition_matrix" in changes and "sojourn_s" not in changes:
            changes["sojourn_s"] = None
        if "process_noise" in changes and "sigma_accel" not in changes:
            changes["sigma_accel"] = None
        if "filter_process_noise" in changes and "filter_sigma_accel" not in changes:
            changes["filter_sigma_accel"] = None
        new = replace(self, **changes)
        derived = {}
        touched = set(changes)
        if new.tracker is not None and touched & {"dt", "measurement_sigma", "tracker"}:
            derived["tracker"] = new.tracker.with_(
                dt=new.dt, measurement_sigma=new.measurement_sigma
            )
        if (
            new.sojourn_s is not None
            and "transition_matrix" not in changes
            and touched & {"dt", "sojourn_s", "switch_probabilities"}
        ):
            derived["transition_matrix"] = _tup(
                markov.transition_matrix_from_sojourn(
                    new.sojourn_s, new.dt, new.switch_probabilities
                )
            )
        for q_key, s_key in (
            ("process_noise", "sigma_accel"),
            ("filter_process_noise", "filter_sigma_accel"),
        ):
            sig = getattr(new, s_key)
            if (
                sig is not None
                and q_key not in changes
                and touched & {"dt", s_key, "sigma_turn_rate"}
            ):
                derived[q_key] = _tup(
                    models.white_noise_acceleration(sig, new.dt, new.sigma_turn_rate)
                )
        return replace(new, **derived) if derived else new


def _check_covariance(Q, name: str) -> np.ndarray:
    Q = np.asarray(Q, dtype=float)
    if Q.shape != (models.N_STATE, models.N_STATE) or not np.all(np.isfinite(Q)):
        raise UserError(f"{name}: must be a finite (5, 5) covariance, got shape {Q.shape}")
    if not np.allclose(Q, Q.T, rtol=1e-9, atol=1e-12):
        raise UserError(f"{name}: must be symmetric")
    w = np.linalg.eigvalsh(Q)
    if w.min() < -1e-9 * max(1.0, abs(w).max()):
        raise UserError(
            f"{name}: must be positive semi-definite (smallest eigenvalue {w.min():.3g})"
        )
    return Q


def _tup(a) -> tuple:
    """A 2-d array as a tuple of tuples of Python floats (hashable, comparable with ==)."""
    return tuple(map(tuple, np.asarray(a, dtype=float).tolist()))


def seed() -> Preset:
    """The paper's numbers (§II, §VI) as ``docs/paper-notes.md`` reads them."""
    Pi = [[0.8, 0.1, 0.1], [0.19, 0.8, 0.01], [0.19, 0.01, 0.8]]
    Q = models.paper_process_noise()
    return Preset(
        name="seed",
        dt=0.1,
        turn_rates=(0.0, math.pi / 4, -math.pi / 4),
        transition_matrix=_tup(markov.validate_transition_matrix(Pi)),
        process_noise=_tup(Q),
        filter_process_noise=_tup(Q),
        measurement_sigma=50.0,
        speed_range=(V_CRUISE, 2 * V_CRUISE),
        initial_mode_probabilities=(1.0, 0.0, 0.0),
    )


def realistic(dt: float = 1.0) -> Preset:
    """Airliner-like: standard-rate (3°/s) turns, sojourn 60 s straight and 20 s turning.

    Speeds 200–260 m/s (≈ 390–505 kt), so a turn is a 10–14 m/s² centripetal acceleration
    and an average turn changes heading by 60°; σ = 50 m position measurements. Leaving
    straight flight turns either way with equal probability; leaving a turn goes back to
    straight flight (stationary law 0.75 / 0.125 / 0.125).

    Truth uses white-noise acceleration σ_a = 0.5 m/s²; the matched filters use
    σ_a = 1.0 m/s² (Q four times the truth's, as a tracking engineer tunes it). Why: the
    IMM's Gaussian approximation of the mode mixture is optimistic for a few steps after a
    mode switch. With the matched σ_a = 0.5 the 200-run average NEES (position/velocity) is
    3.8–3.9 on average but peaks at 5.2–5.3 at maneuver onsets, above the 4.53 upper end of
    its 99% band; with σ_a = 1.0 it peaks at 3.8–4.5 over ten seeds (average ≈ 3.2, i.e.
    slightly conservative) and the average NIS stays inside its 95% band
    (``tests/test_consistency.py``, ``python -m airspace_sim.tracking.consistency``). The
    accuracy cost is under 3% of position RMSE (33.9 m against 33.1 m matched, same seed;
    the best-tuned CV filter gets 48.2 m).

    Mode chain and Q are given in continuous time, so ``with_(dt=...)`` (or
    ``get("realistic", dt=...)``) keeps the behaviour in seconds.
    """
    omega = math.radians(3.0)
    # Leaving a turn goes back to straight flight; leaving straight flight turns either way.
    switch = [[0, 0.5, 0.5], [1, 0, 0], [1, 0, 0]]
    sojourn = (60.0, 20.0, 20.0)
    sigma_turn_rate = 1e-4
    return Preset(
        name="realistic",
        dt=dt,
        turn_rates=(0.0, omega, -omega),
        transition_matrix=_tup(markov.transition_matrix_from_sojourn(sojourn, dt, switch)),
        process_noise=_tup(models.white_noise_acceleration(0.5, dt, sigma_turn_rate)),
        filter_process_noise=_tup(models.white_noise_acceleration(1.0, dt, sigma_turn_rate)),
        measurement_sigma=50.0,
        speed_range=(200.0, 260.0),
        initial_mode_probabilities=None,
        sojourn_s=sojourn,
        switch_probabilities=_tup(switch),
        sigma_accel=0.5,
        filter_sigma_accel=1.0,
        sigma_turn_rate=sigma_turn_rate,
    )


def dense_turns(dt: float = 1.0) -> Preset:
    """:func:`realistic` with known-rate turn modes at 0, ±1, ±2, ±3 °/s for the filters and
    the truth: real airliner turns are mostly 1–2.5 °/s (``docs/tracking.md``).

    Leaving straight flight (mean 60 s) starts any of the six turns; a turn (mean 20 s)
    ends in straight flight half the time and otherwise changes to the next rate of the
    same sign (a roll-in or roll-out), so rates change by 1 °/s steps.
    """
    base = realistic(dt)
    rates = [0.0, 1.0, -1.0, 2.0, -2.0, 3.0, -3.0]
    M = len(rates)
    switch = np.zeros((M, M))
    switch[0, 1:] = 1.0 / (M - 1)
    for i in range(1, M):
        nxt = [j for j in range(1, M) if rates[j] * rates[i] > 0 and abs(rates[j] - rates[i]) == 1]
        switch[i, 0] = 1.0 - 0.25 * len(nxt)
        switch[i, nxt] = 0.25
    sojourn = (60.0,) + (20.0,) * (M - 1)
    return replace(
        base,
        name="dense-turns",
        turn_rates=tuple(math.radians(r) for r in rates),
        transition_matrix=_tup(markov.transition_matrix_from_sojourn(sojourn, dt, switch)),
        sojourn_s=sojourn,
        switch_probabilities=_tup(switch),
    )


def turn_rate(dt: float = 1.0) -> Preset:
    """Two filter modes: straight flight (CV, Ω pinned at 0) and a coordinated turn at the
    estimated rate Ω (EKF), Ω a random walk of 1 °/s per √s; σ_a = 1.5 m/s² in the filter;
    mean sojourn 120 s straight, 30 s turning (how these were chosen: ``docs/tracking.md``).
    As truth the turn mode flies 2 °/s left: this preset is a tracker, not a traffic model.
    """
    base = realistic(dt)
    switch = [[0, 1], [1, 0]]
    sojourn = (120.0, 30.0)
    return replace(
        base,
        name="turn-rate",
        turn_rates=(0.0, math.radians(2.0)),
        transition_matrix=_tup(markov.transition_matrix_from_sojourn(sojourn, dt, switch)),
        sojourn_s=sojourn,
        switch_probabilities=_tup(switch),
        filter_process_noise=_tup(models.white_noise_acceleration(1.5, dt, base.sigma_turn_rate)),
        filter_sigma_accel=1.5,
        estimated_turn_rate=(False, True),
        ct_sigma_turn_rate=math.radians(1.0),
    )


def imm_ct(dt: float = 1.0) -> Preset:
    """The classic IMM-CT tracker (Bar-Shalom, Li & Kirubarajan 2001, §11.7): a quiet
    constant-velocity mode, a coordinated turn at the estimated rate Ω (EKF, Ω a random
    walk) and a manoeuvring constant-velocity mode, each with its own white-noise
    acceleration; Ω pinned at 0 in both CV modes. The mode chain is in seconds (mean
    sojourns), so Π follows ``dt``. A tracker, not a traffic model: as truth its turn
    mode flies 2 °/s left. Numbers tuned on half the traffic calibration flights
    (``docs/tracking.md``).
    """
    base = realistic(dt)
    # quiet CV, CT, manoeuvring CV: leaving a mode goes mostly to the other "steady" one
    switch = [[0.0, 0.8, 0.2], [0.8, 0.0, 0.2], [0.5, 0.5, 0.0]]
    sojourn = (120.0, 60.0, 10.0)
    return replace(
        base,
        name="imm-ct",
        turn_rates=(0.0, math.radians(2.0), 0.0),
        transition_matrix=_tup(markov.transition_matrix_from_sojourn(sojourn, dt, switch)),
        sojourn_s=sojourn,
        switch_probabilities=_tup(switch),
        estimated_turn_rate=(False, True, False),
        ct_sigma_turn_rate=math.radians(0.5),
        filter_mode_sigma_accel=(0.3, 1.5, 5.0),
    )


def imm_ct_airliner(dt: float = 1.0) -> Preset:
    """:func:`imm_ct` for airliner traffic: a quieter straight mode held longer (σ_a 0.1
    m/s², mean sojourn 900 s), the turn mode at σ_a 1 m/s², the manoeuvring mode at 4 m/s².
    Tuned on half the flights of the traffic wheel's ``collections/switzerland`` (even
    positions), measured on the other half (``docs/tracking.md``). A tracker, not a
    traffic model."""
    sojourn = (900.0, 60.0, 10.0)
    base = imm_ct(dt)
    return replace(
        base,
        name="imm-ct-airliner",
        transition_matrix=_tup(
            markov.transition_matrix_from_sojourn(sojourn, dt, base.switch_probabilities)
        ),
        sojourn_s=sojourn,
        filter_mode_sigma_accel=(0.1, 1.0, 4.0),
    )


def imm_cta(dt: float = 1.0) -> Preset:
    """:func:`imm_ct` with the along-track acceleration in the turn mode's state: quiet
    constant velocity, a coordinated turn at the estimated rate Ω *and* estimated
    along-track acceleration ``a`` (EKF, :mod:`airspace_sim.tracking.along_track`; Ω and
    ``a`` random walks), manoeuvring constant velocity; the filter's state is
    ``[x, vx, y, vy, Ω, a]``, ``a`` pinned at 0 in both CV modes. A tracker, not a traffic
    model (as truth its turn mode flies 2 °/s left at constant speed). Numbers tuned on
    half the traffic calibration flights (``docs/tracking.md``). Not in :data:`PRESETS`
    (no name for scenarios): on the other half it is within 1% of ``imm-ct``; the world's
    tracks are 5-state, so its trackers refuse it.
    """
    return replace(
        imm_ct(dt),
        name="imm-cta",
        along_track_acceleration=(False, True, False),
        filter_mode_sigma_along_track=(0.0, 0.05, 0.0),
        filter_mode_sigma_accel=(0.3, 1.0, 6.0),
    )


PRESETS = {
    "seed": seed,
    "realistic": realistic,
    "dense-turns": dense_turns,
    "turn-rate": turn_rate,
    "imm-ct": imm_ct,
    "imm-ct-airliner": imm_ct_airliner,
}

#: The tracker preset for recorded (real) traffic, chosen on real flights over ``realistic``
#: and ``imm-ct-airliner`` (``docs/tracking.md``, ``docs/real-traffic.md``). Simulated
#: traffic keeps ``realistic``, whose modes are the traffic's own.
RECORDED_TRACKER = "imm-ct"


#: (name, factory, dt) -> Preset: a world (and every env reset) asks for the same preset,
#: and rebuilding Π = expm(Λ dt) was ~90% of a reset. Presets are frozen and hold only
#: tuples, so sharing one is safe; the factory is part of the key so that replacing an
#: entry of PRESETS is never served a stale preset.
_CACHE: dict[tuple, Preset] = {}


def get(name: str, dt: float | None = None) -> Preset:
    """The preset called ``name``; a :class:`UserError` listing the known names if unknown.

    ``dt`` (seconds), if given, changes the step via :meth:`Preset.with_` (continuous-time
    presets keep their behaviour in seconds; the ``seed`` preset's numbers stay per step).
    Results are cached on every input (name, the factory behind it, dt).
    """
    try:
        factory = PRESETS[name]
    except KeyError:
        raise UserError(f"unknown preset {name!r} (known: {', '.join(sorted(PRESETS))})") from None
    key = (name, factory, None if dt is None else float(dt))
    preset = _CACHE.get(key)
    if preset is None:
        preset = factory()
        preset = preset if dt is None else preset.with_(dt=dt)
        _CACHE[key] = preset
    return preset
