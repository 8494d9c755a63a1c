"""One registry of named parts: autopilots, sensors, trackers and resolvers.

Built-in parts register themselves with :func:`register`. Extra parts are loaded the way a
third party would ship them, by :func:`load_plugins`:

- the entry-point group ``airspace_sim.plugins``: each entry point names a module (or a
  callable taking no argument) whose import registers its parts;
- a plugins folder: every ``*.py`` file in the folders listed in the environment variable
  ``AIRSPACE_SIM_PLUGINS`` (``os.pathsep``-separated) and in ``./plugins`` is imported.

The registry is per process but holds only factories, never simulation state, so several
worlds in one process do not interfere.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import os
import sys
from collections.abc import Callable
from pathlib import Path

from airspace_sim.errors import UserError

KINDS = ("autopilot", "sensor", "tracker", "resolver")
ENTRY_POINT_GROUP = "airspace_sim.plugins"

_REGISTRY: dict[str, dict[str, Callable]] = {kind: {} for kind in KINDS}
_loaded_plugins = False


def register(kind: str, name: str) -> Callable[[Callable], Callable]:
    """Decorator: register ``factory`` as the part ``name`` of ``kind``."""
    if kind not in _REGISTRY:
        raise ValueError(f"unknown part kind {kind!r}; kinds are {', '.join(KINDS)}")

    def deco(factory: Callable) -> Callable:
        _REGISTRY[kind][name] = factory
        return factory

    return deco


def names(kind: str) -> list[str]:
    """Sorted names registered for ``kind`` (after loading built-ins and plugins)."""
    _ensure_loaded()
    return sorted(_REGISTRY[kind])


def get(kind: str, name: str) -> Callable:
    """The factory registered as ``name`` of ``kind``; a :class:`UserError` if unknown."""
    _ensure_loaded()
    try:
        return _REGISTRY[kind][name]
    except KeyError:
        known = ", ".join(sorted(_REGISTRY[kind])) or "none"
        raise UserError(f"unknown {kind} {name!r} (known: {known})") from None


def _ensure_loaded() -> None:
    global _loaded_plugins
    if _loaded_plugins:
        return
    _loaded_plugins = True
    _import_builtins()
    load_plugins()


def _import_builtins() -> None:
    # Importing these modules runs their @register decorators.
    for mod in (
        "airspace_sim.avoidance.resolvers",
        "airspace_sim.world.autopilots",
        "airspace_sim.world.sensors",
        "airspace_sim.world.trackers",
    ):
        if importlib.util.find_spec(mod) is not None:
            importlib.import_module(mod)


def plugin_folders() -> list[Path]:
    """Folders searched for ``*.py`` plugins, in order."""
    folders = [Path(p) for p in os.environ.get("AIRSPACE_SIM_PLUGINS", "").split(os.pathsep) if p]
    folders.append(Path.cwd() / "plugins")
    return folders


def load_plugins() -> list[str]:
    """Import entry-point plugins and plugin-folder files; return what was loaded."""
    loaded = []
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        try:
            obj = ep.load()
            if callable(obj):
                obj()
        except Exception as exc:
            dist = getattr(getattr(ep, "dist", None), "name", None)
            where = f"entry point {ep.name} = {ep.value}" + (
                f" (distribution {dist})" if dist else ""
            )
            raise UserError(f"plugin {where}: failed to load: {_one_line(exc)}") from exc
        loaded.append(f"entry point {ep.name}")
    seen = set()
    for folder in plugin_folders():
        if not folder.is_dir():
            continue
        for path in sorted(folder.glob("*.py")):
            key = path.resolve()
            if key in seen or path.name.startswith("_"):
                continue
            seen.add(key)
            mod_name = f"airspace_sim_plugin_{path.stem}"
            if mod_name in sys.modules:
                continue
            spec = importlib.util.spec_from_file_location(mod_name, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[mod_name] = module
            try:
                spec.loader.exec_module(module)
            except Exception as exc:
                del sys.modules[mod_name]
                raise UserError(f"plugin {path}: failed to load: {_one_line(exc)}") from exc
            loaded.append(str(path))
    return loaded


def _one_line(exc: BaseException) -> str:
    """``"ErrorType: message"`` on one line."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
