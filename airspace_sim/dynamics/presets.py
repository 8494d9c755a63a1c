"""Model presets: the numbers of a jump-Markov aircraft model, as data.

A :class:`Preset` holds everything needed to generate truth (:mod:`.truth`) and to build a
matched IMM (:meth:`Preset.imm_arguments`): time step, per-mode turn rates, mode chain,
process and measurement noise, initial speeds. Presets differ only in their numbers.

- ``seed``: the paper's numbers as ``shared/design/seed-model.md`` reads them: ΔT = 0.1 s,
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
    turn_rates : per-mode turn rate ω_q in rad/s, counter-clockwise positive, shape (M,).
    transition_matrix : Π, (M, M), row i = Pr(next mode | mode i), per step of ``dt``.
    process_noise : Q used by the truth generator, (5, 5), added each step.
    filter_process_noise : Q used by the matched IMM's mode filters, (5, 5).
    measurement_sigma : position measurement noise σ in metres (R = σ² I₂).
    speed_range : initial ground speed range in m/s.
    pin_turn_rate : if true, each mode filter sets Ω to its own mode's rate every step
        (transition row of Ω zeroed, offset ω_q), so the combined Ω estimate is the
        mode-weighted turn rate; if false Ω is carried as a random walk.
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

    @property
    def n_modes(self) -> int:
        return len(self.turn_rates)

    def transitions(self) -> np.ndarray:
        """Per-mode transition matrices ``A_q``, shape (M, 5, 5)."""
        F = models.transition(np.asarray(self.turn_rates), self.dt)
        if self.pin_turn_rate:
            F[:, 4, 4] = 0.0
        return F

    def turn_rate_offsets(self) -> np.ndarray:
        """Per-mode additive offsets ``u_q`` (M, 5): ``X(k+1) = A_q X(k) + u_q``."""
        u = np.zeros((self.n_modes, models.N_STATE))
        if self.pin_turn_rate:
            u[:, models.TURN_RATE] = self.turn_rates
        return u

    def mu0(self) -> np.ndarray:
        """Initial mode probabilities (M,): the given ones, else the chain's stationary law."""
        if self.initial_mode_probabilities is not None:
            return np.asarray(self.initial_mode_probabilities, dtype=float)
        Pi = np.asarray(self.transition_matrix)
        w, v = np.linalg.eig(Pi.T)
        p = np.real(v[:, np.argmin(np.abs(w - 1.0))])
        return p / p.sum()

    def imm_arguments(self) -> dict:
        """Keyword arguments for :class:`~airspace_sim.tracking.IMM` except x0, P0, mu0."""
        return dict(
            transitions=self.transitions(),
            process_noise=np.broadcast_to(
                np.asarray(self.filter_process_noise), (self.n_modes, 5, 5)
            ).copy(),
            measurement_matrix=models.position_measurement_matrix(),
            measurement_noise=models.measurement_noise(self.measurement_sigma),
            transition_matrix=np.asarray(self.transition_matrix, dtype=float),
            offsets=self.turn_rate_offsets(),
        )

    def with_(self, **changes) -> "Preset":
        """A copy with some fields changed (e.g. ``preset.with_(dt=0.5)``)."""
        return replace(self, **changes)


def _tup(a) -> tuple:
    return tuple(map(tuple, np.asarray(a, dtype=float)))


def seed() -> Preset:
    """The paper's numbers (§II, §VI) as ``seed-model.md`` reads them."""
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

    Truth uses white-noise acceleration σ_a = 0.5 m/s²; the matched filters use
    σ_a = 1.0 m/s² (a slightly inflated Q, as a tracking engineer tunes it).
    """
    omega = math.radians(3.0)
    # Leaving a turn goes back to straight flight; leaving straight flight turns either way.
    switch = [[0, 0.5, 0.5], [1, 0, 0], [1, 0, 0]]
    Pi = markov.transition_matrix_from_sojourn([60.0, 20.0, 20.0], dt, switch)
    return Preset(
        name="realistic",
        dt=dt,
        turn_rates=(0.0, omega, -omega),
        transition_matrix=_tup(Pi),
        process_noise=_tup(models.white_noise_acceleration(0.5, dt, 1e-4)),
        filter_process_noise=_tup(models.white_noise_acceleration(1.0, dt, 1e-4)),
        measurement_sigma=50.0,
        speed_range=(200.0, 260.0),
        initial_mode_probabilities=None,
    )


PRESETS = {"seed": seed, "realistic": realistic}


def get(name: str) -> Preset:
    """The preset called ``name``; a :class:`UserError` listing the known names if unknown."""
    try:
        return PRESETS[name]()
    except KeyError:
        raise UserError(f"unknown preset {name!r} (known: {', '.join(sorted(PRESETS))})") from None
