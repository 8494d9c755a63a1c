"""Observation and action spaces of the PettingZoo env, and the observation encoder.

Observation: one flat ``float32`` :class:`gymnasium.spaces.Box` per agent, every entry
normalised and clipped to finite bounds (mostly [-1, 1], flags and probabilities [0, 1]).
Layout (see :meth:`ObservationLayout.names` for every entry's name):

``own`` block (14 entries), the ownship's true state; entries 3, 9, 12 and 13 are in
**action units** (fractions of the aircraft's turn-rate limit ω_max, CCW +), so that an
action equal to one of them flies it:

    0  speed / v_ref                          [0, 2]     v_ref = 300 m/s
    1  sin(heading)                           [-1, 1]    heading CCW from east
    2  cos(heading)                           [-1, 1]
    3  turn rate / ω_max                      [-1, 1]    last step's
    4  cross-track error / (10 r_safe)        [-1, 1]    + left of the route leg
    5  sin(bearing to waypoint - heading)     [-1, 1]    0 with no route
    6  cos(bearing to waypoint - heading)     [-1, 1]    1 with no route
    7  distance to waypoint / (2 range)       [0, 1]     range = sensor range
    8  has a waypoint ahead                   {0, 1}
    9  resolver advice / (ω_max dt)           [-1, 1]    the built-in resolver's turn for
                                                         the coming step (0 when clear)
   10  conflict alert                         {0, 1}
   11  in loss of separation                  {0, 1}
   12  route command / ω_max                  [-1, 1]    the route autopilot's turn toward
                                                         the waypoint (0 with no route)
   13  built-in command / ω_max               [-1, 1]    entry 9 while in conflict, else
                                                         entry 12: "advice + steer to the
                                                         waypoint"

then ``K`` intruder rows (nearest first by estimated range), each ``11 + M`` entries, the
ownship's **tracker** estimates in the ownship's body frame (x forward, y left):

    0  mask: 1 for a track, 0 for padding (the rest of a padding row is 0)
    1  rel. x / range,   2  rel. y / range                        [-1, 1]
    3  rel. vx / (2 v_ref),   4  rel. vy / (2 v_ref)              [-1, 1]
    5  estimated range / range                                    [0, 1]
    6  σx / r_safe,   7  σy / r_safe                              [0, 1]  position std devs
    8  correlation of the position errors ρxy                     [-1, 1]
    9  time to closest approach / lookahead                       [-1, 1]
   10  miss distance at closest approach / (2 r_safe)             [0, 1]
   11.. mode probabilities μ (M of them: straight, left, right)    [0, 1]

Action: a **normalised** heading-rate command ``Box(-1, 1, (1,), float32)``, the fraction
of the aircraft's turn-rate limit ω_max (+1 = full rate left, CCW); values outside [-1, 1]
are clipped, as Gymnasium's ``ClipAction`` would. With ``discrete_actions`` a
``Discrete(6)``: ``DISCRETE_LEVELS`` × ω_max for 0..4 (hard left, left, straight, right,
hard right) and :data:`BUILTIN_ACTION` (5).

**"Do what the built-in pilot would do"**: the discrete action :data:`BUILTIN_ACTION`, or,
in either variant, ``None`` as an agent's action (or leaving the agent out of the action
dict): the aircraft then flies the world's autopilot and CDA resolver for that step, exactly
as background traffic does. ``own.builtin_command`` approximates it in action units (it
leaves out the resolver's "hold heading until the turn back is clear" rule).

Malformed actions raise :class:`~airspace_sim.env.checks.ActionError`, a
:class:`~airspace_sim.errors.UserError` that is also Gymnasium's ``InvalidAction``:
non-finite numbers, strings, bytes, booleans, complex numbers, datetimes, objects, wrong
sizes; a discrete action must be an integer (Python or NumPy, as ``Discrete.contains``
accepts) in 0..5.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces
from numba import njit

V_REF = 300.0  #: m/s, speed normalisation
#: discrete action index -> fraction of the turn-rate limit (CCW +): hard left .. hard right
DISCRETE_LEVELS = (1.0, 0.5, 0.0, -0.5, -1.0)
DISCRETE_NAMES = ("hard left", "left", "straight", "right", "hard right", "built-in")
#: discrete action: fly the world's built-in autopilot and resolver this step
BUILTIN_ACTION = len(DISCRETE_LEVELS)

OWN_NAMES = (
    "speed",
    "sin_heading",
    "cos_heading",
    "turn_rate",
    "cross_track",
    "sin_bearing_to_waypoint",
    "cos_bearing_to_waypoint",
    "distance_to_waypoint",
    "has_waypoint",
    "advice",
    "conflict",
    "in_los",
    "route_command",
    "builtin_command",
)
OWN_LOW = (0, -1, -1, -1, -1, -1, -1, 0, 0, -1, 0, 0, -1, -1)
OWN_HIGH = (2, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1)
INTRUDER_NAMES = (
    "mask",
    "rel_x",
    "rel_y",
    "rel_vx",
    "rel_vy",
    "range",
    "sigma_x",
    "sigma_y",
    "rho_xy",
    "tcpa",
    "dcpa",
)
INTRUDER_LOW = (0, -1, -1, -1, -1, 0, 0, 0, -1, -1, 0)
INTRUDER_HIGH = (1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1)


@dataclass(frozen=True)
class ObservationLayout:
    """Sizes and scales of the flat observation vector."""

    n_intruders: int  #: K
    n_modes: int  #: M
    sensor_range: float  #: m
    r_safe: float  #: m
    lookahead: float  #: s

    @property
    def own_size(self) -> int:
        return len(OWN_NAMES)

    @property
    def intruder_size(self) -> int:
        return len(INTRUDER_NAMES) + self.n_modes

    @property
    def size(self) -> int:
        return self.own_size + self.n_intruders * self.intruder_size

    def names(self) -> list[str]:
        """Name of every entry, e.g. ``own.speed``, ``intruder0.rel_x``, ``intruder0.mu1``."""
        out = [f"own.{n}" for n in OWN_NAMES]
        for k in range(self.n_intruders):
            out += [f"intruder{k}.{n}" for n in INTRUDER_NAMES]
            out += [f"intruder{k}.mu{m}" for m in range(self.n_modes)]
        return out

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(size,) float32 lower and upper bounds (read-only arrays, built once)."""
        return self._bounds

    @functools.cached_property
    def _bounds(self) -> tuple[np.ndarray, np.ndarray]:
        ilow = INTRUDER_LOW + (0,) * self.n_modes
        ihigh = INTRUDER_HIGH + (1,) * self.n_modes
        low = np.array(OWN_LOW + ilow * self.n_intruders, dtype=np.float32)
        high = np.array(OWN_HIGH + ihigh * self.n_intruders, dtype=np.float32)
        low.flags.writeable = high.flags.writeable = False
        return low, high

    def space(self) -> spaces.Box:
        low, high = self.bounds()
        return spaces.Box(low, high, dtype=np.float32)

    def intruder_block(self, obs: np.ndarray) -> np.ndarray:
        """View of ``obs`` (..., size) as (..., K, 11 + M) intruder rows."""
        return obs[..., self.own_size :].reshape(
            obs.shape[:-1] + (self.n_intruders, self.intruder_size)
        )


