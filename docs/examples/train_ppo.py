"""Train one PPO policy shared by every aircraft of a ring, then compare it on held-out seeds
and on a ring size it never saw with random turns, straight flight and the built-in
resolver.

    pip install -e '.[rl]'
    python docs/examples/train_ppo.py                       # ring8, 100k agent-steps
    python docs/examples/train_ppo.py --timesteps 300000 --num-cpus 2 --unseen 12 16

Training: SuperSuit's chain (``airspace_sim.env.vector.sb3_vec_env``: black death →
one vector slot per agent → copies of the env in processes), Stable-Baselines3 PPO with an
MLP, rewards normalised by ``VecNormalize`` (the env's rewards are not rescaled), CPU only.
Training seeds come from PPO's seed; evaluation seeds start at 10 000, so every evaluation
ring (radius, phase, speeds, start times) is new to the policy.

Evaluation: per policy and setting, the mean per episode of losses of separation and NMACs
(pair events, all aircraft; from ``World.metrics()``) and the mean return per agent.
Policies: ``trained`` (deterministic actions), ``random`` (uniform in [-1, 1]),
``straight`` (0: hold the heading), ``built-in`` (``None``: the world's route autopilot and
CDA resolver); the helpers are in ``airspace_sim.env.evaluation``. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import time

from airspace_sim.env.evaluation import batch_actor, evaluate, markdown_table, ring_env


def train(args):
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from airspace_sim.env.vector import sb3_vec_env

    torch.set_num_threads(1)
    venv = sb3_vec_env(
        ring_env(args.train),
        num_vec_envs=args.num_vec_envs,
        num_cpus=args.num_cpus,
    )
    venv = VecNormalize(VecMonitor(venv), norm_obs=False, norm_reward=True, gamma=0.99)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=args.n_steps,
        batch_size=args.batch_size,
        n_epochs=5,
        learning_rate=3e-4,
        gamma=0.99,
        gae_lambda=0.95,
        ent_coef=0.0,
        policy_kwargs=dict(net_arch=[64, 64]),
        seed=args.seed,
        verbose=0,
    )
    t0 = time.perf_counter()
    model.learn(args.timesteps, progress_bar=args.progress)
    venv.close()
    return model, time.perf_counter() - t0


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--train", type=int, default=8, help="ring size trained on (default 8)")
    p.add_argument("--unseen", type=int, nargs="*", default=[12], help="ring sizes not trained on")
    p.add_argument("--timesteps", type=int, default=100_000, help="agent-steps of training")
    p.add_argument("--num-vec-envs", type=int, default=4, help="copies of the env")
    p.add_argument("--num-cpus", type=int, default=2, help="worker processes")
    p.add_argument("--n-steps", type=int, default=128, help="PPO rollout length per slot")
    p.add_argument("--batch-size", type=int, default=512)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--episodes", type=int, default=10, help="held-out episodes per setting")
    p.add_argument("--save", help="save the trained policy here (.zip)")
    p.add_argument("--progress", action="store_true", help="tqdm progress bar while training")
    args = p.parse_args(argv)

    model, seconds = train(args)
    print(f"trained {args.timesteps} agent-steps on ring{args.train} in {seconds:.0f} s")
    if args.save:
        model.save(args.save)
    act = batch_actor(lambda obs: model.predict(obs, deterministic=True)[0])
    rows = evaluate(act, [args.train, *args.unseen], args.episodes)
    print()
    print(markdown_table(rows, args.train, args.episodes))


if __name__ == "__main__":
    main()
