"""Metrics of six shipped scenario settings, one line each: the A/B check for a change that
must not alter results (run it on both trees, ``diff`` the outputs) or that should (read
what moved).

    PYTHONPATH=<tree> python docs/benchmarks/compare_metrics.py [--set key=value ...]

``--set`` is applied to every case on top of its own overrides (e.g.
``--set 'tracker.model="imm-ct"'`` to see what another tracker does to the world).
"""

import argparse
import json

from airspace_sim.scenarios import load
from airspace_sim.world import World

CASES = [
    ("demo", [], 0),
    ("dense_random", [], 0),
    ("ring", ["traffic.count=32"], 0),
    ("dense_random", ['resolver.kind="bands-probabilistic"', "duration=200"], 1),
    ("head_on", ['resolver.kind="seed"'], 0),
    ("crossing", ['tracker.kind="truth"'], 0),
]
KEYS = ("los_events", "nmac_events", "min_separation_m", "extra_path_pct", "track_rmse_m")
KEYS += ("mode_accuracy", "alerts")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    for name, overrides, seed in CASES:
        metrics = World(load(name, overrides + args.set), seed=seed).run()
        print(name, overrides, json.dumps({k: metrics[k] for k in KEYS}))


if __name__ == "__main__":
    main()
