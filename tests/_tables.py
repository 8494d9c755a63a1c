"""Helpers shared by the campaign and sweep tests."""

from pathlib import Path


def same_rows(a, b) -> bool:
    """Tables equal value by value (NaN equal to NaN), same schema and row order."""
    assert a.schema == b.schema, (a.schema, b.schema)
    da, db = a.to_pydict(), b.to_pydict()
    for k in da:
        for x, y in zip(da[k], db[k], strict=True):
            assert x == y or (x != x and y != y), (k, x, y)
    return True


def pids_where(pred) -> list[int]:
    """Pids of the processes whose (``/proc/<pid>/stat`` text, cmdline bytes) satisfy ``pred``."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat, cmd = (d / "stat").read_text(), (d / "cmdline").read_bytes()
            except OSError:
                continue
            if pred(stat, cmd):
                out.append(int(d.name))
    return out
