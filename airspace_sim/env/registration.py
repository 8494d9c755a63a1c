"""Registering the env with PettingZoo 1.27's registry (``pettingzoo.register``/``make``).

On import of :mod:`airspace_sim.env`, every shipped scenario ``<name>`` (a file stem in the
repository's ``scenarios/`` folder) is registered as ``airspace_sim/<name>-v0`` in both the
``"parallel"`` and ``"aec"`` registries::

    import pettingzoo, airspace_sim.env
    env = pettingzoo.make("parallel", "airspace_sim/head_on-v0", max_cycles=100)

:func:`make` is the same thing without naming the registry type.
"""

from __future__ import annotations

import warnings

ENV_NAMESPACE = "airspace_sim"
VERSION = 0


def env_id(scenario: str) -> str:
    """The registry id of a shipped scenario: ``airspace_sim/<scenario>-v0``."""
    return f"{ENV_NAMESPACE}/{scenario}-v{VERSION}"


def _entry(kind: str, scenario: str):
    from airspace_sim import env as env_pkg

    factory = env_pkg.parallel_env if kind == "parallel" else env_pkg.env

    def make_env(**kwargs):
        kwargs.setdefault("scenario", scenario)
        return factory(**kwargs)

    make_env.__name__ = f"{scenario}_{kind}_env"
    make_env.__qualname__ = make_env.__name__
    return make_env


def register_envs() -> list[str]:
    """Register every shipped scenario; returns the ids. Safe to call more than once."""
    import pettingzoo

    from airspace_sim.scenarios import available

    ids = []
    for name in available():
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
