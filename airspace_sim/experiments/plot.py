"""A sweep's metric against a grid key, one line per value of another key (matplotlib PNG).

Each point is a cell's mean over its seeds with its 95 % t-interval as an error bar
(:func:`~airspace_sim.experiments.summary.mean_ci`); cells that differ in grid keys other
than ``x`` and ``hue`` are pooled. A numeric ``x`` is plotted on a linear axis in value
order, any other as categories in table order.
"""

from __future__ import annotations

from pathlib import Path

from airspace_sim.errors import UserError


def plot_metric(table, metric: str, x: str, hue: str | None, path, keys: list[str]) -> Path:
    """Write the PNG to ``path`` and return it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from airspace_sim.experiments.summary import mean_ci

    cols = table.to_pydict()
    metrics = [c for c in table.column_names if c not in keys and c not in ("settings", "seed")]
    if metric not in cols or metric in keys or metric in ("settings", "seed"):
        raise UserError(f"--plot: no metric {metric!r}; known: {', '.join(metrics)}")
    for opt, k in (("--x", x), ("--hue", hue)):
        if k is not None and k not in keys:
            raise UserError(f"{opt}: {k!r} is not a grid key; grid keys: {', '.join(keys) or '-'}")
    if hue is not None and hue == x:
        raise UserError(f"--hue: must differ from --x ({x!r})")
    xs = list(dict.fromkeys(cols[x]))
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xs)
    if numeric:
        xs = sorted(xs)
    hues = list(dict.fromkeys(cols[hue])) if hue else [None]
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=120)
    for h in hues:
        px, py, pe = [], [], []
        for j, xv in enumerate(xs):
            vals = [
                cols[metric][i]
                for i in range(table.num_rows)
                if cols[x][i] == xv and (hue is None or cols[hue][i] == h)
            ]
            if not vals:
                continue
            m, half, _ = mean_ci([float("nan") if v is None else float(v) for v in vals])
            px.append(xv if numeric else j)
            py.append(m)
            pe.append(0.0 if half != half else half)
        label = None if hue is None else f"{hue}={h}"
        ax.errorbar(px, py, yerr=pe, marker="o", capsize=3, label=label)
    if not numeric:
        ax.set_xticks(range(len(xs)), [str(v) for v in xs])
    ax.set_xlabel(x)
    ax.set_ylabel(f"{metric} (mean, 95% CI)")
    ax.grid(alpha=0.3)
    if hue:
        ax.legend()
    fig.tight_layout()
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(path)
    except OSError as exc:
        raise UserError(f"--plot-out: cannot write {path}: {exc.strerror}") from None
    finally:
        plt.close(fig)
    return path
