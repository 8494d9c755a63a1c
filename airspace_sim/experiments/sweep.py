"""Sweeps: one scenario over every combination of grid settings and seeds (``airspace-sim sweep``).

A grid axis is ``KEY=V1,V2,...``: a scenario key (dotted, as for ``--set``) and its values,
each parsed as TOML (commas inside ``[...]``, ``{...}`` or quotes do not split). Keys that must
change together are one axis: ``traffic.count,traffic.radius=[32,33700],[64,67200]`` (each
value a TOML array with one element per key). The runs are the Cartesian product of the
axes (in the order given, the last axis fastest) times the seeds.

A run is the world of :class:`~airspace_sim.world.World` built from the scenario with the
base overrides (``--set``) and its cell's settings, seeded with its seed, run to the end of
its duration (or ``steps``); its row holds ``settings`` (the canonical ``key=value`` text of
its cell), one column per grid key (typed: integer, float, bool or string), ``seed`` and
every metric of :meth:`World.run() <airspace_sim.world.World.run>`. The run key is
(``settings``, ``seed``); a run's row depends on nothing else (the world's random streams are
keyed by seed), so rows are identical for any worker count or backend. Rows are sorted by
cell (grid order), then seed.

The manifest holds the scenario's text (SHA-256), the base overrides, ``steps`` and, when a
cell replays recorded traffic, the SHA-256 of every ``[recorded]`` file the cells refer to
(``recorded_sha256``, file value -> digest): a resumed sweep with more seeds or more grid
values reuses every run it already has, and one whose recording changed is refused.
"""

from __future__ import annotations

import hashlib
import itertools
import json
from dataclasses import dataclass

from airspace_sim.errors import UserError

KEY_COLUMNS = ("settings", "seed")
MAX_SEED = 2**63 - 1
#: Columns a grid key cannot be called (the run key and World.run's metrics are separate).
RESERVED = {"settings", "seed"}


@dataclass(frozen=True)
class Axis:
    """One grid axis: ``keys`` (scenario keys changed together) and ``values`` (one tuple of
    TOML value texts per point, one text per key)."""

    keys: tuple[str, ...]
    values: tuple[tuple[str, ...], ...]


@dataclass(frozen=True)
class Run:
    """One run: its cell (position in the grid), settings ((key, TOML text) pairs) and seed."""

    cell: int
    settings: tuple[tuple[str, str], ...]
    seed: int

    @property
    def key(self) -> tuple[str, int]:
        return (settings_text(self.settings), self.seed)


def settings_text(settings) -> str:
    """Canonical text of a cell's settings: ``key=value`` pairs, sorted by key, ``;``-joined."""
    return ";".join(f"{k}={v}" for k, v in sorted(settings))


def split_top_level(text: str) -> list[str]:
    """Split ``text`` at commas outside brackets, braces and quotes."""
    out, depth, quote, cur = [], 0, None, []
    for c in text:
        if quote:
            quote = None if c == quote else quote
        elif c in "\"'":
            quote = c
        elif c in "[{":
            depth += 1
        elif c in "]}":
            depth -= 1
        elif c == "," and depth == 0:
            out.append("".join(cur).strip())
            cur = []
            continue
        cur.append(c)
    out.append("".join(cur).strip())
    return out


def _toml_text(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float, str)):
        return json.dumps(value)
    raise ValueError


def parse_axis(item: str) -> Axis:
    """``"traffic.count=32,64"`` -> :class:`Axis`; a :class:`UserError` naming the item."""
    from airspace_sim.scenarios.overrides import parse_key, parse_value

    if "=" not in item:
        raise UserError(f"--grid {item}: expected KEY=V1,V2,... e.g. traffic.count=32,64")
    lhs, _, rhs = item.partition("=")
    keys = tuple(k.strip() for k in lhs.split(","))
    for k in keys:
        parse_key(k)  # UserError on a malformed key
        if k in RESERVED:
            raise UserError(f"--grid {item}: {k!r} cannot be a grid key (use --seeds)")
    if len(set(keys)) != len(keys):
        raise UserError(f"--grid {item}: a key is repeated")
    texts = split_top_level(rhs)
    if any(not t for t in texts):
        raise UserError(f"--grid {item}: empty value (expected KEY=V1,V2,...)")
    if len(set(texts)) != len(texts):
        raise UserError(f"--grid {item}: a value is repeated")
    if len(keys) == 1:
        return Axis(keys, tuple((t,) for t in texts))
    values = []
    for t in texts:
        v = parse_value(t)
        try:
            if not isinstance(v, list) or len(v) != len(keys):
                raise ValueError
            values.append(tuple(_toml_text(e) for e in v))
        except ValueError:
            raise UserError(
                f"--grid {lhs}: value {t!r} must be an array of {len(keys)} numbers, "
                "booleans or strings, one per key"
            ) from None
    return Axis(keys, tuple(values))


