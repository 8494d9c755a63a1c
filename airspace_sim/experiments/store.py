"""The state of a resumable experiment on disk: ``<out>.parts/`` with a manifest and parts.

Layout, for an output file ``results.parquet``::

    results.parquet.parts/manifest.json      what the rows depend on (settings; JSON)
    results.parquet.parts/part-<name>.parquet rows of one finished unit of work
    results.parquet                          every wanted row, sorted; rebuilt from the parts

Every file is written whole or not at all: serialised in memory, written to a hidden
temporary file in the same folder, ``fsync``-ed, then renamed over its name (``os.replace``
is atomic on POSIX), so a kill, a crash or a full disk never leaves a half file under a real
name. A full disk becomes a :class:`~airspace_sim.errors.UserError` saying how many runs are
safe and that rerunning resumes.

Each part carries the manifest's fingerprint (SHA-256 of its canonical JSON) in its Parquet
metadata, so the parts say themselves which settings made them. :meth:`PartStore.open`
verifies everything before any work:

- temporary files left by a kill are removed (they were never renamed, so never counted);
- a part that does not read back (truncated, zero bytes, not Parquet, wrong columns) is
  renamed ``<name>.damaged`` with a warning, and its runs are computed again;
- a damaged manifest is rewritten from the current settings when every intact part carries
  the current fingerprint (nothing is lost), else the run stops naming the folder to delete;
- a part made with other settings stops the run, naming the file.

The final file is always rebuilt from the parts, so a damaged final file is repaired by
rerunning.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path

from airspace_sim.errors import UserError

MANIFEST = "manifest.json"
FINGERPRINT_KEY = b"airspace_sim.manifest"


def fingerprint(manifest: dict) -> str:
    """SHA-256 (hex) of ``manifest`` as canonical JSON (sorted keys, no spaces)."""
    text = json.dumps(manifest, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` whole or not at all (temporary file, fsync, rename).

    Raises :class:`OSError` (the temporary file removed) if the write fails."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            view = memoryview(data)
            while view:
                n = os.write(fd, view)
                view = view[n:]
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise
    try:  # make the rename itself durable
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    except OSError:
        pass


def parquet_bytes(table) -> bytes:
    """``table`` serialised as a Parquet file, in memory."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    return sink.getvalue().to_pybytes()


