"""``airspace-sim bench``: tracker-updates per second of the batched IMM and of filterpy."""

from __future__ import annotations

from airspace_sim.commands._args import positive_int

HELP = "Benchmark the batched IMM against filterpy's IMMEstimator (tracker-updates per second)."


def add_arguments(parser) -> None:
    parser.add_argument(
        "--steps", type=positive_int, default=20, help="IMM steps per timing (default 20)"
    )
    parser.add_argument(
        "--repeats",
        type=positive_int,
        default=5,
        help="timings per batch size; the median is reported (default 5)",
    )
    parser.add_argument(
        "--sizes", default="1,100,10000", help="comma-separated batch sizes B (default 1,100,10000)"
    )
    parser.add_argument(
        "--filterpy-updates", type=positive_int, default=1000,
        help="single-tracker filterpy updates to time, split over the repeats (default 1000)",
    )  # fmt: skip
    parser.add_argument("--preset", default="seed", help="model preset (default seed)")
    parser.add_argument(
        "--kernel", choices=("auto", "generated", "loops"), default="auto",
        help="IMM step kernel (default auto: generated code for the preset's model)",
    )  # fmt: skip
    parser.add_argument(
        "--json", metavar="PATH", default=None, help="also write the results as JSON to PATH"
    )


def run(args) -> int:
    import json
    from pathlib import Path

    from airspace_sim.errors import UserError
    from airspace_sim.tracking.benchmark import format_table, run_benchmark

    try:
        sizes = [int(s) for s in str(args.sizes).split(",") if s.strip()]
    except ValueError:
        raise UserError(f"--sizes: expected comma-separated integers, got {args.sizes!r}") from None
    result = run_benchmark(
        sizes=sizes,
        steps=args.steps,
        repeats=args.repeats,
        filterpy_updates=args.filterpy_updates,
        preset=args.preset,
        kernel=args.kernel,
    )
    print(format_table(result))
    if args.json:
        path = Path(args.json)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(result, indent=2) + "\n")
        except OSError as exc:
            raise UserError(f"--json: cannot write {path}: {exc}") from None
    return 0
