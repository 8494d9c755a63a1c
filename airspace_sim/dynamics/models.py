"""Linear motion models for the state ``[x, vx, y, vy, Ω]`` (paper §II).

``x``, ``y`` are east and north positions in metres, ``vx``, ``vy`` velocities in m/s and
``Ω`` the turn rate in rad/s. Turn rates are counter-clockwise positive (left turns).

The paper's ``A2``/``A3`` are the coordinated-turn (CT) transition with a known turn rate,
but its third row has a sign error (see ``docs/paper-notes.md`` §1). Here the
standard, self-consistent CT matrix is used (Bar-Shalom, Li & Kirubarajan 2001, §11.7):
velocity rotates by ``ωΔT`` and position integrates the rotating velocity. The
constant-velocity (CV) matrix ``A1`` is its ``ω → 0`` limit, which :func:`transition`
reaches without dividing by zero.
"""

from __future__ import annotations

import numpy as np

from airspace_sim.geometry import turn_terms

#: Number of state components ``[x, vx, y, vy, Ω]``.
N_STATE = 5
#: Indices of the position components in the state.
POSITION = (0, 2)
#: Indices of the velocity components in the state.
VELOCITY = (1, 3)
#: Index of the turn rate in the state.
TURN_RATE = 4


def transition(turn_rate, dt: float) -> np.ndarray:
    """Coordinated-turn transition matrix for known turn rates (paper §II, ``A_q``).

    Parameters
    ----------
    turn_rate : float or array of shape ``(...)``
        Turn rate ω in rad/s, counter-clockwise (left) positive. ``0`` gives the CV matrix.
    dt : float
        Time step ΔT in seconds.

    Returns
    -------
    ndarray of shape ``(..., 5, 5)``
        ``F`` with ``X(k+1) = F X(k)`` for ``X = [x, vx, y, vy, Ω]``. The ``Ω`` row is the
        identity: the turn rate is carried, not driven, by the model (a per-mode offset in
        :class:`~airspace_sim.tracking.IMM` can pin it to the mode's rate).
    """
    w = np.asarray(turn_rate, dtype=float)
    wt = w * dt
    s, c = turn_terms(w, dt)
    cos, sin = np.cos(wt), np.sin(wt)
    F = np.zeros(w.shape + (N_STATE, N_STATE))
    F[..., 0, 0] = 1.0
    F[..., 0, 1] = s
    F[..., 0, 3] = -c
    F[..., 1, 1] = cos
    F[..., 1, 3] = -sin
    F[..., 2, 1] = c
    F[..., 2, 2] = 1.0
    F[..., 2, 3] = s
    F[..., 3, 1] = sin
    F[..., 3, 3] = cos
    F[..., 4, 4] = 1.0
    return F


def constant_velocity(dt: float) -> np.ndarray:
    """Constant-velocity transition ``A1`` (paper §II), shape ``(5, 5)``."""
    return transition(0.0, dt)


def paper_process_noise() -> np.ndarray:
    """The paper's process-noise covariance ``v = diag(200, 0.1, 200, 0.1, 0.001)`` (§VI).

    Units: m², (m/s)², m², (m/s)², (rad/s)². Added to the state each step as given; the
    paper's ``B`` matrix is inconsistent with it and is not used.
    """
    return np.diag([200.0, 0.1, 200.0, 0.1, 0.001])


def white_noise_acceleration(
    sigma_accel: float, dt: float, sigma_turn_rate: float = 0.0
) -> np.ndarray:
    """Discrete white-noise-acceleration process noise, shape ``(5, 5)``.

    Each horizontal axis gets ``σ_a² [[ΔT⁴/4, ΔT³/2], [ΔT³/2, ΔT²]]`` (Bar-Shalom et al. 2001,
    §6.3.3), with ``σ_a`` in m/s²; the turn rate gets ``(σ_Ω)²`` with ``σ_Ω`` in rad/s per
    step.
    """
    q = sigma_accel**2 * np.array([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]])
    Q = np.zeros((N_STATE, N_STATE))
    Q[np.ix_([0, 1], [0, 1])] = q
    Q[np.ix_([2, 3], [2, 3])] = q
    Q[4, 4] = sigma_turn_rate**2
    return Q


def position_measurement_matrix() -> np.ndarray:
    """``H`` with ``z = H X = [x, y]`` (paper §VI: position-only measurements), ``(2, 5)``."""
    H = np.zeros((2, N_STATE))
    H[0, 0] = 1.0
    H[1, 2] = 1.0
    return H


def measurement_noise(sigma: float = 50.0) -> np.ndarray:
    """Position measurement noise ``R = σ² I₂`` in m² (paper §VI: σ = 50 m), ``(2, 2)``."""
    return sigma**2 * np.eye(2)