def action_space(discrete: bool) -> spaces.Space:
    """The action space of every agent: normalised turn rate, or the discrete levels."""
    if discrete:
        return spaces.Discrete(len(DISCRETE_LEVELS) + 1)
    return spaces.Box(np.float32(-1.0), np.float32(1.0), shape=(1,), dtype=np.float32)


def decode_action(agent: str, action, discrete: bool) -> float:
    """One agent's action as a fraction of its turn-rate limit in [-1, 1], or NaN for the
    built-in pilot (``None``, or :data:`BUILTIN_ACTION`); :class:`ActionError` if malformed
    (see the module docstring)."""
    from airspace_sim.env.checks import ActionError

    if action is None:
        return math.nan
    arr = action if isinstance(action, np.ndarray) else None
    if discrete:
        ok = isinstance(action, (int, np.integer)) and not isinstance(action, (bool, np.bool_))
        if arr is not None and arr.dtype.kind in "iu" and arr.size == 1 and arr.ndim <= 1:
            action, ok = arr.reshape(()).item(), True
        if not ok or not 0 <= int(action) <= BUILTIN_ACTION:
            raise ActionError(
                f"action for agent {agent!r}: expected an integer in 0..{BUILTIN_ACTION} "
                f"({', '.join(DISCRETE_NAMES)}), got {_show(action)}"
            )
        idx = int(action)
        return math.nan if idx == BUILTIN_ACTION else DISCRETE_LEVELS[idx]
    if isinstance(action, (str, bytes, bool, np.bool_, complex)) or not isinstance(
        action, (int, float, np.number, np.ndarray, list, tuple)
    ):
        raise ActionError(
            f"action for agent {agent!r}: expected a number in [-1, 1] (fraction of the "
            f"turn-rate limit), got {_show(action)}"
        )
    try:
        a = np.asarray(action)
    except (TypeError, ValueError):
        a = np.asarray(None)
    if a.dtype.kind not in "fiu":
        raise ActionError(
            f"action for agent {agent!r}: expected a number in [-1, 1] (fraction of the "
            f"turn-rate limit), got {_show(action)}"
        )
    if a.size != 1:
        raise ActionError(
            f"action for agent {agent!r}: expected one number in [-1, 1], got shape {a.shape}"
        )
    value = float(a.reshape(-1)[0])
    if not math.isfinite(value):
        raise ActionError(
            f"action for agent {agent!r}: expected a finite number in [-1, 1], got {value}"
        )
    return min(max(value, -1.0), 1.0)


