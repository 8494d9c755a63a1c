"""Track initialisation from two position measurements (Bar-Shalom, Li & Kirubarajan 2001,
§5.5.3), for the state ``[x, vx, y, vy, Ω]`` (m, m/s, m, m/s, rad/s).

Used by the world's track table (a track starts at the second detection of a pair) and by
the consistency Monte Carlo (:mod:`airspace_sim.tracking.consistency`).
"""

from __future__ import annotations

import numpy as np

from airspace_sim.dynamics import models


def two_point_initialisation(
    z0, z1, dt, R, omega: float = 0.0, omega_var: float = 1e-6, extra_velocity_var: float = 0.0
):
    """State and covariance of tracks started from two position measurements.

    z0, z1 : (B, 2) (or (2,)) earlier and later measured positions, m; dt : s between them,
    a scalar or (B,); R : (2, 2) measurement noise covariance, m².

    Position ``z1``, velocity ``(z1 − z0)/Δt``; per axis pair
    ``P = [[R, R/Δt], [R/Δt, 2R/Δt² + extra_velocity_var·I]]`` (the error covariance of that
    estimate for white measurement noise, plus an allowance (m/s)² for a target that
    manoeuvres between the two points). Ω starts at ``omega`` (rad/s) with variance
    ``omega_var`` (rad/s)². Returns x0 (B, 5), P0 (B, 5, 5).
    """
    z0, z1 = np.atleast_2d(np.asarray(z0, dtype=float)), np.atleast_2d(np.asarray(z1, dtype=float))
    B = z1.shape[0]
    d = np.broadcast_to(np.asarray(dt, dtype=float), (B,))[:, None, None]
    R = np.asarray(R, dtype=float)
    x0 = np.zeros((B, models.N_STATE))
    x0[:, list(models.POSITION)] = z1
    x0[:, list(models.VELOCITY)] = (z1 - z0) / d[:, :, 0]
    x0[:, models.TURN_RATE] = omega
    P0 = np.zeros((B, models.N_STATE, models.N_STATE))
    pos, vel = list(models.POSITION), list(models.VELOCITY)
    P0[np.ix_(range(B), pos, pos)] = R
    P0[np.ix_(range(B), pos, vel)] = R / d
    P0[np.ix_(range(B), vel, pos)] = R / d
    P0[np.ix_(range(B), vel, vel)] = 2 * R / d**2 + extra_velocity_var * np.eye(2)
    P0[:, models.TURN_RATE, models.TURN_RATE] = omega_var
    return x0, P0
