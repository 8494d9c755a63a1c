"""``airspace-sim figures``: PNG counterparts of the paper's figures 4–7 and world-frame figures."""

from __future__ import annotations

from airspace_sim.commands._args import check_output, seed

HELP = "Write the paper's figures 4-7 and world-frame/false-detection figures as PNGs"


def add_arguments(parser) -> None:
    parser.add_argument("--out", default="out/figures", help="output folder (default out/figures)")
    parser.add_argument(
        "--seed", type=seed, default=0, help="campaign seed of the encounters shown (default 0)"
    )
    parser.add_argument(
        "--runs",
        type=int,
        default=100,
        help="encounters per setting in the false-detection comparison (default 100)",
    )


def run(args) -> int:
    from airspace_sim.encounters.figures import make_all
    from airspace_sim.errors import UserError

    if args.runs < 1:
        raise UserError(f"--runs: must be a positive integer, got {args.runs}")
    out = check_output("--out", args.out, folder=True)
    try:
        paths = make_all(out, seed=args.seed, n_false_runs=args.runs)
    except PermissionError as exc:
        raise UserError(f"--out: cannot write into {out}: {exc.strerror}") from None
    for p in paths:
        print(p)
    return 0
