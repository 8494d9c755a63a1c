"""Summary of a sweep: per grid cell, runs and the mean and 95 % confidence interval of metrics.

The interval is Student's t: ``mean ± t(0.975, n−1) · s / √n`` over the cell's runs (seeds),
with ``s`` the sample standard deviation; it needs n ≥ 2 (NaN otherwise). Runs whose metric is
not finite (e.g. ``min_separation_m`` = inf when no pair ever came in range) are left out of
that metric's mean and interval (``runs`` still counts them).
"""

from __future__ import annotations

import math

import numpy as np

#: Metrics shown by default (those present in the table).
DEFAULT_METRICS = (
    "los_events",
    "los_pairs",
    "nmac_events",
    "min_separation_m",
    "alerts",
    "extra_path_pct",
    "track_rmse_m",
)


def mean_ci(values, level: float = 0.95) -> tuple[float, float, int]:
    """(mean, half-width of the ``level`` t-interval, n finite) of ``values``."""
    from scipy import stats

    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    n = v.size
    if n == 0:
        return math.nan, math.nan, 0
    m = float(v.mean())
    if n < 2:
        return m, math.nan, 1
    half = float(stats.t.ppf(0.5 + level / 2, n - 1) * v.std(ddof=1) / math.sqrt(n))
    return m, half, n


def summarize(table, keys: list[str], metrics=None) -> list[dict]:
    """One dict per cell (in table order): the grid ``keys``' values, ``runs`` and for each
    metric ``<m>`` (mean) and ``<m>_ci`` (95 % half-width)."""
    cols = table.to_pydict()
    metrics = [m for m in (metrics or DEFAULT_METRICS) if m in cols]
    cells: dict[tuple, list[int]] = {}
    for j in range(table.num_rows):
        cells.setdefault(tuple(cols[k][j] for k in keys), []).append(j)
    rows = []
    for cell, idx in cells.items():
        row = dict(zip(keys, cell))
        row["runs"] = len(idx)
        for m in metrics:
            vals = [cols[m][j] for j in idx]
            vals = [math.nan if v is None else float(v) for v in vals]
            row[m], row[m + "_ci"], _ = mean_ci(vals)
        rows.append(row)
    return rows


def _fmt(v) -> str:
    if isinstance(v, float):
        if not math.isfinite(v):
            return "n/a" if math.isnan(v) else str(v)
        return f"{v:.4g}"
    return str(v)


def format_summary(rows: list[dict], keys: list[str], markdown: bool = False) -> str:
    """The summary as an aligned text table (or markdown): ``mean ± half-width`` per metric."""
    if not rows:
        return "(no runs)"
    metrics = [k for k in rows[0] if k not in keys and k != "runs" and not k.endswith("_ci")]
    head = [*keys, "runs", *(f"{m} (95% CI)" for m in metrics)]
    body = []
    for r in rows:
        line = [_fmt(r[k]) for k in keys] + [str(r["runs"])]
        for m in metrics:
            half = r[m + "_ci"]
            line.append(_fmt(r[m]) + ("" if math.isnan(half) else f" ± {_fmt(half)}"))
        body.append(line)
    return format_table(head, body, markdown)


def format_table(head: list[str], body: list[list[str]], markdown: bool = False) -> str:
    """Rows of cell texts under ``head``: right-aligned columns, or a markdown table."""
    if markdown:
        out = ["| " + " | ".join(head) + " |", "|" + "|".join(" --- " for _ in head) + "|"]
        return "\n".join(out + ["| " + " | ".join(b) + " |" for b in body])
    widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(head)]
    fmt = "  ".join(f"{{:>{w}}}" for w in widths)
    return "\n".join([fmt.format(*head)] + [fmt.format(*b) for b in body])