class PartStore:
    """Manifest, parts and final file of one experiment (see the module docstring).

    Parameters
    ----------
    out : path of the final Parquet file; parts go to ``<out>.parts/``.
    key : names of the columns that identify a run (e.g. ``("resolver", "encounter")``);
        a run is saved at most once, whatever retries or restarts happen.
    manifest : JSON-able dict of everything the rows depend on; resuming with another is
        refused.
    option : the CLI option that named ``out``, for messages.
    """

    def __init__(self, out, key: Sequence[str], manifest: dict, option: str = "--out"):
        self.out = Path(out)
        self.key = tuple(key)
        self.manifest = json.loads(json.dumps(manifest, allow_nan=False))
        self.fingerprint = fingerprint(self.manifest)
        self.option = option
        self.parts = self.out.with_name(self.out.name + ".parts")
        self.done: set[tuple] = set()
        self._tables: list = []

    # ------------------------------------------------------------------ open / verify
    def open(self) -> set[tuple]:
        """Create or verify the folder; return the keys of the runs already saved."""
        if self.out.is_dir():
            raise UserError(f"{self.option}: {self.out} is a directory, expected a .parquet file")
        try:
            self.parts.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UserError(f"{self.option}: cannot create {self.parts}: {exc.strerror}") from None
        for tmp in self.parts.glob(".*.tmp"):
            tmp.unlink(missing_ok=True)  # a write a kill interrupted: never counted
        tables, foreign, legacy = self._read_parts()
        self._check_manifest(foreign, legacy)
        self._tables = tables
        self.done = set()
        for t in tables:
            self.done.update(self._keys(t))
        return set(self.done)

    def _read_parts(self):
        import pyarrow.parquet as pq

        tables, foreign, legacy = [], [], []
        for f in sorted(self.parts.glob("part-*.parquet")):
            try:
                t = pq.read_table(f)
                missing = [k for k in self.key if k not in t.column_names]
                if missing:
                    raise ValueError(f"no column {missing[0]!r}")
            except Exception as exc:  # noqa: BLE001 - any unreadable part is damaged
                damaged = f.with_name(f.name + ".damaged")
                os.replace(f, damaged)
                warnings.warn(
                    f"{f}: damaged ({type(exc).__name__}: {str(exc).splitlines()[0][:120]}); "
                    f"moved to {damaged.name}, its runs will be run again",
                    stacklevel=3,
                )
                continue
            meta = t.schema.metadata or {}
            fp = meta.get(FINGERPRINT_KEY)
            if fp is None:
                legacy.append(f)
            elif fp.decode() != self.fingerprint:
                foreign.append(f)
                continue
            tables.append(t.replace_schema_metadata(None))
        return tables, foreign, legacy

    def _check_manifest(self, foreign: list[Path], legacy: list[Path]) -> None:
        mpath = self.parts / MANIFEST
        old = None
        damaged = False
        if mpath.exists():
            try:
                old = json.loads(mpath.read_text(encoding="utf-8"))
                if not isinstance(old, dict):
                    raise ValueError("not a JSON object")
            except (ValueError, UnicodeDecodeError, OSError):
                damaged = True
        if old is not None and old != self.manifest:
            diff = sorted(
                k for k in set(old) | set(self.manifest) if old.get(k) != self.manifest.get(k)
            )
            raise UserError(
                f"{self.parts}: made with a different {', '.join(diff)}; "
                f"use another {self.option} or delete {self.parts}"
            )
        if foreign:
            raise UserError(
                f"{foreign[0]}: made with other settings than {mpath}; delete it "
                f"({len(foreign)} such part{'s' if len(foreign) > 1 else ''} in {self.parts})"
            )
        if damaged and legacy:
            raise UserError(
                f"{mpath}: damaged, and {len(legacy)} parts carry no settings to check it "
                f"against; delete {self.parts} or use another {self.option}"
            )
        if old is None:
            if damaged:
                warnings.warn(
                    f"{mpath}: damaged; rewritten from the current settings, which every "
                    "intact part matches",
                    stacklevel=3,
                )
            self._write(mpath, json.dumps(self.manifest, indent=1, sort_keys=True).encode())

    def _keys(self, table) -> Iterable[tuple]:
        return zip(*(table.column(k).to_pylist() for k in self.key))

    # ------------------------------------------------------------------ save
    def _write(self, path: Path, data: bytes) -> None:
        try:
            write_atomic(path, data)
        except OSError as exc:
            if exc.errno in (errno.ENOSPC, errno.EDQUOT):
                what = "the disk is full"
            else:
                what = exc.strerror or str(exc)
            raise UserError(
                f"{path}: cannot write ({what}); {len(self.done)} finished runs are safe in "
                f"{self.parts}: free space and rerun the same command to resume"
            ) from None

    def save(self, name: str, table) -> int:
        """Save the rows of ``table`` not saved yet as ``part-<name>.parquet``; return how
        many were new. Rows whose key is already saved (a retried task) are dropped."""
        import pyarrow as pa

        keys = list(self._keys(table))
        keep = [k not in self.done for k in keys]
        if not any(keep):
            return 0
        if not all(keep):
            table = table.filter(pa.array(keep))
            keys = [k for k, ok in zip(keys, keep) if ok]
        meta = dict(table.schema.metadata or {})
        meta[FINGERPRINT_KEY] = self.fingerprint.encode()
        table = table.replace_schema_metadata(meta)
        safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
        path = self.parts / f"part-{safe}.parquet"
        if path.exists():  # same name, other rows (a retried unit saved partly): keep both
            path = self.parts / f"part-{safe}-{len(self.done):09d}.parquet"
        self._write(path, parquet_bytes(table))
        self._tables.append(table.replace_schema_metadata(None))
        self.done.update(keys)
        return len(keys)

    # ------------------------------------------------------------------ assemble
    def assemble(self, order: dict, schema=None, lead: Sequence[str] = ()):
        """Write and return the final table: the rows whose key is in ``order`` (key ->
        position), one per key, sorted by position; cast to ``schema`` if given, else with
        the columns ``lead`` first (those present), then the others in their order."""
        import numpy as np
        import pyarrow as pa

        if self._tables:
            t = pa.concat_tables(self._tables, promote_options="permissive")
        elif schema is not None:
            t = schema.empty_table()
        else:
            t = pa.table({k: pa.array([], pa.int64()) for k in self.key})
        pos = np.array([order.get(k, -1) for k in self._keys(t)], dtype=np.int64)
        first = np.zeros(len(pos), dtype=bool)
        if len(pos):
            _, idx = np.unique(pos, return_index=True)
            first[idx] = True
        keep = np.flatnonzero((pos >= 0) & first)
        keep = keep[np.argsort(pos[keep], kind="stable")]
        t = t.take(pa.array(keep, pa.int64()))
        if schema is not None:
            t = t.select(schema.names).cast(schema)
        elif lead:
            first = [c for c in lead if c in t.column_names]
            t = t.select(first + [c for c in t.column_names if c not in first])
        self._write(self.out, parquet_bytes(t))
        return t
