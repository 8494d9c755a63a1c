"""``airspace-sim encounters``: a seeded Monte Carlo campaign of encounters (paper §VI).

Example::

    airspace-sim encounters --runs 10000 --workers 2 --resolver none,seed,bands \\
        --frame relative --out out/relative.parquet --seed 0
    airspace-sim encounters --runs 100000 --backend ray --address ray://head:10001

One row per (encounter, resolver) goes to the parquet file; a summary table per resolver is
printed. Rerunning the same command resumes: finished encounters are skipped.
"""

from __future__ import annotations

import math

from airspace_sim.commands._args import check_output, seed

HELP = "Run a seeded Monte Carlo campaign of encounters; write parquet and print a summary"


def add_arguments(parser) -> None:
    parser.add_argument(
        "--runs", type=int, default=100, help="number of encounters N (default 100)"
    )
    parser.add_argument(
        "--workers", type=int, default=1, help="local worker processes K (default 1)"
    )
    parser.add_argument(
        "--backend",
        default="local",
        choices=["local", "ray"],
        help="local worker processes, or Ray tasks (pip install 'airspace-sim[ray]') "
        "(default local)",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="Ray cluster address (with --backend ray; default: start a local Ray with "
        "--workers CPUs)",
    )
    parser.add_argument(
        "--resolver",
        default="none,seed,bands",
        help="comma-separated resolver names, or 'oracle' (default none,seed,bands)",
    )
    parser.add_argument(
        "--frame",
        default="relative",
        help="relative (the paper's frame) or world (ownship moving) (default relative)",
    )
    parser.add_argument(
        "--out", default="results.parquet", help="output parquet file (default results.parquet)"
    )
    parser.add_argument("--seed", type=seed, default=0, help="campaign seed (default 0)")
    parser.add_argument(
        "--chunk-size", type=int, default=100, help="encounters per unit of work (default 100)"
    )
    parser.add_argument(
        "--own-motion",
        default="straight",
        choices=["straight", "markov"],
        help="world frame: ownship flies straight or its own mode chain when not avoiding",
    )
    parser.add_argument(
        "--max-turn-rate",
        type=float,
        default=45.0,
        help="world frame: ownship turn-rate limit in deg/s (default 45 = the seed model's ω)",
    )
    parser.add_argument(
        "--summary-md", default=None, help="also write the summary as a markdown table here"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args) -> int:
    import time

    from airspace_sim.encounters.campaign import (
        format_oracle_breakdown,
        format_summary,
        oracle_breakdown,
        run_campaign,
        summarize,
    )
    from airspace_sim.encounters.relative import EncounterConfig
    from airspace_sim.errors import UserError

    if not (math.isfinite(args.max_turn_rate) and args.max_turn_rate > 0):
        raise UserError(
            f"--max-turn-rate: must be a positive number of deg/s, got {args.max_turn_rate!r}"
        )
    if args.summary_md:  # before the campaign, not after it ran
        check_output("--summary-md", args.summary_md)
    if args.address and args.backend != "ray":
        raise UserError("--address: only with --backend ray")
    cfg = EncounterConfig(
        own_motion=args.own_motion, max_turn_rate=math.radians(args.max_turn_rate)
    )
    t0 = time.perf_counter()
    table = run_campaign(
        args.out,
        args.runs,
        args.resolver,
        frame=args.frame,
        seed=args.seed,
        workers=args.workers,
        chunk_size=args.chunk_size,
        cfg=cfg,
        progress=not args.no_progress,
        backend=args.backend,
        address=args.address,
    )
    wall = time.perf_counter() - t0
    rows = summarize(table)
    print(format_summary(rows))
    breakdown = oracle_breakdown(table)
    if breakdown:
        print(
            "\nLosses of separation against the oracle (perfect knowledge of the intruder's future):"
        )
        print(format_oracle_breakdown(breakdown))
    print(f"{table.num_rows} rows -> {args.out} ({wall:.1f} s wall)")
    if args.summary_md:
        from pathlib import Path

        text = format_summary(rows, markdown=True) + "\n"
        if breakdown:
            text += "\n" + format_oracle_breakdown(breakdown, markdown=True) + "\n"
        try:
            Path(args.summary_md).write_text(text)
        except OSError as exc:
            raise UserError(f"--summary-md {args.summary_md}: cannot write: {exc}") from None
    return 0
