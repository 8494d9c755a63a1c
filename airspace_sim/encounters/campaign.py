"""Monte Carlo campaigns of encounters: workers, parquet output, resume.

:func:`run_campaign` runs encounters ``0..runs-1`` of campaign ``seed`` for each resolver
and writes one row per (encounter, resolver) (:data:`COLUMNS`).

Reproducibility: encounter ``i`` draws every random number from
``SeedSequence([seed, i])`` (:func:`~airspace_sim.encounters.relative.draw_encounters`), and
the batched IMM treats its rows independently, so an encounter's row is the same whatever
chunk, batch, worker or order runs it: results are identical for any ``--workers``.

Running, resuming and the files on disk are the shared run engine's
(:mod:`airspace_sim.experiments`): work is split into units (one resolver, up to
``chunk_size`` encounters), run on a backend (local processes or Ray), and each finished unit
is written atomically as ``<out>.parts/part-<resolver>-<first>-<last>.parquet``. The run key
is (resolver, encounter): a restarted run skips every key already saved, a retried task never
adds a row twice, and the final ``<out>`` is rebuilt from the parts sorted by resolver, then
encounter. ``<out>.parts/manifest.json`` records the seed, frame and configuration:
resuming with different ones is refused (a UserError), since the rows would not be
comparable. Damaged state files are repaired or named (:mod:`airspace_sim.experiments.store`).

The pseudo-resolver ``"oracle"`` asks, with perfect knowledge of the intruder's future,
whether any manoeuvre of an open-loop family within the limits avoids loss of separation
(:func:`~airspace_sim.encounters.world_frame.oracle_world`,
:func:`~airspace_sim.encounters.relative.oracle_relative`).
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict

import numpy as np

from airspace_sim.encounters.relative import EncounterConfig
from airspace_sim.errors import UserError

FRAMES = ("relative", "world")
ORACLE = "oracle"

#: (name, kind) of every column; kind: "int", "float", "bool", "str".
COLUMNS = [
    ("seed", "int"),
    ("encounter", "int"),
    ("resolver", "str"),
    ("frame", "str"),
    ("min_separation_m", "float"),
    ("los", "bool"),
    ("intrusion_depth", "float"),
    ("n_manoeuvres", "int"),
    ("heading_change_rad", "float"),
    ("position_rmse_m", "float"),
    ("measurement_rmse_m", "float"),
    ("mode_accuracy", "float"),
    ("true_straight_fraction", "float"),
    ("false_detections", "float"),
    ("own_turn_straight_steps", "float"),
    ("quiet_false_detections", "float"),
    ("quiet_straight_steps", "float"),
    ("steps", "int"),
    ("world_position_rmse_m", "float"),
    ("world_mode_accuracy", "float"),
    ("world_false_detections", "float"),
    ("world_own_turn_straight_steps", "float"),
    ("world_quiet_false_detections", "float"),
    ("world_quiet_straight_steps", "float"),
    ("rel_position_rmse_m", "float"),
    ("rel_mode_accuracy", "float"),
    ("rel_false_detections", "float"),
    ("rel_own_turn_straight_steps", "float"),
    ("rel_quiet_false_detections", "float"),
    ("rel_quiet_straight_steps", "float"),
]


def _schema():
    import pyarrow as pa

    types = {"int": pa.int64(), "float": pa.float64(), "bool": pa.bool_(), "str": pa.string()}
    return pa.schema([(n, types[k]) for n, k in COLUMNS])


def run_unit(frame: str, resolver: str, seed: int, indices: list, config: dict):
    """Run one unit of work (spawn-safe, top level): encounters ``indices`` with one
    resolver. Returns a dict of column lists (see :data:`COLUMNS`)."""
    cfg = EncounterConfig(**config)
    if frame == "relative":
        from airspace_sim.encounters.relative import oracle_relative, run_relative

        m = (
            oracle_relative(seed, indices, cfg)
            if resolver == ORACLE
            else run_relative(seed, indices, resolver, cfg).metrics
        )
    elif frame == "world":
        from airspace_sim.encounters.world_frame import oracle_world, run_world

        m = (
            oracle_world(seed, indices, cfg)
            if resolver == ORACLE
            else run_world(seed, indices, resolver, cfg).metrics
        )
    else:
        raise UserError(f"frame must be one of {', '.join(FRAMES)}, got {frame!r}")
    n = len(indices)
    cols = {
        "seed": [int(seed)] * n,
        "encounter": [int(i) for i in indices],
        "resolver": [resolver] * n,
        "frame": [frame] * n,
    }
    for name, kind in COLUMNS[4:]:
        v = m.get(name)
        if v is None:
            v = np.full(n, np.nan) if kind == "float" else np.zeros(n, dtype=int)
        v = np.asarray(v)
        if kind == "float":
            cols[name] = v.astype(float).tolist()
        elif kind == "int":
            cols[name] = v.astype(np.int64).tolist()
        else:
            cols[name] = v.astype(bool).tolist()
    return cols


def _table(cols: dict):
    import pyarrow as pa

    return pa.table(cols, schema=_schema())


def _check_resolvers(resolvers: list[str]) -> None:
    from airspace_sim import registry

    if not resolvers:
        raise UserError("--resolver: give at least one resolver name")
    for name in resolvers:
        if name != ORACLE:
            registry.get("resolver", name)  # UserError listing the known names
    if len(set(resolvers)) != len(resolvers):
        raise UserError(f"--resolver: a name is repeated in {','.join(resolvers)}")


def _manifest(seed: int, frame: str, cfg: EncounterConfig) -> dict:
    return {"seed": int(seed), "frame": frame, "config": json.loads(json.dumps(asdict(cfg)))}


def plan_units(
    done: set, runs: int, resolvers: list[str], chunk_size: int
) -> list[tuple[str, list[int]]]:
    """Units (resolver, encounter indices) still to run: missing encounters grouped by
    their aligned chunk ``i // chunk_size``, so a unit never mixes chunks."""
    units = []
    for r in resolvers:
        missing = [i for i in range(runs) if (r, i) not in done]
        groups: dict[int, list[int]] = {}
        for i in missing:
            groups.setdefault(i // chunk_size, []).append(i)
        units += [(r, g) for _, g in sorted(groups.items())]
    return units


def _order(runs: int, resolvers) -> dict:
    """Run key (resolver, encounter) -> row position: sorted by resolver, then encounter."""
    keys = sorted((r, i) for r in resolvers for i in range(int(runs)))
    return {k: j for j, k in enumerate(keys)}


def run_campaign(
    out,
    runs: int,
    resolvers,
    frame: str = "relative",
    seed: int = 0,
    workers: int = 1,
    chunk_size: int = 100,
    cfg: EncounterConfig | None = None,
    progress: bool = True,
    backend: str = "local",
    address: str | None = None,
):
    """Run (or resume) a campaign; write ``out`` (parquet) and return it as a pyarrow Table.

    Parameters
    ----------
    out : path of the final parquet file; parts go to ``<out>.parts/``.
    runs : number of encounters N (indices 0..N-1).
    resolvers : resolver names (registry names, or ``"oracle"``).
    frame : ``"relative"`` (the paper's) or ``"world"``.
    seed : campaign seed.
    workers : K local worker processes (1 = in this process), or the CPUs of a local Ray.
    chunk_size : encounters per unit of work (vectorised together).
    cfg : :class:`EncounterConfig` (default: the paper's setting).
    progress : show a tqdm progress bar on stderr.
    backend : ``"local"`` or ``"ray"`` (:mod:`airspace_sim.experiments.backends`).
    address : Ray cluster address (``backend="ray"``); default: start a local Ray.
    """
    from airspace_sim.experiments import PartStore, Unit, execute, make_backend

    if isinstance(resolvers, str):
        resolvers = [r.strip() for r in resolvers.split(",") if r.strip()]
    resolvers = list(resolvers)
    if not isinstance(runs, (int, np.integer)) or runs < 1:
        raise UserError(f"--runs: must be a positive integer, got {runs!r}")
    if not isinstance(workers, (int, np.integer)) or workers < 1:
        raise UserError(f"--workers: must be a positive integer, got {workers!r}")
    if not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
        raise UserError(f"--chunk-size: must be a positive integer, got {chunk_size!r}")
    if not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**63:
        raise UserError(f"--seed: must be an integer in [0, 2**63), got {seed!r}")
    if frame not in FRAMES:
        raise UserError(f"--frame: must be one of {', '.join(FRAMES)}, got {frame!r}")
    _check_resolvers(resolvers)
    cfg = cfg or EncounterConfig()
    store = PartStore(out, ("resolver", "encounter"), _manifest(seed, frame, cfg))
    done = store.open()
    config = asdict(cfg)
    units = [
        Unit(f"{r}-{ix[0]:07d}-{ix[-1]:07d}", len(ix), (frame, r, int(seed), ix, config))
        for r, ix in plan_units(done, int(runs), resolvers, int(chunk_size))
    ]
    execute(
        store,
        units,
        run_unit,
        make_backend(backend, int(workers), address),
        _table,
        desc=f"encounters ({frame})",
        unit="enc",
        progress=progress,
    )
    return store.assemble(_order(runs, resolvers), _schema())


# ----------------------------------------------------------------------------- summary
def summarize(table) -> list[dict]:
    """One dict per resolver (in table order): runs, LoS count/rate, intrusion depth,
    heading change (deg), manoeuvres, RMSEs, mode accuracy, false-detection rates."""
    cols = table.to_pydict()
    names = list(dict.fromkeys(cols["resolver"]))
    rows = []
    for name in names:
        sel = np.array([r == name for r in cols["resolver"]])

        def col(key, sel=sel):
            return np.asarray(cols[key], dtype=float)[sel]

        def ratio(num, den):
            d = np.nansum(col(den))
            return float(np.nansum(col(num)) / d) if d > 0 else math.nan

        def mean(key):
            v = col(key)
            return float(np.nanmean(v)) if np.any(np.isfinite(v)) else math.nan

        los = col("los")
        rows.append(
            {
                "resolver": name,
                "frame": cols["frame"][int(np.flatnonzero(sel)[0])],
                "runs": int(sel.sum()),
                "los": int(los.sum()),
                "los_rate": float(los.mean()),
                "mean_intrusion": mean("intrusion_depth"),
                "max_intrusion": float(np.nanmax(col("intrusion_depth"))),
                "mean_min_sep_m": mean("min_separation_m"),
                "mean_heading_change_deg": math.degrees(mean("heading_change_rad")),
                "mean_manoeuvres": mean("n_manoeuvres"),
                "position_rmse_m": mean("position_rmse_m"),
                "measurement_rmse_m": mean("measurement_rmse_m"),
                "mode_accuracy": mean("mode_accuracy"),
                "straight_fraction": mean("true_straight_fraction"),
                "false_det_rate_own_turn": ratio("false_detections", "own_turn_straight_steps"),
                "false_det_rate_quiet": ratio("quiet_false_detections", "quiet_straight_steps"),
                "world_false_det_rate_own_turn": ratio(
                    "world_false_detections", "world_own_turn_straight_steps"
                ),
                "rel_false_det_rate_own_turn": ratio(
                    "rel_false_detections", "rel_own_turn_straight_steps"
                ),
                "world_false_det_rate_quiet": ratio(
                    "world_quiet_false_detections", "world_quiet_straight_steps"
                ),
                "rel_false_det_rate_quiet": ratio(
                    "rel_quiet_false_detections", "rel_quiet_straight_steps"
                ),
                "world_position_rmse_m": mean("world_position_rmse_m"),
                "rel_position_rmse_m": mean("rel_position_rmse_m"),
            }
        )
    return rows


def _fmt(v, spec):
    return "n/a" if isinstance(v, float) and not math.isfinite(v) else format(v, spec)


def format_summary(rows: list[dict], markdown: bool = False) -> str:
    """The summary as an aligned text table (or a markdown table)."""
    world = any(r["frame"] == "world" for r in rows)
    head = [
        "resolver",
        "frame",
        "runs",
        "LoS",
        "LoS rate",
        "mean depth",
        "max depth",
        "mean hdg chg (deg)",
        "mean manoeuvres",
        "pos RMSE (m)",
        "meas RMSE (m)",
        "mode acc",
    ]
    if world:
        head += ["false det. own turn: world / rel trk", "false det. otherwise: world / rel trk"]
    else:
        head += ["false det. own turn / otherwise"]
    body = []
    for r in rows:
        line = [
            r["resolver"],
            r["frame"],
            str(r["runs"]),
            str(r["los"]),
            _fmt(r["los_rate"], ".4f"),
            _fmt(r["mean_intrusion"], ".4f"),
            _fmt(r["max_intrusion"], ".4f"),
            _fmt(r["mean_heading_change_deg"], ".1f"),
            _fmt(r["mean_manoeuvres"], ".1f"),
            _fmt(r["position_rmse_m"], ".1f"),
            _fmt(r["measurement_rmse_m"], ".1f"),
            _fmt(r["mode_accuracy"], ".3f"),
        ]
        if world:
            line += [
                f"{_fmt(r['world_false_det_rate_own_turn'], '.3f')} / {_fmt(r['rel_false_det_rate_own_turn'], '.3f')}",
                f"{_fmt(r['world_false_det_rate_quiet'], '.3f')} / {_fmt(r['rel_false_det_rate_quiet'], '.3f')}",
            ]
        else:
            line += [
                f"{_fmt(r['false_det_rate_own_turn'], '.3f')} / {_fmt(r['false_det_rate_quiet'], '.3f')}"
            ]
        body.append(line)
    from airspace_sim.experiments.summary import format_table

    return format_table(head, body, markdown)


def oracle_breakdown(table) -> list[dict]:
    """For each resolver, its losses of separation split by the oracle's verdict.

    Needs ``"oracle"`` rows for the same encounters. ``unavoidable``: encounters where no
    manoeuvre of the oracle's family within the limits clears (oracle LoS). Returns one dict
    per resolver: ``los``, ``los_unavoidable`` (LoS the oracle could not avoid either),
    ``los_avoidable`` (LoS the oracle avoided), ``unavoidable`` and ``runs``.
    """
    cols = table.to_pydict()
    orc = {e: l for r, e, l in zip(cols["resolver"], cols["encounter"], cols["los"]) if r == ORACLE}
    if not orc:
        return []
    out = []
    for name in dict.fromkeys(cols["resolver"]):
        if name == ORACLE:
            continue
        pairs = [
            (e, l)
            for r, e, l in zip(cols["resolver"], cols["encounter"], cols["los"])
            if r == name and e in orc
        ]
        los = [e for e, l in pairs if l]
        out.append(
            {
                "resolver": name,
                "runs": len(pairs),
                "unavoidable": sum(orc[e] for e, _ in pairs),
                "los": len(los),
                "los_unavoidable": sum(orc[e] for e in los),
                "los_avoidable": sum(not orc[e] for e in los),
            }
        )
    return out


def format_oracle_breakdown(rows: list[dict], markdown: bool = False) -> str:
    head = [
        "resolver",
        "runs",
        "oracle: unavoidable",
        "LoS",
        "LoS also unavoidable for the oracle",
        "LoS the oracle avoided",
    ]
    body = [
        [
            r["resolver"],
            str(r["runs"]),
            f"{r['unavoidable']} ({r['unavoidable'] / max(r['runs'], 1):.2%})",
            str(r["los"]),
            str(r["los_unavoidable"]),
            str(r["los_avoidable"]),
        ]
        for r in rows
    ]
    from airspace_sim.experiments.summary import format_table

    return format_table(head, body, markdown)
