"""Hash of the benchmark world's state after a number of steps, to check a speed change
is bit for bit (docs/performance.md).

    PYTHONPATH=/path/to/tree python docs/benchmarks/world_hash.py            # 300×40, 1000×12
    PYTHONPATH=/path/to/tree python docs/benchmarks/world_hash.py 300:40 100:80

For each ``N:STEPS``: :func:`airspace_sim.world.benchmark.random_scenario` with N aircraft
(IMM trackers, resolver ``bands``, seed 0) stepped STEPS times; one SHA-256 over every
step's positions, headings, advice, conflict flags and committed sides, and the final
track table (owner, intruder, age, misses, x, μ in slot order). Run under both trees and
compare the lines.
"""

from __future__ import annotations

import hashlib
import sys

import numpy as np


def world_hash(n: int, steps: int) -> str:
    """SHA-256 hex digest of ``steps`` steps of the ``n``-aircraft benchmark traffic."""
    from airspace_sim.world import World
    from airspace_sim.world.benchmark import random_scenario

    w = World(random_scenario(n, trackers=True, seed=0), seed=0)
    h = hashlib.sha256()

    def add(a):
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())

    for _ in range(steps):
        w.step()
        for a in (w.positions, w.headings, w.advice, w.conflict, w.policy.side, w.active):
            add(a)
    v = w.tracks.view()
    for a in (v.owner, v.intruder, v.age, v.misses, v.x, v.mu):
        add(a)
    return h.hexdigest()


def main(argv: list[str]) -> None:
    specs = argv or ["300:40", "1000:12"]
    for spec in specs:
        n, steps = (int(x) for x in spec.split(":"))
        print(f"{n}:{steps} {world_hash(n, steps)}", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
