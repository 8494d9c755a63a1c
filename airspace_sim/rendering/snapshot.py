"""Reading a world snapshot dict into arrays the renderer draws (no pygame here).

The snapshot comes from :meth:`airspace_sim.world.World.snapshot`. The renderer only needs
positions; everything else is optional and drawn when present. Keys read (units SI):

=================  ===========  ============================================================
key                shape        meaning
=================  ===========  ============================================================
``time``           float        simulated time, s
``step``           int          world step count
``ids``            (N,) str     aircraft names
``positions``      (N, 2)       true positions, m
``headings``       (N,)         true headings, rad CCW from east (else from ``velocities``)
``velocities``     (N, 2)       m/s
``active``         (N,) bool    aircraft still flying (inactive ones are not drawn)
``controlled``     (N,) bool    RL agents (drawn in the agent colour)
``conflict``       (N,) bool    conflict alert raised by the ownship's resolver
``in_los``         (N,) bool    inside r_safe of another aircraft
``nmac``           (N,) bool    inside the NMAC distance of another aircraft
``advice``         (N,)         resolver heading change, rad
``r_safe``         float        protected radius, m
``nmac_distance``  float        NMAC distance, m
``tracks``         dict         ``owner`` (P,) int, ``intruder`` (P,) int, ``x`` (P, 5)
                                ``[x, vx, y, vy, Ω]``, ``P`` (P, 5, 5), ``mu`` (P, M);
                                also accepted flat as ``track_owner``, ``track_x``, ...
``predicted``      (P, S, 2)    predicted positions per track, m (else computed here)
``mode_names``     (M,) str     names of the tracker modes
``los_pairs``      (L, 2) int   aircraft index pairs in loss of separation
=================  ===========  ============================================================
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_ALIASES = {
    "positions": ("positions", "position", "pos"),
    "headings": ("headings", "heading"),
    "velocities": ("velocities", "velocity", "vel"),
    "active": ("active",),
    "controlled": ("controlled",),
    "conflict": ("conflict", "conflicts", "alert"),
    "in_los": ("in_los", "los"),
    "nmac": ("nmac", "in_nmac"),
    "advice": ("advice",),
    "r_safe": ("r_safe",),
    "nmac_distance": ("nmac_distance", "nmac_radius", "r_nmac"),
    "time": ("time", "t"),
    "step": ("step", "step_count"),
    "ids": ("ids", "id", "names"),
    "mode_names": ("mode_names", "modes"),
    "predicted": ("predicted", "track_predicted", "predictions"),
}


def _get(snap: dict, name: str, default=None):
    for key in _ALIASES.get(name, (name,)):
        if key in snap and snap[key] is not None:
            return snap[key]
    return default


@dataclass
class Tracks:
    owner: np.ndarray  #: (P,) int
    intruder: np.ndarray  #: (P,) int
    x: np.ndarray  #: (P, 5)
    P: np.ndarray  #: (P, 5, 5)
    mu: np.ndarray  #: (P, M)
    predicted: np.ndarray | None  #: (P, S, 2) or None


@dataclass
class Frame:
    """Arrays of one snapshot, normalised."""

    time: float
    step: int | None
    ids: list
    positions: np.ndarray
    headings: np.ndarray
    active: np.ndarray
    controlled: np.ndarray
    conflict: np.ndarray
    in_los: np.ndarray
    nmac: np.ndarray
    advice: np.ndarray | None
    r_safe: float | None
    nmac_distance: float | None
    tracks: Tracks | None
    mode_names: list
    los_pairs: np.ndarray | None = None  #: (L, 2) int aircraft index pairs in LoS

    @property
    def n(self) -> int:
        return len(self.positions)


def _bool(snap, name, n):
    v = _get(snap, name)
    if v is None:
        return np.zeros(n, dtype=bool)
    return np.asarray(v, dtype=bool).reshape(n)


def _tracks(snap: dict) -> Tracks | None:
    t = snap.get("tracks")
    if t is not None and not isinstance(t, dict):
        # an object with attributes (e.g. a TrackTable)
        t = {k: getattr(t, k) for k in ("owner", "intruder", "x", "P", "mu") if hasattr(t, k)}
    if t is None:
        t = {
            k: snap[f"track_{k}"]
            for k in ("owner", "intruder", "x", "P", "mu")
            if f"track_{k}" in snap
        }
    if not t or "owner" not in t or "x" not in t:
        return None
    owner = np.asarray(t["owner"], dtype=int).reshape(-1)
    n = len(owner)
    intruder = np.asarray(t.get("intruder", np.full(n, -1)), dtype=int).reshape(n)
    x = np.asarray(t["x"], dtype=float)
    x = x.reshape(n, x.shape[-1] if x.ndim == 2 else 5)
    P = t.get("P")
    P = np.asarray(P, dtype=float).reshape(n, x.shape[1], x.shape[1]) if P is not None else None
    if P is None:
        P = np.zeros((n, x.shape[1], x.shape[1]))
    mu = t.get("mu")
    mu = np.asarray(mu, dtype=float) if mu is not None else np.zeros((n, 0))
    mu = mu.reshape(n, mu.shape[-1] if mu.ndim == 2 else 0)
    pred = t.get("predicted", _get(snap, "predicted"))
    if pred is not None:
        pred = np.asarray(pred, dtype=float)
        if pred.ndim != 3 or pred.shape[0] != n or pred.shape[-1] != 2:
            pred = None
    return Tracks(owner, intruder, x, P, mu, pred)


def read_snapshot(snap: dict) -> Frame:
    """Normalise a snapshot dict (see the module docstring for the keys)."""
    pos = _get(snap, "positions")
    if pos is None:
        raise KeyError("snapshot has no 'positions'")
    pos = np.asarray(pos, dtype=float).reshape(-1, 2)
    n = len(pos)
    hdg = _get(snap, "headings")
    if hdg is None:
        vel = _get(snap, "velocities")
        if vel is not None:
            vel = np.asarray(vel, dtype=float).reshape(n, 2)
            hdg = np.arctan2(vel[:, 1], vel[:, 0])
        else:
            hdg = np.zeros(n)
    hdg = np.asarray(hdg, dtype=float).reshape(n)
    active = _get(snap, "active")
    active = np.ones(n, dtype=bool) if active is None else np.asarray(active, bool).reshape(n)
    ids = _get(snap, "ids")
    ids = [str(i) for i in ids] if ids is not None else [str(i) for i in range(n)]
    advice = _get(snap, "advice")
    advice = None if advice is None else np.asarray(advice, dtype=float).reshape(n)
    r_safe = _get(snap, "r_safe")
    nmac_d = _get(snap, "nmac_distance")
    step = _get(snap, "step")
    modes = _get(snap, "mode_names")
    return Frame(
        time=float(_get(snap, "time", 0.0)),
        step=None if step is None else int(step),
        ids=ids,
        positions=pos,
        headings=hdg,
        active=active,
        controlled=_bool(snap, "controlled", n),
        conflict=_bool(snap, "conflict", n),
        in_los=_bool(snap, "in_los", n),
        nmac=_bool(snap, "nmac", n),
        advice=advice,
        r_safe=None if r_safe is None else float(r_safe),
        nmac_distance=None if nmac_d is None else float(nmac_d),
        tracks=_tracks(snap),
        mode_names=[str(m) for m in modes] if modes is not None else [],
        los_pairs=_pairs(snap.get("los_pairs")),
    )


def _pairs(p):
    if p is None:
        return None
    p = np.asarray(p)
    if p.size == 0:
        return np.zeros((0, 2), dtype=int)
    return p.astype(int).reshape(-1, 2)


def predict_positions(x: np.ndarray, horizon: float, n_points: int) -> np.ndarray:
    """Coordinated-turn extrapolation of states ``x`` (P, 5) ``[x, vx, y, vy, Ω]``.

    Returns (P, n_points, 2) positions at ``horizon * k / n_points`` s, k = 1..n_points,
    flying the estimated turn rate Ω (straight when |Ω| is tiny).
    """
    x = np.asarray(x, dtype=float)
    t = horizon * np.arange(1, n_points + 1) / n_points  # (S,)
    px, vx, py, vy = x[:, 0:1], x[:, 1:2], x[:, 2:3], x[:, 3:4]
    w = x[:, 4:5] if x.shape[1] > 4 else np.zeros_like(px)
    wt = w * t
    small = np.abs(w) < 1e-6
    w_safe = np.where(small, 1.0, w)
    s = np.where(small, t, np.sin(wt) / w_safe)
    c = np.where(small, 0.0, (1 - np.cos(wt)) / w_safe)
    xs = px + vx * s - vy * c
    ys = py + vy * s + vx * c
    return np.stack([xs, ys], axis=-1)
