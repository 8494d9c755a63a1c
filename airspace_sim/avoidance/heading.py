"""World-frame exact heading changes (``docs/paper-notes.md`` §3, last paragraph).

The paper (§V) rotates the *relative* velocity by ``θ``. A real ownship can only turn its own
velocity at constant speed: with ``v_rel(ψ) = v_i − R(ψ)·v_o`` the relative velocities it can
reach lie on a circle of radius ``|v_o|`` around ``v_i``. This module intersects that circle
with the lines that matter, in closed form:

- :func:`tangent_heading_change`: ``v_rel(ψ)`` along a tangent from ``B`` to the safety circle
  (the boundary of the collision cone, infinite look-ahead);
- :func:`range_at_time_heading_changes`: ``|B + t·v_rel(ψ)| = R`` at a fixed time ``t`` (the
  boundary of the clear set of a finite look-ahead, where the closest point is at ``t``).

Both reduce to ``a·cos(ψ) + b·sin(ψ) = c`` with two roots ``ψ = φ ± acos(c/√(a²+b²))``.
Angles are radians, CCW positive; ``ψ < 0`` is a right turn. Rotation
``R(ψ) = [[cos ψ, −sin ψ], [sin ψ, cos ψ]]``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from airspace_sim.avoidance.escape import escape_side, line_of_sight_angles
from airspace_sim.geometry import rotate, wrap_angle


def _solve_cos_sin(a, b, c):
    """Roots ``ψ`` of ``a cos ψ + b sin ψ = c``: shape ``(..., 2)`` (NaN where none), wrapped."""
    amp = np.hypot(a, b)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = c / amp
    phi = np.arctan2(b, a)
    ok = np.abs(ratio) <= 1.0
    half = np.arccos(np.clip(ratio, -1.0, 1.0))
    roots = np.stack([wrap_angle(phi - half), wrap_angle(phi + half)], axis=-1)
    return np.where(ok[..., None], roots, np.nan)


def tangent_direction(rel_position, r_safe, side):
    """Unit direction ``(..., 2)`` of the tangent from ``B`` to the safety circle on ``side``.

    ``side = +1``: the line of sight ``BO`` rotated CCW by ``β``; ``−1``: clockwise by ``β``
    (``β = asin(R/|B|)``, ``π/2`` when inside). ``B = 0`` uses the line of sight ``(−1, 0)``.
    """
    b = np.asarray(rel_position, dtype=float)
    beta, _ = line_of_sight_angles(b, np.zeros_like(b), r_safe)
    dist = np.hypot(b[..., 0], b[..., 1])
    los = np.where(dist[..., None] > 0, -b / np.where(dist > 0, dist, 1.0)[..., None], [-1.0, 0.0])
    return rotate(los, np.asarray(side, dtype=float) * beta)


def tangent_heading_changes(own_velocity, intruder_velocity, rel_position, r_safe, side):
    """Both ownship heading changes that put ``v_rel`` on the tangent ray of ``side``.

    Solves ``v_i − R(ψ)v_o = λu`` with ``u`` = :func:`tangent_direction` and ``λ > 0``
    (``λ < 0`` would be the tangent *line* traversed away from the circle, not the cone's
    boundary). Writing ``n = perp(u)``, the condition ``n·R(ψ)v_o = n·v_i`` is
    ``a cos ψ + b sin ψ = c`` with ``a = n·v_o``, ``b = n·perp(v_o)``, ``c = n·v_i``.

    Parameters
    ----------
    own_velocity, intruder_velocity : array_like, shape ``(..., 2)``, m/s (world frame)
    rel_position : array_like, shape ``(..., 2)``, intruder minus ownship, m
    r_safe : float or array broadcastable to ``(...)``, m
    side : ``±1`` or array broadcastable to ``(...)``

    Returns
    -------
    ndarray, shape ``(..., 2)``
        The two roots in ``[−π, π)`` radians, NaN where a root does not exist or has
        ``λ ≤ 0`` (relative to ``10⁻¹²·(|v_o| + |v_i|)``).
    """
    vo = np.asarray(own_velocity, dtype=float)
    vi = np.asarray(intruder_velocity, dtype=float)
    u = tangent_direction(rel_position, r_safe, side)
    n = np.stack([-u[..., 1], u[..., 0]], axis=-1)
    vo_perp = np.stack([-vo[..., 1], vo[..., 0]], axis=-1)
    a = np.sum(n * vo, axis=-1)
    b = np.sum(n * vo_perp, axis=-1)
    c = np.sum(n * vi, axis=-1)
    roots = _solve_cos_sin(a, b, c)
    v_rel = vi[..., None, :] - rotate(vo[..., None, :], roots)
    lam = np.sum(v_rel * u[..., None, :], axis=-1)
    # λ must be positive: λ = 0 is v_rel = 0 (no relative motion, no tangent direction)
    scale = np.hypot(vo[..., 0], vo[..., 1]) + np.hypot(vi[..., 0], vi[..., 1])
    return np.where(lam > 1e-12 * scale[..., None], roots, np.nan)


def tangent_heading_change(own_velocity, intruder_velocity, rel_position, r_safe, side=None):
    """Smallest ownship heading change putting ``v_rel`` on a tangent to the safety circle.

    The world-frame counterpart of :func:`~airspace_sim.avoidance.escape.escape_angle`:
    the own speed is kept, only its heading turns by ``ψ``, and ``v_rel = v_i − R(ψ)v_o`` is
    made to lie on the tangent ray from ``B`` (so the relative track from ``B`` just touches
    the circle of radius ``r_safe``). When the intruder is static (``v_i = 0``) this equals
    the paper's unclamped ``θ``.

    Parameters
    ----------
    own_velocity, intruder_velocity : array_like, shape ``(..., 2)``
        World-frame velocities, m/s.
    rel_position : array_like, shape ``(..., 2)``
        Intruder minus ownship position, m.
    r_safe : float or array broadcastable to ``(...)``
        Safety radius, m.
    side : None, ``±1`` or array
        Which tangent: ``None`` chooses the escape side of the current relative velocity
        exactly as :func:`~airspace_sim.avoidance.escape.escape_side` (away from the line of
        sight on the side it already passes; head-on → right turn side ``−1``).

    Returns
    -------
    psi : ndarray, shape ``(...)``
        Heading change, radians in ``[−π, π)``, CCW positive; the root of smallest ``|ψ|``
        (a tie goes to the right turn, ``ψ < 0``). NaN where the tangent is unreachable at
        the own speed.
    reachable : ndarray of bool, shape ``(...)``
    """
    vo = np.asarray(own_velocity, dtype=float)
    vi = np.asarray(intruder_velocity, dtype=float)
    if side is None:
        _, gamma = line_of_sight_angles(rel_position, vi - vo, r_safe)
        side = escape_side(gamma)
    roots = tangent_heading_changes(vo, vi, rel_position, r_safe, side)
    psi = _smallest(roots)
    return psi, ~np.isnan(psi)


def range_at_time_heading_changes(own_velocity, intruder_velocity, rel_position, radius, t):
    """Heading changes ``ψ`` (..., 2) with ``|B + t·v_rel(ψ)| = radius`` at time ``t > 0``.

    With ``P = B + t·v_i`` the condition ``|P − t·R(ψ)v_o|² = radius²`` is
    ``P·R(ψ)v_o = (|P|² + t²|v_o|² − radius²) / (2t)``: again ``a cos ψ + b sin ψ = c``.
    Roots in ``[−π, π)`` radians, NaN where none. Units: m, m/s, s.
    """
    vo = np.asarray(own_velocity, dtype=float)
    vi = np.asarray(intruder_velocity, dtype=float)
    b_ = np.asarray(rel_position, dtype=float)
    t = np.asarray(t, dtype=float)
    p = b_ + t[..., None] * vi
    vo_perp = np.stack([-vo[..., 1], vo[..., 0]], axis=-1)
    a = np.sum(p * vo, axis=-1)
    b = np.sum(p * vo_perp, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        c = (np.sum(p * p, axis=-1) + t**2 * np.sum(vo * vo, axis=-1) - np.asarray(radius) ** 2) / (
            2.0 * t
        )
    return _solve_cos_sin(a, b, c)


def _smallest(roots):
    """The root of smallest ``|ψ|`` along the last axis (ties → negative), NaN if all NaN."""
    mag = np.where(np.isnan(roots), np.inf, np.abs(roots))
    # prefer the right turn on an exact tie: sort key |ψ| then (ψ > 0)
    key = mag + 0.0
    best = np.argmin(key, axis=-1)
    other = 1 - best
    tie = (
        np.take_along_axis(key, other[..., None], -1)[..., 0]
        == np.take_along_axis(key, best[..., None], -1)[..., 0]
    )
    r_best = np.take_along_axis(roots, best[..., None], -1)[..., 0]
    r_other = np.take_along_axis(roots, other[..., None], -1)[..., 0]
    return np.where(tie & (r_other < r_best), r_other, r_best)


@njit(cache=True, error_model="numpy")
def _wrap(x):  # pragma: no cover - compiled
    """:func:`~airspace_sim.geometry.wrap_angle` of a scalar, rad: ``(x + π) % 2π − π`` with
    numpy's float remainder (``fmod``, then the divisor's sign), so the same bits. For
    ``|x + π| < 4π`` (every root here) ``fmod`` is ``y``, ``y − 2π`` or ``y + 2π``, each
    exact (Sterbenz), so it is taken without the libm call."""
    y = x + np.pi
    two_pi = 2.0 * np.pi
    if 0.0 <= y < two_pi:
        m = y
    elif two_pi <= y < 2.0 * two_pi:
        m = y - two_pi
    elif -two_pi < y < 0.0:
        m = y
    elif -2.0 * two_pi < y <= -two_pi:
        m = y + two_pi
    else:
        m = np.fmod(y, two_pi)
    if m < 0.0:
        m += two_pi
    elif m == 0.0:
        m = 0.0  # numpy gives +0 (the divisor's sign), fmod may give −0
    return m - np.pi


@njit(cache=True, error_model="numpy")
def _sum2(x0, x1):  # pragma: no cover - compiled
    """``np.sum`` of two numbers: ``x0 + x1`` except that ``−0 + −0`` is ``+0`` (the reduction
    starts from ``0.0``); the sign of a zero matters to ``atan2``."""
    return (0.0 + x0) + x1


#: guard band of the fast tangent-ray test, relative to ``|v_o| + |v_i|`` (see
#: :func:`_on_tangent_ray`); far above the fast cos / sin's error bound (≈ 2e-8)
_RAY_GUARD = 1e-6


@njit(inline="always", error_model="numpy")
def _ray_fast(cos_psi, sin_psi, vox, voy, vix, viy, ux, uy, approx):  # pragma: no cover
    """:func:`_on_tangent_ray`'s fast test without the root itself: 1 (on the ray), 0 (not)
    or 2 (undecided: :func:`_on_tangent_ray` with the root and the exact scale decides).
    ``cos_psi``, ``sin_psi`` within ~3·10⁻⁸ of the root's cos and sin (the angle-sum
    formula, also with ``√(a² + b²)`` for ``hypot(a, b)``); ``approx`` the scale ``|v_o| +
    |v_i|`` within a few ulp (from ``sqrt``; inf or NaN where the squares overflow: then
    undecided). A λ beyond the guard band of ``approx`` is beyond the exact scale's by far
    more than the fast λ's error, so a decision here is the exact one; so the roots off
    the ray need no ``atan2`` or ``acos``."""
    threshold = 1e-12 * approx
    guard = _RAY_GUARD * approx
    wx = vix - (cos_psi * vox - sin_psi * voy)
    wy = viy - (sin_psi * vox + cos_psi * voy)
    lam = _sum2(wx * ux, wy * uy)
    if lam > threshold + guard:
        return 1
    if lam < threshold - guard:
        return 0
    return 2


@njit(cache=True, error_model="numpy")
def _on_tangent_ray(psi, cos_psi, sin_psi, vox, voy, vix, viy, ux, uy, scale):  # pragma: no cover
    """The tangent-ray test of :func:`tangent_heading_changes` (``λ > 1e-12·scale``) for the
    root ``psi`` of ``a cos ψ + b sin ψ = c`` (as :func:`_solve_cos_sin`), decided from
    ``cos_psi``, ``sin_psi``: its cos and sin from the angle-sum formula (no libm call),
    within ~2e-8 of ``cos(psi)``, ``sin(psi)`` (:func:`_ray_fast`). Only a λ within
    :data:`_RAY_GUARD`·scale of the threshold (relative speed ≲ 1e-6·scale at the root) is
    recomputed with ``cos(psi)``, ``sin(psi)`` as the numpy reference does, so the decision
    is always the reference's."""
    fast = _ray_fast(cos_psi, sin_psi, vox, voy, vix, viy, ux, uy, scale)
    if fast != 2:
        return fast == 1
    cp, sp = np.cos(psi), np.sin(psi)
    wx = vix - (cp * vox - sp * voy)
    wy = viy - (sp * vox + cp * voy)
    return _sum2(wx * ux, wy * uy) > 1e-12 * scale


