"""Env speed and results of two checkouts side by side (docs/env-speed.md).

    python docs/benchmarks/env_ab.py ab ring8 12 100 /path/to/base /path/to/other
    PYTHONPATH=/path/to/tree python docs/benchmarks/env_ab.py hash

``ab``: one long-lived worker process per tree (``PYTHONPATH`` set to it) runs 100 env
steps, 100 bare-world steps (the env's world, agents turning at random) and 5 resets in
turn, the order swapped every round, so both see the same load; prints medians of CPU ms
per step and the ratios. ``hash``: SHA-256 of env rollouts with fixed random actions
(observations, rewards, terminations, truncations, infos, global state) and of the world
state after every step; run it under both trees and compare the lines.
"""

from __future__ import annotations

import hashlib
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np


def worker(name: str) -> None:
    """Read ``env N`` / ``world N`` / ``reset N`` lines, print CPU ms per call."""
    from airspace_sim.env import make

    env = make(name)
    rng = np.random.default_rng(0)
    pool = [rng.uniform(-1, 1, (len(env.possible_agents), 1)).astype(np.float32) for _ in range(64)]
    state = {"episode": 0, "k": 0, "world": env._make_world(env.scenario, 0)}
    env.reset(seed=0)

    def env_step():
        if not env.agents:
            state["episode"] += 1
            env.reset(seed=state["episode"])
        a = pool[state["k"] % 64]
        state["k"] += 1
        env.step({ag: a[k] for k, ag in enumerate(env.agents)})

    def world_step():
        w = state["world"]
        if w.done or not (w.controlled & w.active).any():
            w = state["world"] = env._make_world(env.scenario, 0)
        w.step(np.where(w.controlled, rng.uniform(-1, 1, w.n) * w.max_turn_rate, np.nan))

    def reset():
        state["episode"] += 1
        env.reset(seed=10_000 + state["episode"])

    for _ in range(30):
        env_step()
        world_step()
    print("ready", flush=True)
    calls = {"env": env_step, "world": world_step, "reset": reset}
    for line in sys.stdin:
        kind, n = line.split()
        c = time.process_time()
        for _ in range(int(n)):
            calls[kind]()
        print((time.process_time() - c) / int(n) * 1e3, flush=True)


def ab(name: str, rounds: int, steps: int, base: str, other: str) -> None:
    trees = {"base": base, "other": other}
    procs = {
        t: subprocess.Popen(
            [sys.executable, __file__, "worker", name],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=dict(os.environ, PYTHONPATH=path),
        )
        for t, path in trees.items()
    }
    for p in procs.values():
        assert p.stdout.readline().strip() == "ready"
    blocks = (("env", steps), ("world", steps), ("reset", max(steps // 20, 2)))
    res = {(t, k): [] for t in trees for k, _ in blocks}
    for r in range(rounds):
        for kind, n in blocks:
            for t in list(trees)[:: 1 if r % 2 == 0 else -1]:
                procs[t].stdin.write(f"{kind} {n}\n")
                procs[t].stdin.flush()
                res[(t, kind)].append(float(procs[t].stdout.readline()))
    for p in procs.values():
        p.stdin.close()
        p.wait()
    print(
        f"{name}: {rounds} alternating rounds, median CPU ms per call (load {os.getloadavg()[0]:.1f})"
    )
    for kind, _ in blocks:
        b, o = (statistics.median(res[(t, kind)]) for t in trees)
        print(f"  {kind:6s} base {b:7.3f}  other {o:7.3f}  other/base {o / b:.3f}")
    per_round = [o / b for b, o in zip(res[("base", "env")], res[("other", "env")])]
    print(f"  env other/base per round: median {statistics.median(per_round):.3f}")


def _feed(h, obj) -> None:
    if isinstance(obj, dict):
        for k in sorted(obj):
            h.update(str(k).encode())
            _feed(h, obj[k])
    elif isinstance(obj, np.ndarray):
        h.update(obj.tobytes() + str(obj.dtype).encode())
    else:
        h.update(repr(obj).encode())


def hashes() -> None:
    from airspace_sim.env import make
    from airspace_sim.scenarios import load
    from airspace_sim.world import World
    from airspace_sim.world.benchmark import random_scenario

    cases = [
        ("ring8", {}, 400),
        ("dense8", {}, 200),
        ("ring16", {"ended": "leave"}, 200),
        ("ring4", {"discrete_actions": True}, 200),
        ("head_on", {}, 150),
        ("dense32", {}, 60),
    ]
    for name, kw, steps in cases:
        env = make(name, **kw)
        rng = np.random.default_rng(1)
        h = hashlib.sha256()
        episode = 0
        _feed(h, env.reset(seed=episode))
        space = env.action_space(env.possible_agents[0])
        for t in range(steps):
            if not env.agents:
                episode += 1
                _feed(h, env.reset(seed=episode))
            if kw.get("discrete_actions"):
                acts = {a: int(rng.integers(space.n)) for a in env.agents}
            else:
                acts = {a: rng.uniform(-1, 1, (1,)).astype(np.float32) for a in env.agents}
                if t % 7 == 0 and env.agents:
                    acts.pop(env.agents[0])  # left to the built-in pilot
            _feed(h, env.step(acts))
            _feed(h, env.state())
        print("env", name, kw, steps, h.hexdigest()[:16])
    env = make("ring8")
    worlds = [
        ("random300", World(random_scenario(300)), 40, None),
        ("ring8-world", env._make_world(env.scenario, 3), 120, np.random.default_rng(0)),
        ("demo", World(load("demo")), 300, None),
    ]
    for name, w, steps, rng in worlds:
        h = hashlib.sha256()
        for _ in range(steps):
            if rng is None:
                w.step()
            else:
                turn = rng.uniform(-1, 1, w.n) * w.max_turn_rate
                w.step(np.where(w.controlled & (rng.random(w.n) < 0.7), turn, np.nan))
            for a in (w.positions, w.headings, w.advice, w.conflict, w.tracks.view().x):
                h.update(np.ascontiguousarray(a).tobytes())
            h.update(w.policy.side.tobytes() + w.policy.off_route_s.tobytes())
        h.update(json.dumps(w.metrics(), sort_keys=True, default=str).encode())
        print("world", name, steps, h.hexdigest()[:16])


if __name__ == "__main__":
    mode = sys.argv[1]
    if mode == "worker":
        worker(sys.argv[2])
    elif mode == "ab":
        ab(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5], sys.argv[6])
    else:
        hashes()