def parse_seeds(text: str) -> list[int]:
    """``"0-99"``, ``"3"``, ``"0,5,9"`` or ``"0-9,20-29"`` -> seeds in order, each in [0, 2**63)."""
    seeds: list[int] = []
    for part in str(text).split(","):
        part = part.strip()
        try:
            if "-" in part[1:]:
                a, b = part.split("-", 1)
                lo, hi = int(a), int(b)
                if hi < lo:
                    raise ValueError
                if hi - lo >= 10**7:
                    raise UserError(f"--seeds: range {part} has more than 10 million seeds")
                seeds.extend(range(lo, hi + 1))
            else:
                seeds.append(int(part))
        except ValueError:
            raise UserError(
                f"--seeds: expected e.g. 0-99, 5 or 0,3,7, got {text!r} (at {part!r})"
            ) from None
    bad = [s for s in seeds if not 0 <= s <= MAX_SEED]
    if bad:
        raise UserError(f"--seeds: seeds must be in [0, 2**63), got {bad[0]}")
    if len(set(seeds)) != len(seeds):
        raise UserError(f"--seeds: a seed is repeated in {text!r}")
    return seeds


def plan(axes: list[Axis], seeds: list[int]) -> list[Run]:
    """Every run: the product of the axes (last fastest) times the seeds, in row order."""
    keys = [k for a in axes for k in a.keys]
    if len(set(keys)) != len(keys):
        raise UserError("--grid: a key appears in two axes")
    runs = []
    for cell, point in enumerate(itertools.product(*(a.values for a in axes))):
        texts = [t for p in point for t in p]
        settings = tuple(zip(keys, texts))
        runs += [Run(cell, settings, s) for s in seeds]
    return runs


def column_types(axes: list[Axis]) -> dict[str, str]:
    """Grid key -> column kind (``int``, ``float``, ``bool``, ``str``) from its values."""
    from airspace_sim.scenarios.overrides import parse_value

    kinds = {}
    for a in axes:
        for j, k in enumerate(a.keys):
            vals = [parse_value(p[j]) for p in a.values]
            if all(isinstance(v, bool) for v in vals):
                kinds[k] = "bool"
            elif all(isinstance(v, int) and not isinstance(v, bool) for v in vals):
                kinds[k] = "int" if all(abs(v) < 2**63 for v in vals) else "str"
            elif all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
                kinds[k] = "float"
            else:
                kinds[k] = "str"
    return kinds


def _value(text: str, kind: str):
    from airspace_sim.scenarios.overrides import parse_value

    if kind == "str":
        v = parse_value(text)
        return v if isinstance(v, str) else text
    v = parse_value(text)
    return float(v) if kind == "float" else v


def _overrides(settings) -> list[str]:
    return [f"{k}={v}" for k, v in settings]


def load_cell(text: str, source: str, name: str, base: list[str], settings):
    """The validated scenario of one cell (a :class:`UserError` names the grid setting)."""
    from airspace_sim.scenarios.loader import from_dict, parse_toml

    try:
        return from_dict(parse_toml(text, source), source, [*base, *_overrides(settings)], name)
    except UserError as exc:
        msg = str(exc)
        for k, v in settings:
            if msg.startswith(f"--set {k}"):
                raise UserError(f"--grid {k}={v}:{msg[len('--set ' + k) + 1 :]}") from None
        raise


def run_one(text: str, source: str, name: str, base: list[str], settings, seed, steps, kinds):
    """Run one world (spawn-safe, top level); return its row as a dict."""
    from airspace_sim.world import World

    sc = load_cell(text, source, name, base, settings)
    metrics = World(sc, seed=int(seed)).run(steps)
    row = {"settings": settings_text(settings)}
    row.update({k: _value(v, kinds[k]) for k, v in settings})
    row["seed"] = int(seed)
    for k, v in metrics.items():
        if k in row:
            k = f"metric.{k}"  # a grid key named like a metric keeps both
        row[k] = v
    return row


_ARROW = {"int": "int64", "float": "float64", "bool": "bool_", "str": "string"}


def row_table(row: dict, kinds: dict):
    """One row as a pyarrow Table: grid columns typed by ``kinds``, metrics by value type."""
    import pyarrow as pa

    fields = []
    for k, v in row.items():
        if k in kinds:
            tp = getattr(pa, _ARROW[kinds[k]])()
        elif k == "settings":
            tp = pa.string()
        elif isinstance(v, bool):
            tp = pa.bool_()
        elif isinstance(v, int):
            tp = pa.int64()
        elif isinstance(v, float):
            tp = pa.float64()
        else:
            tp = pa.string()
            v = json.dumps(v) if not isinstance(v, str) else v
            row = {**row, k: v}
        fields.append(pa.field(k, tp))
    return pa.table({k: [v] for k, v in row.items()}, schema=pa.schema(fields))


