"""Experiments: many seeded runs on one engine, resumable, identical on any backend.

- :mod:`.store`: the state on disk (manifest, atomic Parquet parts, verify and repair).
- :mod:`.backends`: where units run (this process, local worker processes, Ray).
- :mod:`.engine`: units -> backend -> parts, with a progress bar.
- :mod:`.sweep`: ``airspace-sim sweep``: a scenario over a grid of settings and seeds.
- :mod:`.summary`: mean and 95 % confidence interval per grid cell.
- :mod:`.plot`: a metric against a grid key (matplotlib PNG).

The encounter campaigns (:mod:`airspace_sim.encounters.campaign`) run on the same engine.
See ``docs/sweeps.md``.
"""

from airspace_sim.experiments.backends import BACKENDS, LocalBackend, RayBackend, make_backend
from airspace_sim.experiments.engine import Unit, execute
from airspace_sim.experiments.store import PartStore

__all__ = [
    "BACKENDS",
    "LocalBackend",
    "PartStore",
    "RayBackend",
    "Unit",
    "execute",
    "make_backend",
]
