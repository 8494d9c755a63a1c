"""Encounters: the paper's relative-frame reproduction, world-frame runs, Monte Carlo
campaigns and figures (paper §V–VII).

- :mod:`.relative`: the paper's encounter, ownship at the origin (:func:`run_relative`).
- :mod:`.world_frame`: ownship moving, world-frame tracking (:func:`run_world`).
- :mod:`.campaign`: seeded Monte Carlo runner with workers, parquet output and resume.
- :mod:`.figures`: matplotlib counterparts of the paper's figures 4–7 and more.
"""

from airspace_sim.encounters.relative import EncounterBatch, EncounterConfig, run_relative

__all__ = ["EncounterBatch", "EncounterConfig", "run_relative"]
