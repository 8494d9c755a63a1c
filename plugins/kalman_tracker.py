"""Tracker plugin ``"kalman"``: a single-model constant-velocity Kalman filter (a baseline).

Loaded by :func:`airspace_sim.registry.load_plugins` from ``./plugins`` (or a folder in
``$AIRSPACE_SIM_PLUGINS``, or an ``airspace_sim.plugins`` entry point naming this module).
Use it in a scenario with ``[tracker] kind = "kalman"`` or ``--set tracker.kind=kalman``.

It follows the world's tracker-factory interface (:mod:`airspace_sim.world.trackers`)::

    factory(preset: Preset, sigma: float) -> filter with zero rows;
    filter.append(x0 (k, 5), P0 (k, 5, 5), mu0) -> rows; filter.remove(mask or indices);
    filter.step(z (B, 2)) (NaN row = predict only); filter.x, .P, .mu (B, 1)

The state is the world's ``[x, vx, y, vy, Ω]`` (m, m/s, rad/s). The model is constant
velocity with Ω pinned to 0; its process noise is the preset's filter Q plus a manoeuvre
allowance: white-noise acceleration with σ_m = ½·max|ω|·mean speed (half the centripetal
acceleration of the preset's turns), the usual way a single CV filter is tuned to survive
turns it does not model. Pass ``sigma_accel`` (m/s²) to choose σ_m yourself.
"""

from __future__ import annotations

import numpy as np

from airspace_sim.dynamics import models
from airspace_sim.registry import register
from airspace_sim.tracking.kalman import KalmanFilter


def manoeuvre_sigma(preset) -> float:
    """Default σ_m (m/s²): half the centripetal acceleration of the preset's fastest turn."""
    omega = float(np.max(np.abs(preset.turn_rates), initial=0.0))
    speed = float(np.mean(preset.speed_range))
    return 0.5 * omega * speed


class ConstantVelocityTracker(KalmanFilter):
    """Batched CV Kalman filter over ``[x, vx, y, vy, Ω]`` with Ω held at 0."""

    def __init__(self, preset, sigma: float, sigma_accel: float | None = None):
        dt = float(preset.dt)
        F = models.constant_velocity(dt)
        F[models.TURN_RATE, :] = 0.0  # Ω pinned to 0: the CV assumption
        self.sigma_accel = manoeuvre_sigma(preset) if sigma_accel is None else float(sigma_accel)
        Q = np.asarray(preset.filter_process_noise, dtype=float).copy()
        Q += models.white_noise_acceleration(self.sigma_accel, dt)
        Q[models.TURN_RATE, :] = Q[:, models.TURN_RATE] = 0.0
        Q[models.TURN_RATE, models.TURN_RATE] = 1e-12  # keeps P positive definite
        super().__init__(
            transition=F,
            process_noise=Q,
            measurement_matrix=models.position_measurement_matrix(),
            measurement_noise=models.measurement_noise(max(float(sigma), 1e-3)),
            x0=np.zeros((0, models.N_STATE)),
            P0=np.zeros((0, models.N_STATE, models.N_STATE)),
        )

    def append(self, x0, P0, mu0=None) -> np.ndarray:
        """Add tracks (``mu0`` ignored: one mode); Ω starts at 0."""
        x0 = np.array(x0, dtype=float, ndmin=2)
        x0[:, models.TURN_RATE] = 0.0
        return super().append(x0, P0)

    def remove(self, indices) -> None:
        """Drop rows given as indices or as a (B,) boolean mask (the track table's form)."""
        idx = np.asarray(indices)
        if idx.dtype == bool:
            if idx.shape != (self.B,):
                raise ValueError(f"remove: mask must have shape ({self.B},), got {idx.shape}")
            idx = np.flatnonzero(idx)
        super().remove(idx.astype(np.int64))


@register("tracker", "kalman")
def kalman_tracker(
    preset, sigma: float, sigma_accel: float | None = None
) -> ConstantVelocityTracker:
    """The ``"kalman"`` tracker: :class:`ConstantVelocityTracker` with R = σ² I."""
    return ConstantVelocityTracker(preset, sigma, sigma_accel)
