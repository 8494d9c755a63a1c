"""Plots of a tracker evaluation on recorded flights (matplotlib PNGs).

- :func:`plot_flight`: one flight segment over a window of time, as the trackers saw it: the
  path (truth, measurements, IMM, smoothed IMM) and, against time, the turn rate (truth,
  the IMM's Ω̂ as it ran and smoothed), the turns flagged (the truth's side against the
  IMM's flags, running and smoothed), the IMM's mode probabilities and the position errors
  (IMM, best-tuned CV filter, smoothed IMM). Where a tracker misses a turn, this shows why.
- :func:`plot_summary`: one setting's figures: turning seconds flagged by the time since the
  turn began (:attr:`~airspace_sim.tracking.evaluation.Evaluation.onset`) and position RMSE
  by phase, IMM against CV (:attr:`~airspace_sim.tracking.evaluation.Evaluation.phases`).
- :func:`most_turning` and :func:`turning_window`: which segments and which window to draw.

Inputs are :func:`~airspace_sim.tracking.evaluation.evaluate_with_record`'s results.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from airspace_sim.errors import UserError
from airspace_sim.tracking.evaluation import TURNING_DEG_S, _right_flags

#: Colours of a left and a right turn.
SIDE_COLOURS = ("tab:blue", "tab:orange")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _turning(omega) -> np.ndarray:
    """Bool array like ``omega`` (rad/s): a turning second (|ω| ≥ ``TURNING_DEG_S``)."""
    with np.errstate(invalid="ignore"):
        return np.abs(np.degrees(omega)) >= TURNING_DEG_S


def most_turning(truths, n: int) -> list[int]:
    """Indices of the ``n`` truths (:class:`~airspace_sim.tracking.evaluation.Truth`) with
    the most turning steps, most first (earlier first among equals)."""
    counts = [int(np.count_nonzero(_turning(tr.state[:, 4]))) for tr in truths]
    return sorted(range(len(truths)), key=lambda f: -counts[f])[: max(int(n), 0)]


def turning_window(omega, steps: int) -> tuple[int, int]:
    """(start, stop): the ``steps`` consecutive steps of ``omega`` (T,) rad/s (NaN: no truth)
    holding the most turning steps, the first such window; the whole truth if shorter."""
    live = np.flatnonzero(np.isfinite(omega))
    if live.size == 0:
        return 0, 0
    lo, hi = int(live[0]), int(live[-1]) + 1
    if hi - lo <= steps:
        return lo, hi
    c = np.concatenate([[0], np.cumsum(_turning(omega[lo:hi]))])
    start = lo + int(np.argmax(c[steps:] - c[:-steps]))
    return start, start + steps


def _side(p_left, p_right) -> np.ndarray:
    """(T,) +1 where a left turn is flagged, −1 a right one, 0 neither."""
    return np.where(p_left > 0.5, 1, np.where(p_right > 0.5, -1, 0))


def _rug(ax, t, side, level: float, label: str) -> None:
    for s, colour in zip((1, -1), SIDE_COLOURS):
        on = side == s
        ax.scatter(t[on], np.full(on.sum(), level), s=4, marker="|", color=colour, lw=1)
    ax.text(t[0], level + 0.3, label, fontsize=7, va="bottom")


def plot_flight(record, f: int, path, window_s: float = 900.0) -> Path:
    """Write the PNG of segment ``f`` of ``record`` (a
    :class:`~airspace_sim.tracking.evaluation.Record`) over the ``window_s`` seconds with the
    most turning seconds (:func:`turning_window`) to ``path``; return the path."""
    plt = _pyplot()
    dt = record.period_s
    a, b = turning_window(record.truth[:, f, 4], max(int(round(window_s / dt)), 1))
    t = np.arange(a, b) * dt
    X, Z = record.truth[a:b, f], record.z[a:b, f]
    imm, cv = record.imm[a:b, f], record.cv[a:b, f]
    sm = None if record.smoothed is None else record.smoothed[a:b, f]
    km = 1e-3
    x0, y0 = X[0, 0], X[0, 2]

    fig = plt.figure(figsize=(15, 8.5), dpi=100)
    grid = fig.add_gridspec(4, 2, width_ratios=(1, 1.6), height_ratios=(2, 0.8, 1.3, 1.3))
    ax_map = fig.add_subplot(grid[:, 0])
    ax_w = fig.add_subplot(grid[0, 1])
    ax_f = fig.add_subplot(grid[1, 1], sharex=ax_w)
    ax_mu = fig.add_subplot(grid[2, 1], sharex=ax_w)
    ax_e = fig.add_subplot(grid[3, 1], sharex=ax_w)

    ax_map.plot((Z[:, 0] - x0) * km, (Z[:, 1] - y0) * km, ".", ms=2, color="0.7",
                label="measurements")  # fmt: skip
    ax_map.plot((X[:, 0] - x0) * km, (X[:, 2] - y0) * km, "k", lw=1.5, label="truth")
    ax_map.plot((imm[:, 0] - x0) * km, (imm[:, 2] - y0) * km, color="tab:red", lw=1,
                label="IMM")  # fmt: skip
    if sm is not None:
        ax_map.plot((sm[:, 0] - x0) * km, (sm[:, 2] - y0) * km, "--", color="tab:green",
                    lw=1, label="IMM smoothed")  # fmt: skip
    ax_map.plot(0.0, 0.0, "ko", ms=5)
    ax_map.set(xlabel="east (km)", ylabel="north (km)", aspect="equal",
               title=f"{record.names[f]}: {t[0]:g}–{t[-1]:g} s (dot: start)")  # fmt: skip
    ax_map.legend(fontsize=8, loc="best")

    ax_w.plot(t, np.degrees(X[:, 4]), "k", lw=1.5, label="truth ω")
    ax_w.plot(t, np.degrees(imm[:, 4]), color="tab:red", lw=1, label="IMM Ω̂")
    if sm is not None:
        ax_w.plot(t, np.degrees(sm[:, 4]), "--", color="tab:green", lw=1, label="smoothed Ω̂")
    for s in (-1, 1):
        ax_w.axhline(s * TURNING_DEG_S, color="0.6", ls=":", lw=0.8)
    lo, hi = ax_w.get_ylim()
    ax_w.set(ylabel="turn rate (°/s, left +)", ylim=(lo, hi + 0.3 * (hi - lo)))
    ax_w.legend(fontsize=8, ncol=3, loc="upper right")

    truth_side = np.where(_turning(X[:, 4]), np.sign(X[:, 4]), 0)
    _rug(ax_f, t, truth_side, 2.0, "truth turning (blue left, orange right)")
    imm_side = _side(record.p_left[a:b, f], record.p_right[a:b, f])
    _rug(ax_f, t, imm_side, 1.0, "IMM flags")
    if record.smoothed_p_left is not None:
        _rug(ax_f, t, _side(record.smoothed_p_left[a:b, f], record.smoothed_p_right[a:b, f]),
             0.0, "smoothed IMM flags")  # fmt: skip
    ax_f.set(ylim=(-0.5, 3.0), yticks=[])

    for j, name in enumerate(record.mode_names):
        (line,) = ax_mu.plot(t, record.mu[a:b, f, j], lw=1, label=name)
        if record.smoothed_mu is not None:
            ax_mu.plot(t, record.smoothed_mu[a:b, f, j], "--", lw=0.8, color=line.get_color())
    ax_mu.set(ylabel="mode probability", ylim=(-0.02, 1.45), yticks=[0, 0.5, 1])
    ax_mu.legend(fontsize=8, ncol=len(record.mode_names), loc="upper right",
                 title="solid: running, dashed: smoothed", title_fontsize=7)  # fmt: skip

    def err(e):
        return np.hypot(e[:, 0] - X[:, 0], e[:, 2] - X[:, 2])

    ax_e.plot(t, err(cv), color="0.5", lw=0.8, label="best CV")
    ax_e.plot(t, err(imm), color="tab:red", lw=0.8, label="IMM")
    if sm is not None:
        ax_e.plot(t, err(sm), color="tab:green", lw=0.8, label="IMM smoothed")
    hi = ax_e.get_ylim()[1]
    ax_e.set(
        xlabel="time since the segment's first sample (s)",
        ylabel="position error (m)",
        ylim=(0, hi * 1.3),
    )
    ax_e.legend(fontsize=8, ncol=3, loc="upper right")

    scored = record.evaluated[a:b, f] & _turning(X[:, 4])
    right = _right_flags(record.p_left[a:b, f], record.p_right[a:b, f], X)
    share = f"{100 * right[scored].mean():.0f}%" if scored.any() else "–"
    fig.suptitle(f"{record.names[f]}, {dt:g} s: turning seconds in this window flagged "
                 f"with the right side by the running IMM: {share}")  # fmt: skip
    fig.tight_layout()
    return _save(fig, plt, path)


def plot_summary(evaluation, path) -> Path:
    """Write the PNG of one :class:`~airspace_sim.tracking.evaluation.Evaluation`'s flags by
    time since the turn began and position RMSE by phase to ``path``; return the path."""
    plt = _pyplot()
    ev = evaluation
    fig, (ax_o, ax_p) = plt.subplots(1, 2, figsize=(12, 4.5), dpi=100)

    def span(lo, hi):
        return f"{lo:g}–{hi:g} s" if math.isfinite(hi) else f"{lo:g} s on"

    labels = [span(lo, hi) for lo, hi, _, _ in ev.onset]
    x = np.arange(len(labels))
    ax_o.bar(x, [100 * fl for _, _, _, fl in ev.onset], color="tab:red", width=0.6)
    for i, (_, _, share, fl) in enumerate(ev.onset):
        ax_o.text(i, 100 * np.nan_to_num(fl) + 1.5, f"{100 * share:.0f}% of the turning s",
                  ha="center", fontsize=8)  # fmt: skip
    ax_o.axhline(100 * ev.turning_flagged, color="k", ls="--", lw=1,
                 label=f"all turning seconds: {100 * ev.turning_flagged:.1f}%")  # fmt: skip
    if ev.smoothed_turning_flagged is not None:
        ax_o.axhline(100 * ev.smoothed_turning_flagged, color="tab:green", ls="--", lw=1,
                     label=f"smoothed IMM, all: {100 * ev.smoothed_turning_flagged:.1f}%")  # fmt: skip
    ax_o.set(xticks=x, xticklabels=labels, ylim=(0, 100), xlabel="time since the turn began",
             ylabel="flagged, right side (%)", title="running IMM's turn flags")  # fmt: skip
    ax_o.legend(fontsize=8, loc="upper left")

    labels = [f"{ph}\n{span(lo, hi)}" for ph, lo, hi, *_ in ev.phases]
    x = np.arange(len(labels))
    ax_p.bar(x - 0.2, [imm for *_, imm, _ in ev.phases], width=0.4, color="tab:red",
             label=f"IMM (all: {ev.pos_imm:.1f} m)")  # fmt: skip
    ax_p.bar(x + 0.2, [cv for *_, cv in ev.phases], width=0.4, color="0.6",
             label=f"best CV, σ_a {ev.cv_sigma:g} m/s² (all: {ev.pos_cv:.1f} m)")  # fmt: skip
    ax_p.set(xticks=x, ylabel="position RMSE (m)", title="position error by phase")
    ax_p.set_xticklabels(labels, fontsize=7)
    ax_p.legend(fontsize=8)
    fig.suptitle(f"{ev.preset}, σ {ev.sigma_m:g} m every {ev.period_s:g} s: {ev.n_flights} "
                 f"segments, {ev.n_seconds / 3600:.1f} h")  # fmt: skip
    fig.tight_layout()
    return _save(fig, plt, path)


def _save(fig, plt, path) -> Path:
    path = Path(path)
    try:
        fig.savefig(path)
    except OSError as exc:
        raise UserError(f"plot {path}: cannot write ({exc.strerror})") from None
    finally:
        plt.close(fig)
    return path
