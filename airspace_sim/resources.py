"""Memory a run may take, checked before it is allocated.

The track table grows with the pairs in sensor range, which no scenario file states: a
ring's aircraft all meet at its centre, a sector's random traffic meets a few neighbours.
So the check is made where the memory is asked for (:meth:`airspace_sim.tracking.SlotIMM`
growing its lanes), not by guessing a worst case when the scenario is loaded.
"""

from __future__ import annotations

import os

from airspace_sim.errors import UserError

#: Fraction of the machine's physical memory one allocation of the track table may bring
#: the table to.
MEMORY_FRACTION = 0.5


def physical_memory_bytes() -> int | None:
    """The machine's physical memory in bytes, or None where the OS does not say."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None


def check_allocation(what: str, nbytes: int, hint: str = "") -> None:
    """Raise a one-line :class:`UserError` if ``nbytes`` would exceed
    :data:`MEMORY_FRACTION` of physical memory; ``what`` names the allocation."""
    total = physical_memory_bytes()
    if total is None or nbytes <= MEMORY_FRACTION * total:
        return
    raise UserError(
        f"{what}: needs {nbytes / 2**30:.1f} GiB, more than {MEMORY_FRACTION:.0%} of this "
        f"machine's {total / 2**30:.1f} GiB{'; ' + hint if hint else ''}"
    )
