"""The paper's escape angle (paper §V, Figure 3; ``docs/paper-notes.md`` §3).

Relative frame: ownship ``O`` at the origin, intruder estimate ``B`` (the relative position),
per-step displacement ``Δ = v_rel·ΔT``. The predicted points are ``C_j = B + jΔ`` for
``j = 1..horizon``; a conflict is predicted when some ``|C_j| < R_safe``. Then

- ``β = asin(R_safe / |OB|)``: half-angle of the tangent cone from ``B`` to the safety circle
  (``|OB| ≤ R_safe``, already inside: ``β = π/2``);
- ``γ``: the signed angle from ``BC_j`` (the direction of ``Δ``) to ``BO = −B``, CCW
  positive, ``γ = atan2(Δ × BO, Δ · BO)`` exactly as the paper writes it;
- the relative velocity is rotated *away* from the line of sight, on the side it already
  passes, until it makes the angle ``β`` with ``BO``: then the predicted track from ``B`` is
  tangent to the safety circle. The rotation is ``θ = −sgn(γ)·(β − |γ|)`` with
  ``sgn(0) = +1``, clamped to ``±max_angle``.

Conventions (deliberate, tested in ``tests/test_escape_angle.py``):

- ``θ`` is the CCW-positive rotation of the **relative velocity** in the (non-rotating) frame.
  The paper writes ``θ = β − γ`` and "rotates the coordinate frame"; rotating the frame by
  ``θ`` rotates vectors in it by ``−θ``, so for ``γ > 0`` the two agree up to that sign. For
  ``γ < 0`` the paper's formula read literally crosses the line of sight to the far tangent;
  here the magnitude is always ``β − |γ|`` (the nearer tangent, on the side the track
  already passes), as ``docs/paper-notes.md`` §3 specifies.
- **Head-on** (``|γ| ≤ HEAD_ON_TOLERANCE``, including exactly ``γ = 0``): the ownship turns
  right, i.e. clockwise. For a static intruder ``v_rel = −v_own``, so rotating the ownship
  velocity by ``ψ`` rotates ``v_rel`` by the same ``ψ``; a right (clockwise) ownship turn is
  therefore a **negative** ``θ``: ``θ = −β`` (then clamped). The intruder turning right too
  (rules of the air) also rotates ``v_rel`` clockwise, so the two agree. Seen in the relative
  frame the intruder then passes to the ownship's left.
- Zero relative velocity: ``C_j = B`` for all ``j``, so a conflict only if already inside; the
  direction is undefined and it is treated as head-on (turn right by ``min(π/2, max_angle)``),
  which gives the ownship a relative velocity to escape with.
- ``B = O`` (coincident): ``β = π/2``, the line of sight is undefined, treated as head-on.
- Already inside and already moving outward (``|γ| ≥ π/2``): the track needs no rotation to
  stop closing, ``θ = 0`` (the conflict flag is still true).
- No conflict: ``θ = 0``.
"""

from __future__ import annotations

import numpy as np

#: Lines of sight within this angle (radians) of the relative velocity count as head-on.
HEAD_ON_TOLERANCE = 1e-9


def line_of_sight_angles(rel_position, rel_velocity, r_safe):
    """``β`` and signed ``γ`` of paper §V for arrays of shape ``(..., 2)``.

    Parameters
    ----------
    rel_position, rel_velocity : array_like, shape ``(..., 2)``
        Intruder minus ownship, metres and m/s (any consistent units).
    r_safe : float or array broadcastable to ``(...)``
        Safety radius, metres.

    Returns
    -------
    beta, gamma : ndarray, shape ``(...)``
        ``β = asin(R/|B|)`` (``π/2`` where ``|B| ≤ R``) and ``γ ∈ (−π, π]``, the CCW angle from
        the relative velocity to the line of sight ``BO = −B`` (``0`` where either is zero).
    """
    b = np.asarray(rel_position, dtype=float)
    v = np.asarray(rel_velocity, dtype=float)
    r = np.asarray(r_safe, dtype=float)
    dist = np.hypot(b[..., 0], b[..., 1])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ratio = np.where(dist > r, r / np.where(dist > 0, dist, 1.0), 1.0)
    beta = np.arcsin(np.clip(ratio, 0.0, 1.0))
    bo_x, bo_y = -b[..., 0], -b[..., 1]
    cross = v[..., 0] * bo_y - v[..., 1] * bo_x
    dot = v[..., 0] * bo_x + v[..., 1] * bo_y
    gamma = np.arctan2(cross, dot)
    # atan2(±0, −0) is ±π: a zero vector has no direction, call it head-on (γ = 0)
    degenerate = ((v[..., 0] == 0) & (v[..., 1] == 0)) | (dist == 0)
    return beta, np.where(degenerate, 0.0, gamma)


