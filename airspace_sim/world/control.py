"""Tracks gathered into per-ownship arrays, the form every resolver takes (paper §V).

For the ownships that run the resolver, the confirmed tracks are gathered into padded
arrays ``(n_own, K, ·)`` (intruder slot ``k`` of ownship ``o``; ``valid`` marks used slots)
with ``rel_position = track position − own true position`` and ``rel_velocity = track
velocity − own true velocity`` (world frame, m and m/s). :class:`~.policy.AvoidancePolicy`
runs the resolver on them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Encounters:
    """Tracks of the resolver-running ownships as padded arrays.

    owners : (n_own,) aircraft index of each row; rows : (n_own, K) track row or −1;
    rel_position, rel_velocity : (n_own, K, 2) m, m/s; valid : (n_own, K) bool.
    """

    owners: np.ndarray
    rows: np.ndarray
    rel_position: np.ndarray
    rel_velocity: np.ndarray
    valid: np.ndarray

    @classmethod
    def empty(cls) -> Encounters:
        """No ownship."""
        z = np.zeros((0, 0, 2))
        return cls(
            np.zeros(0, np.int64), np.zeros((0, 0), np.int64), z, z.copy(), np.zeros((0, 0), bool)
        )

    def subset(self, mask: np.ndarray) -> Encounters:
        return Encounters(
            self.owners[mask],
            self.rows[mask],
            self.rel_position[mask],
            self.rel_velocity[mask],
            self.valid[mask],
        )

    def compact(self, keep: np.ndarray) -> Encounters:
        """Only the slots with ``keep`` (n_own, K) True, packed to the left, K shrunk."""
        keep = keep & self.valid
        n = self.owners.size
        K = int(keep.sum(axis=1).max(initial=0))
        order = np.argsort(~keep, axis=1, kind="stable")[:, :K]  # kept slots first
        take = lambda a: np.take_along_axis(a, order.reshape(n, K, *([1] * (a.ndim - 2))), axis=1)
        valid = take(keep)
        return Encounters(
            self.owners,
            np.where(valid, take(self.rows), -1),
            np.where(valid[..., None], take(self.rel_position), 0.0),
            np.where(valid[..., None], take(self.rel_velocity), 0.0),
            valid,
        )


def reachable(
    enc: Encounters, own_velocity, radius: float, lookahead: float, step: float = 10.0
) -> np.ndarray:
    """(n_own, K) bool: could the intruder come within ``radius`` during the look-ahead for
    SOME heading of the ownship (own speed kept, intruder straight)?

    ``|r + v_i t − v_o(ψ) t| ≥ |r + v_i t| − |v_o| t``; the right side is sampled every
    ``step`` seconds and lowered by its Lipschitz bound ``(|v_i| + |v_o|)·step/2``, so the
    test never drops an intruder that could matter (the band search's result is the same
    up to which exact boundary candidates it tries).
    """
    vo = np.asarray(own_velocity, dtype=float)[:, None, :]
    vi = enc.rel_velocity + vo
    so = np.hypot(vo[..., 0], vo[..., 1])  # (n, 1)
    t = np.arange(0.0, lookahead + step, step)
    t[-1] = min(t[-1], lookahead)
    px = enc.rel_position[..., 0:1] + vi[..., 0:1] * t
    py = enc.rel_position[..., 1:2] + vi[..., 1:2] * t
    f = np.hypot(px, py) - so[..., None] * t
    slack = (np.hypot(vi[..., 0], vi[..., 1]) + so) * step / 2.0
    return (f.min(axis=-1) - slack < radius) & enc.valid


def gather(track_owner, track_x, positions, velocities, runs, keep=None) -> Encounters:
    """Padded per-ownship arrays of the tracks whose owner has ``runs[owner]`` True.

    track_owner (P,) int, track_x (P, 5) track states (world frame); positions, velocities
    (N, 2) true own states, m, m/s; runs (N,) bool; keep (P,) bool, optional: only these
    tracks. ``rows`` of the result index the P tracks given.
    """
    use = runs[track_owner] if track_owner.size else np.zeros(0, dtype=bool)
    if keep is not None:
        use = use & keep
    sel = np.flatnonzero(use)
    if sel.size == 0:
        return Encounters.empty()
    own = track_owner[sel]
    order = np.argsort(own, kind="stable")
    sel, own = sel[order], own[order]
    owners, start, counts = np.unique(own, return_index=True, return_counts=True)
    K = int(counts.max())
    local = np.repeat(np.arange(owners.size), counts)
    slot = np.arange(sel.size) - np.repeat(start, counts)
    rows = np.full((owners.size, K), -1, dtype=np.int64)
    rows[local, slot] = sel
    x = track_x[sel]
    rp = np.zeros((owners.size, K, 2))
    rv = np.zeros((owners.size, K, 2))
    rp[local, slot] = x[:, (0, 2)] - positions[own]
    rv[local, slot] = x[:, (1, 3)] - velocities[own]
    return Encounters(owners, rows, rp, rv, rows >= 0)