@njit(cache=True)
def fractions_into(actions, out) -> bool:  # pragma: no cover - compiled
    """``out`` (A,) float64 ← the continuous ``actions`` (A,) (any float dtype) clipped to
    [-1, 1], as ``np.clip(actions.astype(np.float64), -1.0, 1.0)``; False (``out`` not
    all written) if one is not finite, for :func:`decode_action` to report."""
    for k in range(actions.size):
        a = np.float64(actions[k])
        if not np.isfinite(a):
            return False
        out[k] = -1.0 if a < -1.0 else (1.0 if a > 1.0 else a)
    return True


@njit(cache=True)
def turn_rates_into(frac, idx, max_rate, rates):  # pragma: no cover - compiled
    """``rates`` (N,) rad/s ← NaN (the built-in pilot), then ``frac[k] · max_rate[i]`` for
    each acting agent ``k`` of aircraft ``i = idx[k]`` (``frac`` NaN: built-in too)."""
    rates[:] = np.nan
    for k in range(idx.size):
        i = idx[k]
        rates[i] = frac[k] * max_rate[i]


def _show(value) -> str:
    """A one-line, bounded rendering of a bad value for an error message."""
    text = repr(value).replace("\n", " ")
    return text if len(text) <= 60 else text[:57] + "..."


def encode_intruders(
    layout: ObservationLayout,
    own_pos: np.ndarray,
    own_vel: np.ndarray,
    heading: float,
    x: np.ndarray,
    P: np.ndarray,
    mu: np.ndarray,
) -> np.ndarray:
    """The K intruder rows (K, 11 + M) of one ownship from its tracks ``x`` (T, 5), ``P``
    (T, 5, 5), ``mu`` (T, M); see :func:`encode_intruders_batch`."""
    x = np.asarray(x, dtype=np.float64).reshape(-1, 5)
    return encode_intruders_batch(
        layout,
        np.zeros(len(x), dtype=np.int64),
        np.reshape(own_pos, (1, 2)),
        np.reshape(own_vel, (1, 2)),
        np.reshape(heading, (1,)),
        x,
        P,
        mu,
    )[0]


