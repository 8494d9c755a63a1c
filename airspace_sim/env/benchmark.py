"""Env speed: steps per second, reset cost, and the world underneath as the peer.

:func:`bench_env` times, in one process and one after the other:

- ``env``: parallel-env steps with random actions (every agent, every step), headless,
  resetting when the episode ends (resets timed apart);
- ``world``: the bare :meth:`World.step` of the same world, its agents turning at random as
  in the env (the peer: env time / world time per step says what the env layer costs on
  top: observations, rewards, infos);
- ``reset``: ``env.reset(seed=k)`` for fresh seeds, in world steps (a reset should cost at
  most a few);
- optionally PettingZoo's own ``pettingzoo.test.performance_benchmark`` on the AEC form
  (5 s of wall clock; it prints turns and cycles per second, captured here).

Timings are medians over ``repeats`` blocks, wall clock and process CPU time; absolute
numbers depend on the machine and its load, the ratios much less. ``airspace-sim
bench-env`` prints them.
"""

from __future__ import annotations

import contextlib
import io
import re
import statistics
import time

import gymnasium
import numpy as np


def _timed(fn, n: int) -> tuple[float, float]:
    """(wall s, CPU s) of ``n`` calls of ``fn``."""
    w0, c0 = time.perf_counter(), time.process_time()
    for _ in range(n):
        fn()
    return time.perf_counter() - w0, time.process_time() - c0


def bench_env(
    env_id: str = "ring8",
    steps: int = 500,
    repeats: int = 3,
    resets: int = 10,
    seed: int = 0,
    pettingzoo_benchmark: bool = False,
    **env_kwargs,
) -> dict:
    """Steps per second of the env ``env_id`` (a registry id or scenario name) and of its
    world, reset cost, per the module docstring. Returns a dict of the medians."""
    from airspace_sim.env import make

    env = make(env_id, **env_kwargs)
    rng = np.random.default_rng(seed)
    space = env.action_space(env.possible_agents[0])
    env.reset(seed=seed)
    state = {"episode": seed}

    def env_step():
        if not env.agents:
            state["episode"] += 1
            env.reset(seed=state["episode"])
        actions = {a: _sample(space, rng) for a in env.agents}
        env.step(actions)

    for _ in range(20):  # warm-up: numba caches, first frames of the track table
        env_step()
    env_rows = [_timed(env_step, steps) for _ in range(repeats)]

    def fresh_world():
        return env._make_world(env.scenario, seed)  # the env's agents, controlled

    world = fresh_world()
    holder = {"w": world}

    def world_step():
        w = holder["w"]
        if w.done or not (w.controlled & w.active).any():
            holder["w"] = w = fresh_world()
        # the same work as the env's step: every agent turns at random
        rates = np.where(w.controlled, rng.uniform(-1.0, 1.0, w.n) * w.max_turn_rate, np.nan)
        w.step(rates)

    for _ in range(20):
        world_step()
    world_rows = [_timed(world_step, steps) for _ in range(repeats)]

    k = iter(range(10_000, 10_000 + resets * repeats + 1))
    reset_rows = [_timed(lambda: env.reset(seed=next(k)), resets) for _ in range(repeats)]

    env_ms = statistics.median(w for w, _ in env_rows) / steps * 1e3
    env_cpu = statistics.median(c for _, c in env_rows) / steps * 1e3
    world_ms = statistics.median(w for w, _ in world_rows) / steps * 1e3
    world_cpu = statistics.median(c for _, c in world_rows) / steps * 1e3
    reset_ms = statistics.median(w for w, _ in reset_rows) / resets * 1e3
    out = {
        "env": env_id,
        "agents": len(env.possible_agents),
        "aircraft": env.world.n,
        "steps": steps,
        "repeats": repeats,
        "env_ms_per_step": env_ms,
        "env_cpu_ms_per_step": env_cpu,
        "env_steps_per_s": 1e3 / env_ms,
        "env_cpu_steps_per_s": 1e3 / env_cpu if env_cpu > 0 else float("inf"),
        "world_ms_per_step": world_ms,
        "world_cpu_ms_per_step": world_cpu,
        "env_over_world": env_ms / world_ms,
        "reset_ms": reset_ms,
        "reset_in_steps": reset_ms / env_ms,
    }
    if pettingzoo_benchmark:
        out.update(_pettingzoo_benchmark(env_id, **env_kwargs))
    return out


def _sample(space, rng):
    if isinstance(space, gymnasium.spaces.Discrete):
        return int(rng.integers(space.n))
    return rng.uniform(-1.0, 1.0, space.shape).astype(np.float32)


def _pettingzoo_benchmark(env_id: str, **env_kwargs) -> dict:
    """PettingZoo's ``performance_benchmark`` on the AEC form; its printout parsed."""
    from pettingzoo.test import performance_benchmark

    from airspace_sim.env import make

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        performance_benchmark(make(env_id, parallel=False, **env_kwargs))
    text = buf.getvalue()
    turns = re.search(r"([\d.]+) turns per second", text)
    cycles = re.search(r"([\d.]+) cycles per second", text)
    return {
        "pettingzoo_turns_per_s": float(turns.group(1)) if turns else float("nan"),
        "pettingzoo_cycles_per_s": float(cycles.group(1)) if cycles else float("nan"),
    }


def format_report(r: dict) -> str:
    lines = [
        f"{r['env']}: {r['agents']} agents, {r['aircraft']} aircraft, "
        f"{r['repeats']} × {r['steps']} steps (medians)",
        f"  env    {r['env_steps_per_s']:8.0f} steps/s  ({r['env_ms_per_step']:.3f} ms/step wall,"
        f" {r['env_cpu_ms_per_step']:.3f} ms CPU: {r['env_cpu_steps_per_s']:.0f} steps/s)",
        f"  world  {1e3 / r['world_ms_per_step']:8.0f} steps/s  ({r['world_ms_per_step']:.3f} "
        f"ms/step wall, {r['world_cpu_ms_per_step']:.3f} ms CPU)",
        f"  env / world time per step: {r['env_over_world']:.2f}",
        f"  reset  {r['reset_ms']:.2f} ms = {r['reset_in_steps']:.1f} env steps",
    ]
    if "pettingzoo_turns_per_s" in r:
        lines.append(
            f"  pettingzoo performance_benchmark (AEC form): "
            f"{r['pettingzoo_turns_per_s']:.0f} turns/s, "
            f"{r['pettingzoo_cycles_per_s']:.0f} cycles/s"
        )
    return "\n".join(lines)
