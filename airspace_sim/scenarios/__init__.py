"""Scenarios: TOML files in the repository's ``scenarios/`` folder, validated into dataclasses.

    from airspace_sim.scenarios import load, build_aircraft
    sc = load("head_on", overrides=["traffic.count=4"])      # a name or a path
    aircraft = build_aircraft(sc, np.random.default_rng(sc.seed))

The dataclasses in :mod:`.schema` are the single source of truth for keys, types and units;
:mod:`.loader` derives its checks from them. Any problem is one
:class:`~airspace_sim.errors.UserError` line naming file (or ``--set``), key and value.
"""

from airspace_sim.scenarios.loader import available, from_dict, load, resolve
from airspace_sim.scenarios.schema import (
    AircraftSpec,
    ResolverSpec,
    Scenario,
    SensorSpec,
    Separation,
    TrackerSpec,
    TrafficSpec,
)
from airspace_sim.scenarios.traffic import build_aircraft

__all__ = [
    "AircraftSpec",
    "ResolverSpec",
    "Scenario",
    "SensorSpec",
    "Separation",
    "TrackerSpec",
    "TrafficSpec",
    "available",
    "build_aircraft",
    "from_dict",
    "load",
    "resolve",
]
