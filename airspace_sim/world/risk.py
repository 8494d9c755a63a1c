"""Risk ratio: NMACs with the scenario's resolver over NMACs without it, on the same seeds.

The ACAS X / DAIDALUS studies' headline number: ``risk_ratio = Σ NMAC(resolver) /
Σ NMAC(unequipped)`` over the same encounters (here: the same scenario and seeds, so the
same traffic, sensor noise and Markov pilots until the resolver first acts). The unequipped
runs use resolver ``"none"``, which never turns (it still flags conflicts, so alerts are
counted alike). NaN when the unequipped runs have no NMAC (the ratio is undefined, not 0).
The same for losses of separation (``los_ratio``).

    python -m airspace_sim.world.risk dense_random --seeds 0-15
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys

from airspace_sim.errors import UserError


def unequipped(scenario):
    """The same scenario with resolver ``"none"`` (look-ahead and margin kept: the conflict
    flags, hence ``alerts``, are those of the equipped resolver's CPA test)."""
    spec = dataclasses.replace(scenario.resolver, kind="none", params={})
    return dataclasses.replace(scenario, resolver=spec)


def _ratio(a: int, b: int) -> float:
    return a / b if b else math.nan


def risk_ratio(scenario, seeds, progress: bool = False) -> dict:
    """Run ``scenario`` with its resolver and unequipped on every seed of ``seeds``.

    Returns ``risk_ratio``, ``los_ratio`` (NaN when the denominator is 0), the summed
    ``nmac_equipped``, ``nmac_unequipped``, ``los_pairs_equipped``, ``los_pairs_unequipped``
    (NMAC counted as ``nmac_pairs``: each pair once per run), ``runs`` and ``per_seed``: a
    list of ``{seed, nmac_equipped, nmac_unequipped, los_pairs_equipped,
    los_pairs_unequipped}``.
    """
    from airspace_sim.world import World

    seeds = [int(s) for s in seeds]
    bare = unequipped(scenario)
    rows = []
    it = seeds
    if progress:
        from tqdm import tqdm

        it = tqdm(seeds, desc="risk ratio", unit="seed")
    for seed in it:
        eq = World(scenario, seed=seed).run()
        un = World(bare, seed=seed).run()
        rows.append(
            {
                "seed": seed,
                "nmac_equipped": eq["nmac_pairs"],
                "nmac_unequipped": un["nmac_pairs"],
                "los_pairs_equipped": eq["los_pairs"],
                "los_pairs_unequipped": un["los_pairs"],
            }
        )
    tot = {k: sum(r[k] for r in rows) for k in rows[0]} if rows else {}
    ne, nu = tot.get("nmac_equipped", 0), tot.get("nmac_unequipped", 0)
    le, lu = tot.get("los_pairs_equipped", 0), tot.get("los_pairs_unequipped", 0)
    return {
        "risk_ratio": _ratio(ne, nu),
        "los_ratio": _ratio(le, lu),
        "nmac_equipped": ne,
        "nmac_unequipped": nu,
        "los_pairs_equipped": le,
        "los_pairs_unequipped": lu,
        "runs": len(rows),
        "per_seed": rows,
    }


def parse_seeds(text: str) -> list[int]:
    """``"0-15"``, ``"0,3,7"`` or a mix (``"0-3,9"``) → list of ints."""
    out = []
    try:
        for part in text.split(","):
            a, _, b = part.strip().partition("-")
            out.extend(range(int(a), int(b) + 1) if b else [int(a)])
    except ValueError:
        raise UserError(f"--seeds: expected e.g. 0-15 or 0,3,7, got {text!r}") from None
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        prog="python -m airspace_sim.world.risk",
        description="NMACs (and LoS pairs) with the scenario's resolver over those without "
        "it (resolver 'none'), on the same seeds. Prints one JSON object.",
    )
    ap.add_argument("scenario", help="scenario name (scenarios/) or TOML path")
    ap.add_argument("--seeds", default="0-9", help="seeds, e.g. 0-15 or 0,3,7 (default 0-9)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args(argv)
    from airspace_sim.scenarios import load

    try:
        sc = load(args.scenario, args.set)
        out = risk_ratio(sc, parse_seeds(args.seeds), progress=True)
    except UserError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
