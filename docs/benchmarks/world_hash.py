"""Bit-for-bit check of a change to the world step: SHA-256 of the world state after every
step of the benchmark traffic, one line per case; run it under both trees and compare.

    PYTHONPATH=<tree> python docs/benchmarks/world_hash.py [N:STEPS ...]

Default cases ``300:40 1000:12`` (:func:`airspace_sim.world.benchmark.random_scenario`,
seed 0). Hashed after every step, as raw bytes: positions, headings, velocities, advice,
conflict flags, committed sides, LoS and NMAC flags, and the live tracks (slots, owner,
intruder, misses, age, state ``x``, covariance ``P``, mode probabilities ``mu``); at the
end, every metric of ``World.metrics()`` (the safety metrics, ``wcv_*`` and
``induced_los_pairs``, are not among ``compare_metrics.py``'s keys). Each line also gives
the hash of the final step alone; the process CPU seconds of each case go to stderr, so
that stdout can be ``diff``-ed.
"""

from __future__ import annotations

import hashlib
import json
import sys
import time

import numpy as np

from airspace_sim.world import World
from airspace_sim.world.benchmark import random_scenario


def state_bytes(world: World):
    """The arrays hashed after a step, in a fixed order (C-contiguous copies)."""
    view = world.tracks.view()
    arrays = (
        world.positions,
        world.headings,
        world.velocities,
        world.advice,
        world.conflict,
        world.policy.side,
        world.in_los,
        world.nmac,
        view.slots,
        view.owner,
        view.intruder,
        view.misses,
        view.age,
        view.x,
        view.P,
        view.mu,
    )
    for a in arrays:
        a = np.ascontiguousarray(a)
        yield f"{a.dtype.str}{a.shape}".encode()
        yield a.tobytes()


def run_case(n: int, steps: int) -> tuple[str, float]:
    """(the case's lines, process CPU s it took)."""
    c0 = time.process_time()
    world = World(random_scenario(n, trackers=True, seed=0), seed=0)
    every = hashlib.sha256()
    for _ in range(steps):
        world.step()
        last = hashlib.sha256()
        for b in state_bytes(world):
            every.update(b)
            last.update(b)
    metrics = json.dumps(world.metrics(), sort_keys=True, default=repr)
    every.update(metrics.encode())
    cpu = time.process_time() - c0
    return (
        f"random{n} steps={steps} tracks={len(world.tracks)} all={every.hexdigest()[:24]} "
        f"last={last.hexdigest()[:24]}\n  metrics {metrics}"
    ), cpu


def main(argv: list[str]) -> None:
    cases = argv or ["300:40", "1000:12"]
    for case in cases:
        n, steps = (int(v) for v in case.split(":"))
        line, cpu = run_case(n, steps)
        print(line, flush=True)
        print(f"random{n}: {cpu:.1f} s CPU", file=sys.stderr)


if __name__ == "__main__":
    main(sys.argv[1:])
