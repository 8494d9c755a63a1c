"""Vectorising the env for training: SuperSuit's chain, ready for Stable-Baselines3.

    from stable_baselines3 import PPO
    from airspace_sim.env.vector import sb3_vec_env
    venv = sb3_vec_env("ring8", num_vec_envs=4, num_cpus=2)   # 4 copies × 8 agents
    model = PPO("MlpPolicy", venv, seed=0).learn(100_000)      # one policy shared by all

This is SuperSuit's documented recipe, unchanged:
``black_death_v3`` (agents end at different times; ended agents get zero observations and
rewards until the episode ends) → ``pettingzoo_env_to_vec_env_v1`` (one vector slot per
possible agent: a shared policy) → ``concat_vec_envs_v1`` (copies of the env, in
``num_cpus`` processes; the env pickles). Each agent-slot is then one SB3 "env".

One adaptor is added (:func:`seeded_vec_env_class`): SuperSuit 3.11's Stable-Baselines3 wrapper
has no working ``seed()`` (``PPO(seed=...)`` fails with ``'ProcConcatVec' object has no
attribute 'seed'``) and its ``reset`` drops seeds; the adaptor keeps SB3's contract (the
seed given to ``seed()`` is used by the next ``reset()``; copy k of the env gets ``seed +
k``, as SuperSuit numbers them), so ``PPO(seed=s)`` runs are repeatable.

SuperSuit and Stable-Baselines3 are optional (``pip install airspace-sim[rl]``); nothing
here imports them before it is called.
"""

from __future__ import annotations

import functools

from airspace_sim.errors import UserError


def supersuit_vec_env(env=None, num_vec_envs: int = 1, num_cpus: int = 0, **env_kwargs):
    """The SuperSuit chain as a Gymnasium vector env (one slot per agent and copy).

    env : a parallel env, a registry id or scenario name (``"ring8"``), or None to build
        ``parallel_env(**env_kwargs)``; num_vec_envs : copies of it; num_cpus : worker
        processes (0 = all in this process).
    """
    import supersuit as ss

    from airspace_sim import env as aenv

    if env is None:
        env = aenv.parallel_env(**env_kwargs)
    elif isinstance(env, str):
        env = aenv.make(env, **env_kwargs)
    elif env_kwargs:
        raise UserError("supersuit_vec_env: keyword arguments need env=None or an env id")
    env = ss.black_death_v3(env)
    venv = ss.pettingzoo_env_to_vec_env_v1(env)
    return ss.concat_vec_envs_v1(venv, int(num_vec_envs), num_cpus=int(num_cpus))


def sb3_vec_env(env=None, num_vec_envs: int = 1, num_cpus: int = 0, **env_kwargs):
    """:func:`supersuit_vec_env` as a Stable-Baselines3 ``VecEnv`` whose ``seed()`` works
    (:func:`seeded_vec_env_class`)."""
    return seeded_vec_env_class()(supersuit_vec_env(env, num_vec_envs, num_cpus, **env_kwargs))


@functools.cache
def seeded_vec_env_class():
    """SuperSuit's ``SB3VecEnvWrapper`` with SB3's seeding contract: ``seed(s)`` is used by
    the next ``reset()`` (``reset(seed=s)`` too). Built on first use, so importing this
    module needs neither SuperSuit nor Stable-Baselines3."""
    from supersuit.vector.sb3_vector_wrapper import SB3VecEnvWrapper

    class SeededVecEnv(SB3VecEnvWrapper):
        def __init__(self, venv):
            super().__init__(venv)
            self._pending_seed = None

        def seed(self, seed=None):
            self._pending_seed = seed
            return [None if seed is None else seed + k for k in range(self.num_envs)]

        def reset(self, seed=None, options=None):
            seed = self._pending_seed if seed is None else seed
            self._pending_seed = None
            observations, self.reset_infos = self.venv.reset(seed=seed, options=options)
            return observations

    return SeededVecEnv
