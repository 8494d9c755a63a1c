"""Throughput of the batched IMM against filterpy's ``IMMEstimator`` (tracker-updates per second).

One tracker-update is one full IMM cycle (mixing, mode-matched predict and update, mode
probabilities, combination) for one tracker. Both estimators run the same model (a preset's
:meth:`~airspace_sim.dynamics.presets.Preset.imm_arguments`) on the same simulated
measurements, in this process, on one core:

- ours: for each batch size B, one warm-up step (numba compilation or cache load), then
  ``repeats`` timings of ``steps`` consecutive :meth:`IMM.step` calls; the rate is
  ``B · steps / time``, and the median over the repeats is reported;
- filterpy: it has no batch, so one tracker is stepped (``predict`` then ``update``) for
  ``filterpy_updates`` cycles split over ``repeats`` timings, and the median rate is
  reported for every B (B trackers would take B times as long).

Rates are wall-clock (``time.perf_counter``); the same runs are also timed in process CPU
time (``time.process_time``), which is less affected by other processes competing for the
cores (``*_cpu_updates_per_s``). The ratio uses the wall-clock rates.
"""

from __future__ import annotations

import os
import platform
import time

import numpy as np

from airspace_sim.errors import UserError

DEFAULT_SIZES = (1, 100, 10_000)


def _setup(preset_name: str, B: int, steps: int, seed: int):
    from airspace_sim.dynamics import presets, truth

    pre = presets.get(preset_name)
    args = pre.imm_arguments()
    tr = truth.simulate(pre, steps + 2, B, np.random.default_rng(seed))
    sig = pre.measurement_sigma
    P0 = np.diag([sig**2, 30.0**2, sig**2, 30.0**2, 0.1**2])
    x0 = tr.states[0].copy()
    x0[:, [0, 2]] = tr.measurements[0]
    return pre, args, x0, P0, tr.measurements[1:]


def _time_ours(preset_name: str, B: int, steps: int, repeats: int, seed: int, kernel: str):
    from airspace_sim.tracking import IMM

    pre, args, x0, P0, z = _setup(preset_name, B, steps, seed)
    rates, cpu = [], []
    imm = IMM(x0=x0, P0=P0, mu0=pre.mu0(), kernel=kernel, **args)
    imm.step(z[0])  # warm-up: compile or load the kernel
    used = imm.kernel
    for _ in range(repeats):
        imm = IMM(x0=x0, P0=P0, mu0=pre.mu0(), kernel=kernel, **args)
        imm.step(z[0])
        t, c = time.perf_counter(), time.process_time()
        for k in range(1, steps + 1):
            imm.step(z[k])
        c = time.process_time() - c
        rates.append(B * steps / (time.perf_counter() - t))
        cpu.append(B * steps / c if c > 0 else float("nan"))
    return rates, cpu, used


