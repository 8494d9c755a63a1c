"""Risk ratio: NMACs with the scenario's resolver over NMACs without it, on the same seeds.

The ACAS X / DAIDALUS studies' headline number: ``risk_ratio = Σ NMAC(resolver) /
Σ NMAC(unequipped)`` over the same encounters (here: the same scenario and seeds, so the
same traffic, sensor noise and Markov pilots until the resolver first acts). The unequipped
runs use resolver ``"none"``, which never turns (it still flags conflicts, so alerts are
counted alike). NaN when the unequipped runs have no NMAC (the ratio is undefined, not 0).
The same for losses of separation (``los_ratio``).

The command line is ``airspace-sim risk SCENARIO --seeds 0-15`` (:mod:`airspace_sim.commands.risk`).
"""

from __future__ import annotations

import dataclasses
import math

#: The per-seed counts, in the order of a row and of the totals.
COUNTS = ("nmac_equipped", "nmac_unequipped", "los_pairs_equipped", "los_pairs_unequipped")


def unequipped(scenario):
    """The same scenario with resolver ``"none"`` (look-ahead and margin kept: the conflict
    flags, hence ``alerts``, are those of the equipped resolver's CPA test)."""
    spec = dataclasses.replace(scenario.resolver, kind="none", params={})
    return dataclasses.replace(scenario, resolver=spec)


def _ratio(a: int, b: int) -> float:
    return a / b if b else math.nan


def seed_counts(scenario, seed: int) -> dict:
    """One seed's row: ``scenario`` run equipped and unequipped (spawn-safe, top level).

    NMAC counted as ``nmac_pairs`` and LoS as ``los_pairs``: each pair once per run."""
    from airspace_sim.world import World

    eq = World(scenario, seed=seed).run()
    un = World(unequipped(scenario), seed=seed).run()
    return {
        "seed": seed,
        "nmac_equipped": eq["nmac_pairs"],
        "nmac_unequipped": un["nmac_pairs"],
        "los_pairs_equipped": eq["los_pairs"],
        "los_pairs_unequipped": un["los_pairs"],
    }


def risk_ratio(scenario, seeds, progress: bool = False, workers: int = 1) -> dict:
    """Run ``scenario`` with its resolver and unequipped on every seed of ``seeds``, on
    ``workers`` local processes (1: in this process); the result does not depend on it.

    Returns ``risk_ratio``, ``los_ratio`` (NaN when the denominator is 0), the summed
    ``nmac_equipped``, ``nmac_unequipped``, ``los_pairs_equipped``, ``los_pairs_unequipped``,
    ``runs`` and ``per_seed``: a list, in the order of ``seeds``, of :func:`seed_counts`
    rows ``{seed, nmac_equipped, nmac_unequipped, los_pairs_equipped, los_pairs_unequipped}``.
    ``progress``: a tqdm bar on stderr, one tick per seed.
    """
    import sys

    from tqdm import tqdm

    from airspace_sim.experiments import LocalBackend

    seeds = [int(s) for s in seeds]
    rows: list = [None] * len(seeds)
    bar = tqdm(
        total=len(seeds), desc="risk ratio", unit="seed", disable=not progress, file=sys.stderr
    )
    try:
        with LocalBackend(workers) as backend:
            for i, row in backend.imap(seed_counts, [(scenario, s) for s in seeds]):
                rows[i] = row
                bar.update(1)
    finally:
        bar.close()
    tot = {k: sum(r[k] for r in rows) for k in COUNTS}
    return {
        "risk_ratio": _ratio(tot["nmac_equipped"], tot["nmac_unequipped"]),
        "los_ratio": _ratio(tot["los_pairs_equipped"], tot["los_pairs_unequipped"]),
        **tot,
        "runs": len(rows),
        "per_seed": rows,
    }
