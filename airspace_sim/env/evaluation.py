"""Evaluating a policy on held-out seeds: the table the training examples print.

    from airspace_sim.env.evaluation import batch_actor, evaluate, markdown_table
    act = batch_actor(lambda obs: model.predict(obs, deterministic=True)[0])  # (n, D) → (n, 1)
    rows = evaluate(act, sizes=[8, 12], episodes=10)
    print(markdown_table(rows, trained_size=8))

Shared by ``docs/examples/train_ppo.py`` (Stable-Baselines3) and
``docs/examples/train_rllib.py`` (Ray RLlib), so both report the same metrics the same way.
Per policy and ring size: the mean (and standard deviation) over episodes of losses of
separation and NMACs (pair events over all aircraft, from ``World.metrics()``) and of the
mean return per agent. The rings are :func:`.registration.ring_kwargs` with every aircraft an
agent; evaluation seeds start at :data:`FIRST_SEED`, far from any training seed, so every
ring (radius, phase, speeds, start times) is new to the policy.

An *actor* maps ``(agents, observations)`` to an action dict for those agents. The
baselines (:data:`BASELINES`): ``random`` (uniform in [-1, 1]), ``straight`` (0: hold the
heading), ``built-in`` (``None``: the world's route autopilot and CDA resolver).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from airspace_sim.env.airspace_env import AirspaceParallelEnv
from airspace_sim.env.registration import ring_kwargs

FIRST_SEED = 10_000  #: the first held-out evaluation seed

#: ``actor(agents, obs) -> {agent: action}``
Actor = Callable[[list, dict], dict]


def ring_env(n: int, **kw) -> AirspaceParallelEnv:
    """The ``ring{n}`` env (every aircraft an agent, geometry drawn per seed)."""
    return AirspaceParallelEnv(**{**ring_kwargs(n), **kw})


def batch_actor(predict: Callable[[np.ndarray], np.ndarray]) -> Actor:
    """An actor from a shared policy's batched forward pass: ``predict`` maps stacked
    observations (n_agents, obs_dim) to actions (n_agents, 1) (turn fractions)."""

    def act(agents, obs):
        actions = np.asarray(predict(np.stack([obs[a] for a in agents])), dtype=np.float32)
        return {a: actions[k].reshape(1) for k, a in enumerate(agents)}

    return act


def random_actor(rng: np.random.Generator) -> Actor:
    """Uniform turn fractions in [-1, 1], drawn from ``rng``."""
    return lambda agents, obs: {a: rng.uniform(-1, 1, 1).astype(np.float32) for a in agents}


def straight_actor(agents, obs) -> dict:
    """Hold the heading (turn fraction 0)."""
    return {a: np.zeros(1, np.float32) for a in agents}


def builtin_actor(agents, obs) -> dict:
    """``None`` for every agent: the built-in autopilot and resolver fly it."""
    return dict.fromkeys(agents)


#: baseline name → actor factory (called with the episode set's random generator)
BASELINES: dict[str, Callable[[np.random.Generator], Actor]] = {
    "random": random_actor,
    "straight": lambda rng: straight_actor,
    "built-in": lambda rng: builtin_actor,
}


def play(env: AirspaceParallelEnv, act: Actor, seed: int) -> tuple[int, int, float]:
    """One episode from ``reset(seed=seed)``: (LoS events, NMAC events, mean return per
    agent)."""
    obs, _ = env.reset(seed=seed)
    ret = dict.fromkeys(env.agents, 0.0)
    while env.agents:
        obs, rew, *_ = env.step(act(list(env.agents), obs))
        for a, r in rew.items():
            ret[a] += r
    m = env.world.metrics()
    return m["los_events"], m["nmac_events"], float(np.mean(list(ret.values())))


def evaluate(
    trained: Actor | None,
    sizes: list[int],
    episodes: int,
    first_seed: int = FIRST_SEED,
) -> list[tuple]:
    """Rows ``(ring size, policy, LoS, NMAC, return, std LoS, std NMAC, std return)`` over
    seeds ``first_seed .. first_seed + episodes - 1``, for ``trained`` (left out if None)
    and every baseline, per ring size."""
    rows = []
    for n in sizes:
        env = ring_env(n)
        policies = ({"trained": lambda rng: trained} if trained is not None else {}) | BASELINES
        for name, factory in policies.items():
            act = factory(np.random.default_rng(0))
            res = np.array([play(env, act, first_seed + k) for k in range(episodes)])
            rows.append((n, name, *res.mean(axis=0), *res.std(axis=0)))
        env.close()
    return rows


def markdown_table(
    rows: list[tuple], trained_size: int, episodes: int, first_seed: int = FIRST_SEED
) -> str:
    """The rows of :func:`evaluate` as a Markdown table under a one-line heading."""
    lines = [
        f"Held-out seeds ({first_seed}..{first_seed + episodes - 1}), means per episode (± std):",
        "",
        "| ring | policy | LoS | NMAC | return per agent |",
        "| --- | --- | --- | --- | --- |",
    ]
    for n, policy, los, nmac, ret, s_los, s_nmac, s_ret in rows:
        seen = "trained on" if n == trained_size else "unseen"
        lines.append(
            f"| {n} ({seen}) | {policy} | {los:.1f} ± {s_los:.1f} | {nmac:.1f} ± {s_nmac:.1f} "
            f"| {ret:.2f} ± {s_ret:.2f} |"
        )
    return "\n".join(lines)
