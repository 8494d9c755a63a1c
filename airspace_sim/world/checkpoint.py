"""Checkpoints: a :class:`~airspace_sim.world.World` saved to a file and resumed bit for bit.

Format (version 4)::

    AIRSPACE-SIM CHECKPOINT\\n                  magic line
    format 4\\n                                 format version
    mac <64 hex digits>\\n                      HMAC-SHA256 over the next line and the payload
    {"meta": ..., "code": ..., "world_bytes": L}\\n     one JSON line (run metadata)
    <L bytes: pickle of the World>

Why an authenticated pickle and not a pickle-free format: a World holds pymunk bodies,
compiled IMM kernels' buffers and parts that plugins define (any class), and a resumed run
must step exactly as the uninterrupted one. Pickle captures all of that with no per-part
code; a hand-written format would need every part, including third-party ones, to
serialise itself, and each would be a place for resumed runs to drift. But unpickling runs
whatever the file says, so a file is unpickled only after its HMAC verifies under the
user's own secret key (:func:`key_path`, 32 random bytes in a file created with mode 0600):
a checkpoint this user's airspace-sim wrote. A file from another user or machine (another
key), or changed after it was written, is refused in one line before anything in it is
parsed beyond the size fields. Copy the key file along with checkpoints to resume them
elsewhere.

The header also records a fingerprint of the sources; resuming under other code warns (a
World pickled by other code may not load or may step differently). Every problem is one
:class:`~airspace_sim.errors.UserError` line naming the file.
"""

from __future__ import annotations

import errno
import functools
import hashlib
import hmac
import json
import os
import secrets
import stat
import sys
from pathlib import Path

from airspace_sim.errors import UserError

MAGIC = b"AIRSPACE-SIM CHECKPOINT\n"
#: Bumped whenever a saved World lacks state the code now needs, so that an old file is
#: refused in one line instead of resuming (with only a code warning) into a failure later.
#: 4: worlds hold ``World.retired`` (recorded traffic that left stays out); a format-3
#: world resumes, then fails on recorded traffic.
FORMAT = 4
#: Environment variable naming the key file (tests, or a key shared between machines).
KEY_ENV = "AIRSPACE_SIM_CHECKPOINT_KEY"
_KEY_BYTES = 32
_MAX_HEADER_BYTES = 1 << 20  # the JSON line holds metadata only


# --------------------------------------------------------------------------- the key


def key_path() -> Path:
    """The secret key file: ``$AIRSPACE_SIM_CHECKPOINT_KEY``, else
    ``$XDG_DATA_HOME/airspace_sim/checkpoint.key``, else
    ``~/.local/share/airspace_sim/checkpoint.key``."""
    if os.environ.get(KEY_ENV):
        return Path(os.environ[KEY_ENV])
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "airspace_sim" / "checkpoint.key"


def _read_key(path: Path) -> bytes:
    st = path.stat()
    if stat.S_IMODE(st.st_mode) & 0o077:
        raise UserError(
            f"checkpoint key {path}: readable by other users "
            f"(mode {stat.S_IMODE(st.st_mode):o}); run chmod 600 {path}"
        )
    key = bytes.fromhex(path.read_text().strip())
    if len(key) != _KEY_BYTES:
        raise ValueError(f"{len(key)} bytes, expected {_KEY_BYTES}")
    return key


def load_key(create: bool) -> bytes | None:
    """The user's checkpoint key; with ``create``, made (0600) if there is none yet;
    without, None if there is none. :class:`UserError` if it cannot be read or made."""
    path = key_path()
    try:
        return _read_key(path)
    except FileNotFoundError:
        if not create:
            return None
    except (OSError, ValueError) as exc:
        raise UserError(f"checkpoint key {path}: unreadable or damaged: {exc}") from None
    try:
        path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except FileExistsError:  # another run made it meanwhile
        return load_key(create=False)
    except OSError as exc:
        raise UserError(f"checkpoint key {path}: cannot create: {exc}") from None
    key = secrets.token_bytes(_KEY_BYTES)
    with os.fdopen(fd, "w") as f:
        f.write(key.hex() + "\n")
    return key


def _mac(key: bytes, header_line: bytes, blob: bytes) -> str:
    m = hmac.new(key, header_line, hashlib.sha256)
    m.update(blob)
    return m.hexdigest()


# --------------------------------------------------------------------------- saving


@functools.cache  # the sources do not change under a running process
def code_fingerprint() -> str:
    """SHA-256 (hex, 16 digits) of the ``airspace_sim`` package's Python sources.

    A checkpoint resumes bit-identically only under the code that wrote it; resuming under
    other code is allowed but warned about (:func:`load`).
    """
    import airspace_sim

    root = Path(airspace_sim.__file__).parent
    h = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        h.update(f.relative_to(root).as_posix().encode())
        h.update(b"\0")
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def is_checkpoint(path: Path) -> bool:
    """Whether ``path`` starts with the checkpoint magic line (contents not checked)."""
    try:
        with open(path, "rb") as f:
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return False


