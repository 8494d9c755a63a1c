"""PettingZoo environment over the airspace world.

    import airspace_sim.env as aenv
    par = aenv.parallel_env(scenario="head_on", max_cycles=200, agents=2)
    aec = aenv.env(scenario="crossing", render_mode="rgb_array")
    # or through PettingZoo's registry (registered on import of this package):
    import pettingzoo
    par = pettingzoo.make("parallel", "airspace_sim/head_on-v0")
    ring = pettingzoo.make("parallel", "airspace_sim/ring8-v0")  # 8 agents, random geometry

Training with SuperSuit and Stable-Baselines3: :mod:`.vector`; the guide is ``docs/rl.md``.

Keyword arguments are those of :class:`AirspaceParallelEnv`. The observation layout and
action spaces are in :mod:`.spaces`, the reward terms in :mod:`.rewards`.
"""

from pettingzoo.utils import parallel_to_aec

from airspace_sim.env.airspace_env import (
    RESET_OPTIONS,
    STATE_NAMES,
    AirspaceParallelEnv,
    agent_ids,
)
from airspace_sim.env.checks import ActionError, ResetNeeded, SeedError
from airspace_sim.env.registration import MULTI_AGENT, env_id, make, register_envs
from airspace_sim.env.rewards import DEFAULT_WEIGHTS
from airspace_sim.env.spaces import (
    BUILTIN_ACTION,
    DISCRETE_LEVELS,
    DISCRETE_NAMES,
    ObservationLayout,
)


def parallel_env(**kwargs) -> AirspaceParallelEnv:
    """A :class:`AirspaceParallelEnv` (PettingZoo parallel API)."""
    return AirspaceParallelEnv(**kwargs)


def env(**kwargs):
    """The same env in PettingZoo's AEC form (``parallel_to_aec``)."""
    return parallel_to_aec(AirspaceParallelEnv(**kwargs))


raw_env = AirspaceParallelEnv
REGISTERED_IDS = register_envs()

__all__ = [
    "ActionError",
    "AirspaceParallelEnv",
    "BUILTIN_ACTION",
    "MULTI_AGENT",
    "RESET_OPTIONS",
    "ResetNeeded",
    "STATE_NAMES",
    "SeedError",
    "agent_ids",
    "DEFAULT_WEIGHTS",
    "DISCRETE_LEVELS",
    "DISCRETE_NAMES",
    "ObservationLayout",
    "REGISTERED_IDS",
    "env",
    "env_id",
    "make",
    "parallel_env",
    "raw_env",
    "register_envs",
]