def encode_intruders_batch(
    layout: ObservationLayout,
    slot: np.ndarray,
    own_pos: np.ndarray,
    own_vel: np.ndarray,
    heading: np.ndarray,
    x: np.ndarray,
    P: np.ndarray,
    mu: np.ndarray,
) -> np.ndarray:
    """Intruder rows (A, K, 11 + M) of A ownships at once.

    ``slot`` (T,) says which ownship (0..A-1) each track row belongs to; ``own_pos`` and
    ``own_vel`` (A, 2), ``heading`` (A,) are the ownships' true states; ``x`` (T, 5),
    ``P`` (T, 5, 5), ``mu`` (T, M) the tracks. Per ownship the nearest K tracks by estimated
    range are kept, nearest first (ties by track order); tracks with non-finite estimates
    are ignored; unused rows are zero (mask 0).
    """
    A = len(heading)
    K, F = layout.n_intruders, layout.intruder_size
    out = np.zeros((A, K, F), dtype=np.float64)
    x = np.asarray(x, dtype=np.float64).reshape(-1, 5)
    slot = np.asarray(slot, dtype=np.int64).reshape(-1)
    if len(x) == 0 or K == 0 or A == 0:
        return out
    P = np.asarray(P, dtype=np.float64).reshape(len(x), 5, 5)
    mu = np.asarray(mu, dtype=np.float64).reshape(len(x), -1)
    ok = np.all(np.isfinite(x[:, :4]), axis=1)
    if not ok.all():
        x, P, mu, slot = x[ok], P[ok], mu[ok], slot[ok]
        if len(x) == 0:
            return out
    own_pos = np.ascontiguousarray(own_pos, dtype=np.float64)
    own_vel = np.ascontiguousarray(own_vel, dtype=np.float64)
    heading = np.ascontiguousarray(heading, dtype=np.float64)
    dist = np.hypot(x[:, 0] - own_pos[slot, 0], x[:, 2] - own_pos[slot, 1])
    order = np.lexsort((np.arange(len(x)), dist, slot))  # by ownship, then range
    _encode_rows(
        order,
        slot,
        dist,
        np.ascontiguousarray(x),
        np.ascontiguousarray(P),
        np.ascontiguousarray(mu),
        own_pos,
        own_vel,
        heading,
        layout.sensor_range,
        layout.r_safe,
        layout.lookahead,
        out,
    )
    return out


def encode_intruders_into(
    layout: ObservationLayout,
    slot: np.ndarray,
    own_pos: np.ndarray,
    own_vel: np.ndarray,
    heading: np.ndarray,
    x: np.ndarray,
    P: np.ndarray,
    mu: np.ndarray,
    obs: np.ndarray,
) -> None:
    """:func:`encode_intruders_batch` written into the intruder block of ``obs`` (A, size)
    float64 (columns ``own_size`` on), every row of it (unused rows zero), in one numba
    pass (:func:`_intruders_into`): the same values bit for bit. ``x`` (T, 5), ``P``
    (T, 5, 5), ``mu`` (T, M) float64 C-contiguous (a :class:`~.trackers.TrackView`'s)."""
    _intruders_into(
        np.asarray(slot, dtype=np.int64),
        np.ascontiguousarray(x, dtype=np.float64),
        np.ascontiguousarray(P, dtype=np.float64),
        np.ascontiguousarray(mu, dtype=np.float64),
        own_pos,
        own_vel,
        heading,
        layout.sensor_range,
        layout.r_safe,
        layout.lookahead,
        layout.own_size,
        layout.n_intruders,
        obs,
    )


@njit(cache=True, error_model="numpy")
def _intruders_into(
    slot, x, P, mu, own_pos, own_vel, heading, rng_, r_safe, look, col0, K, obs
):  # pragma: no cover - compiled
    """:func:`encode_intruders_into`: zero the block, keep the tracks with finite
    ``x[:, :4]``, order them by (ownship, ``hypot`` range, track row) as
    :func:`encode_intruders_batch`'s ``lexsort`` does (a total order: the same rows),
    then the rows of :func:`_encode_rows` (:func:`_intruder_row`, the rotation computed
    once per ownship) written into ``obs``."""
    A = obs.shape[0]
    F = (obs.shape[1] - col0) // K if K > 0 else 0
    for a in range(A):
        for c in range(col0, obs.shape[1]):
            obs[a, c] = 0.0
    T = x.shape[0]
    if T == 0 or K == 0 or A == 0:
        return
    dist = np.empty(T)
    order = np.empty(T, dtype=np.int64)
    n = 0
    for t in range(T):
        if not (
            math.isfinite(x[t, 0])
            and math.isfinite(x[t, 1])
            and math.isfinite(x[t, 2])
            and math.isfinite(x[t, 3])
        ):
            continue
        a = slot[t]
        d = math.hypot(x[t, 0] - own_pos[a, 0], x[t, 2] - own_pos[a, 1])
        dist[t] = d
        # insertion by (slot, dist, t): t is larger than every row placed before it
        k = n
        while k > 0:
            q = order[k - 1]
            if slot[q] < a or (slot[q] == a and not (d < dist[q])):
                break
            order[k] = q
            k -= 1
        order[k] = t
        n += 1
    # per ownship: its body-frame rotation (the same math.cos / math.sin of the same
    # heading as _encode_rows computes per row) and the next free row
    cos_h, sin_h = np.empty(A), np.empty(A)
    for a in range(A):
        cos_h[a], sin_h[a] = math.cos(heading[a]), math.sin(heading[a])
    m = min(F - 11, mu.shape[1])
    prev, rank = -1, 0
    for q in range(n):
        t = order[q]
        a = slot[t]
        if a != prev:
            prev, rank = a, 0
        if rank >= K:
            continue
        _intruder_row(
            obs[a], col0 + rank * F, t, a, cos_h[a], sin_h[a], x, P, mu, own_pos, own_vel,
            dist[t], rng_, r_safe, look, m,
        )  # fmt: skip
        rank += 1


