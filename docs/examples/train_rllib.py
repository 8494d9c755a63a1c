"""Train one PPO policy shared by every aircraft of a ring with Ray RLlib, save a checkpoint,
then compare it on held-out seeds with random turns, straight flight and the built-in
resolver.

    pip install -e '.[rllib]'
    python docs/examples/train_rllib.py                          # local Ray, 2 CPUs, ring8
    python docs/examples/train_rllib.py --iterations 40 --unseen 12
    python docs/examples/train_rllib.py --address auto --env-runners 16   # join a cluster
    python docs/examples/train_rllib.py --from-checkpoint rllib-ring8     # evaluate only

Training: the registered id ``airspace_sim/ring<n>-v0`` (every aircraft an agent, geometry
drawn per seed) through RLlib's own PettingZoo wrapper
(``ray.rllib.env.wrappers.pettingzoo_env.ParallelPettingZooEnv``), RLlib's new API stack
(RLModule, Learner, EnvRunner), PPO with one module ``shared`` that every agent maps to,
torch on CPU. Sampling runs in ``--env-runners`` EnvRunner actors, the update in the driver
(``num_learners=0``); on a cluster, raise ``--env-runners`` (and ``--learners`` for remote
learners). ``--seed`` seeds RLlib (env runner k resets its env with seed + k first, then the
env draws the next episodes' seeds), so training never sees the evaluation seeds.

Checkpoint: ``Algorithm.save_to_path`` at the end (``--checkpoint``, a directory). The
evaluation loads the trained module back from it (``RLModule.from_checkpoint``), so the
table is of what was saved.

Evaluation (``airspace_sim.env.evaluation``, shared with ``train_ppo.py``): per policy and
ring size, the mean per episode of losses of separation and NMACs (pair events over all
aircraft, from ``World.metrics()``) and the mean return per agent, over seeds from 10 000.
``trained`` takes the mean of the module's Gaussian (deterministic). Prints a Markdown table.

The package must be importable on every node of a cluster (``pip install airspace-sim[rllib]``
there, or the same image); the driver only sends the config.
"""

from __future__ import annotations

import argparse
import os
import time

from airspace_sim.env.evaluation import evaluate, markdown_table
from airspace_sim.env.rllib import MODULE_ID, ppo_config, trained_actor


def train(config, iterations: int, checkpoint: str, progress: bool = False):
    """``iterations`` PPO iterations, then a checkpoint in ``checkpoint``; returns
    (checkpoint path, seconds, agent-steps sampled, last result)."""
    from tqdm import tqdm

    algo = config.build_algo()
    t0 = time.perf_counter()
    for _ in tqdm(range(iterations), desc="PPO iterations", disable=not progress):
        result = algo.train()
    seconds = time.perf_counter() - t0
    path = algo.save_to_path(os.path.abspath(checkpoint))
    steps = int(result["env_runners"]["num_module_steps_sampled_lifetime"][MODULE_ID])
    algo.stop()
    return path, seconds, steps, result


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--train", type=int, default=8, help="ring size trained on (default 8)")
    p.add_argument("--unseen", type=int, nargs="*", default=[], help="ring sizes not trained on")
    p.add_argument("--iterations", type=int, default=20, help="PPO iterations (default 20)")
    p.add_argument("--train-batch", type=int, default=1000, help="env steps per iteration")
    p.add_argument("--minibatch", type=int, default=512, help="agent-steps per SGD minibatch")
    p.add_argument("--epochs", type=int, default=5, help="SGD passes per iteration")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--address", help="join this Ray cluster (e.g. auto, ray://head:10001); default local"
    )
    p.add_argument("--num-cpus", type=int, default=2, help="CPUs of the local Ray (default 2)")
    p.add_argument("--env-runners", type=int, default=2, help="EnvRunner actors (1 CPU each)")
    p.add_argument("--learners", type=int, default=0, help="remote learners (0: the driver)")
    p.add_argument("--checkpoint", help="checkpoint directory (default rllib-ring<train>)")
    p.add_argument("--from-checkpoint", help="skip training; evaluate this checkpoint")
    p.add_argument("--episodes", type=int, default=10, help="held-out episodes per setting")
    p.add_argument("--progress", action="store_true", help="tqdm progress bar while training")
    args = p.parse_args(argv)
    if args.iterations < 1:
        p.error(f"--iterations: at least 1, got {args.iterations}")

    checkpoint = args.from_checkpoint
    if checkpoint is None:
        import ray
        import torch

        # one torch thread in the driver, where the learner runs: two threads contending
        # with the env runners on two cores made the update ~20x slower
        torch.set_num_threads(1)

        if args.address:
            ray.init(address=args.address)
        else:
            ray.init(num_cpus=args.num_cpus, include_dashboard=False)
        config = ppo_config(
            f"ring{args.train}",
            args.seed,
            env_runners=args.env_runners,
            learners=args.learners,
            train_batch=args.train_batch,
            minibatch=args.minibatch,
            epochs=args.epochs,
        )
        checkpoint, seconds, steps, result = train(
            config, args.iterations, args.checkpoint or f"rllib-ring{args.train}", args.progress
        )
        ray.shutdown()
        ret = result["env_runners"].get("episode_return_mean", float("nan"))
        print(
            f"trained {args.iterations} iterations ({steps} agent-steps) on ring{args.train} "
            f"in {seconds:.0f} s; last episode return (sum over agents) {ret:.2f}"
        )
        print(f"checkpoint: {checkpoint}")
    rows = evaluate(trained_actor(checkpoint), [args.train, *args.unseen], args.episodes)
    print()
    print(markdown_table(rows, args.train, args.episodes))


if __name__ == "__main__":
    main()
