"""Plot the side-by-side ring runs of bluesky_rings.py: per ring size and side, losses of
separation, extra path and the share of aircraft not arrived at 2R/v + 300 s.

    python docs/benchmarks/plot_bluesky_rings.py docs/benchmarks/results/bluesky_rings_s31.jsonl \\
        --out docs/bluesky_rings.png [--jitter 0]

Reads the JSON lines bluesky_rings.py prints (or writes with ``--out``); one run per line,
``side``, ``n``, ``jitter``, ``los_pairs``, ``extra_pct``, ``not_arrived``. Each point is the
median over the runs of that side and size, the bar its range.
"""

from __future__ import annotations

import argparse
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

#: panel title and how a run gives its value
PANELS = (
    ("LoS pairs per run", lambda r: r["los_pairs"]),
    ("extra path, %", lambda r: r["extra_pct"]),
    ("not arrived at 2R/v + 300 s, % of aircraft", lambda r: 100.0 * r["not_arrived"] / r["n"]),
)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rows", nargs="+", help="JSON-lines files from bluesky_rings.py")
    ap.add_argument("--out", required=True, help="PNG to write")
    ap.add_argument("--jitter", type=float, default=0.0, help="which start jitter to plot, m")
    args = ap.parse_args(argv)
    rows = [
        r
        for path in args.rows
        for line in open(path)
        if line.startswith("{")
        for r in [json.loads(line)]
        if r["jitter"] == args.jitter
    ]
    if not rows:
        print(f"no runs with jitter {args.jitter:g} m in {', '.join(args.rows)}", file=sys.stderr)
        return 1
    sides = sorted({r["side"] for r in rows})
    fig, axes = plt.subplots(1, len(PANELS), figsize=(4.2 * len(PANELS), 3.6))
    for ax, (title, value) in zip(axes, PANELS):
        for side in sides:
            sizes = sorted({r["n"] for r in rows if r["side"] == side})
            v = [
                np.array([value(r) for r in rows if r["side"] == side and r["n"] == n])
                for n in sizes
            ]
            mid = np.array([np.median(x) for x in v])
            err = np.array(
                [[m - x.min() for m, x in zip(mid, v)], [x.max() - m for m, x in zip(mid, v)]]
            )
            ax.errorbar(sizes, mid, yerr=err, marker="o", capsize=3, label=side)
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("aircraft on the ring")
        ax.grid(alpha=0.3)
    axes[0].set_yscale("symlog", linthresh=1.0)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"converging rings, start jitter {args.jitter:g} m", fontsize=11)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"plot -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
