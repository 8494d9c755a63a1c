"""Markov-switching truth: trajectories driven by the mode chain, and noisy measurements.

Convention (Bar-Shalom et al. 2001, §11.6): ``modes[k]`` is the mode in effect over the
interval ``(k−1, k]``, drawn from ``Π[modes[k−1]]``, and
``X(k) = A_{q(k)} X(k−1) + u_{q(k)} + w(k)`` with ``w ~ N(0, Q)`` (paper §II);
``z(k) = H X(k) + v(k)`` with ``v ~ N(0, σ² I₂)`` (paper §VI).

All randomness comes from the ``numpy.random.Generator`` passed in, so a seed fixes the
result bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from airspace_sim.dynamics import models
from airspace_sim.dynamics.markov import mode_cdf, next_modes
from airspace_sim.dynamics.presets import Preset
from airspace_sim.errors import UserError


@dataclass
class Trajectories:
    """Truth and measurements of B targets over T steps.

    states : (T, B, 5) true ``[x, vx, y, vy, Ω]`` (m, m/s, rad/s)
    modes : (T, B) int, mode in effect over ``(k−1, k]``
    measurements : (T, B, 2) noisy positions in metres
    dt : seconds between steps
    """

    states: np.ndarray
    modes: np.ndarray
    measurements: np.ndarray
    dt: float


def noise_factor(Q: np.ndarray) -> np.ndarray:
    """``L`` with ``L Lᵀ = Q`` for a symmetric positive semi-definite Q, shape (n, n).

    Uses the eigendecomposition rather than Cholesky because white-noise-acceleration Q
    is singular.
    """
    w, V = np.linalg.eigh(np.asarray(Q, dtype=float))
    return V * np.sqrt(np.clip(w, 0.0, None))


def sample_modes(Pi: np.ndarray, previous: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Next modes (B,) given previous modes (B,) and Π (M, M), one uniform draw per target.

    Inverse-CDF sampling: with ``u ~ U[0, 1)`` the next mode is the number of cumulative
    probabilities ``≤ u``. Each row's CDF is divided by its last entry so that it ends at
    exactly 1: a mode with zero probability (including trailing ones, where rounding of the
    cumulative sum could leave the CDF just below 1) is never drawn.
    """
    previous = np.asarray(previous)
    return next_modes(mode_cdf(Pi), previous, rng.random(previous.shape))


def initial_states(preset: Preset, n_targets: int, rng: np.random.Generator) -> np.ndarray:
    """Targets at the origin with uniformly random heading and speed in ``speed_range``, (B, 5)."""
    heading = rng.uniform(-np.pi, np.pi, n_targets)
    speed = rng.uniform(*preset.speed_range, n_targets)
    x0 = np.zeros((n_targets, models.N_STATE))
    x0[:, 1] = speed * np.cos(heading)
    x0[:, 3] = speed * np.sin(heading)
    return x0


def simulate(
    preset: Preset,
    n_steps: int,
    n_targets: int = 1,
    rng: np.random.Generator | None = None,
    x0: np.ndarray | None = None,
    mode0: np.ndarray | None = None,
) -> Trajectories:
    """Generate ``n_targets`` Markov-switching trajectories of ``n_steps`` steps.

    Parameters
    ----------
    preset : the model's numbers.
    n_steps : T, number of time steps including the initial one.
    n_targets : B.
    rng : source of randomness (default ``np.random.default_rng(0)``).
    x0 : (B, 5) initial states; default :func:`initial_states`. Their Ω is replaced by
        the initial mode's turn rate (Ω is the mode's rate, not a free state).
    mode0 : (B,) initial modes; default drawn from ``preset.mu0()``.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    B, T = int(n_targets), int(n_steps)
    if T < 1 or B < 1:
        raise UserError(f"simulate: n_steps and n_targets must be >= 1, got {n_steps}, {n_targets}")
    if x0 is not None and np.shape(x0) != (B, models.N_STATE):
        raise UserError(f"simulate: x0 must have shape ({B}, {models.N_STATE}), got {np.shape(x0)}")
    if mode0 is not None:
        m0 = np.asarray(mode0)
        if m0.shape != (B,) or np.any((m0 < 0) | (m0 >= preset.n_modes)):
            raise UserError(f"simulate: mode0 must be {B} mode indices in [0, {preset.n_modes})")
    Pi = np.asarray(preset.transition_matrix, dtype=float)
    F = models.transition(np.asarray(preset.turn_rates), preset.dt)  # (M, 5, 5)
    rates = np.asarray(preset.turn_rates, dtype=float)
    L = noise_factor(np.asarray(preset.process_noise))
    sigma = preset.measurement_sigma

    states = np.empty((T, B, models.N_STATE))
    modes = np.empty((T, B), dtype=np.int64)
    x = initial_states(preset, B, rng) if x0 is None else np.array(x0, dtype=float)
    q = (
        rng.choice(len(rates), size=B, p=preset.mu0())
        if mode0 is None
        else np.asarray(mode0, dtype=np.int64)
    )
    x[:, models.TURN_RATE] = rates[q]
    states[0], modes[0] = x, q
    for k in range(1, T):
        q = sample_modes(Pi, q, rng)
        x = np.einsum("bij,bj->bi", F[q], x) + rng.standard_normal((B, models.N_STATE)) @ L.T
        x[:, models.TURN_RATE] = rates[q]
        states[k], modes[k] = x, q
    positions = states[..., list(models.POSITION)]
    measurements = positions + sigma * rng.standard_normal(positions.shape)
    return Trajectories(states=states, modes=modes, measurements=measurements, dt=preset.dt)
