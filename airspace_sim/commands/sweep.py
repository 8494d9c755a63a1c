"""``airspace-sim sweep SCENARIO``: run a scenario over a grid of settings and seeds.

Examples::

    airspace-sim sweep ring --grid traffic.count,traffic.radius=[32,33700],[64,67200] \\
        --grid resolver.kind=bands,seed --seeds 0-9 --workers 2 --out out/ring.parquet \\
        --plot los_events --x traffic.count --hue resolver.kind
    airspace-sim sweep ring --grid resolver.kind=bands,seed --seeds 0-99 \\
        --backend ray --address ray://head:10001 --out ring.parquet

One Parquet row per run (its settings, seed and every metric of ``World.run()``); a summary
table per cell (mean ± 95 % confidence interval) is printed. Rerunning the same command
resumes: finished runs are skipped. Details: ``docs/sweeps.md``.
"""

from __future__ import annotations

from airspace_sim.commands._args import add_set_option, positive_int

HELP = "run a scenario over a grid of settings x seeds; write parquet, summary, plot"


def add_arguments(parser) -> None:
    parser.add_argument("scenario", help="scenario name or path to a .toml file")
    parser.add_argument(
        "--grid",
        action="append",
        default=[],
        metavar="KEY=V1,V2",
        help="a grid axis (repeatable; product of all): a scenario key and its values, e.g. "
        "traffic.count=32,64; keys changed together: a,b=[1,2],[3,4]",
    )
    parser.add_argument("--seeds", default="0", help="seeds, e.g. 0-99, 5 or 0,3,7 (default 0)")
    add_set_option(parser, "in every run")
    parser.add_argument(
        "--steps", type=positive_int, help="world steps per run (default: duration / dt)"
    )
    parser.add_argument(
        "--workers",
        type=positive_int,
        default=1,
        help="local worker processes, or CPUs of the local Ray started (default 1)",
    )
    parser.add_argument(
        "--backend", default="local", choices=["local", "ray"], help="where runs go (default local)"
    )
    parser.add_argument(
        "--address",
        default=None,
        help="Ray cluster address (with --backend ray; default: a local Ray)",
    )
    parser.add_argument(
        "--out", default="results.parquet", help="output parquet file (default results.parquet)"
    )
    parser.add_argument(
        "--metrics",
        default=None,
        help="comma-separated metrics for the summary (default: LoS, NMAC, separation, "
        "alerts, extra path, track RMSE)",
    )
    parser.add_argument(
        "--summary-md", default=None, help="also write the summary as markdown here"
    )
    parser.add_argument("--plot", metavar="METRIC", default=None, help="plot this metric ...")
    parser.add_argument("--x", metavar="KEY", default=None, help="... against this grid key")
    parser.add_argument("--hue", metavar="KEY", default=None, help="... one line per value of KEY")
    parser.add_argument(
        "--plot-out", default=None, help="PNG path (default: <out>-<METRIC>.png beside --out)"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _check_writable(option: str, path) -> None:
    from pathlib import Path

    parent = Path(path).resolve().parent
    if not parent.is_dir():
        from airspace_sim.errors import UserError

        raise UserError(f"{option}: folder {parent} does not exist")


def run(args) -> int:
    import time
    from pathlib import Path

    from airspace_sim.errors import UserError
    from airspace_sim.experiments.plot import plot_metric
    from airspace_sim.experiments.summary import format_summary, summarize
    from airspace_sim.experiments.sweep import parse_axis, run_sweep

    # every option checked before any work
    axes = [parse_axis(g) for g in args.grid]
    keys = [k for a in axes for k in a.keys]
    if args.address and args.backend != "ray":
        raise UserError("--address: only with --backend ray")
    if args.plot is None and (args.x or args.hue):
        raise UserError("--x/--hue: only with --plot METRIC")
    if args.plot is not None:
        if args.x is None:
            raise UserError("--plot: give the grid key to plot against with --x KEY")
        for opt, k in (("--x", args.x), ("--hue", args.hue)):
            if k is not None and k not in keys:
                raise UserError(
                    f"{opt}: {k!r} is not a grid key; grid keys: {', '.join(keys) or '-'}"
                )
    plot_out = args.plot_out or (
        str(Path(args.out).with_suffix("")) + f"-{args.plot}.png" if args.plot else None
    )
    if args.summary_md:
        _check_writable("--summary-md", args.summary_md)
    metrics = [m.strip() for m in args.metrics.split(",")] if args.metrics else None

    t0 = time.perf_counter()
    table = run_sweep(
        args.scenario,
        axes,
        args.seeds,
        args.out,
        overrides=args.overrides,
        steps=args.steps,
        workers=args.workers,
        backend=args.backend,
        address=args.address,
        progress=not args.no_progress,
    )
    wall = time.perf_counter() - t0
    if metrics:
        unknown = [m for m in metrics if m not in table.column_names]
        if unknown:
            raise UserError(f"--metrics: no metric {unknown[0]!r} in {args.out}")
    rows = summarize(table, keys, metrics)
    print(format_summary(rows, keys))
    print(f"{table.num_rows} rows -> {args.out} ({wall:.1f} s wall)")
    if args.summary_md:
        Path(args.summary_md).write_text(format_summary(rows, keys, markdown=True) + "\n")
    if args.plot:
        print(f"plot -> {plot_metric(table, args.plot, args.x, args.hue, plot_out, keys)}")
    return 0
