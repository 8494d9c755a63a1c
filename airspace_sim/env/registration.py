"""Registering the env with PettingZoo 1.27's registry (``pettingzoo.register``/``make``).

On import of :mod:`airspace_sim.env`, every shipped scenario ``<name>`` (a file stem in the
repository's ``scenarios/`` folder) is registered as ``airspace_sim/<name>-v0`` in both the
``"parallel"`` and ``"aec"`` registries, with the scenario's own agents (its ``controlled``
marks, else its first aircraft), and so is every multi-agent id of :data:`MULTI_AGENT`,
where **every aircraft is an agent** and the seed draws the geometry::

    import pettingzoo, airspace_sim.env
    env = pettingzoo.make("parallel", "airspace_sim/head_on-v0", max_cycles=100)
    env = pettingzoo.make("parallel", "airspace_sim/ring8-v0")      # 8 agents

:func:`make` is the same thing without naming the registry type. Keyword arguments given
to ``make`` override the registered ones.
"""

from __future__ import annotations

import math
import warnings

ENV_NAMESPACE = "airspace_sim"
VERSION = 0
R_SAFE_M = 3000.0  #: the shipped ring and dense scenarios' r_safe


def ring_kwargs(n: int) -> dict:
    """Env keyword arguments of ``ring`` with n aircraft (any n ≥ 2), all agents; radius drawn in [R, R + 10 km] with R at least
    15 km and 15% above the ring's minimum, phase in [0, 360)°, speeds in [210, 250] m/s,
    start delays in [0, 10] s, heading offsets ±5°; long enough for the slowest to cross."""
    r_min = R_SAFE_M / math.sin(math.pi / n)
    lo = max(15_000.0, 1000.0 * math.ceil(1.15 * r_min / 1000.0))
    hi = lo + 10_000.0
    duration = 10.0 * math.ceil(((2 * hi + 2500.0) / 210.0 + 30.0) / 10.0)
    return dict(
        scenario="ring",
        agents="all",
        overrides=[
            f"traffic.count={n}",
            f"traffic.radius={lo}",
            f"randomise.radius=[{lo}, {hi}]",
            "randomise.phase_deg=[0.0, 360.0]",
            "randomise.speed=[210.0, 250.0]",
            "randomise.start_s=[0.0, 10.0]",
            "randomise.heading_deg=[-5.0, 5.0]",
            f"duration={duration}",
        ],
    )


def dense_kwargs(n: int) -> dict:
    """``dense_random`` with n aircraft, all agents, at its density (60 in 100 km × 100 km:
    6 per 1000 km²); the seed draws positions and routes, as for every random sector."""
    side = 100_000.0 * math.sqrt(n / 60.0)
    return dict(
        scenario="dense_random",
        agents="all",
        overrides=[f"traffic.count={n}", f"traffic.sector={side:.1f}", "duration=400.0"],
    )


#: Multi-agent ids (``airspace_sim/<name>-v0``) → the keyword arguments they stand for.
MULTI_AGENT = {
    **{f"ring{n}": ring_kwargs(n) for n in (4, 8, 16, 32)},
    **{f"dense{n}": dense_kwargs(n) for n in (8, 16, 32)},
}


def env_id(scenario: str) -> str:
    """The registry id of a shipped scenario or multi-agent name: ``airspace_sim/<name>-v0``."""
    return f"{ENV_NAMESPACE}/{scenario}-v{VERSION}"


def _entry(kind: str, name: str):
    from airspace_sim import env as env_pkg

    factory = env_pkg.parallel_env if kind == "parallel" else env_pkg.env
    defaults = MULTI_AGENT.get(name, {"scenario": name})

    def make_env(**kwargs):
        return factory(**{**defaults, **kwargs})

    make_env.__name__ = f"{name}_{kind}_env"
    make_env.__qualname__ = make_env.__name__
    return make_env


def register_envs() -> list[str]:
    """Register every shipped scenario and multi-agent id; returns the ids. Safe to call
    more than once."""
    import pettingzoo

    from airspace_sim.scenarios import available

    ids = []
    for name in list(available()) + list(MULTI_AGENT):
        eid = env_id(name)
        for kind in ("parallel", "aec"):
            registry = (
                pettingzoo.parallel_registry if kind == "parallel" else pettingzoo.aec_registry
            )
            if eid in registry:
                continue
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                pettingzoo.register(kind, eid, entry_point=_entry(kind, name))
        ids.append(eid)
    return ids


def make(env_id_or_scenario: str, parallel: bool = True, **kwargs):
    """``make("airspace_sim/head_on-v0")`` or ``make("head_on")``: a parallel (or AEC) env."""
    import pettingzoo

    eid = env_id_or_scenario
    if "/" not in eid and not eid.endswith(f"-v{VERSION}"):
        eid = env_id(eid)
    return pettingzoo.make("parallel" if parallel else "aec", eid, **kwargs)
