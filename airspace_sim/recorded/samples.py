"""The OpenSky samples shipped in the ``traffic`` wheel, found at run time, never copied here.

``traffic`` 2.8.1 ships real OpenSky trajectories under ``traffic/data/samples/``:
flight-inspection (``calibration/*.json.gz``, full of turns), and collections
(``collections/switzerland.json.gz``: ~1200 flights over Switzerland on 1 Aug 2018, 10 s
sampling; ``collections/savan.json.gz``: one calibration aircraft over a month, 1 s).
OpenSky's terms restrict redistributing them, so this module reads them from wherever the
user has them: an installed ``traffic`` package, or the wheel itself (read as a zip; none of
``traffic``'s dependencies are needed), downloaded with

    pip download traffic==2.8.1 --no-deps -d DIR

and found through the ``AIRSPACE_SIM_TRAFFIC_WHEEL`` environment variable (the wheel file or
its directory), ``wheel=`` arguments, or in ``~/.cache/airspace_sim/``. :func:`path`
extracts a sample to a cache directory (``traffic-2.8.1-samples`` under
``AIRSPACE_SIM_CACHE``, default ``~/.cache/airspace_sim``) and returns it,
so that :func:`airspace_sim.recorded.read` and the CLI read it like any file.

    from airspace_sim.recorded import read, samples
    flights = read(samples.path("collections/switzerland"))
    samples.names()        # ['calibration/ajaccio', ..., 'collections/switzerland', ...]
"""

from __future__ import annotations

import importlib.util
import os
import zipfile
from pathlib import Path

from airspace_sim.errors import UserError

VERSION = "2.8.1"
PREFIX = "traffic/data/samples/"
HOW = (
    f"run `pip download traffic=={VERSION} --no-deps -d ~/.cache/airspace_sim` (or -d DIR "
    "and set AIRSPACE_SIM_TRAFFIC_WHEEL=DIR), or install traffic"
)


def _installed_dir() -> Path | None:
    spec = importlib.util.find_spec("traffic")
    if spec is None or not spec.submodule_search_locations:
        return None
    d = Path(list(spec.submodule_search_locations)[0]) / "data" / "samples"
    return d if d.is_dir() else None


def find_wheel(wheel: str | os.PathLike | None = None) -> Path | None:
    """The traffic wheel: ``wheel`` (a file or a directory holding it), else the
    ``AIRSPACE_SIM_TRAFFIC_WHEEL`` variable, else the cache's parent directory
    (``~/.cache/airspace_sim``); None if none holds one."""
    where = wheel if wheel is not None else os.environ.get("AIRSPACE_SIM_TRAFFIC_WHEEL")
    if not where:
        where = _cache_dir().parent  # where HOW suggests downloading it
    p = Path(where).expanduser()
    if p.is_dir():
        found = sorted(p.glob(f"traffic-{VERSION}-*.whl")) or sorted(p.glob("traffic-*.whl"))
        return found[-1] if found else None
    return p if p.is_file() else None


def names(wheel=None) -> list[str]:
    """Available samples as ``"folder/name"`` (without ``.json.gz``); empty if none found."""
    d = _installed_dir()
    if d is not None:
        return sorted(str(p.relative_to(d))[: -len(".json.gz")] for p in d.glob("**/*.json.gz"))
    w = find_wheel(wheel)
    if w is None:
        return []
    with zipfile.ZipFile(w) as z:
        return sorted(
            n[len(PREFIX) : -len(".json.gz")]
            for n in z.namelist()
            if n.startswith(PREFIX) and n.endswith(".json.gz")
        )


def available(wheel=None) -> bool:
    """Are the samples installed or in a findable wheel?"""
    return bool(names(wheel))


def _cache_dir() -> Path:
    env = os.environ.get("AIRSPACE_SIM_CACHE")
    base = Path(env).expanduser() if env else Path.home() / ".cache" / "airspace_sim"
    return base / f"traffic-{VERSION}-samples"


def path(name: str, wheel=None) -> Path:
    """A readable file of sample ``name`` (``"collections/switzerland"``, or just
    ``"switzerland"`` when unambiguous): the installed file, or the wheel's member
    extracted once to the cache directory. A one-line UserError if it cannot be found."""
    name = name.removesuffix(".json.gz")
    d = _installed_dir()
    known = names(wheel)
    if not known:
        raise UserError(f"traffic samples not found: {HOW}")
    matches = [n for n in known if n == name or n.split("/")[-1] == name]
    if len(matches) != 1:
        what = "ambiguous" if matches else "unknown"
        raise UserError(
            f"traffic sample {name!r}: {what} (e.g. {', '.join(known[:3])}, ... "
            f"{len(known)} in all)"
        )
    rel = matches[0] + ".json.gz"
    if d is not None:
        return d / rel
    out = _cache_dir() / rel
    if not out.is_file():
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(".part")
        with zipfile.ZipFile(find_wheel(wheel)) as z:
            tmp.write_bytes(z.read(PREFIX + rel))
        tmp.replace(out)
    return out
