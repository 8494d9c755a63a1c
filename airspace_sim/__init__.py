"""airspace_sim: a 2D multi-aircraft airspace simulator.

Packages, one per domain:

- :mod:`airspace_sim.dynamics`: jump-Markov aircraft models (paper §II) and truth generation.
- :mod:`airspace_sim.tracking`: the batched IMM estimator (paper §IV).
- :mod:`airspace_sim.avoidance`: conflict detection and avoidance (paper §V).
- :mod:`airspace_sim.world`: the pymunk world of aircraft, sensors and trackers.
- :mod:`airspace_sim.env`: the PettingZoo parallel environment.
- :mod:`airspace_sim.rendering`: the pygame renderer (the only pygame importer).
- :mod:`airspace_sim.scenarios`: TOML scenario loading and validation.

Units are SI throughout: metres, seconds, radians (and m/s, rad/s).
"""

__version__ = "0.1.0"
