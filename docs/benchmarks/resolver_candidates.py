"""Candidate resolvers against ``bands`` on rings and ``dense_random`` (same seeds).

    python docs/benchmarks/resolver_candidates.py ring:64:0-2 dense:0-3 \\
        --kinds bands bands-reciprocal bands-reciprocal:share=0.7

Each case × kind prints one JSON line: LoS pairs, NMAC pairs, induced LoS pairs, extra
path %, mean / max arrival delay, not arrived, wall time. ``kind:key=value`` sets
``resolver.params`` (a TOML value: a number, true or false).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
import tomllib

from airspace_sim.scenarios import load
from airspace_sim.world import World
from airspace_sim.world.benchmark import ring_scenario


def seeds_of(text):
    a, _, b = text.partition("-")
    return list(range(int(a), int(b) + 1)) if b else [int(a)]


def scenario(case, kind, policy=(), overrides=()):
    name, params = kind.split(":")[0], {}
    for kv in kind.split(":")[1:]:
        k, v = kv.split("=")
        params[k] = tomllib.loads(f"v = {v}")["v"]
    knobs = {k: tomllib.loads(f"v = {v}")["v"] for k, _, v in (kv.partition("=") for kv in policy)}
    parts = case.split(":")
    if parts[0] == "ring":
        sc = ring_scenario(int(parts[1]), overrides=tuple(overrides))
    elif parts[0] == "scn":
        sc = load(parts[1], list(overrides))
    else:
        sc = load("dense_random", list(overrides))
    # a kind's label is the whole of its params: the scenario file's own are not inherited
    spec = dataclasses.replace(sc.resolver, kind=name, params=params, **knobs)
    return dataclasses.replace(sc, resolver=spec), seeds_of(parts[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "cases", nargs="+", help="ring:N:SEEDS, dense:SEEDS or scn:SCENARIO:SEEDS (a file)"
    )
    ap.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="scenario override for every case (as airspace-sim run --set)",
    )
    ap.add_argument("--kinds", nargs="+", default=["bands", "bands-reciprocal"])
    ap.add_argument(
        "--policy",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="CDA policy knobs of [resolver] for every run, e.g. resume_margin=0.5",
    )
    args = ap.parse_args(argv)
    keys = (
        "los_pairs",
        "nmac_pairs",
        "induced_los_pairs",
        "extra_path_pct",
        "arrival_delay_mean_s",
        "arrival_delay_max_s",
        "not_arrived",
        "wcv_pairs",
    )
    for case in args.cases:
        for kind in args.kinds:
            sc, seeds = scenario(case, kind, args.policy, args.overrides)
            for seed in seeds:
                t0 = time.perf_counter()
                m = World(sc, seed=seed).run()
                row = {"case": case, "kind": kind, "policy": " ".join(args.policy), "seed": seed}
                if args.overrides:
                    row["set"] = " ".join(args.overrides)  # what --set changed in the case
                row.update({k: m[k] for k in keys})
                row["wall_s"] = round(time.perf_counter() - t0, 1)
                print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