@njit(cache=True, error_model="numpy")
def _encode_rows(order, slot, dist, x, P, mu, own_pos, own_vel, heading, rng_, r_safe, look, out):
    """The rows of :func:`encode_intruders_batch`, written into ``out`` (A, K, F): tracks
    in ``order`` (by ownship, then range), the first K of each ownship."""
    K, F = out.shape[1], out.shape[2]
    m = min(F - 11, mu.shape[1])
    prev, rank = -1, 0
    for q in range(order.size):
        t = order[q]
        a = slot[t]
        if a != prev:
            prev, rank = a, 0
        if rank >= K:
            continue
        _intruder_row(
            out[a, rank], 0, t, a, math.cos(heading[a]), math.sin(heading[a]), x, P, mu,
            own_pos, own_vel, dist[t], rng_, r_safe, look, m,
        )  # fmt: skip
        rank += 1


@njit(inline="always", error_model="numpy")
def _intruder_row(
    dst, b, t, a, c, s, x, P, mu, own_pos, own_vel, dist_t, rng_, r_safe, look, m
):  # pragma: no cover - compiled
    """Track ``t``'s intruder row for ownship ``a`` into ``dst[b : b + 11 + m]``: ``c``,
    ``s`` the cos and sin of the ownship's heading, ``dist_t`` the track's range m,
    ``rng_`` the sensor range m, ``r_safe`` m, ``look`` the look-ahead s, ``m`` the modes
    written (the one row formula of :func:`_encode_rows` and :func:`_intruders_into`)."""
    dx, dy = x[t, 0] - own_pos[a, 0], x[t, 2] - own_pos[a, 1]
    dvx, dvy = x[t, 1] - own_vel[a, 0], x[t, 3] - own_vel[a, 1]
    # world frame -> body frame (x forward, y left)
    px, py = c * dx + s * dy, -s * dx + c * dy
    vx, vy = c * dvx + s * dvy, -s * dvx + c * dvy
    pxx, pxy, pyy = P[t, 0, 0], P[t, 0, 2], P[t, 2, 2]
    var_x = c * c * pxx + 2 * c * s * pxy + s * s * pyy
    var_y = s * s * pxx - 2 * c * s * pxy + c * c * pyy
    cov = -c * s * pxx + (c * c - s * s) * pxy + c * s * pyy
    sx, sy = math.sqrt(max(var_x, 0.0)), math.sqrt(max(var_y, 0.0))
    rho = cov / (sx * sy) if sx * sy > 0 else 0.0
    # closest point of approach on straight lines
    vv = vx * vx + vy * vy
    tcpa = -(px * vx + py * vy) / vv if vv > 1e-9 else 0.0
    ahead = max(tcpa, 0.0)
    dst[b] = 1.0
    dst[b + 1], dst[b + 2] = px / rng_, py / rng_
    dst[b + 3], dst[b + 4] = vx / (2 * V_REF), vy / (2 * V_REF)
    dst[b + 5] = dist_t / rng_
    dst[b + 6], dst[b + 7] = sx / r_safe, sy / r_safe
    dst[b + 8] = rho
    dst[b + 9] = tcpa / look
    dst[b + 10] = math.hypot(px + vx * ahead, py + vy * ahead) / (2 * r_safe)
    for k in range(m):
        dst[b + 11 + k] = mu[t, k]


