"""The one run engine of campaigns and sweeps: units of work -> backend -> parts on disk.

A unit is a name (its part file), the number of runs in it (for the progress bar) and the
arguments of a top-level function returning the unit's rows as a dict of columns. The
engine hands the units to a backend (:mod:`.backends`), saves each result as it arrives
(:class:`~airspace_sim.experiments.store.PartStore`, which drops run keys it already has),
and shows a tqdm bar. Which worker ran what, and in which order, changes nothing on disk but
the part names: the final table is sorted by run key.

SIGTERM is handled like Ctrl-C while the engine runs (the backend stops its workers, the
parts saved so far stay), so ``kill`` and ``kill -INT`` leave the same resumable state as
``kill -9``.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class Unit:
    """One unit of work: ``fn(*args)`` gives ``runs`` rows, saved as ``part-<name>``."""

    name: str
    runs: int
    args: tuple


@contextlib.contextmanager
def _sigterm_interrupts():
    """Turn SIGTERM into KeyboardInterrupt while inside (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def execute(
    store,
    units: Sequence[Unit],
    fn: Callable,
    backend,
    to_table: Callable,
    desc: str = "runs",
    unit: str = "run",
    progress: bool = True,
) -> int:
    """Run ``units`` on ``backend`` and save each result in ``store``; return the number of
    new rows. ``to_table(result)`` turns a result into a pyarrow Table."""
    from tqdm import tqdm

    total = sum(u.runs for u in units)
    bar = tqdm(
        total=total,
        desc=desc,
        unit=unit,
        disable=not progress or total == 0,
        file=sys.stderr,
        smoothing=0.1,
    )
    new = 0
    try:
        with _sigterm_interrupts(), backend:
            for i, result in backend.imap(fn, [u.args for u in units]):
                new += store.save(units[i].name, to_table(result))
                bar.update(units[i].runs)
    finally:
        bar.close()
    return new
