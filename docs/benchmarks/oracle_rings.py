"""How far is the resolver from the best achievable? Rings of 8–16 aircraft: our resolver
against a centralised, perfect-knowledge plan (:mod:`airspace_sim.avoidance.oracle`).

    python docs/benchmarks/oracle_rings.py --sizes 8 12 16 --seeds 0-4 [--ours shipped|bands]

The ring is :func:`bluesky_rings.ring_traffic` (the same as ``ring_scenario``: radius 20 km
at these sizes, 230 m/s, 3°/s, r_safe 3000 m). The oracle's plan is flown in the World by
controlled aircraft (``oracle.fly_in_world``: tracker ``truth``, no resolver) to check it:
its LoS pairs must be 0 and its extra path is the World's ``extra_path_pct``. Ours: ``ring_scenario`` (IMM tracks
from σ = 50 m) with ``--ours``' resolver (:func:`bluesky_rings.our_scenario`: ``shipped``, the
default, ``scenarios/ring.toml``'s; ``bands`` at margin 10%), seeds as given, and the same
with perfect tracks (``tracker = "truth"``). Prints JSON lines, then a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bluesky_rings import R_SAFE, SPEED, our_scenario, parse_seeds, ring_traffic  # noqa: E402

from airspace_sim.avoidance.oracle import best_plan, fly_in_world  # noqa: E402
from airspace_sim.world import World  # noqa: E402

RATE = math.radians(3.0)


def ours(n, seed, tracker, which="shipped"):
    m = World(our_scenario(n, seed, which, tracker=tracker), seed=seed).run()
    keys = ("los_pairs", "extra_path_pct", "arrival_delay_mean_s", "arrival_delay_max_s")
    return {k: m[k] for k in keys} | {"not_arrived": m["not_arrived"]}


def _span(values, fmt):
    v = np.array(values, dtype=float)
    lo, hi = np.nanmin(v), np.nanmax(v)
    return fmt.format(lo) if lo == hi else f"{fmt.format(lo)}–{fmt.format(hi)}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[8, 12, 16])
    ap.add_argument("--seeds", default="0-4")
    ap.add_argument("--orders", type=int, default=4, help="priority orders the oracle tries")
    ap.add_argument("--ours", choices=["shipped", "bands"], default="shipped")
    args = ap.parse_args(argv)
    rows = []
    for n in args.sizes:
        start, heading, dest, radius, duration = ring_traffic(n, 0)
        t0 = time.perf_counter()
        plan = best_plan(start, heading, dest, SPEED, RATE, R_SAFE, duration, orders=args.orders)
        wall = time.perf_counter() - t0
        m = fly_in_world(plan, start, heading, dest, SPEED, RATE, R_SAFE)
        t0_, d, T = plan.params[0]
        row = {
            "n": n,
            "side": f"oracle ({plan.method})",
            "los_pairs": m["los_pairs"],
            "extra_path_pct": m["extra_path_pct"],
            "plan_extra_pct": plan.extra_pct,
            "arrival_delay_mean_s": m["arrival_delay_mean_s"],
            "arrival_delay_max_s": m["arrival_delay_max_s"],
            "not_arrived": m["not_arrived"],
            "manoeuvre": [t0_, math.degrees(d), T] if plan.method == "common" else None,
            "wall_s": round(wall, 1),
        }
        rows.append(row)
        print(json.dumps(row), flush=True)
        for tracker in ("imm", "truth"):
            for seed in parse_seeds(args.seeds):
                side = f"{args.ours} ({tracker})"
                row = ours(n, seed, tracker, args.ours) | {"n": n, "seed": seed, "side": side}
                rows.append(row)
                print(json.dumps(row), flush=True)
    print()
    print(
        "| aircraft | who | LoS pairs | extra path % | mean delay s | max delay s | not arrived |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for n in args.sizes:
        for side in sorted({r["side"] for r in rows if r["n"] == n}, key=lambda s: s[0] != "o"):
            rs = [r for r in rows if r["n"] == n and r["side"] == side]
            cols = [
                _span([r[k] for r in rs], fmt)
                for k, fmt in (
                    ("los_pairs", "{:.0f}"),
                    ("extra_path_pct", "{:.1f}"),
                    ("arrival_delay_mean_s", "{:.0f}"),
                    ("arrival_delay_max_s", "{:.0f}"),
                    ("not_arrived", "{:.0f}"),
                )
            ]
            print(f"| {n} | {side} | " + " | ".join(cols) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
