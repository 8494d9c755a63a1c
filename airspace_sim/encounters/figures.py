"""Figures: counterparts of the paper's figures 4–7 and two world-frame figures (PNG, Agg).

:func:`make_all` writes, into a folder:

- ``fig4_trajectories.png``: about 15 relative-frame encounters with the paper's avoidance
  (true relative tracks, safety circle, start circle, ownship at the origin);
- ``fig5_mode_probabilities.png``: (a) IMM mode probabilities over time, (b) estimated mode
  (argmax μ) with the true mode overlaid and the ownship's frame rotations marked;
- ``fig6_relative_track.png``: one encounter's relative track (true, estimated,
  measurements), safety circle, the predicted unsafe points C_j ('+') and the intruder's
  mode switches;
- ``fig7_estimation_error.png``: estimation error vs measurement error over time, x and y;
- ``world_frame.png``: a world-frame encounter: ownship and intruder tracks, heading change
  and separation over time;
- ``false_detections.png``: P(turn) from the world-frame and the relative-frame tracker
  during own manoeuvres, and the false-detection rates over a small campaign.

Distances are plotted in km, times in s, angles in degrees.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from airspace_sim.encounters.relative import EncounterConfig, run_relative
from airspace_sim.encounters.world_frame import run_world

MODE_NAMES = ("1 straight", "2 left", "3 right")
MODE_COLORS = ("tab:blue", "tab:green", "tab:red")
FILES = (
    "fig4_trajectories.png",
    "fig5_mode_probabilities.png",
    "fig6_relative_track.png",
    "fig7_estimation_error.png",
    "world_frame.png",
    "false_detections.png",
)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update(
        {
            "font.size": 11,
            "axes.titlesize": 12,
            "axes.labelsize": 11,
            "legend.fontsize": 9,
            "figure.dpi": 100,
        }
    )
    return plt


def _circle(ax, radius_km, **kw):
    t = np.linspace(0, 2 * np.pi, 361)
    ax.plot(radius_km * np.cos(t), radius_km * np.sin(t), **kw)


def _valid(tr, key, b):
    a = tr[key][:, b]
    ok = tr["active"][:, b]
    return a[ok]


def pick_encounter(batch, min_manoeuvres: int = 3) -> int:
    """Column of the first encounter in ``batch`` with at least ``min_manoeuvres`` rotations
    and an intruder turn, else the one with the most rotations."""
    m = batch.metrics
    tr = batch.trace
    turned = np.array(
        [(tr["mode"][tr["active"][:, b], b] != 0).any() for b in range(len(batch.indices))]
    )
    ok = np.flatnonzero((m["n_manoeuvres"] >= min_manoeuvres) & turned & (m["steps"] > 80))
    return int(ok[0]) if ok.size else int(np.argmax(m["n_manoeuvres"]))


def fig4(batch, path, cfg: EncounterConfig):
    plt = _plt()
    tr = batch.trace
    fig, ax = plt.subplots(figsize=(7.5, 7.5))
    _circle(
        ax, cfg.r_safe / 1e3, color="red", lw=2, label=f"safety circle R = {cfg.r_safe / 1e3:g} km"
    )
    _circle(
        ax,
        cfg.start_radius / 1e3,
        color="gray",
        ls="--",
        lw=1.2,
        label=f"start circle {cfg.start_radius / 1e3:g} km",
    )
    for b in range(len(batch.indices)):
        xy = _valid(tr, "truth", b)[:, [0, 2]] / 1e3
        los = batch.metrics["los"][b]
        ax.plot(xy[:, 0], xy[:, 1], lw=1.3, color="tab:orange" if los else "tab:blue", alpha=0.9)
        ax.plot(xy[0, 0], xy[0, 1], "o", ms=4, color="k")
    ax.plot([], [], color="tab:blue", label="intruder track (relative), no LoS")
    ax.plot([], [], color="tab:orange", label="intruder track, loss of separation")
    ax.plot([], [], "o", color="k", ms=4, label="start")
    ax.plot(0, 0, marker="^", color="k", ms=10, ls="none", label="ownship (origin)")
    n_los = int(batch.metrics["los"].sum())
    ax.set_title(
        f"Fig. 4 counterpart: {len(batch.indices)} relative-frame encounters, paper's CDA\n"
        f"({n_los} with loss of separation, min separation {batch.metrics['min_separation_m'].min():.0f} m)"
    )
    ax.set_xlabel("relative east x (km)")
    ax.set_ylabel("relative north y (km)")
    ax.set_aspect("equal")
    lim = cfg.start_radius / 1e3 * 1.5
    ax.set_xlim(-lim, lim)
    ax.set_ylim(-lim, lim)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", framealpha=0.9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _rotation_times(tr, b):
    t = tr["time"]
    return t[(tr["theta"][:, b] != 0) & tr["active"][:, b]]


def fig5(batch, b, path):
    plt = _plt()
    tr = batch.trace
    ok = tr["active"][:, b]
    t = tr["time"][ok]
    mu = tr["mu"][ok, b]
    mode = tr["mode"][ok, b]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for j in range(mu.shape[1]):
        a1.plot(t, mu[:, j], color=MODE_COLORS[j], lw=1.4, label=f"μ mode {MODE_NAMES[j]}")
    rot = _rotation_times(tr, b)
    for k, tt in enumerate(rot):
        for ax in (a1, a2):
            ax.axvspan(
                tt,
                tt + batch.dt,
                color="0.8",
                lw=0,
                label="ownship rotation θ ≠ 0" if (k == 0 and ax is a1) else None,
            )
    a1.set_ylabel("mode probability")
    a1.set_ylim(-0.02, 1.25)
    a1.set_title(f"Fig. 5 counterpart (encounter {batch.indices[b]}): (a) IMM mode probabilities")
    a1.legend(loc="upper center", ncol=4, fontsize=8.5)
    a1.grid(alpha=0.3)
    est = np.argmax(mu, axis=1)
    a2.step(t, mode + 1, where="post", color="k", lw=2.2, label="true mode")
    a2.step(t, est + 1, where="post", color="tab:orange", lw=1.2, label="estimated mode (argmax μ)")
    acc = float(np.mean(est[1:] == mode[1:]))
    a2.set_title(f"(b) estimated vs true mode (agreement {acc:.0%})")
    a2.set_yticks([1, 2, 3], MODE_NAMES)
    a2.set_ylim(0.8, 3.9)
    a2.set_xlabel("time (s)")
    a2.set_ylabel("mode")
    a2.legend(loc="upper center", ncol=2)
    a2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def fig6(batch, b, path, cfg: EncounterConfig):
    plt = _plt()
    tr = batch.trace
    ok = tr["active"][:, b]
    xy = tr["truth"][ok, b][:, [0, 2]] / 1e3
    est = tr["estimate"][ok, b][:, [0, 2]] / 1e3
    z = tr["z"][ok, b] / 1e3
    mode = tr["mode"][ok, b]
    fig, ax = plt.subplots(figsize=(11.5, 7.5))
    _circle(ax, cfg.r_safe / 1e3, color="red", lw=2, label="safety circle (R = 3 km)")
    ax.plot(z[:, 0], z[:, 1], ".", color="0.6", ms=3, label="measurements (σ = 50 m)")
    ax.plot(xy[:, 0], xy[:, 1], color="k", lw=1.8, label="true relative track")
    ax.plot(est[:, 0], est[:, 1], color="tab:blue", lw=1.2, ls="--", label="IMM estimate")
    pred = tr["predicted"][ok, b] / 1e3
    unsafe = tr["predicted_unsafe"][ok, b]
    first = True
    for k in range(pred.shape[0]):
        if unsafe[k].any():
            j = int(np.argmax(unsafe[k]))
            ax.plot(est[k, 0], est[k, 1], "+", color="red", ms=11, mew=1.8)
            ax.plot(
                pred[k, j, 0],
                pred[k, j, 1],
                "+",
                color="darkred",
                ms=11,
                mew=1.8,
                label="estimate B and its unsafe prediction C_j" if first else None,
            )
            ax.plot([est[k, 0], pred[k, j, 0]], [est[k, 1], pred[k, j, 1]], color="red", lw=0.8)
            first = False
    sw = np.flatnonzero(np.diff(mode) != 0) + 1
    for m in range(3):
        s = sw[mode[sw] == m]
        ax.plot(
            xy[s, 0],
            xy[s, 1],
            "*",
            ms=7,
            color=MODE_COLORS[m],
            ls="none",
            label=f"intruder switches to mode {MODE_NAMES[m]}",
        )
    ax.plot(xy[0, 0], xy[0, 1], "o", color="k", ms=6, label="start")
    # zoom on the track (the ownship is at the origin, R = 3 km away)
    pad = 0.3
    ax.set_xlim(xy[:, 0].min() - pad, xy[:, 0].max() + pad)
    ax.set_ylim(xy[:, 1].min() - pad, xy[:, 1].max() + pad)
    ax.set_aspect("equal")
    ms = batch.metrics["min_separation_m"][b]
    ax.set_title(
        f"Fig. 6 counterpart (encounter {batch.indices[b]}): relative track near the safety circle\n"
        f"min separation {ms:.0f} m, {int(batch.metrics['n_manoeuvres'][b])} frame rotations "
        "(ownship at the origin, off the plot)"
    )
    ax.set_xlabel("relative east x (km)")
    ax.set_ylabel("relative north y (km)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), framealpha=0.9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def fig7(batch, b, path):
    plt = _plt()
    tr = batch.trace
    ok = tr["active"][:, b].copy()
    ok[0] = False  # no measurement at t = 0
    t = tr["time"][ok]
    truth = tr["truth"][ok, b]
    est = tr["estimate"][ok, b]
    z = tr["z"][ok, b]
    fig, axes = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for ax, (name, si, zi) in zip(axes, [("x", 0, 0), ("y", 2, 1)]):
        me = z[:, zi] - truth[:, si]
        ee = est[:, si] - truth[:, si]
        ax.plot(
            t,
            me,
            color="0.55",
            lw=1.0,
            label=f"measurement error (RMS {np.sqrt(np.mean(me**2)):.0f} m)",
        )
        ax.plot(
            t,
            ee,
            color="tab:blue",
            lw=1.6,
            label=f"estimation error (RMS {np.sqrt(np.mean(ee**2)):.0f} m)",
        )
        for tt in _rotation_times(tr, b):
            ax.axvline(tt, color="tab:orange", lw=0.6, alpha=0.6)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_ylabel(f"error in {name} (m)")
        ax.legend(loc="upper right")
        ax.grid(alpha=0.3)
    axes[0].set_title(
        f"Fig. 7 counterpart (encounter {batch.indices[b]}): (a) x, (b) y  "
        "(orange lines: ownship frame rotations)"
    )
    axes[1].set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def world_figure(wb, b, path, cfg: EncounterConfig, resolver: str, baseline=None):
    plt = _plt()
    tr = wb.trace
    ok = tr["active"][:, b]
    t = tr["time"][ok]
    own = tr["own"][ok, b][:, [0, 2]] / 1e3
    intr = tr["intruder"][ok, b][:, [0, 2]] / 1e3
    fig = plt.figure(figsize=(13, 6.5))
    ax = fig.add_subplot(1, 2, 1)
    if baseline is not None:
        okb = baseline.trace["active"][:, b]
        okb = okb & (np.arange(okb.size) < ok.sum())  # same time span as the avoiding run (a copy)
        ob = baseline.trace["own"][okb, b][:, [0, 2]] / 1e3
        ax.plot(
            ob[:, 0],
            ob[:, 1],
            color="tab:blue",
            lw=1.2,
            ls=":",
            label=f"ownship without avoidance (same time span; min sep {baseline.metrics['min_separation_m'][b]:.0f} m)",
        )
    ax.plot(own[:, 0], own[:, 1], color="tab:blue", lw=2, label="ownship with avoidance")
    ax.plot(intr[:, 0], intr[:, 1], color="tab:red", lw=2, label="intruder (true)")
    est = tr["estimate"][ok, b][:, [0, 2]] / 1e3
    ax.plot(
        est[:, 0], est[:, 1], color="tab:red", lw=1, ls="--", label="intruder (world-frame IMM)"
    )
    marks = np.arange(0, len(t), max(1, int(round(2.0 / wb.dt))))
    _c = np.linspace(0, 2 * np.pi, 100)
    for k in marks:
        ax.plot([own[k, 0], intr[k, 0]], [own[k, 1], intr[k, 1]], color="0.6", lw=0.8)
        ax.plot(
            own[k, 0] + cfg.r_safe / 1e3 * np.cos(_c),
            own[k, 1] + cfg.r_safe / 1e3 * np.sin(_c),
            color="tab:blue",
            lw=0.5,
            alpha=0.45,
        )
        ax.annotate(f"{t[k]:.0f} s", intr[k], fontsize=8, color="tab:red")
    ax.plot([], [], color="tab:blue", lw=0.5, label="safety circle, every 2 s")
    ax.plot([], [], color="0.6", lw=0.8, label="line of sight, every 2 s")
    ax.plot(own[0, 0], own[0, 1], "o", color="tab:blue")
    ax.plot(intr[0, 0], intr[0, 1], "o", color="tab:red")
    ax.set_aspect("equal")
    ax.set_xlabel("east (km)")
    ax.set_ylabel("north (km)")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.12), fontsize=8, ncol=2)
    ax.set_title(
        f"World frame, resolver '{resolver}' (encounter {wb.indices[b]}),\n"
        f"turn-rate limit {math.degrees(cfg.max_turn_rate):.0f} deg/s"
    )
    a2 = fig.add_subplot(2, 2, 2)
    hdg = np.degrees(np.unwrap(np.arctan2(tr["own"][ok, b, 3], tr["own"][ok, b, 1])))
    a2.plot(t, hdg - hdg[0], color="tab:blue", lw=1.8, label="ownship heading change from start")
    a2.set_ylabel("heading change (deg)")
    a2.grid(alpha=0.3)
    a2.legend(loc="best", fontsize=8)
    a2.set_title(
        f"total |heading change| {np.degrees(wb.metrics['heading_change_rad'][b]):.0f} deg "
        f"in {int(wb.metrics['n_manoeuvres'][b])} steps",
        fontsize=10,
    )
    a3 = fig.add_subplot(2, 2, 4, sharex=a2)
    sep = np.hypot(*(tr["intruder"][ok, b][:, [0, 2]] - tr["own"][ok, b][:, [0, 2]]).T) / 1e3
    if baseline is not None:
        okb = baseline.trace["active"][:, b]
        tb = baseline.trace["time"][okb]
        sb = (
            np.hypot(
                *(
                    baseline.trace["intruder"][okb, b][:, [0, 2]]
                    - baseline.trace["own"][okb, b][:, [0, 2]]
                ).T
            )
            / 1e3
        )
        a3.plot(tb, sb, color="k", lw=1.2, ls=":", label="without avoidance")
    a3.plot(t, sep, color="k", lw=1.8, label="with avoidance")
    a3.axhline(cfg.r_safe / 1e3, color="red", lw=1.5, label="R_safe")
    a3.set_xlabel("time (s)")
    a3.set_ylabel("true separation (km)")
    a3.legend(loc="best", fontsize=8)
    a3.grid(alpha=0.3)
    a3.set_title(f"min separation {wb.metrics['min_separation_m'][b]:.0f} m", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def false_detection_figure(wb, b, rates: dict, path, n_runs: int):
    """(a) One world-frame encounter with own manoeuvres: turn evidence max(μ2, μ3) − μ1 of
    each tracker (> 0: a turn is detected). (b) False-detection rates per setting."""
    plt = _plt()
    tr = wb.trace
    ok = tr["active"][:, b].copy()
    ok[0] = False
    t = tr["time"][ok]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(14, 5.5), gridspec_kw={"width_ratios": [1.4, 1]})
    turning = tr["own_turn_rate"][ok, b] != 0
    for k in np.flatnonzero(turning):
        a1.axvspan(t[k] - wb.dt, t[k], color="0.85", lw=0)
    a1.plot([], [], color="0.85", lw=8, label="ownship turning")
    for key, color, name in (
        ("mu_rel", "tab:red", "relative-frame tracker (paper)"),
        ("mu", "tab:blue", "world-frame tracker"),
    ):
        mu = tr[key][ok, b]
        a1.plot(t, np.maximum(mu[:, 1], mu[:, 2]) - mu[:, 0], color=color, lw=1.3, label=name)
    straight = tr["mode"][ok, b] == 0
    a1.fill_between(
        t, -0.6, -0.55, where=~straight, step="pre", color="k", lw=0, label="intruder truly turning"
    )
    a1.axhline(0, color="k", lw=0.8)
    a1.set_xlabel("time (s)")
    a1.set_ylabel("turn evidence max(μ2, μ3) − μ1")
    a1.set_ylim(-0.62, 0.6)
    a1.grid(alpha=0.3)
    a1.legend(loc="upper right", fontsize=8, ncol=2)
    a1.set_title(f"World frame, encounter {wb.indices[b]}: > 0 means 'turn detected'")
    labels = list(rates)
    x = np.arange(len(labels))
    own = [rates[k][0] for k in labels]
    quiet = [rates[k][1] for k in labels]
    a2.bar(x - 0.18, own, 0.36, color="tab:orange", label="within 0.5 s of an own turn")
    a2.bar(x + 0.18, quiet, 0.36, color="0.6", label="otherwise")
    for xi, v in list(zip(x - 0.18, own)) + list(zip(x + 0.18, quiet)):
        a2.text(xi, v, f"{v:.3f}", ha="center", va="bottom", fontsize=9)
    a2.set_xticks(x, labels, fontsize=9)
    a2.set_ylabel("false turn detections per straight step")
    a2.set_title(f"Intruder straight but argmax μ = turn ({n_runs} encounters each)")
    a2.legend(loc="upper right", fontsize=8)
    a2.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _rate(m, num, den):
    d = m[den].sum()
    return float(m[num].sum() / d) if d else math.nan


def make_all(out_dir, seed: int = 0, n_tracks: int = 15, n_false_runs: int = 100) -> list[Path]:
    """Write all figures into ``out_dir``; return their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cfg = EncounterConfig()
    paths = [out / f for f in FILES]
    batch = run_relative(seed, range(n_tracks), "seed", cfg, record=True)
    fig4(batch, paths[0], cfg)
    b = pick_encounter(batch)
    fig5(batch, b, paths[1])
    fig6(batch, b, paths[2], cfg)
    fig7(batch, b, paths[3])
    # world frame: an encounter that is a loss of separation without avoidance and clear with it
    n_world = min(40, n_false_runs)
    wb = run_world(seed, range(n_world), "bands", cfg, record=True)
    wn = run_world(seed, range(n_world), "none", cfg, record=True)
    good = np.flatnonzero(wn.metrics["los"] & ~wb.metrics["los"] & (wb.metrics["n_manoeuvres"] > 5))
    bw = int(good[0]) if good.size else int(np.argmax(wb.metrics["n_manoeuvres"]))
    world_figure(wb, bw, paths[4], cfg, "bands", baseline=wn)
    # false detections: the paper's relative frame, and the world frame with an ownship that
    # also flies its own mode chain (many own turns), seen by both trackers
    rel = run_relative(seed, range(n_false_runs), "seed", cfg).metrics
    mcfg = EncounterConfig(own_motion="markov")
    wm = run_world(seed, range(n_false_runs), "bands", mcfg, record=True)
    m = wm.metrics
    rates = {
        "paper's relative frame\n(rotation ≤ 45°/step)": (
            _rate(rel, "false_detections", "own_turn_straight_steps"),
            _rate(rel, "quiet_false_detections", "quiet_straight_steps"),
        ),
        "world frame,\nrelative-frame tracker": (
            _rate(m, "rel_false_detections", "rel_own_turn_straight_steps"),
            _rate(m, "rel_quiet_false_detections", "rel_quiet_straight_steps"),
        ),
        "world frame,\nworld-frame tracker": (
            _rate(m, "world_false_detections", "world_own_turn_straight_steps"),
            _rate(m, "world_quiet_false_detections", "world_quiet_straight_steps"),
        ),
    }
    bf = int(np.argmax(m["rel_false_detections"] - m["world_false_detections"]))
    false_detection_figure(wm, bf, rates, paths[5], n_false_runs)
    return paths