def predicted_conflict(rel_position, rel_velocity, r_safe, dt, horizon=3):
    """Paper §V detection: does some ``C_j = B + jΔ``, ``j = 1..horizon``, lie inside ``r_safe``?

    ``Δ = rel_velocity·dt``; inside means ``|C_j| < r_safe`` (strict). Shapes as in
    :func:`escape_angle`; returns a bool array of shape ``(...)``.
    """
    b = np.asarray(rel_position, dtype=float)
    d = np.asarray(rel_velocity, dtype=float) * dt
    r = np.asarray(r_safe, dtype=float)
    conflict = np.zeros(np.broadcast_shapes(b.shape[:-1], d.shape[:-1], r.shape), dtype=bool)
    for j in range(1, int(horizon) + 1):  # small fixed horizon: loop over steps, not pairs
        c = b + j * d
        conflict |= np.hypot(c[..., 0], c[..., 1]) < r
    return conflict


def escape_angle(rel_position, rel_velocity, r_safe, dt, horizon=3, max_angle=np.pi / 4):
    """The paper's escape rotation of the relative velocity (paper §V, Figure 3).

    Parameters
    ----------
    rel_position : array_like, shape ``(..., 2)``
        Intruder position relative to the ownship ``B``, metres.
    rel_velocity : array_like, shape ``(..., 2)``
        Intruder velocity relative to the ownship, m/s.
    r_safe : float or array broadcastable to ``(...)``
        Safety radius ``R_safe``, metres (paper: 3000 m).
    dt : float
        Prediction step ``ΔT``, seconds (``Δ = rel_velocity·dt``).
    horizon : int
        Number of predicted steps ``j = 1..horizon`` (paper: 3).
    max_angle : float
        Clamp on ``|θ|``, radians (paper: π/4 per step).

    Returns
    -------
    theta : ndarray, shape ``(...)``
        CCW-positive rotation of the relative velocity, radians, that makes the predicted
        track tangent to the safety circle, clamped to ``±max_angle``; ``0`` where no conflict.
        See the module docstring for the side, head-on and degenerate-case conventions.
    conflict : ndarray of bool, shape ``(...)``
        Some ``|C_j| < r_safe``.
    """
    conflict = predicted_conflict(rel_position, rel_velocity, r_safe, dt, horizon)
    theta = escape_rotation(rel_position, rel_velocity, r_safe)
    theta = np.clip(theta, -max_angle, max_angle)
    return np.where(conflict, theta, 0.0), conflict


def escape_side(gamma):
    """Which tangent of the escape: ``−1`` (rotate clockwise) or ``+1`` (CCW), shape of ``gamma``.

    The relative velocity is rotated away from the line of sight: clockwise when the line of
    sight lies CCW of it (``γ > 0``) or head-on (``|γ| ≤ HEAD_ON_TOLERANCE``: ownship turns
    right), counter-clockwise when ``γ < 0``.
    """
    gamma = np.asarray(gamma, dtype=float)
    return np.where(gamma < -HEAD_ON_TOLERANCE, 1.0, -1.0)


def escape_rotation(rel_position, rel_velocity, r_safe):
    """Unclamped escape rotation ``θ = side·max(β − |γ|, 0)``, not masked by the conflict flag.

    Shapes and units as in :func:`escape_angle`; returns radians, shape ``(...)``. Head-on
    inside the tolerance uses the right-turn side with magnitude ``β + |γ|`` so that the
    rotated velocity is still exactly tangent (it then makes ``β`` with ``BO`` on the
    clockwise side).
    """
    beta, gamma = line_of_sight_angles(rel_position, rel_velocity, r_safe)
    side = escape_side(gamma)
    # angle from the relative velocity to BO measured on the escape side: the rotated
    # direction must reach angle β from BO on that side.
    # side −1 (clockwise): new direction = BO rotated by −β, from v that is γ − β.
    # side +1 (CCW):       new direction = BO rotated by +β, from v that is γ + β.
    theta = np.where(side < 0, gamma - beta, gamma + beta)
    # already outside the cone on that side (only possible when inside and moving outward,
    # or not in conflict): no rotation.
    theta = np.where(side < 0, np.minimum(theta, 0.0), np.maximum(theta, 0.0))
    return theta
