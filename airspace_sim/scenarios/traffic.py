"""Generated traffic: the aircraft a scenario's ``[traffic]`` table asks for.

:func:`build_aircraft` returns the hand-placed ``[[aircraft]]`` followed by the generated
ones. Patterns (``traffic.pattern``):

- ``ring``: BlueSky's "super conflict" (``SYN SUPER n``): ``count`` aircraft evenly spaced on
  a circle of ``radius`` metres around the origin, all heading to the centre, each with a
  route waypoint at the diametrically opposite point so that they all cross the centre. The
  ring must be wide enough that neighbours start at least 2·r_safe apart:
  ``radius ≥ r_safe / sin(π / count)``.
- ``random``: ``count`` aircraft uniform in a square sector of side ``sector`` metres centred
  on the origin, each flying towards a random point on the sector's edge at least half a side
  away (a route across the sector). Initial separation from every other aircraft is more
  than r_safe (rejection sampling); with ``spawn_clear_s`` = T, no pair would lose
  separation within T seconds flying straight.
- ``encounter``: the paper's encounter (§VI): ``count`` intruders on a circle of ``radius``
  metres around ``aircraft[0]`` (the ownship), each in a random direction that makes it
  unsafe if both keep straight (closest approach < r_safe, in the future). Intruders do not
  avoid (non-cooperative), as in the paper.

Speeds are uniform in ``speed ± speed_spread``; the first ``controlled`` generated aircraft
are RL agents. All randomness comes from the ``rng`` argument.

Randomised geometry (``[randomise]``, :class:`~.schema.RandomiseSpec`): a scenario that sets
ranges there gets, per seed, a ring radius and phase (drawn first, before the pattern is
built), then per aircraft (hand-placed and generated, in order) a heading offset, a speed
and a start delay (the aircraft starts ``speed · delay`` metres back along its heading).
Waypoints stay where the pattern put them, so route aircraft steer back onto their route.
A scenario without ranges draws nothing extra: its aircraft are those of earlier versions,
bit for bit.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from airspace_sim.errors import UserError
from airspace_sim.scenarios.schema import AircraftSpec, Scenario

MAX_TRIES = 2000  # rejection-sampling attempts per aircraft


def build_aircraft(
    scenario: Scenario, rng: np.random.Generator | int | None = None
) -> list[AircraftSpec]:
    """Hand-placed aircraft (copies) followed by the generated traffic, seeded by ``rng``."""
    rng = np.random.default_rng(rng) if not isinstance(rng, np.random.Generator) else rng
    hand = [dataclasses.replace(a, waypoints=list(a.waypoints)) for a in scenario.aircraft]
    if scenario.recorded.file:
        from airspace_sim.recorded.scenario import recorded_aircraft

        hand += recorded_aircraft(scenario, taken={a.id for a in hand})
    t = scenario.traffic
    r = scenario.randomise
    phase = 0.0
    if t.pattern == "ring" and t.count:
        if r.radius is not None:
            t = dataclasses.replace(t, radius=float(rng.uniform(*r.radius)))
            scenario = dataclasses.replace(scenario, traffic=t)
        if r.phase_deg is not None:
            phase = math.radians(rng.uniform(*r.phase_deg))
    generated = []
    if t.pattern != "none" and t.count:
        # the loader checked the pattern and that no hand-placed id clashes with a generated one
        generated = BUILDERS[t.pattern](scenario, rng)
        for i, a in enumerate(generated):
            a.controlled = i < t.controlled
        if phase:
            generated = [_rotated(a, phase) for a in generated]
    return _jittered(hand + generated, r, rng)


def _rotated(a: AircraftSpec, angle: float) -> AircraftSpec:
    """``a`` with its position, heading and waypoints rotated by ``angle`` rad about the
    origin (CCW)."""
    c, s = math.cos(angle), math.sin(angle)
    rot = lambda p: (c * p[0] - s * p[1], s * p[0] + c * p[1])
    return dataclasses.replace(
        a,
        position=rot(a.position),
        heading_deg=(a.heading_deg + math.degrees(angle)) % 360.0,
        waypoints=[rot(w) for w in a.waypoints],
    )


def _jittered(aircraft: list[AircraftSpec], r, rng: np.random.Generator) -> list[AircraftSpec]:
    """Per-aircraft draws of :class:`~.schema.RandomiseSpec` (heading offset, speed, start
    delay), in that order, one array of len(aircraft) each; nothing drawn for unset ranges."""
    n = len(aircraft)
    dh = np.zeros(n) if r.heading_deg is None else rng.uniform(*r.heading_deg, size=n)
    speed = None if r.speed is None else rng.uniform(*r.speed, size=n)
    delay = np.zeros(n) if r.start_s is None else rng.uniform(*r.start_s, size=n)
    if r.heading_deg is None and speed is None and r.start_s is None:
        return aircraft
    out = []
    for k, a in enumerate(aircraft):
        v = a.speed if speed is None else float(speed[k])
        h = math.radians(a.heading_deg + dh[k])
        back = v * delay[k]
        pos = (a.position[0] - back * math.cos(h), a.position[1] - back * math.sin(h))
        heading = (a.heading_deg + dh[k]) % 360.0
        out.append(dataclasses.replace(a, position=pos, heading_deg=float(heading), speed=v))
    return out


def randomise_problem(scenario: Scenario) -> tuple[str, str] | None:
    """``(dotted key, message)`` if the scenario's ``[randomise]`` ranges cannot be drawn
    from (the loader's cross-field check), else None."""
    r, t = scenario.randomise, scenario.traffic
    if r.radius is not None and t.pattern == "ring" and t.count:
        r_min = ring_min_radius(t.count, scenario.separation.r_safe)
        if r.radius[0] < r_min * (1 - 1e-12):
            return (
                "randomise.radius",
                f"expected a low end of at least {math.ceil(r_min)} m for a ring of {t.count} "
                f"aircraft (neighbours 2·r_safe apart), got {list(r.radius)}",
            )
    return None


def _ids(prefix: str, n: int) -> list[str]:
    width = max(2, len(str(n - 1)))
    return [f"{prefix}{i:0{width}d}" for i in range(n)]


def _speeds(scenario: Scenario, rng: np.random.Generator) -> np.ndarray:
    t = scenario.traffic
    return t.speed + rng.uniform(-t.speed_spread, t.speed_spread, size=t.count)


def _spec(scenario, aid, pos, heading_rad, speed, waypoints=(), avoid=True) -> AircraftSpec:
    t = scenario.traffic
    return AircraftSpec(
        id=aid,
        position=(float(pos[0]), float(pos[1])),
        heading_deg=float(math.degrees(heading_rad) % 360.0),
        speed=float(speed),
        autopilot=t.autopilot,
        waypoints=[(float(w[0]), float(w[1])) for w in waypoints],
        max_turn_rate_deg=t.max_turn_rate_deg,
        speed_range=t.speed_range,
        max_acceleration=t.max_acceleration,
        avoid=avoid,
    )


def ring_min_radius(count: int, r_safe: float) -> float:
    """Smallest ring radius at which ``count`` evenly spaced neighbours are 2·r_safe apart."""
    if count < 2:
        return 0.0
    return r_safe / math.sin(math.pi / count)


def ring(scenario: Scenario, rng: np.random.Generator) -> list[AircraftSpec]:
    """BlueSky's super conflict: evenly on a circle, all converging on the centre."""
    t = scenario.traffic
    n, radius, r_safe = t.count, t.radius, scenario.separation.r_safe
    r_min = ring_min_radius(n, r_safe)
    if radius < r_min * (1 - 1e-12):
        raise UserError(
            f"{scenario.source}: traffic.radius: a ring of {n} aircraft needs a radius of at "
            f"least {math.ceil(r_min)} m (neighbours 2·r_safe = {2 * r_safe:g} m apart), "
            f"got {radius:g}"
        )
    speeds = _speeds(scenario, rng)
    out = []
    for i, aid in enumerate(_ids("ring", n)):
        a = 2 * math.pi * i / n
        pos = (radius * math.cos(a), radius * math.sin(a))
        out.append(_spec(scenario, aid, pos, a + math.pi, speeds[i], [(-pos[0], -pos[1])]))
    return out


def _edge_point(u: float, side: float) -> tuple[float, float]:
    """Point at arc length ``u`` ∈ [0, 4·side) along the edge of a centred square."""
    h = side / 2
    k, s = divmod(u, side)
    return [(-h + s, -h), (h, -h + s), (h - s, h), (-h, h - s)][int(k) % 4]


def random_sector(scenario: Scenario, rng: np.random.Generator) -> list[AircraftSpec]:
    """Uniform in a square sector, initially separated by more than r_safe, routes across it.

    With ``traffic.spawn_clear_s`` = T > 0, an aircraft (position and route) is redrawn until
    flying straight it keeps more than r_safe from every aircraft placed before it over
    ``[0, T]`` seconds, so that no pair is born in a conflict too close to resolve.
    """
    t = scenario.traffic
    side, r_safe, clear_s = t.sector, scenario.separation.r_safe, float(t.spawn_clear_s)
    hand = scenario.aircraft
    n_hand = len(hand)
    placed = np.empty((n_hand + t.count, 2))
    vel = np.empty((n_hand + t.count, 2))  # m/s, for the spawn_clear_s check
    for k, a in enumerate(hand):
        placed[k] = a.position
        h = math.radians(a.heading_deg)
        vel[k] = a.speed * math.cos(h), a.speed * math.sin(h)
    m = n_hand
    speeds = _speeds(scenario, rng)
    # Only aircraft within r_safe of a candidate can reject it, and within the reach
    # r_safe + (fastest relative speed)·T can fail its spawn-clear test (the distance at
    # time t is at least |Δp| - |Δv|·t), so each test looks only at the 3 x 3 grid cells
    # around the candidate: the same decisions as against every placed aircraft.
    v_max = max([abs(a.speed) for a in hand] + [float(np.abs(speeds).max())])
    near = _Grid(r_safe)
    clear = _Grid(r_safe + 2 * v_max * clear_s) if clear_s > 0 else None
    for k in range(m):
        near.add(k, placed[k])
        if clear is not None:
            clear.add(k, placed[k])
    out = []
    for i, aid in enumerate(_ids("ac", t.count)):
        for _attempt in range(MAX_TRIES):
            p = _place(rng, placed, near, side, r_safe)
            if p is None:
                raise UserError(
                    f"{scenario.source}: traffic.count: cannot place {t.count} aircraft more "
                    f"than r_safe = {r_safe:g} m apart in a {side:g} m sector (placed {i}); "
                    f"use a larger traffic.sector or fewer aircraft, got {t.count}"
                )
            for _ in range(MAX_TRIES):
                dest = np.asarray(_edge_point(rng.uniform(0, 4 * side), side))
                if np.hypot(*(dest - p)) >= side / 2:
                    break
            heading = math.atan2(dest[1] - p[1], dest[0] - p[0])
            v = speeds[i] * np.array([math.cos(heading), math.sin(heading)])
            if clear is None:
                break
            idx = clear.around(p)
            if _min_distance(placed[idx] - p, vel[idx] - v, clear_s) > r_safe:
                break
        else:
            raise UserError(
                f"{scenario.source}: traffic.spawn_clear_s: cannot place {t.count} aircraft "
                f"clear of each other for {clear_s:g} s in a {side:g} m sector (placed {i}); "
                f"use a smaller traffic.spawn_clear_s, a larger sector or fewer aircraft, "
                f"got {clear_s:g}"
            )
        placed[m], vel[m] = p, v
        near.add(m, p)
        if clear is not None:
            clear.add(m, p)
        m += 1
        out.append(_spec(scenario, aid, p, heading, speeds[i], [tuple(dest)]))
    return out


class _Grid:
    """Indices of points bucketed in square cells (a dict of the occupied cells), so that
    every point within ``reach`` metres of a query point is in its 3 x 3 cells.

    The cell side is ``1.01·reach + 1`` m rather than ``reach``: a pair whose computed
    distance rounds to within ``reach`` (coordinates up to the loader's 1e8 m carry ~1e-8 m
    of rounding) is then never two cells apart, whatever the rounding of ``x / cell``.
    Hand-placed aircraft outside the sector just land in their own cells.
    """

    def __init__(self, reach: float):
        self.cell = 1.01 * reach + 1.0
        self.cells: dict[tuple[int, int], list[int]] = {}

    def _key(self, p) -> tuple[int, int]:
        return math.floor(p[0] / self.cell), math.floor(p[1] / self.cell)

    def add(self, k: int, p) -> None:
        self.cells.setdefault(self._key(p), []).append(k)

    def around(self, p) -> np.ndarray:
        """Indices (int array, any order) of the points in the 3 x 3 cells around ``p``."""
        ix, iy = self._key(p)
        out: list[int] = []
        for jx in (ix - 1, ix, ix + 1):
            for jy in (iy - 1, iy, iy + 1):
                out += self.cells.get((jx, jy), ())
        return np.array(out, dtype=np.intp)


def _min_distance(rel_pos: np.ndarray, rel_vel: np.ndarray, horizon_s: float) -> float:
    """Smallest distance over ``[0, horizon_s]`` of straight relative motion, metres.

    rel_pos (K, 2) m, rel_vel (K, 2) m/s; ``inf`` for K = 0.
    """
    if rel_pos.shape[0] == 0:
        return math.inf
    vv = np.einsum("ij,ij->i", rel_vel, rel_vel)
    t = -np.einsum("ij,ij->i", rel_pos, rel_vel) / np.where(vv > 0, vv, 1.0)
    t = np.clip(np.where(vv > 0, t, 0.0), 0.0, horizon_s)
    return float(np.hypot(*(rel_pos + t[:, None] * rel_vel).T).min())


def _place(rng, placed: np.ndarray, near: _Grid, side: float, r_safe: float, batch: int = 64):
    """Rejection sampling: the first of i.i.d. uniform candidates (drawn ``batch`` at a
    time) farther than r_safe from every placed point; None after MAX_TRIES.

    ``near`` holds the indices into ``placed`` of the points placed so far; a candidate is
    tested only against those in its grid cells (the others are farther than r_safe), with
    the same squared distance per pair as a test against all of them.
    """
    r2 = r_safe**2
    for _ in range(0, MAX_TRIES, batch):
        cand = rng.uniform(-side / 2, side / 2, size=(batch, 2))
        for c in cand:
            idx = near.around(c)
            if idx.size == 0 or ((c - placed[idx]) ** 2).sum(axis=-1).min() > r2:
                return c
    return None


def miss_distance(rel_pos: np.ndarray, rel_vel: np.ndarray) -> tuple[float, float]:
    """Closest-approach distance and time for straight flight (time clipped at 0)."""
    vv = float(rel_vel @ rel_vel)
    t_cpa = 0.0 if vv == 0 else max(0.0, -float(rel_pos @ rel_vel) / vv)
    return float(np.hypot(*(rel_pos + t_cpa * rel_vel))), t_cpa


def encounter(scenario: Scenario, rng: np.random.Generator) -> list[AircraftSpec]:
    """The paper's encounter: intruders on a circle around the ownship, aimed to be unsafe."""
    t = scenario.traffic
    own = scenario.aircraft[0]
    own_pos = np.asarray(own.position, float)
    h = math.radians(own.heading_deg)
    own_vel = own.speed * np.array([math.cos(h), math.sin(h)])
    r_safe = scenario.separation.r_safe
    speeds = _speeds(scenario, rng)
    out = []
    for i, aid in enumerate(_ids("intruder", t.count)):
        bearing = rng.uniform(0, 2 * math.pi)
        rel = t.radius * np.array([math.cos(bearing), math.sin(bearing)])
        for _ in range(MAX_TRIES):
            heading = rng.uniform(0, 2 * math.pi)
            vel = speeds[i] * np.array([math.cos(heading), math.sin(heading)])
            d, t_cpa = miss_distance(rel, vel - own_vel)
            if d < r_safe and t_cpa > 0:
                break
        else:  # pragma: no cover - needs a radius far larger than r_safe and a slow intruder
            raise UserError(
                f"{scenario.source}: traffic: no intruder heading at speed {speeds[i]:.0f} m/s "
                f"from {t.radius:g} m leads to a conflict"
            )
        out.append(_spec(scenario, aid, own_pos + rel, heading, speeds[i], avoid=False))
    return out


#: Generator of each ``traffic.pattern`` (the loader's ``TRAFFIC_PATTERNS``).
BUILDERS = {"ring": ring, "random": random_sector, "encounter": encounter}
