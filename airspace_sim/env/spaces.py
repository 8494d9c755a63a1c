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
    K, F, M = layout.n_intruders, layout.intruder_size, layout.n_modes
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
    own_pos = np.asarray(own_pos, dtype=np.float64)
    own_vel = np.asarray(own_vel, dtype=np.float64)
    heading = np.asarray(heading, dtype=np.float64)
    rel_p = x[:, [0, 2]] - own_pos[slot]
    rel_v = x[:, [1, 3]] - own_vel[slot]
    dist = np.hypot(rel_p[:, 0], rel_p[:, 1])
    order = np.lexsort((np.arange(len(x)), dist, slot))  # by ownship, then range
    s_slot = slot[order]
    rank = np.arange(len(order)) - np.searchsorted(s_slot, s_slot, side="left")
    keep = rank < K
    order, s_slot, rank = order[keep], s_slot[keep], rank[keep]
    c = np.cos(heading[s_slot])
    s = np.sin(heading[s_slot])
    rp, rv = rel_p[order], rel_v[order]
    # world frame -> body frame (x forward, y left)
    rp = np.stack([c * rp[:, 0] + s * rp[:, 1], -s * rp[:, 0] + c * rp[:, 1]], axis=1)
    rv = np.stack([c * rv[:, 0] + s * rv[:, 1], -s * rv[:, 0] + c * rv[:, 1]], axis=1)
    pxx, pxy, pyy = P[order, 0, 0], P[order, 0, 2], P[order, 2, 2]
    vx = c * c * pxx + 2 * c * s * pxy + s * s * pyy
    vy = s * s * pxx - 2 * c * s * pxy + c * c * pyy
    cxy = -c * s * pxx + (c * c - s * s) * pxy + c * s * pyy
    sx = np.sqrt(np.clip(vx, 0, None))
    sy = np.sqrt(np.clip(vy, 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.where(sx * sy > 0, cxy / (sx * sy), 0.0)
        # closest point of approach on straight lines
        vv = np.sum(rv * rv, axis=1)
        tcpa = np.where(vv > 1e-9, -np.sum(rp * rv, axis=1) / vv, 0.0)
    miss = rp + rv * np.clip(tcpa, 0, None)[:, None]
    dcpa = np.hypot(miss[:, 0], miss[:, 1])
    rng_, r_safe = layout.sensor_range, layout.r_safe
    rows = np.zeros((len(order), F))
    rows[:, 0] = 1.0
    rows[:, 1:3] = rp / rng_
    rows[:, 3:5] = rv / (2 * V_REF)
    rows[:, 5] = dist[order] / rng_
    rows[:, 6] = sx / r_safe
    rows[:, 7] = sy / r_safe
    rows[:, 8] = rho
    rows[:, 9] = tcpa / layout.lookahead
    rows[:, 10] = dcpa / (2 * r_safe)
    if M and mu.shape[1]:
        m = min(M, mu.shape[1])
        rows[:, 11 : 11 + m] = mu[order, :m]
    out[s_slot, rank] = rows
    return out


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
