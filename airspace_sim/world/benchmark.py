"""Steps per second of a world, and the synthetic scenarios used to measure it.

    from airspace_sim.world.benchmark import bench_world
    bench_world(100, steps=50, trackers=True)
    # {'n_aircraft': 100, 'steps': 50, 'trackers': True, 'steps_per_s': ..., ...}

The benchmark traffic (:func:`random_scenario`) keeps the density constant as N grows:
N aircraft uniform in a square of side ``10 km·√N`` (one aircraft per 100 km², a busy
terminal area), each flying a route across it at 230 m/s, sensor range 40 km (so each
aircraft has about 50 neighbours in range whatever N), σ = 50 m, 1 s steps, r_safe 3 km,
resolver ``bands`` (look-ahead 120 s). ``trackers=True`` tracks every intruder in range
with the IMM from noisy measurements; ``trackers=False`` uses tracker ``"truth"`` (perfect
surveillance, no filter), everything else identical.

:func:`ring_scenario` builds the converging ring (BlueSky's ``SYN SUPER``). Both are the
scenario generator's patterns (:mod:`airspace_sim.scenarios.traffic`) through the loader.
"""

from __future__ import annotations

import math
import time

import numpy as np

from airspace_sim.scenarios import Scenario, from_dict


def ring_scenario(
    n: int,
    r_safe: float = 3000.0,
    radius: float | None = None,
    speed: float = 230.0,
    dt: float = 1.0,
    tracker: str = "imm",
    resolver: str = "bands",
    lookahead: float = 120.0,
    margin: float = 0.1,
    sigma: float = 50.0,
    sensor_range: float = 40000.0,
    duration: float | None = None,
    seed: int = 0,
    overrides: tuple[str, ...] = (),
) -> Scenario:
    """``n`` aircraft evenly on a circle, all heading for the diametrically opposite point
    (the scenario generator's ``traffic.pattern = "ring"``, validated by the loader).

    ``radius`` defaults to the smallest ring on which neighbours start 10% more than
    2·r_safe apart (``1.1·r_safe / sin(π/n)``), but at least 20 km. ``duration`` defaults
    to the straight crossing time plus 300 s. Route autopilot, 3°/s turn limit, all avoid.
    ``overrides`` are ``--set KEY=VALUE`` strings applied on top (``traffic.speed_range=0.1``).
    """
    if radius is None:
        radius = max(1.1 * r_safe / math.sin(math.pi / n), 20000.0)
    if duration is None:
        duration = math.ceil(2.0 * radius / speed + 300.0)
    return from_dict(
        {
            "name": f"ring{n}",
            "description": f"{n} aircraft on a {radius / 1000:.1f} km ring",
            "seed": seed,
            "dt": dt,
            "duration": float(duration),
            "separation": {"r_safe": r_safe},
            "sensor": {"range": sensor_range, "sigma": sigma},
            "tracker": {"kind": tracker},
            "resolver": {"kind": resolver, "lookahead": lookahead, "margin": margin},
            "traffic": {"pattern": "ring", "count": n, "radius": radius, "speed": speed},
        },
        source=f"<ring_scenario({n})>",
        overrides=overrides,
    )


def random_scenario(
    n: int, trackers: bool = True, seed: int = 0, resolver: str = "bands", duration: float = 600.0
) -> Scenario:
    """The benchmark traffic (module docstring): ``n`` aircraft at constant density
    (``traffic.pattern = "random"`` in a sector of side ``10 km·√n``)."""
    return from_dict(
        {
            "name": f"random{n}",
            "seed": seed,
            "dt": 1.0,
            "duration": float(duration),
            "separation": {"r_safe": 3000.0},
            "sensor": {"range": 40000.0, "sigma": 50.0},
            "tracker": {"kind": "imm" if trackers else "truth"},
            "resolver": {"kind": resolver, "lookahead": 120.0},
            "traffic": {"pattern": "random", "count": n, "sector": 10000.0 * math.sqrt(n)},
        },
        source=f"<random_scenario({n})>",
    )


def bare_imm(
    preset, sigma: float, n_tracks: int, steps: int, seed: int = 0, kernel: str = "auto"
) -> dict:
    """Time the bare IMM step over ``n_tracks`` tracks: the world's ``"imm"`` tracker
    (:class:`~airspace_sim.world.trackers.ImmTracker`, ``preset`` at the world's dt, R = σ²I)
    with every slot live and measured, targets at 230 m/s flying straight, started by
    two-point initialisation. One untimed step (kernel compilation or cache load), then
    ``steps`` timed ones.

    Returns ``ms_per_step`` (median wall-clock time over the steps), ``cpu_ms_per_step``
    (median process CPU time, less affected by other processes on the machine),
    ``ms_mean``, ``n_tracks``, ``kernel``.
    """
    from airspace_sim.tracking.initialisation import two_point_initialisation
    from airspace_sim.world.trackers import ImmTracker

    tracker = ImmTracker(preset, sigma, ImmTracker.Params(kernel=kernel))
    rng = np.random.default_rng(seed)
    dt = float(preset.dt)
    p0 = rng.uniform(-1e5, 1e5, (n_tracks, 2))
    heading = rng.uniform(-math.pi, math.pi, n_tracks)
    v = 230.0 * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    R = sigma**2 * np.eye(2)

    def z_at(k):
        return p0 + v * (dt * k) + sigma * rng.standard_normal((n_tracks, 2))

    x0, P0 = two_point_initialisation(z_at(0), z_at(1), dt, R, omega_var=np.radians(3.0) ** 2)
    slots = tracker.birth(x0, P0)
    Z = np.full((tracker.capacity, 2), np.nan)
    times, cpu = [], []
    for k in range(2, steps + 3):
        Z[slots] = z_at(k)
        t0, c0 = time.perf_counter(), time.process_time()
        tracker.step(Z)
        cpu.append(time.process_time() - c0)
        times.append(time.perf_counter() - t0)
    times = np.array(times[1:])
    return {
        "ms_per_step": 1000.0 * float(np.median(times)),
        "cpu_ms_per_step": 1000.0 * float(np.median(cpu[1:])),
        "ms_mean": 1000.0 * float(times.mean()),
        "n_tracks": int(n_tracks),
        "kernel": tracker.imm.kernel,
    }


