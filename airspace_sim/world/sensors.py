"""Surveillance sensors: which intruders an ownship measures this scan, and how noisily.

*Who is in range* comes from the pymunk space (:mod:`.bodies`, RANGE circles of radius
``range/2``: two overlap exactly when the aircraft are closer than ``range``); a sensor
only decides, for each (owner, intruder) pair in range, whether it is detected on this scan
and what it reports. Registered as ``"radar"``.

Interface (plugins implement the same)::

    factory(spec: SensorSpec, dt: float) -> sensor
    sensor.period_steps -> int       # world steps between scans (≥ 1)
    sensor.scans(step) -> bool       # does a scan happen at world step index ``step``
    sensor.measure(owner (P,), intruder (P,), positions (N, 2), pair_keys (P,) uint64, step)
        -> (z (P, 2) m world-frame positions, detected (P,) bool)

Measurements are intruder positions in WORLD coordinates (the ownship knows where it is),
so trackers work in the world frame and the ownship's own turns are never mistaken for the
intruder's (``shared/design/seed-model.md`` §3, weakness 1).
"""

from __future__ import annotations

import numpy as np

from airspace_sim.errors import UserError
from airspace_sim.registry import register
from airspace_sim.scenarios.schema import SensorSpec
from airspace_sim.world import streams


class Radar:
    """Position-only sensor: ``z = p_intruder + w``, ``w ~ N(0, σ² I₂)``; each pair in range
    detected with probability ``detection_probability`` per scan; one scan every ``period``
    seconds (rounded to whole world steps). Random numbers are counter-based per pair and
    step (:mod:`.streams`), so they do not depend on which other pairs exist."""

    def __init__(self, spec: SensorSpec, dt: float):
        if not (spec.sigma >= 0 and np.isfinite(spec.sigma)):
            raise UserError(
                f"sensor.sigma: must be a non-negative number of metres, got {spec.sigma!r}"
            )
        if not (0.0 <= spec.detection_probability <= 1.0):
            raise UserError(
                f"sensor.detection_probability: must be in [0, 1], got {spec.detection_probability!r}"
            )
        if not (spec.period > 0):
            raise UserError(f"sensor.period: must be positive seconds, got {spec.period!r}")
        self.sigma = float(spec.sigma)
        self.pd = float(spec.detection_probability)
        self.period_steps = max(1, round(spec.period / dt))

    def scans(self, step: int) -> bool:
        return step % self.period_steps == 0

    def measure(self, owner, intruder, positions, pair_keys, step):
        truth = positions[intruder]
        if self.pd >= 1.0:
            detected = np.ones(owner.size, dtype=bool)
        else:
            detected = streams.uniform(pair_keys, streams.DETECT, step) < self.pd
        z = truth.copy()
        if self.sigma > 0:
            z[:, 0] += self.sigma * streams.normal(pair_keys, streams.NOISE_X, step)
            z[:, 1] += self.sigma * streams.normal(pair_keys, streams.NOISE_Y, step)
        return z, detected


register("sensor", "radar")(Radar)
