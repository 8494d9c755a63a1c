"""``airspace-sim bench-env``: PettingZoo env steps per second against its bare world.

Times the parallel env with random actions, the bare world underneath with the same random
turns (the peer), and resets (:func:`airspace_sim.env.benchmark.bench_env`); with
``--pettingzoo`` also runs PettingZoo's ``performance_benchmark`` (5 s)::

    airspace-sim bench-env
    airspace-sim bench-env --env ring16 --steps 300 --pettingzoo --json out/bench_env.json

Absolute numbers depend on the machine and its load; compare ratios from one run.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from airspace_sim.commands._args import positive_int
from airspace_sim.errors import UserError

HELP = "benchmark the PettingZoo env (steps/s, reset cost) against its bare world"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--env", default="ring8", help="registry id or scenario name (default ring8)"
    )
    parser.add_argument(
        "--steps", type=positive_int, default=500, help="timed steps per block (default 500)"
    )
    parser.add_argument(
        "--repeats", type=positive_int, default=3, help="timed blocks, median (default 3)"
    )
    parser.add_argument(
        "--pettingzoo",
        action="store_true",
        help="also run pettingzoo.test.performance_benchmark on the AEC form (5 s)",
    )
    parser.add_argument("--json", metavar="PATH", help="also write the results as JSON")


def run(args) -> int:
    from airspace_sim.env.benchmark import bench_env, format_report

    if args.json:
        path = Path(args.json)
        if not path.parent.resolve().is_dir():
            raise UserError(f"--json {path}: no such folder {str(path.parent)!r}")
    r = bench_env(args.env, args.steps, args.repeats, pettingzoo_benchmark=args.pettingzoo)
    print(format_report(r))
    if args.json:
        try:
            path.write_text(json.dumps(r, indent=2) + "\n")
        except OSError as exc:
            raise UserError(f"--json {path}: cannot write: {exc}") from None
    return 0