def _rss_bytes(field: str) -> int | None:
    """``VmRSS`` (now) or ``VmHWM`` (peak) of this process from ``/proc/self/status``, bytes
    (None where there is no such file)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _reset_peak_rss() -> bool:
    """Reset this process's peak RSS (Linux ≥ 4.0: ``5`` into ``/proc/self/clear_refs``),
    so that the next ``VmHWM`` is the peak since now. False where that is not possible."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


#: most untimed steps :func:`bench_world` adds to ``warmup`` while waiting for a conflict
MAX_EXTRA_WARMUP = 50


def _kernel_specialisations() -> int:
    """Compiled (or cache-loaded) numba specialisations in this process: the sum over
    every live numba dispatcher of its overloads. One more between two calls means a
    kernel was compiled or loaded in between."""
    import gc

    from numba.core.registry import CPUDispatcher

    return sum(len(o.overloads) for o in gc.get_objects() if isinstance(o, CPUDispatcher))


def bench_world(
    n_aircraft: int,
    steps: int = 50,
    trackers: bool = True,
    warmup: int = 5,
    seed: int = 0,
    compare_imm: bool = True,
) -> dict:
    """Time ``steps`` world steps of :func:`random_scenario` with ``n_aircraft`` aircraft.

    Returns a dict: ``n_aircraft``, ``steps``, ``trackers``, ``steps_per_s`` and
    ``seconds`` (after ``warmup_steps`` untimed steps: at least ``warmup``, and on until one
    step after the first with a conflict, at most :data:`MAX_EXTRA_WARMUP` more, so that
    the numba kernels are compiled or loaded before the timing),
    ``ms_per_step`` (median wall-clock time over the timed steps), ``cpu_ms_per_step``
    (median process CPU time), ``mean_tracks`` (average number of (ownship, intruder)
    tracks), ``setup_s``, ``warmup_steps``, ``kernels_loaded_timed`` (numba specialisations
    compiled or loaded during the timed steps: 0 unless a kernel first ran late); on Linux
    also ``peak_rss_mb`` (the process's peak resident memory
    while the world was built and stepped, MB) and ``bytes_per_track`` (that peak less the
    resident memory before, per mean track: everything the world holds, shared by its
    tracks). With trackers and ``compare_imm``, also ``imm`` (:func:`bare_imm`
    over ``round(mean_tracks)`` tracks of the world's tracker preset, timed right after, in
    this process), ``ratio`` (world ms per step over the bare IMM's, wall clock) and
    ``cpu_ratio`` (the same in CPU time).
    """
    import gc

    from airspace_sim.world import World

    gc.collect()
    peak_known = _reset_peak_rss()
    rss0 = _rss_bytes("VmRSS")
    t0 = time.perf_counter()
    sc = random_scenario(n_aircraft, trackers=trackers, seed=seed)
    world = World(sc, seed=seed)
    setup = time.perf_counter() - t0
    # the band-search kernels are first called (compiled, or loaded from numba's cache)
    # in the first step with a conflict, once tracks are confirmed: warm up until one step
    # after that one too, so that no timed step compiles or loads a kernel
    warm, until = 0, None
    while warm < warmup + MAX_EXTRA_WARMUP:
        if warm >= warmup and until is not None and warm >= until:
            break
        world.step()
        warm += 1
        if until is None and world.conflict.any():
            until = warm + 1
    loaded = _kernel_specialisations()
    tracks = 0
    per_step, cpu = [], []
    t0 = time.perf_counter()
    for _ in range(steps):
        t1, c1 = time.perf_counter(), time.process_time()
        world.step()
        cpu.append(time.process_time() - c1)
        per_step.append(time.perf_counter() - t1)
        tracks += len(world.tracks)
    elapsed = time.perf_counter() - t0
    loaded = _kernel_specialisations() - loaded
    out = {
        "n_aircraft": int(n_aircraft),
        "steps": int(steps),
        "trackers": bool(trackers),
        "steps_per_s": steps / elapsed if elapsed > 0 else math.inf,
        "seconds": elapsed,
        "ms_per_step": 1000.0 * float(np.median(per_step)),
        "cpu_ms_per_step": 1000.0 * float(np.median(cpu)),
        "mean_tracks": tracks / max(steps, 1),
        "setup_s": setup,
        "warmup_steps": warm,
        "kernels_loaded_timed": loaded,
    }
    peak = _rss_bytes("VmHWM") if peak_known else None
    if peak is not None and rss0 is not None:
        out["peak_rss_mb"] = peak / 2**20
        out["bytes_per_track"] = (peak - rss0) / max(out["mean_tracks"], 1.0)
    preset = world.tracker_preset
    del world  # the bare IMM below runs without the world's memory
    if trackers and compare_imm:
        n_tracks = max(1, round(out["mean_tracks"]))
        imm = bare_imm(preset, sc.sensor.sigma, n_tracks, steps, seed)
        out["imm"] = imm
        out["ratio"] = out["ms_per_step"] / imm["ms_per_step"]
        out["cpu_ratio"] = out["cpu_ms_per_step"] / imm["cpu_ms_per_step"]
    return out