#: guard band of the search-window test, on the cosine of a root (see :func:`_pair_roots`);
#: far above the angle-sum cos's error bound (≈ 2e-8)
_WINDOW_GUARD = 1e-6


@njit(inline="always", error_model="numpy")
def _window_cos(limit):  # pragma: no cover - compiled
    """``cos(limit)`` for :func:`_pair_roots`'s window test; −inf (no test) unless
    ``limit < π`` (``|ψ| ≤ limit`` is ``cos ψ ≥ cos limit`` for ``ψ`` in ``[−π, π)`` only
    then)."""
    return np.cos(limit) if limit < np.pi else -np.inf


@njit(inline="always", error_model="numpy")
def _may_have_roots(a, b, c, cos_min):  # pragma: no cover - compiled
    """False only where ``a cos ψ + b sin ψ = c`` certainly has no root (``c² > (a² + b²)
    (1 + 10⁻⁹)``), or where both roots certainly lie outside the window (their cosines
    below ``cos_min``, from ``amp = √(a² + b²)`` within a few ulp of ``hypot``, on roots
    well apart): both without libm's ``hypot``. Elsewhere, and when ``a² + b²`` is so
    large or small that it could have overflowed or underflowed, True (decide exactly)."""
    amp2 = a * a + b * b
    if not (1e-280 < amp2 < 1e280):
        return True
    c2 = c * c
    if c2 > amp2 * (1.0 + 1e-9):
        return False
    if cos_min > -np.inf and c2 < amp2 * (1.0 - 1e-9):
        amp = np.sqrt(amp2)
        cphi, sphi, ch = a / amp, b / amp, c / amp
        sh = np.sqrt(max(1.0 - ch * ch, 0.0))
        if cphi * ch + sphi * sh < cos_min and cphi * ch - sphi * sh < cos_min:
            return False
    return True


