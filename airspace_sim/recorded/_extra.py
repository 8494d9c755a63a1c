"""The ``real`` extra's modules (pandas, pyproj), imported when a recording is read."""

from __future__ import annotations

import importlib

from airspace_sim.errors import UserError


def require(module: str):
    """``module`` imported, or a one-line :class:`UserError` saying how to install it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise UserError(
            f"reading recorded traffic needs {module}: pip install 'airspace-sim[real]'"
        ) from None
