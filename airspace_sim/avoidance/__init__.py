"""Conflict detection and avoidance (paper §V; issue 3).

- :mod:`.escape`: the paper's escape angle ``θ`` in the relative frame (§V, Figure 3).
- :mod:`.heading`: exact world-frame heading changes (own speed kept, heading turned).
- :mod:`.bands`: multi-intruder heading bands over a look-ahead (DAIDALUS-style).
- :mod:`.probability`: conflict probability from the IMM's mode mixture.
- :mod:`.resolvers`: the resolver classes registered as ``"none"``, ``"seed"``,
  ``"seed-world"``, ``"bands"``, ``"bands-probabilistic"`` (protocol
  :class:`airspace_sim.parts.Resolver`), and :func:`~.resolvers.build_resolver`.
- :mod:`.roundabout`: ``"bands-roundabout"``, bands under a right-of-way convention, with
  co-rotated candidates and recovery by latest loss as options (issue 13, docs/resolvers.md).
- :mod:`.mode_bands`: ``"bands-modes"``, bands whose candidates also clear each likely IMM
  mode's predicted path.
- :mod:`.flown_bands`: ``"bands-flown"`` and ``"bands-flown-turns"``, headings judged as flown
  at the turn rate (the ring and dense scenarios' resolver).
- :mod:`.speed_bands`: ``"bands-flown-speed"``, ``"bands-flown"`` with speed as a second
  control (:mod:`.cpa_speed`: the path turning and changing speed).
- :mod:`.paired_bands`: ``"bands-flown-paired"``, ``"bands-flown"`` whose boxed pairs pick
  their headings together (explicit coordination of equipped aircraft).
- :mod:`.intent_bands`: ``"bands-flown-intent"``, ``"bands-flown"`` with each equipped
  intruder predicted along the heading it broadcasts it steers to (intent-based).

Units: metres, seconds, radians; angles CCW positive (a negative heading change is a right
turn); relative quantities are intruder minus ownship.
"""

from airspace_sim.avoidance.bands import BandResult, band_search, resume_heading_change
from airspace_sim.avoidance.escape import escape_angle, escape_rotation, predicted_conflict
from airspace_sim.avoidance.heading import tangent_heading_change
from airspace_sim.avoidance.probability import conflict_probability, probability_inside_circle

__all__ = [
    "BandResult",
    "band_search",
    "conflict_probability",
    "escape_angle",
    "escape_rotation",
    "predicted_conflict",
    "probability_inside_circle",
    "resume_heading_change",
    "tangent_heading_change",
]