def _file_sha256(file: str, source: str) -> str:
    """SHA-256 (hex) of the bytes of the ``[recorded] file`` value ``file`` of ``source``."""
    from airspace_sim.recorded.scenario import resolve_file

    path = resolve_file(file, source)
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except OSError as exc:
        raise UserError(f"{source}: recorded.file: cannot read {path}: {exc.strerror}") from None
    return h.hexdigest()


def _part_name(run: Run) -> str:
    h = hashlib.sha1(settings_text(run.settings).encode()).hexdigest()[:12]
    return f"{h}-s{run.seed}"


def run_sweep(
    scenario,
    grid=(),
    seeds="0",
    out="results.parquet",
    overrides=(),
    steps: int | None = None,
    workers: int = 1,
    backend: str = "local",
    address: str | None = None,
    progress: bool = True,
):
    """Run (or resume) a sweep; write ``out`` and return the table (see the module docstring).

    Parameters
    ----------
    scenario : scenario name or path to a TOML file.
    grid : ``KEY=V1,V2,...`` items (or :class:`Axis` objects).
    seeds : ``"0-99"``-style text or a list of ints.
    out : final Parquet file; parts in ``<out>.parts/``.
    overrides : ``--set`` items applied to every run before the grid's.
    steps : world steps per run (default: each scenario's duration / dt).
    workers : local processes, or CPUs of the local Ray started (``backend="ray"``).
    backend, address : ``"local"`` or ``"ray"``; a Ray cluster address.
    progress : tqdm bar on stderr.
    """
    import numpy as np

    from airspace_sim.experiments import PartStore, Unit, execute, make_backend
    from airspace_sim.scenarios import build_aircraft
    from airspace_sim.scenarios.loader import display_path, resolve
    from airspace_sim.scenarios.overrides import format_key, parse_key
    from airspace_sim.scenarios.overrides import parse as parse_override

    axes = [a if isinstance(a, Axis) else parse_axis(a) for a in grid]
    seed_list = parse_seeds(seeds) if isinstance(seeds, str) else [int(s) for s in seeds]
    if not seed_list:
        raise UserError("--seeds: give at least one seed")
    if steps is not None and (not isinstance(steps, int) or steps < 1):
        raise UserError(f"--steps: must be a positive integer, got {steps!r}")
    base = list(overrides)
    base_keys = {format_key(parse_override(o)[0]) for o in base}
    clash = [k for a in axes for k in a.keys if format_key(parse_key(k)) in base_keys]
    if clash:
        raise UserError(f"--grid {clash[0]}: also given with --set; give it once")
    path = resolve(scenario)
    source = display_path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{source}: cannot read: {exc}") from None
    runs = plan(axes, seed_list)
    kinds = column_types(axes)
    seen_cells = set()
    recorded = {}  # [recorded] file value -> SHA-256 of its bytes
    for r in runs:  # every cell valid before any work: errors come first, on one line
        if r.cell not in seen_cells:
            seen_cells.add(r.cell)
            sc = load_cell(text, source, path.stem, base, r.settings)
            build_aircraft(sc, np.random.default_rng(0))  # traffic-level checks (ring radius)
            if sc.recorded.file and sc.recorded.file not in recorded:
                recorded[sc.recorded.file] = _file_sha256(sc.recorded.file, sc.source)
    manifest = {
        "kind": "sweep",
        "scenario": path.stem,
        "scenario_sha256": hashlib.sha256(text.encode()).hexdigest(),
        "overrides": base,
        "steps": steps,
    }
    if recorded:  # absent without recorded traffic: earlier sweeps' manifests still match
        manifest["recorded_sha256"] = recorded
    store = PartStore(out, KEY_COLUMNS, manifest)
    done = store.open()
    units = [
        Unit(_part_name(r), 1, (text, source, path.stem, base, r.settings, r.seed, steps, kinds))
        for r in runs
        if r.key not in done
    ]
    execute(
        store,
        units,
        run_one,
        make_backend(backend, int(workers), address),
        lambda row: row_table(row, kinds),
        desc=f"sweep {path.stem}",
        unit="run",
        progress=progress,
    )
    order = {r.key: j for j, r in enumerate(runs)}
    return store.assemble(order, lead=["settings", *kinds, "seed"])


def grid_keys(table) -> list[str]:
    """The grid columns of a sweep table: those between ``settings`` and ``seed``."""
    names = table.column_names
    return names[names.index("settings") + 1 : names.index("seed")]


__all__ = [
    "Axis",
    "Run",
    "column_types",
    "grid_keys",
    "parse_axis",
    "parse_seeds",
    "plan",
    "run_one",
    "run_sweep",
    "settings_text",
]
