"""Checks of what a user hands the env (constructor arguments, seeds, reset options), with
Gymnasium's error conventions where Gymnasium has them.

Every error here is a one-line :class:`~airspace_sim.errors.UserError` (so the CLI prints
it and exits 2); the seed, action and order errors are also the exception Gymnasium raises
for the same mistake, so code written against Gymnasium catches them:

- seeds: :class:`SeedError` is a ``gymnasium.error.Error``, raised where
  ``gymnasium.utils.seeding.np_random`` raises it (not an integer, negative) and with its
  wording; Python and NumPy integers are accepted (bools are not), up to 2⁶³ - 1 (the
  world's seed range);
- actions: :class:`ActionError` is a ``gymnasium.error.InvalidAction``;
- ``step()`` before ``reset()``: :class:`ResetNeeded` is a ``gymnasium.error.ResetNeeded``,
  as Gymnasium's ``OrderEnforcing`` wrapper raises it;
- other arguments: a ``UserError`` (a ``ValueError``); an unknown keyword argument stays
  Python's ``TypeError``, as ``gymnasium.make`` lets it be.
"""

from __future__ import annotations

import math
import numbers

import gymnasium.error

from airspace_sim.errors import UserError

MAX_SEED = 2**63 - 1  #: the world's seed range (counter-based streams are keyed on it)


class SeedError(UserError, gymnasium.error.Error):
    """A seed Gymnasium's ``seeding.np_random`` (or the world's range) rejects."""


class ActionError(UserError, gymnasium.error.InvalidAction):
    """A malformed action or action dict."""


class ResetNeeded(UserError, gymnasium.error.ResetNeeded):
    """``step()`` (or ``state()``) called before ``reset()``."""


def _is_int(value) -> bool:
    return (
        isinstance(value, numbers.Integral)
        and not isinstance(value, bool)
        and (type(value).__name__ != "bool_")
    )


def seed(value, where: str = "seed") -> int | None:
    """``value`` as a world seed (None stays None); :class:`SeedError` as Gymnasium words it."""
    if value is None:
        return None
    if not _is_int(value):
        raise SeedError(f"{where}: Seed must be a python integer, actual type: {type(value)}")
    value = int(value)
    if value < 0:
        raise SeedError(f"{where}: Seed must be greater or equal to zero, actual value: {value}")
    if value > MAX_SEED:
        raise SeedError(f"{where}: Seed must be at most 2**63 - 1, actual value: {value}")
    return value


def integer(value, where: str, lo: int, hi: int | None = None) -> int:
    """An integer in ``[lo, hi]`` (Python or NumPy; not a bool, not a float such as 1.5)."""
    span = f"≥ {lo}" if hi is None else f"in {lo}..{hi}"
    if not _is_int(value) or int(value) < lo or (hi is not None and int(value) > hi):
        raise UserError(f"{where}: expected an integer {span}, got {value!r}")
    return int(value)


def positive_number(value, where: str) -> float:
    """A finite positive real number (not a bool, NaN or inf)."""
    ok = isinstance(value, numbers.Real) and not isinstance(value, bool)
    if not ok or not math.isfinite(float(value)) or float(value) <= 0:
        raise UserError(f"{where}: expected a finite positive number, got {value!r}")
    return float(value)


def flag(value, where: str) -> bool:
    """True or False (Python or NumPy bool)."""
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        return bool(value)
    raise UserError(f"{where}: expected True or False, got {value!r}")


def one_of(value, where: str, choices) -> str:
    if value not in choices:
        raise UserError(f"{where}: expected one of {', '.join(map(repr, choices))}, got {value!r}")
    return value
