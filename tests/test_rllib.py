"""Ray RLlib on the env: RLlib's own PettingZoo wrapper around a registered id, the
contract its new API stack relies on (spaces per agent, agents ending one by one, the
``__all__`` flags, the extra empty step of its vector env), and a couple of PPO iterations
with one shared module, a checkpoint and the evaluation actor read back from it.

Skipped without ``ray[rllib]`` (``pip install -e '.[rllib]'``)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("ray.rllib", reason="ray[rllib] is not installed: pip install -e '.[rllib]'")
torch = pytest.importorskip("torch", reason="torch is not installed: pip install -e '.[rllib]'")

from ray.rllib.env.multi_agent_episode import MultiAgentEpisode  # noqa: E402
from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv  # noqa: E402

from airspace_sim import env as aenv  # noqa: E402
from airspace_sim.env import evaluation  # noqa: E402
from airspace_sim.env import rllib as arl  # noqa: E402

SEED = 3


def first_ending_step(seed: int) -> int:
    """The step on which the first agent of ring4 ends under the built-in pilot."""
    env = aenv.make("ring4")
    env.reset(seed=seed)
    t = 0
    while env.agents:
        _, _, term, _, _ = env.step({})
        t += 1
        if any(term.values()):
            return t
    raise AssertionError("no agent ended")


def test_wrapper_spaces_and_mixed_ending():
    """Truncate ring4 on the step where its first agent ends: that step mixes a terminated
    agent with truncated ones. RLlib's wrapper then sets neither ``__all__`` (its vector env
    would not reset); ours sets ``truncateds["__all__"]``, on the same step at which RLlib's
    MultiAgentEpisode, fed the same steps, is done. Spaces are per agent; agents leave one
    by one and never come back."""
    T = first_ending_step(SEED)
    raw = ParallelPettingZooEnv(aenv.make("ring4", max_cycles=T))
    env = arl.rllib_env({"id": "ring4", "kwargs": {"max_cycles": T}})
    assert isinstance(env, ParallelPettingZooEnv)
    par = env.par_env
    agents = list(par.possible_agents)
    assert set(env.observation_space) == set(env.action_space) == set(agents)
    for a in agents:
        assert env.observation_space[a] == par.observation_space(a)
        assert env.action_space[a] == par.action_space(a)

    obs, infos = env.reset(seed=SEED)
    raw.reset(seed=SEED)
    episode = MultiAgentEpisode(
        observation_space=env.observation_space, action_space=env.action_space
    )
    episode.add_env_reset(observations=obs, infos=infos)
    alive, steps, ended = set(agents), dict.fromkeys(agents, 0), {}
    for t in range(1, T + 1):
        assert set(obs) == alive
        for a, o in obs.items():
            assert env.observation_space[a].contains(o)
        actions = {a: np.zeros(1, np.float32) for a in alive}  # stored only
        obs, rew, term, trunc, infos = env.step({})  # the built-in pilot flies every agent
        _, _, raw_term, raw_trunc, _ = raw.step({})
        assert set(rew) == set(term) - {"__all__"} == alive
        assert not episode.is_done
        episode.add_env_step(
            observations=obs,
            actions=actions,
            rewards=rew,
            infos=infos,
            terminateds=term,
            truncateds=trunc,
        )
        for a in list(alive):
            steps[a] += 1
            if term[a] or trunc[a]:
                ended[a] = "terminated" if term[a] else "truncated"
                alive.discard(a)
        if t < T:
            assert not (term["__all__"] or trunc["__all__"] or episode.is_done)
    assert not alive and not par.agents
    assert {"terminated", "truncated"} <= set(ended.values())  # the mixed last step
    assert not raw_term["__all__"] and not raw_trunc["__all__"]  # RLlib's wrapper alone
    assert not term["__all__"] and trunc["__all__"]  # ours
    assert episode.is_done
    for a in agents:
        sa = episode.agent_episodes[a]
        assert len(sa) == steps[a] and sa.is_done
        if ended[a] == "terminated":  # RLlib marks every agent of the closing step terminated
            assert sa.is_terminated


def test_ppo_shared_policy_checkpoint_and_actor(tmp_path, local_ray):
    """Two PPO iterations on ring4 (short episodes, tiny batches): every agent's steps go
    to the one ``shared`` module, the update is finite, and the checkpoint's module acts
    exactly as the module the env runner samples with. Sampling is in the driver
    (``env_runners=0``): an EnvRunner actor would double the test's time (Ray starts a
    process that imports torch and RLlib); the env creator is pickled by reference, as
    actors on a cluster receive it."""
    import ray.cloudpickle

    assert ray.cloudpickle.loads(ray.cloudpickle.dumps(arl.rllib_env)) is arl.rllib_env
    torch.set_num_threads(1)
    config = arl.ppo_config(
        "ring4",
        seed=0,
        env_runners=0,
        train_batch=120,
        minibatch=120,
        epochs=1,
        fragment=60,
        hidden=(16,),
        env_kwargs={"max_cycles": 40},
    )
    algo = config.build_algo()
    try:
        for _ in range(2):
            result = algo.train()
        path = algo.save_to_path(str(tmp_path / "ck"))
        learned = algo.get_module(arl.MODULE_ID)  # the env runner's copy, synced
    finally:
        algo.stop()

    runners = result["env_runners"]
    assert result["num_env_steps_sampled_lifetime"] >= 240
    agent_steps = runners["num_agent_steps_sampled_lifetime"]
    assert set(agent_steps) <= set(aenv.make("ring4").possible_agents) and len(agent_steps) == 4
    assert runners["num_module_steps_sampled_lifetime"] == {
        arl.MODULE_ID: sum(agent_steps.values())
    }
    assert runners["num_episodes_lifetime"] >= 2  # max_cycles 40 < 120 env steps per iteration
    stats = result["learners"][arl.MODULE_ID]
    assert np.isfinite([stats["total_loss"], stats["policy_loss"], stats["vf_loss"]]).all()

    act = arl.trained_actor(path)
    env = evaluation.ring_env(4, max_cycles=40)
    obs, _ = env.reset(seed=evaluation.FIRST_SEED)
    agents = list(env.agents)
    got = act(agents, obs)
    from ray.rllib.core.columns import Columns

    with torch.no_grad():
        batch = torch.from_numpy(np.stack([obs[a] for a in agents]))
        mean = learned.forward_inference({Columns.OBS: batch})[Columns.ACTION_DIST_INPUTS][:, :1]
    want = np.clip(mean.numpy(), -1, 1)
    assert np.array_equal(np.stack([got[a] for a in agents]), want)
    for a in agents:
        assert env.action_space(a).contains(got[a])
    los, nmac, ret = evaluation.play(env, act, evaluation.FIRST_SEED)
    assert los >= 0 and nmac >= 0 and np.isfinite(ret)
