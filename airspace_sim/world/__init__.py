"""The airspace world (issue 4): a pymunk space of kinematic aircraft, autopilots, sensors,
one batched track table and conflict avoidance, stepped together.

- :mod:`.world`: :class:`World`, one step of the whole world, metrics and snapshots.
- :mod:`.bodies`: the pymunk space, sensor circles and collision handlers (LoS, NMAC, range).
- :mod:`.autopilots`: ``straight``, ``route``, ``markov`` (registry kind ``"autopilot"``).
- :mod:`.sensors`: ``radar`` (registry kind ``"sensor"``).
- :mod:`.trackers`: the track table over all (ownship, intruder) pairs; ``imm`` tracker.
- :mod:`.control`: gathering tracks for the resolver, advice, resuming the route.
- :mod:`.metrics`: LoS, NMAC, separation, alerts, extra path, tracking accuracy.
- :mod:`.streams`: counter-based per-aircraft random numbers (seeded, order independent).
- :mod:`.benchmark`: :func:`bench_world` steps per second.
"""

from airspace_sim.world.world import World

__all__ = ["World"]
