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


def parent_pid(pid: int) -> int:
    """The parent of ``pid`` (0 if it is gone); ``/proc/<pid>/stat``'s 4th field, read after
    the command name, which may hold spaces."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return 0
    return int(stat.rsplit(")", 1)[1].split()[1])


def descends_from(pid: int, root: int) -> bool:
    """Is ``root`` an ancestor of ``pid``?"""
    while pid > 1:
        pid = parent_pid(pid)
        if pid == root:
            return True
    return False
