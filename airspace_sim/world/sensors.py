"""Surveillance sensors: which intruders an ownship measures this scan, and how noisily.

*Who is in range* comes from the pymunk space (:mod:`.bodies`, RANGE circles of radius
``range/2``: two overlap exactly when the aircraft are closer than ``range``); a sensor
only decides, for each (owner, intruder) pair in range, whether it is detected on this scan
and what it reports. Registered as ``"radar"``, a class fitting :class:`airspace_sim.parts.Sensor` (constructed
as ``cls(spec, dt, params)``; methods, shapes and units there). Its settings are validated
by the scenario loader (``sensor.*``), which the sensor trusts.

Measurements are intruder positions in WORLD coordinates (the ownship knows where it is),
so trackers work in the world frame and the ownship's own turns are never mistaken for the
intruder's (``docs/paper-notes.md`` §3, weakness 1).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from airspace_sim.parts import NoParams, Sensor
from airspace_sim.registry import register
from airspace_sim.scenarios.schema import SensorSpec
from airspace_sim.world import streams


@register("sensor", "radar")
class Radar(Sensor):
    """Position-only sensor: ``z = p_intruder + w``, ``w ~ N(0, σ² I₂)``; each pair in range
    detected with probability ``detection_probability`` per scan; one scan every ``period``
    seconds (a whole number of world steps). Random numbers are counter-based per pair and
    step (:mod:`.streams`), so they do not depend on which other pairs exist."""

    Params = NoParams

    def __init__(self, spec: SensorSpec, dt: float, params=None):
        self.sigma = float(spec.sigma)
        self.pd = float(spec.detection_probability)
        self.period_steps = max(1, round(spec.period / dt))

    def scans(self, step: int) -> bool:
        return step % self.period_steps == 0

    def measure(self, owner, intruder, positions, pair_keys, step):
        truth = np.ascontiguousarray(positions[intruder], dtype=float)
        keys = np.ascontiguousarray(pair_keys, dtype=np.uint64)
        wx1, wx2 = streams.normal_words(streams.NOISE_X, step)
        wy1, wy2 = streams.normal_words(streams.NOISE_Y, step)
        return _radar_kernel(
            truth,
            keys,
            self.sigma,
            self.pd,
            streams.counter_word(streams.DETECT, step),
            wx1,
            wx2,
            wy1,
            wy2,
        )

    def measure_numpy(self, owner, intruder, positions, pair_keys, step):
        """:meth:`measure` with the numpy streams (the reference for :func:`_radar_kernel`)."""
        truth = positions[intruder]
        if self.pd >= 1.0:
            detected = np.ones(owner.size, dtype=bool)
        else:
            detected = streams.uniform_numpy(pair_keys, streams.DETECT, step) < self.pd
        z = truth.copy()
        if self.sigma > 0:
            z[:, 0] += self.sigma * streams.normal_numpy(pair_keys, streams.NOISE_X, step)
            z[:, 1] += self.sigma * streams.normal_numpy(pair_keys, streams.NOISE_Y, step)
        return z, detected


@njit(cache=True)
def _radar_kernel(truth, keys, sigma, pd, w_detect, wx1, wx2, wy1, wy2):  # pragma: no cover
    """``(z (P, 2) m, detected (P,) bool)`` of :meth:`Radar.measure` for the intruders' true
    positions ``truth`` (P, 2) m and pair keys (P,) uint64; the counter words are those of
    the DETECT uniform and the NOISE_X, NOISE_Y normals (:mod:`.streams`)."""
    P = keys.size
    z = truth.copy()
    detected = np.ones(P, dtype=np.bool_)
    for p in range(P):
        if pd < 1.0:
            detected[p] = streams.draw_uniform(keys[p], w_detect) < pd
        if sigma > 0:
            z[p, 0] += sigma * streams.draw_normal(keys[p], wx1, wx2)
            z[p, 1] += sigma * streams.draw_normal(keys[p], wy1, wy2)
    return z, detected