@njit(cache=True, error_model="numpy")
def _pair_roots(
    vox, voy, sv, vv, bx, by, vix, viy, rad, lookahead_s, cos_lim, out, m
):  # pragma: no cover
    """The six boundary roots of one (ownship, intruder) pair, as
    :func:`boundary_heading_changes` documents; ``sv = |v_o|``, ``vv = v_o·v_o``. With
    ``m < 0`` into ``out`` (6,) in their columns (NaN where none); else the roots that
    exist into ``out[m], out[m + 1], …`` in column order (the packed rows of
    :func:`boundary_roots_in_window`, written in place: no scratch row to copy and test
    for NaN). Returns the next ``m`` (``m`` itself for ``m < 0``).

    A root whose cosine, from the angle-sum formula (``cos φ = a/amp``, ``cos h = c/amp``,
    ``sin h = √(1 − cos²h)``, error ≲ 2·10⁻⁸), is below ``cos_lim`` − :data:`_WINDOW_GUARD`
    lies outside ``|ψ| ≤ limit`` (:func:`_window_cos`) and is left NaN without its
    ``atan2``, ``acos`` and wrap: the candidate sort drops such roots anyway. Equations
    with certainly no root skip ``hypot`` too, and the range equation also when both its
    roots are outside (:func:`_may_have_roots`; nine in ten tangent equations have a root
    in the window, so theirs go straight to the exact test). A root inside the window, or
    near its edge, is computed as the numpy reference computes it. A tangent root's window
    and ray tests come first, from ``√(a² + b²)`` and ``sv + √(|v_i|²)`` (:func:`_ray_fast`),
    then ``hypot``, ``atan2`` and ``acos`` for the equations with a root that passed.
    """
    packed = m >= 0
    if not packed:
        out[:] = np.nan
    # tangent_direction: line of sight rotated by ±β
    dist = np.hypot(bx, by)
    ratio = rad / (dist if dist > 0 else 1.0) if dist > rad else 1.0
    beta = np.arcsin(min(max(ratio, 0.0), 1.0))
    if dist > 0:
        lx, ly = -bx / dist, -by / dist
    else:
        lx, ly = -1.0, 0.0
    approx = -1.0  # sv + |v_i| from sqrt, for the ray test: computed when a root needs it
    cos_min = cos_lim - _WINDOW_GUARD
    cb, sb = np.cos(beta), np.sin(beta)
    for s in range(2):
        cs, sn = cb, (sb if s == 1 else -sb)  # cos, sin of ang = (2s − 1)·β
        ux = cs * lx - sn * ly
        uy = sn * lx + cs * ly
        nx, ny = -uy, ux
        a = _sum2(nx * vox, ny * voy)
        b = _sum2(nx * -voy, ny * vox)
        c = _sum2(nx * vix, ny * viy)
        # certainly no root (the first test of _may_have_roots); its window test is left to
        # the one below: nine in ten tangent equations have a root in the window
        amp2 = a * a + b * b
        normal = 1e-280 < amp2 < 1e280
        c2 = c * c
        if normal and c2 > amp2 * (1.0 + 1e-9):
            continue
        # certainly two roots: the window and ray tests from amp = √(a² + b²) (a few ulp
        # from hypot), and hypot, atan2 and acos only for a root that passes them (a
        # third of these equations has no root on the ray in the window); near |c| = amp,
        # or where a² + b² could overflow or underflow, the exact amp first, as numpy
        sure = normal and c2 < amp2 * (1.0 - 1e-9)
        if sure:
            amp = np.sqrt(amp2)
        else:
            # scalar _solve_cos_sin (no atan2 without a root)
            amp = np.hypot(a, b)
            if not (abs(c / amp) <= 1.0):
                continue
        # roots φ ∓ h: cos φ = a/amp, sin φ = b/amp, cos h = c/amp, sin h ≥ 0
        cphi, sphi = a / amp, b / amp
        ch = min(max(c / amp, -1.0), 1.0)
        sh = np.sqrt(max(1.0 - ch * ch, 0.0))
        cos_m, sin_m = cphi * ch + sphi * sh, sphi * ch - cphi * sh  # root φ − h
        cos_p, sin_p = cphi * ch - sphi * sh, sphi * ch + cphi * sh  # root φ + h
        in_m, in_p = not (cos_m < cos_min), not (cos_p < cos_min)
        if not (in_m or in_p):
            continue
        if approx < 0.0:
            approx = sv + np.sqrt(vix * vix + viy * viy)
        # λ > 0: the tangent ray
        ray_m = _ray_fast(cos_m, sin_m, vox, voy, vix, viy, ux, uy, approx) if in_m else 0
        ray_p = _ray_fast(cos_p, sin_p, vox, voy, vix, viy, ux, uy, approx) if in_p else 0
        if ray_m == 0 and ray_p == 0:
            continue
        if sure:
            amp = np.hypot(a, b)
        phi = np.arctan2(b, a)
        half = np.arccos(min(max(c / amp, -1.0), 1.0))
        if ray_m != 0:
            root = _wrap(phi - half)
            if ray_m == 1 or _on_tangent_ray(
                root, cos_m, sin_m, vox, voy, vix, viy, ux, uy, sv + np.hypot(vix, viy)
            ):
                out[m if packed else 2 * s] = root
                m += packed
        if ray_p != 0:
            root = _wrap(phi + half)
            if ray_p == 1 or _on_tangent_ray(
                root, cos_p, sin_p, vox, voy, vix, viy, ux, uy, sv + np.hypot(vix, viy)
            ):
                out[m if packed else 2 * s + 1] = root
                m += packed
    # range_at_time_heading_changes at t = T
    t = lookahead_s
    px, py = bx + t * vix, by + t * viy
    a = _sum2(px * vox, py * voy)
    b = _sum2(px * -voy, py * vox)
    c = (_sum2(px * px, py * py) + t * t * vv - rad * rad) / (2.0 * t)
    if not _may_have_roots(a, b, c, cos_min):
        return m
    amp = np.hypot(a, b)
    if not (abs(c / amp) <= 1.0):
        return m
    in_m = in_p = True
    if cos_lim > -np.inf:
        cphi, sphi = a / amp, b / amp
        ch = min(max(c / amp, -1.0), 1.0)
        sh = np.sqrt(max(1.0 - ch * ch, 0.0))
        in_m = not (cphi * ch + sphi * sh < cos_min)
        in_p = not (cphi * ch - sphi * sh < cos_min)
        if not (in_m or in_p):
            return m
    phi = np.arctan2(b, a)
    half = np.arccos(min(max(c / amp, -1.0), 1.0))
    if in_m:
        out[m if packed else 4] = _wrap(phi - half)
        m += packed
    if in_p:
        out[m if packed else 5] = _wrap(phi + half)
        m += packed
    return m


