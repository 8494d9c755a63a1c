"""Tune a tracker preset's filter on half the traffic calibration flights, report on the other.

    python docs/benchmarks/tune_tracker.py DIR --split train --period 4 \\
        --candidate '{"filter_mode_sigma_accel": [0.3, 0.5, 3.0]}' ...

DIR holds the traffic 2.8.1 ``calibration/*.json.gz`` samples (never committed). Flights in
name order: even positions are the training half, odd the test half. DIR may also be one
collection file (the extracted ``collections/switzerland.json.gz``): its flights in order,
split the same way. Each candidate is a
JSON object of :class:`~airspace_sim.dynamics.presets.Preset` fields changed on ``--preset``
(default imm-ct, or ``imm-cta``, which has no preset name; rates in deg/s and σ_Ω in
deg/s per √s here); one line per candidate:
IMM / best-tuned CV position RMSE, turning and straight seconds flagged (right sign), NIS.
The CV grid is searched once per run (all of CV_SIGMA_GRID). A candidate may change the
number of modes (``turn_rates`` with ``estimated_turn_rate``, ``sojourn_s``,
``switch_probabilities`` and every per-mode σ for the new modes), e.g. the 4-mode set
quiet CV, steady CT, roll-in/roll-out CT (larger σ_Ω), manoeuvring CV:

    --candidate '{"turn_rates": [0, 2, 2, 0], "estimated_turn_rate": [0, 1, 1, 0],
      "filter_mode_sigma_accel": [0.3, 1.5, 1.5, 5], "filter_mode_sigma_turn_rate":
      [0.3, 0.3, 1.5, 0.3], "sojourn_s": [120, 60, 15, 10], "switch_probabilities":
      [[0, 0.7, 0.2, 0.1], [0.5, 0, 0.4, 0.1], [0.3, 0.6, 0, 0.1], [0.4, 0.3, 0.3, 0]]}'
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from airspace_sim.dynamics import markov, presets
from airspace_sim.recorded import read
from airspace_sim.tracking.consistency import CV_SIGMA_GRID
from airspace_sim.tracking.evaluation import evaluate, resample

SIGMA_BY_PERIOD = {1.0: 50.0, 4.0: 100.0}


def split_arguments(doc: str, period: bool = True) -> argparse.ArgumentParser:
    """The arguments of a script on the calibration samples: DIR, ``--split`` (the half
    :func:`split` gives) and, with ``period``, ``--period`` (s, a key of
    :data:`SIGMA_BY_PERIOD`)."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("directory", type=Path)
    ap.add_argument("--split", choices=("train", "test", "all"), default="train")
    if period:
        ap.add_argument("--period", type=float, default=4.0)
    return ap


def split(directory: Path, half: str) -> list:
    """The half of the flights: of a folder of samples, the files in name order at even
    (train) or odd (test) positions; of one file (a collection such as the extracted
    ``collections/switzerland.json.gz``), ``[(file, half)]``: its flights at even or odd
    positions (:func:`flights_of`). ``all``: every file, or the file whole."""
    if directory.is_file():
        return [directory] if half == "all" else [(directory, half)]
    files = sorted(directory.glob("*.json.gz"))
    if half == "all":
        return files
    return files[0::2] if half == "train" else files[1::2]


def flights_of(sources):
    """The recorded flights of :func:`split`'s sources, in order."""
    for source in sources:
        if isinstance(source, tuple):
            path, half = source
            yield from list(read(path))[0 if half == "train" else 1 :: 2]
        else:
            yield from read(source)


def truths_of(files, period):
    out = []
    for f in flights_of(files):
        speed = np.hypot(f.vx, f.vy)
        out += resample(f.id, f.t_s, f.x_m, f.y_m, period,
                        speed_mps=speed if np.all(np.isfinite(speed)) else None)  # fmt: skip
    return out