@njit(cache=True, error_model="numpy")
def encode_own_rows(
    idx,
    speeds,
    turn_rates,
    max_rate,
    per_step,
    advice,
    cross,
    dist,
    conflict,
    in_los,
    sin_h,
    cos_h,
    rel_b,
    sin_rb,
    cos_rb,
    cross_scale,
    dist_scale,
    out,
):
    """The own block (:data:`OWN_NAMES`) of A ownships, written into ``out[:, :14]``.

    idx (A,) int: the ownships' aircraft indices into the (N,) world arrays ``speeds`` m/s,
    ``turn_rates`` and ``max_rate`` rad/s, ``per_step`` rad (largest heading change per
    step), ``advice`` rad, ``cross`` m, ``dist`` m (NaN: no waypoint ahead), ``conflict``
    and ``in_los`` bool. Per ownship (A,): ``sin_h``, ``cos_h`` of the heading, ``rel_b``
    rad bearing to the waypoint relative to the heading and its ``sin_rb``, ``cos_rb``
    (numpy's, so the values are numpy's bit for bit). ``cross_scale`` = 10·r_safe and
    ``dist_scale`` = 2·sensor range, m.
    """
    for k in range(idx.size):
        i = idx[k]
        row = out[k]
        has_wp = math.isfinite(dist[i])
        steers = per_step[i] > 0.0
        adv = advice[i] / per_step[i] if steers and math.isfinite(advice[i]) else 0.0
        route = rel_b[k] / per_step[i] if has_wp and steers else 0.0
        if route < -1.0:
            route = -1.0
        elif route > 1.0:
            route = 1.0
        row[0] = speeds[i] / V_REF
        row[1] = sin_h[k]
        row[2] = cos_h[k]
        row[3] = turn_rates[i] / max_rate[i] if max_rate[i] > 0.0 else 0.0
        row[4] = cross[i] / cross_scale
        row[5] = sin_rb[k] if has_wp else 0.0
        row[6] = cos_rb[k] if has_wp else 1.0
        row[7] = dist[i] / dist_scale if has_wp else 0.0
        row[8] = 1.0 if has_wp else 0.0
        row[9] = adv
        row[10] = 1.0 if conflict[i] else 0.0
        row[11] = 1.0 if in_los[i] else 0.0
        row[12] = route
        row[13] = adv if conflict[i] else route


def finish_in_place(layout: ObservationLayout, obs: np.ndarray) -> np.ndarray:
    """:func:`finish` of a float64 buffer (A, size) that already holds both blocks:
    NaN -> 0 and clipped into the bounds in one pass (:func:`_finish_rows`); float32
    (A, size). ``obs`` is left as it was."""
    low, high = layout.bounds()
    out = np.empty(obs.shape, dtype=np.float32)
    _finish_rows(obs, low, high, out)
    return out


@njit(cache=True)
def _finish_rows(obs, low, high, out):  # pragma: no cover - compiled
    """``out`` (A, F) float32 ← ``obs`` (A, F) with NaN -> 0, clipped to ``low``, ``high``
    (F,) float32 as numpy's ``clip`` with array bounds does (``x > low ? x : low``, then
    ``y < high ? y : high``: the same signed zeros), then rounded to float32."""
    for r in range(obs.shape[0]):
        for c in range(obs.shape[1]):
            x = obs[r, c]
            if x != x:
                x = 0.0
            lo, hi = np.float64(low[c]), np.float64(high[c])
            x = x if x > lo else lo
            out[r, c] = x if x < hi else hi


def finish(layout: ObservationLayout, own: np.ndarray, intruders: np.ndarray) -> np.ndarray:
    """Concatenate own (..., 14) and intruder (..., K, F) blocks, NaN -> 0, clip into the
    space's bounds; float32 (..., size)."""
    own = np.asarray(own, np.float64)
    intruders = np.asarray(intruders, np.float64)
    lead = own.shape[:-1]
    obs = np.concatenate([own, intruders.reshape(lead + (-1,))], axis=-1)
    obs[np.isnan(obs)] = 0.0
    low, high = layout.bounds()
    return np.clip(obs, low, high, out=obs).astype(np.float32)