@njit(cache=True, error_model="numpy")
def boundary_heading_changes(vo, r, vi, valid, radius, lookahead_s):  # pragma: no cover
    """Per (ownship, intruder) pair the six boundary roots, ``(N, K, 6)`` rad, NaN if none.

    ``vo`` (N, 2) own velocity and ``vi`` (N, K, 2) intruder velocity, m/s (world frame);
    ``r`` (N, K, 2) intruder minus ownship, m; ``valid`` (N, K) bool (invalid pairs: NaN);
    ``radius`` (N, K) m; ``lookahead_s`` T in s. Columns: the two roots of
    :func:`tangent_heading_changes` with ``side = −1``, the two with ``side = +1``, the two
    of :func:`range_at_time_heading_changes` at ``t = T``.
    One fused loop with the numpy functions' operations in their order (they are the
    reference), so the same numbers up to the last bit of the transcendental functions
    (:func:`_pair_roots`). The tangent roots' ray test takes their cos and sin from the
    angle-sum formula (:func:`_on_tangent_ray`, the same decisions); the two tangent
    directions share ``cos β`` and ``sin β`` (libm's cos is even and its sin odd, bit for
    bit).
    """
    n_own, n_int = valid.shape
    out = np.full((n_own, n_int, 6), np.nan)
    for n in range(n_own):
        vox, voy = vo[n, 0], vo[n, 1]
        sv = np.hypot(vox, voy)
        vv = _sum2(vox * vox, voy * voy)
        for k in range(n_int):
            if valid[n, k]:
                _pair_roots(
                    vox,
                    voy,
                    sv,
                    vv,
                    r[n, k, 0],
                    r[n, k, 1],
                    vi[n, k, 0],
                    vi[n, k, 1],
                    radius[n, k],
                    lookahead_s,
                    -np.inf,
                    out[n, k],
                    -1,
                )
    return out


