"""Argument types shared by the CLI commands (``type=`` of :meth:`argparse.ArgumentParser.add_argument`).

Each raises :class:`argparse.ArgumentTypeError`, so argparse prints one line naming the
option and the value, and exits 2.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path


def _int(text: str, what: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None


def positive_int(text: str) -> int:
    """An integer ≥ 1."""
    value = _int(text, "a positive integer")
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def non_negative_int(text: str) -> int:
    """An integer ≥ 0."""
    value = _int(text, "a non-negative integer")
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer, got {value}")
    return value


def positive_float(text: str) -> float:
    """A finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


#: Largest seed: seeds are stored as int64 (parquet columns, numpy seed sequences).
MAX_SEED = 2**63 - 1
#: Frame limits: a 100000x100000 frame is 40 GB of pixels, and pygame dies out of memory.
MAX_FRAME_SIDE = 8192
MAX_FRAME_PIXELS = 4096 * 4096  #: 64 MiB per RGBA surface
MAX_FPS = 1000.0


def seed(text: str) -> int:
    """A seed: an integer in ``[0, 2**63 - 1]``."""
    value = _int(text, "a seed (an integer from 0 to 2**63-1)")
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(
            f"expected a seed from 0 to 2**63-1 = {MAX_SEED}, got {value}"
        )
    return value


def fps(text: str) -> float:
    """Frames per second of a video: a number in ``(0, MAX_FPS]``."""
    value = positive_float(text)
    if value > MAX_FPS:
        raise argparse.ArgumentTypeError(
            f"expected at most {MAX_FPS:g} frames per second, got {text!r}"
        )
    return value


def frame_size(text: str) -> tuple[int, int]:
    """``WIDTHxHEIGHT`` in pixels: ``(width, height)``, each side from 64 to
    :data:`MAX_FRAME_SIDE` and at most :data:`MAX_FRAME_PIXELS` in all."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected WIDTHxHEIGHT in pixels, e.g. 800x800, got {text!r}"
        ) from None
    if w < 64 or h < 64:
        raise argparse.ArgumentTypeError(f"expected at least 64x64 pixels, got {text!r}")
    if w > MAX_FRAME_SIDE or h > MAX_FRAME_SIDE or w * h > MAX_FRAME_PIXELS:
        raise argparse.ArgumentTypeError(
            f"expected at most {MAX_FRAME_SIDE} pixels a side and {MAX_FRAME_PIXELS} in all "
            f"(e.g. 4096x4096), got {text!r}"
        )
    return w, h


def check_output(option: str, path, *, folder: bool = False) -> Path:
    """Check, before any work, that ``path`` (a file, or with ``folder`` a folder) can be
    written: its folder is created if missing and a probe file is written and removed there.
    Returns ``path`` as a :class:`Path`; :class:`~airspace_sim.errors.UserError`
    ``"<option> <path>: ..."`` (one line) if not, so a long run never ends in a failed write.
    """
    import errno
    import tempfile

    from airspace_sim.errors import UserError

    path = Path(path)
    if folder and path.exists() and not path.is_dir():
        raise UserError(f"{option} {path}: exists and is not a folder")
    if not folder and path.is_dir():
        raise UserError(f"{option} {path}: is a folder, expected a file path")

    def why(exc: OSError) -> str:
        return {
            errno.ENOSPC: "disk full",
            errno.EROFS: "read-only file system",
            errno.EACCES: "permission denied",
            errno.ENOTDIR: "a part of the path is a file",
            errno.EEXIST: "a part of the path is a file",
        }.get(exc.errno, exc.strerror or type(exc).__name__)

    where = path if folder else path.parent
    try:
        where.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"{option} {path}: cannot create folder {where}: {why(exc)}") from None
    try:
        with tempfile.TemporaryFile(dir=where) as probe:
            probe.write(b"x")
            probe.flush()
            os.fsync(probe.fileno())
    except OSError as exc:
        raise UserError(f"{option} {path}: cannot write into {where}: {why(exc)}") from None
    return path


def add_set_option(parser, what: str = "") -> None:
    """``--set KEY=VALUE`` (repeatable, the value parsed as TOML) into ``args.overrides``:
    the scenario override every command that loads a scenario takes. ``what``: where it
    applies, appended to the help (e.g. "in every run")."""
    where = f" {what}" if what else ""
    parser.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"override a scenario key{where}, e.g. --set traffic.count=64 "
        "(repeatable; the value is parsed as TOML)",
    )