def _time_filterpy(preset_name: str, updates: int, repeats: int, seed: int):
    try:
        from filterpy.kalman import IMMEstimator, KalmanFilter
    except ImportError:
        return None, None
    per = max(1, updates // repeats)
    pre, args, x0, P0, z = _setup(preset_name, 1, per, seed)
    F, Q, H, R, U = (args[k] for k in ("transitions", "process_noise", "measurement_matrix",
                                       "measurement_noise", "offsets"))  # fmt: skip
    u = np.ones((1, 1))
    rates, cpu = [], []
    for _ in range(repeats):
        filters = []
        for j in range(F.shape[0]):
            kf = KalmanFilter(dim_x=F.shape[1], dim_z=H.shape[0], dim_u=1)
            kf.F, kf.Q, kf.H, kf.R = F[j], Q[j], H, R
            kf.B = U[j][:, None]
            kf.x, kf.P = x0[0][:, None].copy(), P0.copy()
            filters.append(kf)
        imm = IMMEstimator(filters, pre.mu0(), args["transition_matrix"])
        t, c = time.perf_counter(), time.process_time()
        for k in range(per):
            imm.predict(u)
            imm.update(z[k, 0])
        c = time.process_time() - c
        rates.append(per / (time.perf_counter() - t))
        cpu.append(per / c if c > 0 else float("nan"))
    return rates, cpu


def run_benchmark(
    sizes=DEFAULT_SIZES,
    steps: int = 20,
    repeats: int = 5,
    filterpy_updates: int = 1000,
    preset: str = "seed",
    seed: int = 0,
    kernel: str = "auto",
) -> dict:
    """Measure both estimators; return ``{"rows": [...], "meta": {...}}``.

    Each row: ``B``, ``ours_updates_per_s`` (median), ``ours_all`` (every repeat),
    ``ours_cpu_updates_per_s`` (median, CPU time), ``filterpy_updates_per_s`` and
    ``filterpy_cpu_updates_per_s`` (medians, None if filterpy is not installed) and
    ``ratio`` (ours / filterpy, wall clock). ``kernel`` is the IMM's (``meta["kernel"]``
    says which one ran).
    """
    sizes = [int(b) for b in sizes]
    if not sizes or min(sizes) < 1:
        raise UserError(f"bench: batch sizes must be positive integers, got {sizes}")
    for name, v in (("steps", steps), ("repeats", repeats), ("filterpy_updates", filterpy_updates)):
        if int(v) < 1:
            raise UserError(f"bench: {name} must be at least 1, got {v}")
    fp, fp_cpu = _time_filterpy(preset, int(filterpy_updates), int(repeats), seed)
    fp_rate = float(np.median(fp)) if fp else None
    fp_cpu_rate = float(np.median(fp_cpu)) if fp_cpu else None
    rows = []
    for B in sizes:
        ours, ours_cpu, used = _time_ours(preset, B, int(steps), int(repeats), seed, kernel)
        rate = float(np.median(ours))
        rows.append(
            dict(
                B=B,
                ours_updates_per_s=rate,
                ours_all=[float(r) for r in ours],
                ours_cpu_updates_per_s=float(np.median(ours_cpu)),
                filterpy_updates_per_s=fp_rate,
                filterpy_cpu_updates_per_s=fp_cpu_rate,
                ratio=(rate / fp_rate) if fp_rate else None,
            )
        )
    import numba

    meta = dict(
        preset=preset,
        kernel=used,
        steps=int(steps),
        repeats=int(repeats),
        filterpy_updates=int(filterpy_updates),
        filterpy_all=[float(r) for r in fp] if fp else None,
        machine=platform.machine(),
        processor=platform.processor() or platform.uname().processor,
        python=platform.python_version(),
        numpy=np.__version__,
        numba=numba.__version__,
        timer="time.perf_counter (wall clock) and time.process_time (CPU), median over repeats",
        cpu_count=os.cpu_count(),
        load_average=list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    )
    return dict(rows=rows, meta=meta)


def format_table(result: dict) -> str:
    """The result of :func:`run_benchmark` as a plain-text table."""

    def g(v):
        return "n/a" if v is None else f"{v:.3g}"

    head = ("B", "ours updates/s", "filterpy updates/s", "ratio", "ours (CPU)", "filterpy (CPU)")
    lines = [
        f"{head[0]:>8}  {head[1]:>15}  {head[2]:>19}  {head[3]:>7}  {head[4]:>11}  {head[5]:>15}"
    ]
    for r in result["rows"]:
        ratio = "n/a" if r["ratio"] is None else f"{r['ratio']:.0f}x"
        lines.append(
            f"{r['B']:>8}  {g(r['ours_updates_per_s']):>15}  {g(r['filterpy_updates_per_s']):>19}  "
            f"{ratio:>7}  {g(r['ours_cpu_updates_per_s']):>11}  {g(r['filterpy_cpu_updates_per_s']):>15}"
        )
    m = result["meta"]
    load = m.get("load_average")
    lines.append(
        f"(preset {m['preset']}, {m['kernel']} kernel, {m['steps']} steps x {m['repeats']} repeats, median; filterpy "
        f"{m['filterpy_updates']} single-tracker updates; wall clock, CPU time in the last two "
        f"columns" + (f"; load average {load[0]:.1f} on {m['cpu_count']} CPUs)" if load else ")")
    )
    return "\n".join(lines)
