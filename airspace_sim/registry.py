"""One registry of named parts: autopilots, sensors, trackers and resolvers.

Built-in parts register themselves with :func:`register`. Extra parts are loaded the way a
third party would ship them, by :func:`load_plugins`:

- the entry-point group ``airspace_sim.plugins``: each entry point names a module (or a
  callable taking no argument) whose import registers its parts;
- a plugins folder: every ``*.py`` file in the folders listed in the environment variable
  ``AIRSPACE_SIM_PLUGINS`` (``os.pathsep``-separated) and in ``./plugins`` is imported.

The shipped plugins ``kalman`` and ``mvp`` (the files in the repository's ``plugins/``
folder, installed as the package ``airspace_sim_plugins``) are entry points of this
package's own distribution, so an installed airspace-sim finds them from any folder; a
plugins-folder file that is one of them (the repository's ``./plugins``) is not imported a
second time.

Every part is a class fitting its protocol in :mod:`airspace_sim.parts`, checked when it is
registered; parts are constructed only by :func:`build`. The registry is per process but
holds only classes, never simulation state, so several worlds in one process do not
interfere. A plugin that fails to import or to register (even by ``sys.exit``) is one
:class:`UserError` line naming it, raised by every later lookup too: the registry is
incomplete, and whatever asks (each scenario of ``run --list``) is told why.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import inspect
import os
import sys
from collections.abc import Callable
from pathlib import Path

from airspace_sim.errors import UserError

KINDS = ("autopilot", "sensor", "tracker", "resolver")
ENTRY_POINT_GROUP = "airspace_sim.plugins"

_REGISTRY: dict[str, dict[str, type]] = {kind: {} for kind in KINDS}
#: False until the built-ins and plugins are loaded, then True, or the :class:`UserError`
#: of the plugin that failed (raised again by every lookup).
_loaded_plugins: bool | UserError = False


def register(kind: str, name: str, *, replace: bool = False) -> Callable[[type], type]:
    """Class decorator: register ``cls`` as the part ``name`` of ``kind``.

    The class is checked against its protocol (:func:`airspace_sim.parts.check`) now, and
    refused with a one-line :class:`UserError` naming it (name, module, file) and what is
    missing if it does not fit, or if ``name`` is already registered (built-in or plugin)
    and ``replace`` is not True. Registering the very same class again is a no-op (a module
    imported twice).
    """
    from airspace_sim import parts

    if kind not in _REGISTRY:
        raise ValueError(f"unknown part kind {kind!r}; kinds are {', '.join(KINDS)}")

    def deco(cls: type) -> type:
        parts.check(kind, cls, name)
        old = _REGISTRY[kind].get(name)
        if old is not None and old is not cls and not _same(old, cls) and not replace:
            raise UserError(
                f"{kind} {name!r} ({parts.origin(cls)}): would replace the registered "
                f"{kind} {name!r} ({parts.origin(old)}); register it under another name or "
                f"with register({kind!r}, {name!r}, replace=True)"
            )
        _REGISTRY[kind][name] = cls
        return cls

    return deco


def _same(a, b) -> bool:
    """The same class defined twice by re-running its module (same module and name)."""
    return (getattr(a, "__module__", None), getattr(a, "__qualname__", None)) == (
        getattr(b, "__module__", None),
        getattr(b, "__qualname__", None),
    )


def names(kind: str) -> list[str]:
    """Sorted names registered for ``kind`` (after loading built-ins and plugins)."""
    _ensure_loaded()
    return sorted(_REGISTRY[kind])


def get(kind: str, name: str) -> type:
    """The class registered as ``name`` of ``kind``; a :class:`UserError` if unknown."""
    _ensure_loaded()
    try:
        return _REGISTRY[kind][name]
    except KeyError:
        known = ", ".join(sorted(_REGISTRY[kind])) or "none"
        raise UserError(f"unknown {kind} {name!r} (known: {known})") from None


def params_class(kind: str, name: str) -> type:
    """The ``Params`` dataclass of part ``name`` of ``kind`` (``NoParams`` if it has none)."""
    from airspace_sim.parts import NoParams

    return getattr(get(kind, name), "Params", NoParams)


def build(kind: str, name: str, *args, params=None):
    """Construct part ``name`` of ``kind``: ``cls(*args, params)``, the one way parts are made.

    ``params`` is a ready ``Params`` instance, a dict already validated against it
    (:func:`airspace_sim.scenarios.loader.validate_params`; turned into ``Params(**dict)``
    with no further checks) or None (the defaults). ``args`` are the kind's other
    constructor arguments (:data:`airspace_sim.parts.CONSTRUCTOR_ARGS`).
    """
    cls = get(kind, name)
    Params = params_class(kind, name)
    if params is None:
        params = Params()
    elif isinstance(params, dict):
        params = Params(**params)
    return cls(*args, params)


def _ensure_loaded() -> None:
    global _loaded_plugins
    if isinstance(_loaded_plugins, UserError):
        raise UserError(str(_loaded_plugins))
    if _loaded_plugins:
        return
    _loaded_plugins = True
    _import_builtins()
    try:
        load_plugins()
    except UserError as exc:
        _loaded_plugins = exc
        raise


def _import_builtins() -> None:
    # Importing these modules runs their @register decorators.
    for mod in (
        "airspace_sim.avoidance.resolvers",
        "airspace_sim.avoidance.roundabout",
        "airspace_sim.avoidance.mode_bands",
        "airspace_sim.avoidance.turn_bands",
        "airspace_sim.avoidance.flown_bands",
        "airspace_sim.avoidance.speed_bands",
        "airspace_sim.avoidance.paired_bands",
        "airspace_sim.avoidance.intent_bands",
        "airspace_sim.world.autopilots",
        "airspace_sim.recorded.autopilot",
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
    files = set()  # of entry-point modules: a plugins-folder copy of one is skipped
    for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        try:
            obj = ep.load()
            if callable(obj) and not inspect.isclass(obj):
                obj()
        except UserError:
            raise  # a part refused at registration: the message names it and its file
        except (Exception, SystemExit) as exc:
            dist = getattr(getattr(ep, "dist", None), "name", None)
            where = f"entry point {ep.name} = {ep.value}" + (
                f" (distribution {dist})" if dist else ""
            )
            raise UserError(f"plugin {where}: failed to load: {_one_line(exc)}") from exc
        module_file = getattr(sys.modules.get(ep.module), "__file__", None)
        if module_file:
            files.add(Path(module_file).resolve())
        loaded.append(f"entry point {ep.name}")
    seen = set(files)
    # the same plugin installed (site-packages) and in a checkout's plugins/ folder: the
    # folder's identical copy is the one already loaded; an edited copy is still refused
    installed = {f.read_bytes() for f in files if f.is_file()}
    for folder in plugin_folders():
        if not folder.is_dir():
            continue
        for path in sorted(folder.glob("*.py")):
            key = path.resolve()
            if key in seen or path.name.startswith("_") or path.read_bytes() in installed:
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
            except UserError:
                del sys.modules[mod_name]
                raise  # a part refused at registration: the message names it and its file
            except (Exception, SystemExit) as exc:
                del sys.modules[mod_name]
                raise UserError(f"plugin {path}: failed to load: {_one_line(exc)}") from exc
            loaded.append(str(path))
    return loaded


def _one_line(exc: BaseException) -> str:
    """``"ErrorType: message"`` on one line."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__
