"""In-process A/B of the band search's two kernels on the arguments of real world steps.

    PYTHONPATH=<tree> python docs/benchmarks/band_kernels_ab.py capture ARGS.pkl
    PYTHONPATH=<tree> python docs/benchmarks/band_kernels_ab.py time ARGS.pkl \\
        base=<tree A>/airspace_sim/avoidance/cpa.py new=<tree B>/airspace_sim/avoidance/cpa.py

``capture`` steps ``random_scenario(1000, seed=0)`` and pickles the arguments and outputs
of ``cpa.band_rows`` and ``heading.boundary_roots_in_window`` at steps 12–20 (the first
steps with conflicts are 6–11). ``time`` executes each named ``cpa.py`` (its
``band_rows``) or ``heading.py`` (its ``boundary_roots_in_window``) as a module of its
own with numba's ``cache=True`` turned off (so the files of two trees coexist in one
process; ``cpa.py`` imports only numpy and numba), checks that every output equals the
captured one bit for bit, then times them interleaved: 15 rounds over the captured
steps, CPU ms per step (``time.process_time``), min and median. For ``cpa.py`` also
without the best blocked scans (``wanted`` all False). Run it from outside the trees
(``python -c`` and scripts put their own directory first on ``sys.path``).
"""

from __future__ import annotations

import pickle
import sys
import time
import types

import numpy as np


def capture(path: str) -> None:
    """Pickle the two kernels' arguments and outputs at steps 12–20 into ``path``."""
    from airspace_sim.avoidance import bands
    from airspace_sim.world import World
    from airspace_sim.world.benchmark import random_scenario

    caps, cur = [], {}
    kernels = {"win": bands.boundary_roots_in_window, "rows": bands.band_rows}

    def wrap(key):
        def f(*args):
            cur[key] = [np.copy(a) if isinstance(a, np.ndarray) else a for a in args]
            cur[key + "_out"] = kernels[key](*args)
            return cur[key + "_out"]

        return f

    bands.boundary_roots_in_window, bands.band_rows = wrap("win"), wrap("rows")
    world = World(random_scenario(1000, trackers=True, seed=0), seed=0)
    for step in range(21):
        cur.clear()
        world.step()
        if step >= 12 and "rows" in cur:
            caps.append(dict(cur, step=step))
    with open(path, "wb") as fh:
        pickle.dump(caps, fh)
    print(f"{len(caps)} steps into {path}")


def _load(path: str, name: str):
    """The module at ``path`` executed as ``name`` with numba's on-disk cache off."""
    src = open(path).read().replace("cache=True", "cache=False")
    mod = types.ModuleType(name)
    mod.__file__ = path
    sys.modules[name] = mod
    exec(compile(src, path, "exec"), mod.__dict__)
    return mod


def _window_args(fn, cap) -> list:
    """A capture's ``boundary_roots_in_window`` arguments for ``fn``: up to commit d7a5a91
    the kernel took the intruder velocity ``vi``, since then the relative velocity ``v``
    (it adds ``vo`` itself); either is made from ``band_rows``' ``v`` and ``vo`` with the
    addition the older glue made (``v + vo[:, None, :]``, the same bits), so captures and
    kernels of either tree mix."""
    args = list(cap["win"])
    vo, v = cap["rows"][0], cap["rows"][2]
    relative = fn.py_func.__code__.co_varnames[2] == "v"
    args[2] = v if relative else np.ascontiguousarray(v + vo[:, None, :])
    return args


def _same(got, want) -> bool:
    return all(np.array_equal(g, w, equal_nan=True) for g, w in zip(got, want))


def time_kernels(path: str, specs: list[str], rounds: int = 15) -> None:
    """Check and time the named files' kernel on the captured steps (see the module doc)."""
    with open(path, "rb") as fh:
        caps = pickle.load(fh)
    runs = {}
    for spec in specs:
        name, file = spec.split("=", 1)
        mod = _load(file, "ab_" + name)
        if hasattr(mod, "band_rows"):
            runs[name] = (mod.band_rows, "rows")
            off = []
            for c in caps:
                args = list(c["rows"])
                args[12] = np.zeros_like(args[12])
                off.append(args)
            runs[name + " (no best blocked)"] = (mod.band_rows, off)
        else:
            fn = mod.boundary_roots_in_window
            runs[name] = (fn, [_window_args(fn, c) for c in caps])
            for c, args in zip(caps, runs[name][1]):
                if not _same(fn(*args), c["win_out"]):
                    raise SystemExit(f"{name}: output differs at step {c['step']}")
    for label, (fn, key) in runs.items():
        if isinstance(key, str):
            for c in caps:
                if not _same(fn(*c[key]), c[key + "_out"]):
                    raise SystemExit(f"{label}: output differs at step {c['step']}")
    times = {label: [] for label in runs}
    for _ in range(rounds):
        for label, (fn, key) in runs.items():
            arg_sets = [c[key] for c in caps] if isinstance(key, str) else key
            total = 0.0
            for args in arg_sets:
                t0 = time.process_time()
                fn(*args)
                total += time.process_time() - t0
            times[label].append(total / len(arg_sets) * 1e3)
    for label, t in times.items():
        print(f"{label:32s} min {np.min(t):6.2f}  median {np.median(t):6.2f}  ms CPU per step")


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "capture":
        capture(sys.argv[2])
    elif len(sys.argv) >= 4 and sys.argv[1] == "time":
        time_kernels(sys.argv[2], sys.argv[3:])
    else:
        raise SystemExit(__doc__)