def _cannot_write(path: Path, exc: OSError) -> UserError:
    why = {
        errno.ENOSPC: "disk full",
        errno.EDQUOT: "disk quota exceeded",
        errno.EROFS: "read-only file system",
        errno.EACCES: "permission denied",
    }.get(exc.errno, exc.strerror or type(exc).__name__)
    return UserError(
        f"{path}: cannot write the checkpoint: {why} (the previous one, if any, is kept)"
    )


def save(path: Path, world, meta: dict) -> None:
    """Write ``world`` (pickled, authenticated) and ``meta`` (JSON-able dict) to ``path``.

    Atomic: written to ``<path>.tmp``, flushed to disk and renamed, so a kill, a full disk
    or a read-only folder leaves the previous checkpoint intact (and no ``.tmp``).
    """
    import pickle

    key = load_key(create=True)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _cannot_write(path, exc) from None
    blob = pickle.dumps(world, protocol=pickle.HIGHEST_PROTOCOL)
    header = {
        "meta": meta,
        "code": code_fingerprint(),
        "steps_taken": int(world.step_count),
        "world_bytes": len(blob),
    }
    header_line = json.dumps(header, separators=(",", ":")).encode() + b"\n"
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(MAGIC)
            f.write(f"format {FORMAT}\n".encode())
            f.write(f"mac {_mac(key, header_line, blob)}\n".encode())
            f.write(header_line)
            f.write(blob)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise _cannot_write(path, exc) from None
    except BaseException:  # a second Ctrl-C or SIGTERM mid-write: no debris
        tmp.unlink(missing_ok=True)
        raise


# --------------------------------------------------------------------------- loading


def _read(path: Path, f) -> tuple[str, bytes, dict, bytes]:
    """``(mac, header_line, header, blob)`` of an open checkpoint file, shapes checked."""

    def refuse(why: str):
        raise UserError(f"{path}: {why}")

    if f.read(len(MAGIC)) != MAGIC:
        refuse("not an airspace-sim checkpoint (no checkpoint header)")
    line = f.readline(64)
    words = line.split()
    if len(words) != 2 or words[0] != b"format" or not line.endswith(b"\n"):
        refuse("damaged checkpoint header (no format line)")
    if words[1] != str(FORMAT).encode():
        found = words[1].decode("ascii", "replace")
        age = ""
        if found.isdigit():
            age = "an older" if int(found) < FORMAT else "a newer"
            age = f" (written by {age} airspace-sim: rerun the scenario to make a new one)"
        refuse(f"checkpoint format {found}, this airspace-sim reads format {FORMAT}{age}")
    line = f.readline(80)
    words = line.split()
    if len(words) != 2 or words[0] != b"mac" or len(words[1]) != 64:
        refuse("damaged checkpoint header (no mac line)")
    mac = words[1].decode("ascii", "replace")
    header_line = f.readline(_MAX_HEADER_BYTES)
    try:
        header = json.loads(header_line) if header_line.endswith(b"\n") else None
    except ValueError:
        header = None
    required = {"meta": dict, "code": str, "world_bytes": int}
    if not isinstance(header, dict) or any(
        not isinstance(header.get(k), t) for k, t in required.items()
    ):
        refuse("damaged checkpoint header")
    blob = f.read(header["world_bytes"] + 1)
    if len(blob) != header["world_bytes"]:
        refuse(
            f"truncated or damaged checkpoint "
            f"({len(blob)} bytes of world data, expected {header['world_bytes']})"
        )
    return mac, header_line, header, blob


def load(path: Path):
    """``(world, meta)`` saved in ``path`` by :func:`save`.

    Raises :class:`UserError` (one line naming ``path``) for a missing file, one that is not
    a readable checkpoint, or one whose HMAC does not verify under the user's key; unpickles
    only after it verifies.
    """
    import pickle

    from airspace_sim import registry
    from airspace_sim.world import World

    try:
        with open(path, "rb") as f:
            mac, header_line, header, blob = _read(path, f)
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise UserError(f"{path}: is a folder, not a checkpoint") from None
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc}") from None
    key = load_key(create=False)
    if key is None or not hmac.compare_digest(mac, _mac(key, header_line, blob)):
        raise UserError(
            f"{path}: refused: not signed with this user's checkpoint key ({key_path()}); "
            "it was written under another key or modified since"
        )
    meta_types = {"scenario": str, "seed": int, "overrides": list, "total_steps": int}
    if any(not isinstance(header["meta"].get(k), t) for k, t in meta_types.items()):
        raise UserError(f"{path}: damaged checkpoint header (run metadata)")
    other_code = header["code"] != code_fingerprint()
    if other_code:
        print(
            f"airspace-sim: warning: {path} was saved by other airspace_sim code; the resumed "
            f"run may differ from an uninterrupted one",
            file=sys.stderr,
        )
    registry.names("tracker")  # plugins first: a pickled world may refer to plugin classes
    try:
        world = pickle.loads(blob)
    except Exception as exc:  # noqa: BLE001 - e.g. a class that other code renamed
        first = (str(exc).strip().splitlines() or [""])[0]
        raise UserError(
            f"{path}: cannot load the saved world"
            + (" (saved by other airspace_sim code)" if other_code else "")
            + f": {type(exc).__name__}: {first}"
        ) from None
    if not isinstance(world, World):
        raise UserError(f"{path}: holds a {type(world).__name__}, not a World")
    return world, header["meta"]
