"""Ray RLlib glue: the env creator, a PPO config with one module shared by every agent,
and an evaluation actor read back from a checkpoint.

    import ray
    from airspace_sim.env import rllib as arl
    ray.init(num_cpus=2)
    algo = arl.ppo_config("ring8", seed=0).build_algo()      # RLlib's new API stack
    algo.train(); path = algo.save_to_path("/tmp/ring8")
    act = arl.trained_actor(path)                              # for env.evaluation

The env is RLlib's own PettingZoo wrapper
(``ray.rllib.env.wrappers.pettingzoo_env.ParallelPettingZooEnv``) around a registered id
(``"ring8"``, ``"dense16"``, a scenario name), with one fix to its ``__all__`` flags
(:func:`rllib_env_class`). The
functions live in the package, not in a script, because EnvRunner actors unpickle the env
creator and the policy mapping by reference: on a cluster every node imports them from the
installed package. ``docs/examples/train_rllib.py`` is the example; ``docs/rl.md`` the
guide. Ray RLlib is optional (``pip install airspace-sim[rllib]``); nothing here imports it
before it is called.
"""

from __future__ import annotations

import functools
import os

import numpy as np

from airspace_sim.env.evaluation import Actor, batch_actor

MODULE_ID = "shared"  #: the one RLModule every agent maps to
ENV_NAME = "airspace_sim_rllib"  #: the name registered with ``ray.tune.registry``


def rllib_env(config: dict):
    """RLlib's env creator: ``config["id"]`` (e.g. ``"ring8"``) and ``config["kwargs"]``
    → :func:`rllib_env_class` around ``airspace_sim.env.make``. Runs in every EnvRunner
    process; importing the package registers the ids there."""
    from airspace_sim import env as aenv

    return rllib_env_class()(aenv.make(config["id"], **config.get("kwargs", {})))


@functools.cache
def rllib_env_class():
    """RLlib's ``ParallelPettingZooEnv`` with one fix: the episode is over when no agent is
    left. The wrapper sets ``__all__`` only if every agent of the last step terminated, or
    every one truncated; on the step where the episode is truncated while some agent
    ends (an arrival or an NMAC) neither flag was set, RLlib's episode closed (all its
    agents are done) but its vector env did not reset, stepped once more with no actions
    and started an empty episode. Here ``truncateds["__all__"]`` is then set."""
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    class AirspaceRLlibEnv(ParallelPettingZooEnv):
        def step(self, action_dict):
            obs, rewards, terminateds, truncateds, infos = super().step(action_dict)
            if not self.par_env.agents and not terminateds["__all__"]:
                truncateds["__all__"] = True
            return obs, rewards, terminateds, truncateds, infos

    return AirspaceRLlibEnv


def ppo_config(
    env_id: str,
    seed: int,
    env_runners: int = 2,
    learners: int = 0,
    train_batch: int = 1000,
    minibatch: int = 512,
    epochs: int = 5,
    fragment: int | str = "auto",
    hidden: tuple[int, ...] = (64, 64),
    env_kwargs: dict | None = None,
):
    """The PPO config: one module shared by every agent of ``env_id``. ``train_batch``
    and ``fragment`` are env steps (each carries one agent-step per live agent);
    ``minibatch`` is agent-steps."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.default_model_config import DefaultModelConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.tune.registry import register_env

    register_env(ENV_NAME, rllib_env)
    return (
        PPOConfig()
        .environment(ENV_NAME, env_config={"id": env_id, "kwargs": dict(env_kwargs or {})})
        .framework("torch")
        .env_runners(
            num_env_runners=env_runners,
            num_envs_per_env_runner=1,
            num_cpus_per_env_runner=1,
            rollout_fragment_length=fragment,
        )
        .learners(num_learners=learners)
        .training(
            train_batch_size_per_learner=train_batch,
            minibatch_size=minibatch,
            num_epochs=epochs,
            lr=3e-4,
            gamma=0.99,
            lambda_=0.95,
            entropy_coeff=0.0,
        )
        .multi_agent(
            policies={MODULE_ID},
            policy_mapping_fn=lambda agent_id, episode, **kw: MODULE_ID,
        )
        .rl_module(
            rl_module_spec=MultiRLModuleSpec(rl_module_specs={MODULE_ID: RLModuleSpec()}),
            model_config=DefaultModelConfig(fcnet_hiddens=list(hidden)),
        )
        .debugging(seed=seed)
    )


def module_path(checkpoint: str) -> str:
    """Where an Algorithm checkpoint keeps the shared module (RLlib's layout)."""
    return os.path.join(checkpoint, "learner_group", "learner", "rl_module", MODULE_ID)


def trained_actor(checkpoint: str) -> Actor:
    """An evaluation actor from the checkpoint's module: the mean action, clipped to the
    action space [-1, 1] as RLlib's env runner does before it reaches the env."""
    import torch
    from ray.rllib.core.columns import Columns
    from ray.rllib.core.rl_module.rl_module import RLModule

    module = RLModule.from_checkpoint(module_path(checkpoint))
    dist_cls = module.get_inference_action_dist_cls()

    def predict(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            out = module.forward_inference({Columns.OBS: torch.from_numpy(obs)})
            dist = dist_cls.from_logits(out[Columns.ACTION_DIST_INPUTS]).to_deterministic()
            return np.clip(dist.sample().numpy(), -1.0, 1.0)

    return batch_actor(predict)