def measured(a):
    """What the flag scripts start from, for ``a.directory``, ``a.split``, ``a.period`` and
    ``a.preset``: the truths, the preset's tracker model at that setting, the stacked truths
    X (T, F, 5), ``evaluate``'s measurements Z (seed 0) and evaluated steps (T, F)."""
    from airspace_sim.tracking import evaluation as E

    sigma = SIGMA_BY_PERIOD[a.period]
    truths = truths_of(split(a.directory, a.split), a.period)
    p = preset(a.preset).with_(dt=a.period, measurement_sigma=sigma).filter_model()
    X = E._stack(truths)
    return truths, p, X, E.measurements(X, sigma, 0), E._evaluated(X, a.period)


#: Tracker models measured here that are not in presets.PRESETS (no scenario name).
UNLISTED = {"imm-cta": presets.imm_cta}


def preset(name: str):
    """The preset ``name``: a named one (:func:`presets.get`) or one of :data:`UNLISTED`."""
    return UNLISTED[name]() if name in UNLISTED else presets.get(name)


def candidate(base, changes: dict):
    """``base`` with the JSON ``changes``; rates in deg/s (``turn_rates``) and deg/s per √s
    (``ct_sigma_turn_rate``, ``filter_mode_sigma_turn_rate``) here, radians in the preset."""
    changes = dict(changes)
    if "ct_sigma_turn_rate" in changes:
        changes["ct_sigma_turn_rate"] = math.radians(changes["ct_sigma_turn_rate"])
    for k in ("turn_rates", "filter_mode_sigma_turn_rate"):
        if k in changes:
            changes[k] = tuple(math.radians(v) for v in changes[k])
    for k in ("filter_mode_sigma_accel", "sojourn_s", "estimated_turn_rate"):
        if k in changes:
            changes[k] = tuple(changes[k])
    if "switch_probabilities" in changes:
        changes["switch_probabilities"] = tuple(map(tuple, changes["switch_probabilities"]))
    if "turn_rates" in changes and len(changes["turn_rates"]) != base.n_modes:
        # another number of modes: Π (and every per-mode field) must come with it
        sojourn = changes.get("sojourn_s", base.sojourn_s)
        switch = changes.get("switch_probabilities")
        if sojourn is None or len(sojourn) != len(changes["turn_rates"]) or switch is None:
            raise SystemExit("a candidate with another number of modes needs sojourn_s and "
                             "switch_probabilities for its modes")  # fmt: skip
        changes["transition_matrix"] = markov.transition_matrix_from_sojourn(
            sojourn, base.dt, switch
        )
        changes["sojourn_s"], changes["initial_mode_probabilities"] = sojourn, None
    return base.with_(**changes)


def main(argv=None) -> None:
    ap = split_arguments(__doc__)
    ap.add_argument("--preset", default="imm-ct")
    ap.add_argument("--candidate", action="append", default=[])
    a = ap.parse_args(argv)
    files = split(a.directory, a.split)
    sigma = SIGMA_BY_PERIOD[a.period]
    truths = truths_of(files, a.period)
    base = preset(a.preset)
    cv_grid = CV_SIGMA_GRID
    for text in a.candidate or ["{}"]:
        p = candidate(base, json.loads(text))
        ev = evaluate(truths, p, sigma, a.period, cv_sigmas=cv_grid)
        cv_grid = (ev.cv_sigma,)  # the best CV filter of this split and setting
        print(
            f"{a.split} {a.period:g}s {a.preset} {text}: ratio {ev.pos_imm / ev.pos_cv:.3f} "
            f"(IMM {ev.pos_imm:.1f} m, CV {ev.pos_cv:.1f} m @ {ev.cv_sigma:g}) turning "
            f"{100 * ev.turning_flagged:.1f}% straight {100 * ev.straight_flagged:.2f}% "
            f"rate-flag {100 * ev.turning_rate_flagged:.1f}/{100 * ev.straight_rate_flagged:.2f}% "
            f"NIS {ev.nis:.2f}"
            + (
                ""
                if ev.smoothed_turning_flagged is None  # no smoother for along-track models
                else f"; smoothed turning {100 * ev.smoothed_turning_flagged:.1f}% "
                f"straight {100 * ev.smoothed_straight_flagged:.2f}%"
            ),
            flush=True,
        )


if __name__ == "__main__":
    main()
