"""``--set key=value`` overrides applied to a scenario's TOML table before validation.

Keys are dotted paths with optional list indices: ``traffic.count``, ``sensor.sigma``,
``aircraft[1].speed``, ``resolver.params.gain``. Values are parsed as TOML
(``64``, ``1.5``, ``true``, ``[0, 1000]``, ``"text"``, ``{a = 1}``); anything that is not a
TOML value is taken as a string (``sensor.kind=radar``). Missing tables on the way are
created. Type and range checks happen afterwards, in the loader, which reports a bad value as
``--set traffic.count: expected ...``.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Iterable
from typing import Any

from airspace_sim.errors import UserError

_SEGMENT = re.compile(r"([A-Za-z_][A-Za-z0-9_\-]*)((?:\[\d+\])*)$")


def parse_key(key: str) -> list[str | int]:
    """``"aircraft[1].speed"`` → ``["aircraft", 1, "speed"]``; :class:`UserError` if malformed."""
    parts: list[str | int] = []
    if not key:
        raise UserError("--set: empty key (expected key=value, e.g. traffic.count=64)")
    for segment in key.split("."):
        m = _SEGMENT.match(segment)
        if not m:
            raise UserError(
                f"--set {key}: malformed key (expected e.g. traffic.count or aircraft[0].speed)"
            )
        parts.append(m.group(1))
        parts.extend(int(i) for i in re.findall(r"\[(\d+)\]", m.group(2)))
    return parts


def format_key(parts: list[str | int]) -> str:
    """Inverse of :func:`parse_key`."""
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else p)
    return out


def parse_value(text: str) -> Any:
    """A TOML value if ``text`` is one, else the text itself (stripped)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text.strip()


def parse(item: str) -> tuple[list[str | int], Any]:
    """``"traffic.count=64"`` → ``(["traffic", "count"], 64)``."""
    if "=" not in item:
        raise UserError(f"--set {item}: expected key=value, e.g. traffic.count=64")
    key, _, value = item.partition("=")
    parts = parse_key(key.strip())
    try:
        return parts, parse_value(value)
    except RecursionError:
        raise UserError(f"--set {key.strip()}: value nested too deeply") from None


def apply_overrides(data: dict, overrides: Iterable[str]) -> list[str]:
    """Apply ``overrides`` to ``data`` in place.

    Returns the normalised dotted keys that were set, and those of tables the overrides
    created on the way (so that an error about them is reported as ``--set``).
    """
    if isinstance(overrides, str):
        overrides = [overrides]
    done: list[str] = []
    for item in overrides:
        parts, value = parse(item)
        done.extend(_assign(data, parts, value))
        done.append(format_key(parts))
    return done


def _assign(data: dict, parts: list[str | int], value: Any) -> list[str]:
    created = []
    node: Any = data
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        if isinstance(part, int):
            if not isinstance(node, list):
                raise UserError(f"--set {format_key(parts)}: {format_key(parts[:i])} is not a list")
            if part >= len(node):
                raise UserError(
                    f"--set {format_key(parts)}: index {part} out of range "
                    f"({format_key(parts[:i])} has {len(node)} entries)"
                )
        elif not isinstance(node, dict):
            raise UserError(f"--set {format_key(parts)}: {format_key(parts[:i])} is not a table")
        if last:
            node[part] = value
            return created
        if isinstance(node, dict) and part not in node:
            node[part] = [] if isinstance(parts[i + 1], int) else {}
            created.append(format_key(parts[: i + 1]))
        node = node[part]
