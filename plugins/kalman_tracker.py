"""Tracker plugin ``"kalman"``: a single-model constant-velocity Kalman filter (a baseline).

Shipped: installed as ``airspace_sim_plugins.kalman_tracker`` and registered through the
package's own ``airspace_sim.plugins`` entry point (docs/plugins.md), so an installed
airspace-sim finds it anywhere; copy this file into a plugins folder to write your own.
Use it in a scenario with ``[tracker] kind = "kalman"`` or ``--set tracker.kind=kalman``.

It is a :class:`airspace_sim.parts.Tracker`: tracks live in stable slots (births fill free
slots, drops free them, nothing else moves), ``step`` filters the live slots only.

The state is the world's ``[x, vx, y, vy, Ω]`` (m, m/s, rad/s). The model is constant
velocity with Ω pinned to 0; its process noise is the preset's filter Q plus a manoeuvre
allowance: white-noise acceleration with σ_m = ½·max|ω|·mean speed (half the centripetal
acceleration of the preset's turns), the usual way a single CV filter is tuned to survive
turns it does not model. Set ``Params.sigma_accel`` (m/s²) to choose σ_m yourself.
"""

# (no ``from __future__ import annotations``: dataclasses would then look the module up in
# sys.modules, where a plugin file executed on its own is not)
from dataclasses import dataclass

import numpy as np

from airspace_sim import parts
from airspace_sim.dynamics import models
from airspace_sim.registry import register
from airspace_sim.tracking import kalman
from airspace_sim.tracking.prediction import predict_modes_at
from airspace_sim.tracking.slots import Slots


def manoeuvre_sigma(preset) -> float:
    """Default σ_m (m/s²): half the centripetal acceleration of the preset's fastest turn."""
    omega = float(np.max(np.abs(preset.turn_rates), initial=0.0))
    speed = float(np.mean(preset.speed_range))
    return 0.5 * omega * speed


def _ro(a):
    v = a.view()
    v.flags.writeable = False
    return v


@register("tracker", "kalman")
class ConstantVelocityTracker(parts.Tracker):
    """CV Kalman filters over ``[x, vx, y, vy, Ω]`` with Ω held at 0, one per slot, with
    R = σ² I. One mode (``mu`` = 1); its mode prediction is the CV prediction."""

    @dataclass(frozen=True)
    class Params:
        #: manoeuvre allowance σ_m, m/s² (None: :func:`manoeuvre_sigma` of the preset)
        sigma_accel: float | None = None

    predicts_modes = True
    n_modes = 1
    mode_names = ("constant velocity",)

    def __init__(self, preset, sigma: float, params=None):
        self.params = self.Params() if params is None else params
        dt = float(preset.dt)
        F = models.constant_velocity(dt)
        F[models.TURN_RATE, :] = 0.0  # Ω pinned to 0: the CV assumption
        sa = self.params.sigma_accel
        self.sigma_accel = manoeuvre_sigma(preset) if sa is None else float(sa)
        Q = np.asarray(preset.filter_process_noise, dtype=float).copy()
        Q += models.white_noise_acceleration(self.sigma_accel, dt)
        Q[models.TURN_RATE, :] = Q[:, models.TURN_RATE] = 0.0
        Q[models.TURN_RATE, models.TURN_RATE] = 1e-12  # keeps P positive definite
        self.F, self.Q, self.u = F, Q, np.zeros(models.N_STATE)
        self.H = models.position_measurement_matrix()
        self.R = models.measurement_noise(max(float(sigma), 1e-3))
        self._slots = Slots()
        n = models.N_STATE
        self._x = np.zeros((0, n))
        self._P = np.zeros((0, n, n))
        self._mu = np.zeros((0, 1))

    capacity = property(lambda self: self._slots.capacity)
    alive = property(lambda self: _ro(self._slots.alive))
    x = property(lambda self: _ro(self._x), doc="(capacity, 5) by slot; NaN in free slots.")
    P = property(lambda self: _ro(self._P), doc="(capacity, 5, 5) by slot.")
    mu = property(lambda self: _ro(self._mu), doc="(capacity, 1) ones.")

    def birth(self, x0, P0) -> np.ndarray:
        """Start tracks (Ω starts at 0); returns their slots."""
        n = models.N_STATE
        x0 = np.array(x0, dtype=float, ndmin=2)
        x0[:, models.TURN_RATE] = 0.0
        P0 = np.broadcast_to(np.asarray(P0, dtype=float), (x0.shape[0], n, n))
        if not (np.all(np.isfinite(x0)) and np.all(np.isfinite(P0))):
            raise ValueError("kalman tracker birth: x0 and P0 must be finite")
        need = self._slots.capacity_for(x0.shape[0])
        if need > self.capacity:
            old = self.capacity
            for name, shape in (("_x", (need, n)), ("_P", (need, n, n)), ("_mu", (need, 1))):
                a = np.full(shape, np.nan)
                a[:old] = getattr(self, name)
                setattr(self, name, a)
            self._slots.grow(need)
        slots = self._slots.take(x0.shape[0])
        self._x[slots], self._P[slots], self._mu[slots] = x0, P0, 1.0
        return slots

    def drop(self, slots) -> None:
        s = self._slots.release(slots, "kalman tracker drop")
        self._x[s] = self._P[s] = self._mu[s] = np.nan

    def step(self, z, truth=None) -> None:
        """Predict then update every live slot with its row of ``z`` (capacity, 2)."""
        live = self._slots.live()
        if live.size == 0:
            return
        x, P = kalman.predict(self._x[live], self._P[live], self.F, self.Q, self.u)
        x, P, _ = kalman.update(x, P, np.asarray(z, dtype=float)[live], self.H, self.R)
        self._x[live], self._P[live] = x, P

    def predict_modes_at(self, steps, slots):
        """The CV prediction as one mode: (R, 1, S, 5), (R, 1, S, 5, 5)."""
        x, P = self._x[slots], self._P[slots]
        return predict_modes_at(
            self.F[None], self.Q[None], self.u[None], x[:, None], P[:, None], steps
        )