@njit(cache=True, error_model="numpy")
def boundary_roots_in_window(vo, r, v, valid, radius, lookahead_s, limit):  # pragma: no cover
    """The roots of :func:`boundary_heading_changes` that may lie in ``|ψ| ≤ limit[n]``,
    packed: ``(roots (N, 6K), count (N,))``, row ``n``'s ``count[n]`` roots first, in
    the order of that kernel's (K, 6) row, then NaN. Every root with ``|ψ| ≤ limit[n]``
    is there, with the same bits; the others left out are outside (the window test of
    :func:`_pair_roots`). ``v`` (N, K, 2) m/s the *relative* velocity (intruder minus
    ownship): the intruder's is ``v + vo`` (numpy's ``v + vo[:, None]``, the same
    addition, done here instead of in a (N, K, 2) temporary); ``limit`` (N,) rad; other
    arguments as there."""
    n_own, n_int = valid.shape
    out = np.full((n_own, 6 * n_int), np.nan)
    count = np.zeros(n_own, dtype=np.int64)
    for n in range(n_own):
        vox, voy = vo[n, 0], vo[n, 1]
        sv = np.hypot(vox, voy)
        vv = _sum2(vox * vox, voy * voy)
        cos_lim = _window_cos(limit[n])
        row = out[n]
        m = 0
        for k in range(n_int):
            if not valid[n, k]:
                continue
            m = _pair_roots(
                vox,
                voy,
                sv,
                vv,
                r[n, k, 0],
                r[n, k, 1],
                v[n, k, 0] + vox,
                v[n, k, 1] + voy,
                radius[n, k],
                lookahead_s,
                cos_lim,
                row,
                m,
            )
        count[n] = m
    return out, count
