"""The PettingZoo :class:`~pettingzoo.ParallelEnv` over :class:`airspace_sim.world.World`.

Agents are the aircraft chosen by ``agents`` (the scenario's ``controlled`` marks by
default; ``"all"``, a number or any list of ids, hand-placed or generated); every other
aircraft is background traffic flown by the world's autopilots and resolver. Each agent
commands a turn rate as a fraction of its turn-rate limit every step, or leaves the step to
the built-in pilot; see :mod:`.spaces` for the observation layout and action spaces,
:mod:`.rewards` for the reward terms and :mod:`.checks` for input errors.

An agent's episode ends (``terminations``) on an NMAC, on reaching its route's last
waypoint, or when the world takes the aircraft out of play; every agent is truncated after
``max_cycles`` steps. Agents that ended leave ``env.agents``; their aircraft then either
keeps flying with the world's built-in autopilot and resolver (``ended="resolver"``, the
default) or leaves the world at once (``ended="leave"``: no longer seen, tracked or
collided with).

``step()`` once every agent has ended returns five empty dicts (SuperSuit's
``black_death_v3`` makes that call); ``step()`` before the first ``reset()`` raises
:class:`~.checks.ResetNeeded`.

Randomised episodes: the seed draws the geometry of scenarios with a ``[randomise]``
table (:class:`~airspace_sim.scenarios.schema.RandomiseSpec`); ``reset(options=...)``
changes the knobs of :data:`RESET_OPTIONS` for that episode (curricula).

The env is a thin layer over :class:`~airspace_sim.world.World`: route progress is the
world's route autopilot's (:meth:`RouteAutopilot.route_geometry`), ``r_safe``, the sensor
range and the resolver look-ahead that scale the observations are the world's.

Nothing here imports pygame: the renderer is imported when ``render()`` is first called.
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from airspace_sim.env import checks
from airspace_sim.env import rewards as rw
from airspace_sim.env import spaces as sp
from airspace_sim.errors import UserError
from airspace_sim.world.autopilots import RouteAutopilot
from airspace_sim.world.bodies import LOS
from airspace_sim.world.flight import relative_bearings
from airspace_sim.world.snapshot import live_tracks

RENDER_FPS = 10
ENDED = ("resolver", "leave")

#: ``reset(options=...)`` knobs, each for that episode only (Gymnasium's convention):
#: ``traffic_count`` (int, generated aircraft: intruders of an encounter, ring size,
#: random traffic), ``density`` (aircraft per 1000 km² of a ``random`` sector: the
#: sector's side changes, the count does not), ``sensor_sigma`` (m, position noise),
#: ``overrides`` (list of ``"key=value"``, as ``--set``, for anything else). Other keys
#: are ignored with a warning, as Gymnasium envs ignore options they do not know.
RESET_OPTIONS = ("traffic_count", "density", "sensor_sigma", "overrides")

#: global state features per aircraft row (see :meth:`AirspaceParallelEnv.state`)
STATE_NAMES = (
    "present",
    "x",
    "y",
    "vx",
    "vy",
    "sin_heading",
    "cos_heading",
    "turn_rate",
    "agent",
    "in_los",
    "nmac",
    "conflict",
)
STATE_LOW = (0, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0)


def load_scenario(scenario, overrides=()):
    """A :class:`Scenario` from a name, a path or a Scenario object (with overrides)."""
    from airspace_sim.scenarios import Scenario, from_dict, load

    overrides = [overrides] if isinstance(overrides, str) else list(overrides or ())
    if isinstance(scenario, Scenario):
        if not overrides:
            return scenario
        return from_dict(_as_table(scenario), source=scenario.source, overrides=overrides)
    if isinstance(scenario, (str, os.PathLike)):
        return load(scenario, overrides)
    raise UserError(
        f"scenario: expected a scenario name, a path or a Scenario, got {type(scenario).__name__}"
    )


def _as_table(obj):
    """A Scenario as the TOML-like table the loader reads (unset optional fields left out)."""
    if dataclasses.is_dataclass(obj):
        from airspace_sim.scenarios.loader import INTERNAL_FIELDS

        out = {}
        for f in dataclasses.fields(obj):
            v = getattr(obj, f.name)
            if (type(obj).__name__, f.name) not in INTERNAL_FIELDS and v is not None:
                out[f.name] = _as_table(v)
        return out
    if isinstance(obj, (list, tuple)):
        return [_as_table(v) for v in obj]
    if isinstance(obj, dict):
        return {k: _as_table(v) for k, v in obj.items()}
    return obj


def agent_ids(scenario, agents=None) -> list[str]:
    """The ids of the aircraft that are agents, in the world's order.

    ``agents`` None keeps the scenario's ``controlled`` marks, or, if it marks none,
    controls the first aircraft; ``"all"`` every aircraft; an int n the first n
    (hand-placed, then generated); a list of ids exactly those, any of them. Recorded
    aircraft (kinematic autopilots) are never agents: they fly their recording whatever
    the action, so ``"all"`` and n skip them and a listed one is a :class:`UserError`.
    """
    from airspace_sim import registry
    from airspace_sim.scenarios import build_aircraft

    specs = build_aircraft(scenario, np.random.default_rng(scenario.seed))
    ids = [a.id for a in specs]
    recorded = {a.id for a in specs if registry.get("autopilot", a.autopilot).kinematic}
    flyable = [a for a in ids if a not in recorded]
    if not flyable:
        raise UserError("agents: every aircraft is recorded traffic; none can be an agent")
    if agents is None:
        marked = [a.id for a in specs if a.controlled and a.id not in recorded]
        return marked or flyable[:1]
    if isinstance(agents, str):
        if agents != "all":
            raise UserError(f"agents: expected 'all', a number or a list of ids, got {agents!r}")
        return flyable
    if isinstance(agents, (int, np.integer)) and not isinstance(agents, bool):
        n = checks.integer(agents, "agents", 1, len(flyable))
        return flyable[:n]
    if not isinstance(agents, (list, tuple)):
        raise UserError(f"agents: expected 'all', a number or a list of ids, got {agents!r}")
    wanted = [str(a) for a in agents]
    if not wanted:
        raise UserError("agents: expected at least one aircraft id, got none")
    unknown = [a for a in wanted if a not in ids]
    if unknown:
        known = ", ".join(ids if len(ids) <= 12 else ids[:12] + ["..."])
        raise UserError(f"agents: unknown aircraft {unknown[0]!r} (known: {known})")
    if len(set(wanted)) != len(wanted):
        raise UserError(f"agents: an aircraft is listed twice, got {wanted}")
    taken = [a for a in wanted if a in recorded]
    if taken:
        raise UserError(
            f"agents: {taken[0]!r} is recorded traffic (it flies its recording); it cannot be "
            "an agent"
        )
    return [a for a in ids if a in wanted]


class AirspaceParallelEnv(ParallelEnv):
    """Multi-agent airspace env (PettingZoo parallel API).

    Parameters
    ----------
    scenario : a scenario name (file stem in ``scenarios/``), a path or a Scenario.
    render_mode : "rgb_array", "human" or None.
    max_cycles : steps before every agent is truncated (a positive integer); None = the
        scenario's duration.
    overrides : list of ``"key=value"`` applied to the scenario (as ``--set``).
    seed : default world seed for the first ``reset()`` without a seed (None = the
        scenario's seed); Gymnasium's seed rules (:func:`.checks.seed`).
    n_intruders : K, number of intruder rows in the observation.
    discrete_actions : ``Discrete(6)`` actions instead of a continuous turn rate.
    reward : dict of reward term weights (see :mod:`airspace_sim.env.rewards`).
    agents : which aircraft are agents (see :func:`agent_ids`).
    render_size : (width, height) of rendered frames in pixels.
    ended : what the aircraft of an agent whose episode ended does: ``"resolver"`` (keeps
        flying with the built-in autopilot and resolver) or ``"leave"`` (leaves the world).
    max_aircraft : rows of the global state (default: the scenario's number of aircraft);
        ``reset(options=...)`` may not ask for more.
    state_scale_m : metres that map to ±1 in the global state's positions (default: 1.5 ×
        the farthest start position or waypoint from the origin, rounded up to 10 km).
    """

    metadata = {
        "render_modes": ["human", "rgb_array"],
        "name": "airspace_sim_v0",
        "is_parallelizable": True,
        "render_fps": RENDER_FPS,
    }

    def __init__(
        self,
        scenario="head_on",
        render_mode: str | None = None,
        max_cycles: int | None = None,
        overrides=(),
        seed: int | None = None,
        n_intruders: int = 5,
        discrete_actions: bool = False,
        reward: dict | None = None,
        agents=None,
        render_size: tuple[int, int] = (800, 800),
        ended: str = "resolver",
        max_aircraft: int | None = None,
        state_scale_m: float | None = None,
    ):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise UserError(
                f"render_mode: expected one of {', '.join(self.metadata['render_modes'])} "
                f"or None, got {render_mode!r}"
            )
        n_intruders = checks.integer(n_intruders, "n_intruders", 0, 1000)
        if max_cycles is not None:
            max_cycles = checks.integer(max_cycles, "max_cycles", 1, 10**9)
        self.discrete_actions = checks.flag(discrete_actions, "discrete_actions")
        self.ended = checks.one_of(ended, "ended", ENDED)
        seed = checks.seed(seed, "seed")
        try:
            w, h = render_size
            self.render_size = (checks.integer(w, "render_size", 16, 8192),) + (
                checks.integer(h, "render_size", 16, 8192),
            )
        except (TypeError, ValueError) as exc:
            if isinstance(exc, UserError):
                raise
            raise UserError(f"render_size: expected (width, height), got {render_size!r}") from None
        self._overrides = [overrides] if isinstance(overrides, str) else list(overrides or ())
        self.scenario = load_scenario(scenario, self._overrides)
        self._agents_arg = agents
        self.possible_agents = agent_ids(self.scenario, agents)
        self.render_mode = render_mode
        self.max_cycles = max_cycles if max_cycles is not None else self.scenario.n_steps
        self.reward_weights = rw.merge_weights(reward)
        self._term_names = list(rw.TERMS)
        self._weights = np.array([self.reward_weights[t] for t in rw.TERMS], dtype=float)
        self._default_seed = self.scenario.seed if seed is None else seed
        self._seed_rng = None  # draws world seeds for reset(seed=None) after the first
        self._renderer = None
        self._variants = {(): self.scenario}  # reset options -> scenario

        self.world = w = self._make_world(self.scenario, self._default_seed)
        self._agent_set = frozenset(self.possible_agents)
        rate = {a: float(w.max_turn_rate[w.ids.index(a)]) for a in self.possible_agents}
        self._max_rate = rate
        self.max_aircraft = (
            w.n if max_aircraft is None else checks.integer(max_aircraft, "max_aircraft", w.n)
        )
        if state_scale_m is None:
            far = max(
                [float(np.abs(s.position).max()) for s in w.specs]
                + [float(np.abs(p).max()) for s in w.specs for p in s.waypoints]
                + [1.0]
            )
            state_scale_m = 10_000.0 * math.ceil(1.5 * far / 10_000.0)
        self.state_scale_m = checks.positive_number(state_scale_m, "state_scale_m")
        self.observation_layout = sp.ObservationLayout(
            n_intruders=n_intruders,
            n_modes=w.tracks.n_modes,
            sensor_range=w.sensor_range,
            r_safe=w.r_safe,
            lookahead=float(w.lookahead),
        )
        # spaces are built once: observation_space(a) returns the same object every call
        obs_space = self.observation_layout.space()
        act_space = sp.action_space(self.discrete_actions)
        self.observation_spaces = {a: obs_space for a in self.possible_agents}
        self.action_spaces = {a: act_space for a in self.possible_agents}
        f = len(STATE_NAMES)
        low = np.tile(np.array(STATE_LOW, np.float32), self.max_aircraft)
        self.state_space = spaces.Box(low, np.ones(f * self.max_aircraft, np.float32))
        self.agents = []
        self._reset_done = False

    # ---------------------------------------------------------------- spaces
    def observation_space(self, agent):
        return self.observation_spaces[agent]

    def action_space(self, agent):
        return self.action_spaces[agent]

    # ----------------------------------------------------------------- world
    def _make_world(self, scenario, seed):
        """A world of ``scenario`` at ``seed`` whose agents are the possible agents in it."""
        from airspace_sim.scenarios import build_aircraft
        from airspace_sim.world import World

        specs = build_aircraft(scenario, np.random.default_rng(seed))
        agents = set(self.possible_agents)
        for s in specs:
            s.controlled = s.id in agents
        return World(scenario, seed=seed, aircraft=specs)

    def _variant(self, options) -> Any:
        """The scenario for ``reset(options=...)`` (see :data:`RESET_OPTIONS`), cached."""
        if options is None:
            return self.scenario
        if not isinstance(options, dict):
            raise UserError(f"reset: options: expected a dict or None, got {options!r}")
        unknown = [k for k in options if k not in RESET_OPTIONS]
        if unknown:  # ignored, as Gymnasium envs ignore options they do not know
            import gymnasium

            gymnasium.logger.warn(
                f"reset: options: unknown key {unknown[0]!r} ignored "
                f"(known: {', '.join(RESET_OPTIONS)})"
            )
        sc = self.scenario
        extra = []
        if options.get("traffic_count") is not None:
            n = checks.integer(options["traffic_count"], "reset: options.traffic_count", 1)
            extra.append(f"traffic.count={n}")
        if options.get("sensor_sigma") is not None:
            sigma = options["sensor_sigma"]
            if isinstance(sigma, bool) or not isinstance(sigma, (int, float, np.number)):
                raise UserError(f"reset: options.sensor_sigma: expected metres, got {sigma!r}")
            extra.append(f"sensor.sigma={float(sigma)!r}")
        if options.get("density") is not None:
            dens = checks.positive_number(options["density"], "reset: options.density")
            if sc.traffic.pattern != "random":
                raise UserError(
                    "reset: options.density: needs a scenario with traffic.pattern 'random', "
                    f"got {sc.traffic.pattern!r}"
                )
            count = options.get("traffic_count") or sc.traffic.count
            extra.append(f"traffic.sector={math.sqrt(count / dens * 1e9)!r}")
        ov = options.get("overrides") or ()
        ov = [ov] if isinstance(ov, str) else list(ov)
        if not all(isinstance(o, str) for o in ov):
            raise UserError(f"reset: options.overrides: expected 'key=value' strings, got {ov!r}")
        key = tuple(extra + ov)
        if key in self._variants:
            return self._variants[key]
        variant = load_scenario(sc, list(key)) if key else sc
        from airspace_sim.scenarios import build_aircraft

        ids = [a.id for a in build_aircraft(variant, np.random.default_rng(variant.seed))]
        if len(ids) > self.max_aircraft:
            raise UserError(
                f"reset: options: {len(ids)} aircraft, more than max_aircraft "
                f"({self.max_aircraft}, the global state's rows)"
            )
        if not set(ids) & set(self.possible_agents):
            raise UserError(f"reset: options: none of the agents is in the scenario, got {key}")
        self._variants[key] = variant
        return variant

    def _route_state(self):
        """Route state of the live world's aircraft, (N,) arrays: ``(index, done, cross m,
        bearing rad, distance m)`` as :meth:`RouteAutopilot.route_geometry` (index 0, not
        done, NaN distance for aircraft that fly another autopilot), and (N,) metres of
        route covered (0 for aircraft without a route), both from
        :meth:`RouteAutopilot.route_state`."""
        w = self.world
        state = w.flight_state()
        if self._route_everyone:  # one route autopilot flies every aircraft, in order
            g = self._route_aps[0][1].route_state(state)
            return g[:5], g[5]
        n = w.n
        index, done = np.zeros(n, np.int64), np.zeros(n, bool)
        cross, bearing, dist = np.zeros(n), np.zeros(n), np.full(n, np.nan)
        covered = np.zeros(n)
        for members, ap in self._route_aps:
            g = ap.route_state(state)
            index[members], done[members], cross[members], bearing[members] = g[:4]
            dist[members], covered[members] = g[4], g[5]
        return (index, done, cross, bearing, dist), covered

    # ----------------------------------------------------------------- reset
    def reset(self, seed: int | None = None, options: dict | None = None):
        """Start an episode. ``seed``: Gymnasium's rules (:func:`.checks.seed`); the same
        seed gives the same episode bit for bit. ``options``: see :data:`RESET_OPTIONS`."""
        seed = checks.seed(seed, "reset: seed")
        scenario = self._variant(options)
        if seed is not None:
            world_seed = seed
            self._seed_rng, _ = seeding.np_random(world_seed)
        elif self._seed_rng is None:
            world_seed = self._default_seed
            self._seed_rng, _ = seeding.np_random(world_seed)
        else:
            world_seed = int(self._seed_rng.integers(2**31 - 1))
        self.world = w = self._make_world(scenario, world_seed)
        self.world_seed = world_seed
        self._reset_done = True
        self._index = {aid: i for i, aid in enumerate(w.ids)}
        self.agents = [a for a in self.possible_agents if a in self._index]
        self._route_aps = [(m, ap) for m, ap in w.autopilots if isinstance(ap, RouteAutopilot)]
        self._route_everyone = len(self._route_aps) == 1 and np.array_equal(
            self._route_aps[0][0], np.arange(w.n)
        )
        planned = np.zeros(w.n)
        for members, ap in self._route_aps:
            planned[members] = ap.planned
        self._planned = planned
        self._idx_of = {}  # tuple of agents -> ((A,) aircraft indices, all in order)
        # per-world constants of the observations and rewards
        rate = w.max_turn_rate
        self._per_step = rate * w.dt
        self._turns = rate > 0
        self.num_cycles = 0
        self._route, self._covered = self._route_state()
        if self._renderer is not None:
            self._renderer.reset()
        obs = self._observe_all(self.agents)
        idx = self._indices(self.agents)
        infos = self._infos(self.agents, idx)
        zero = rw.weighted_terms(self.reward_weights, {})
        for info in infos.values():
            info["reward_terms"] = dict(zero)
            info["arrived"] = False
        return obs, infos

    # ------------------------------------------------------------------ step
    def step(self, actions: dict):
        """One world step. ``actions``: ``{agent: action}`` (see :mod:`.spaces`); an agent
        left out, or given ``None``, flies the built-in pilot this step."""
        if not self._reset_done:
            raise checks.ResetNeeded("step: cannot call step() before calling reset()")
        if not isinstance(actions, dict):
            raise checks.ActionError(
                f"step: expected a dict {{agent: action}}, got {type(actions).__name__}"
            )
        unknown = [a for a in actions if a not in self._agent_set]
        if unknown:
            raise checks.ActionError(
                f"actions: unknown agent {unknown[0]!r} (agents: {', '.join(self.possible_agents)})"
            )
        if not self.agents:  # every agent ended: SuperSuit's black_death_v3 steps once more
            return {}, {}, {}, {}, {}
        w = self.world
        acting = list(self.agents)
        idx, everyone = self._indices_full(acting)
        # every aircraft in order: views instead of gathers (the same values)
        sel = slice(None) if everyone else idx
        frac = self._decode(acting, actions)
        rates = np.empty(w.n)
        sp.turn_rates_into(frac, idx, w.max_turn_rate, rates)
        w.step(rates)
        self.num_cycles += 1

        self._route, covered = self._route_state()
        done = self._route[1]
        A = idx.size
        weighted = np.empty((A, len(rw.TERMS)))  # (A, terms) in TERMS order
        nearest, ended = np.empty(A), np.empty(A, dtype=bool)
        rw.step_terms(
            idx,
            self._weights,
            w.positions,
            *w.airspace.pair_arrays(LOS),
            w.r_safe,
            w.nmac_distance,
            w.nmac,
            w.conflict,
            self._turns,
            w.turn_rates,
            w.max_turn_rate,
            w.speeds,
            w.dt,
            covered,
            self._covered,
            self._planned,
            done,
            w.active,
            self.max_cycles - self.num_cycles + 1,
            weighted,
            nearest,
            ended,
        )
        self._covered = covered
        done = done[sel]
        truncated = self.num_cycles >= self.max_cycles
        names = self._term_names
        total = weighted.sum(axis=1).tolist()
        weighted = weighted.tolist()
        ended = ended.tolist()
        nearest = nearest.tolist()
        arrived = done.tolist()
        time, step, cols = self._info_columns(sel)
        rewards, terms, truncs, infos = {}, {}, {}, {}
        for k, (a, (c, los, nm, adv, wp)) in enumerate(zip(acting, cols)):
            rewards[a] = total[k]
            terms[a] = ended[k]
            truncs[a] = truncated and not ended[k]
            # the keys of _infos, then the step's
            infos[a] = {
                "time": time,
                "step": step,
                "conflict": c,
                "in_los": los,
                "nmac": nm,
                "advice": adv,
                "waypoint_index": wp,
                "reward_terms": dict(zip(names, weighted[k])),
                "arrived": arrived[k],
                "separation_m": nearest[k],
            }
        obs = self._observe_all(acting)
        self.agents = [a for a in acting if not (terms[a] or truncs[a])]
        if self.ended == "leave":
            gone = [self._index[a] for a in acting if terms[a] or truncs[a]]
            if gone:
                w.retire(gone)
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terms, truncs, infos

    def _indices(self, agents) -> np.ndarray:
        """(A,) int64 world indices of ``agents`` (kept per list of agents: read-only)."""
        return self._indices_full(agents)[0]

    def _indices_full(self, agents) -> tuple[np.ndarray, bool]:
        """``(idx, full)``: :meth:`_indices` and whether they are every aircraft in order."""
        key = tuple(agents)
        got = self._idx_of.get(key)
        if got is None:
            idx = np.array([self._index[a] for a in agents], dtype=np.int64)
            idx.flags.writeable = False
            got = self._idx_of[key] = (idx, np.array_equal(idx, np.arange(self.world.n)))
        return got

    def _decode(self, acting, actions) -> np.ndarray:
        """(A,) turn fractions (NaN: built-in) of the acting agents' actions. The common
        case, one float32 or float64 array of shape (1,) per agent as vector envs send, is
        checked in one go (:func:`.spaces.fractions_into`); anything else goes through
        :func:`.spaces.decode_action` one by one."""
        got = [actions.get(a) for a in acting]
        one = (1,)
        if not self.discrete_actions and all(
            type(g) is np.ndarray and g.shape == one and g.dtype.char in "fd" for g in got
        ):
            frac = np.empty(len(got))
            if not got or sp.fractions_into(np.concatenate(got), frac):
                return frac
        return np.array(
            [sp.decode_action(a, g, self.discrete_actions) for a, g in zip(acting, got)]
        )

    # ----------------------------------------------------------- observation
    def _observe_all(self, agents) -> dict:
        """Observations of ``agents`` (see :mod:`.spaces` for the layout), batched into one
        (A, size) buffer: the own block by :func:`.spaces.encode_own_rows`, the intruder
        block by :func:`.spaces.encode_intruders_into`."""
        agents = list(agents)
        if not agents:
            return {}
        w = self.world
        lay = self.observation_layout
        idx, everyone = self._indices_full(agents)
        sel = slice(None) if everyone else idx  # views instead of gathers (same values)
        pos, vel = w.positions[sel], w.velocities[sel]
        heading = w.headings[sel]
        _, _, cross, bearing, dist = self._route
        rel_b = np.empty(idx.size)
        relative_bearings(bearing, idx, heading, rel_b)
        obs = np.empty((idx.size, lay.size))
        sp.encode_own_rows(
            idx,
            w.speeds,
            w.turn_rates,
            w.max_turn_rate,
            self._per_step,
            w.advice,
            cross,
            dist,
            w.conflict,
            w.in_los,
            np.sin(heading),
            np.cos(heading),
            rel_b,
            np.sin(rel_b),
            np.cos(rel_b),
            10 * lay.r_safe,
            2 * lay.sensor_range,
            obs,
        )
        tr = live_tracks(w)
        if everyone:  # track owners are already rows of this batch
            rows = slice(None)
            slot = tr.owner
        else:
            slot_of = np.full(w.n, -1, dtype=np.int64)  # aircraft -> row in this batch
            slot_of[idx] = np.arange(idx.size)
            rows = np.flatnonzero(slot_of[tr.owner] >= 0)
            slot = slot_of[tr.owner[rows]]
        sp.encode_intruders_into(
            lay, slot, pos, vel, heading, tr.x[rows], tr.P[rows], tr.mu[rows], obs
        )
        obs = sp.finish_in_place(lay, obs)
        return dict(zip(agents, obs))

    def _info_columns(self, idx):
        """``(time s, step, rows)`` of the info dicts of the aircraft ``idx`` (an index
        array or a slice): ``rows`` yields per aircraft (conflict, in_los, nmac, advice
        rad, waypoint_index), the order of :meth:`_infos`' keys (:meth:`step` builds its
        dicts from them too)."""
        w = self.world
        cols = zip(
            w.conflict[idx].tolist(),
            w.in_los[idx].tolist(),
            w.nmac[idx].tolist(),
            w.advice[idx].tolist(),
            self._route[0][idx].tolist(),
        )
        return float(w.time), int(w.step_count), cols

    def _infos(self, agents, idx) -> dict[str, dict[str, Any]]:
        """Per-agent info dicts: time s, step, conflict, in_los, nmac, advice rad,
        waypoint_index (the caller adds reward terms); ``idx`` the agents' aircraft (an
        index array or a slice)."""
        time, step, cols = self._info_columns(idx)
        return {
            a: {
                "time": time,
                "step": step,
                "conflict": c,
                "in_los": los,
                "nmac": nm,
                "advice": adv,
                "waypoint_index": wp,
            }
            for a, (c, los, nm, adv, wp) in zip(agents, cols)
        }

    # ---------------------------------------------------------------- render
    def render(self):
        if self.render_mode is None:
            import gymnasium

            gymnasium.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human'"
            )
            return None
        if self._renderer is None:
            from airspace_sim.rendering import Renderer

            self._renderer = Renderer(*self.render_size)
        frame = self._renderer.render(self.world.snapshot())
        if self.render_mode == "human":
            self._renderer.show(frame)
            return None
        return frame

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def state(self) -> np.ndarray:
        """Global state for a centralised critic: ``(max_aircraft · 12,)`` float32 in
        :attr:`state_space`, one row per aircraft in the world's order (zero rows pad up to
        ``max_aircraft``); per row :data:`STATE_NAMES`: present (1 while the aircraft is in
        the world), absolute position / ``state_scale_m``, velocity / (2 v_ref), sin and cos
        of the heading, turn rate / its limit, live agent, in loss of separation, NMAC,
        conflict alert. Positions are clipped to ±1."""
        if not self._reset_done:
            raise checks.ResetNeeded("state: cannot call state() before calling reset()")
        w = self.world
        n = w.n
        out = np.zeros((self.max_aircraft, len(STATE_NAMES)))
        live = np.zeros(n, bool)
        live[[self._index[a] for a in self.agents]] = True
        act = w.active
        with np.errstate(invalid="ignore", divide="ignore"):
            rate = np.where(w.max_turn_rate > 0, w.turn_rates / w.max_turn_rate, 0.0)
        cols = [
            np.ones(n),
            w.positions[:, 0] / self.state_scale_m,
            w.positions[:, 1] / self.state_scale_m,
            w.velocities[:, 0] / (2 * sp.V_REF),
            w.velocities[:, 1] / (2 * sp.V_REF),
            np.sin(w.headings),
            np.cos(w.headings),
            rate,
            live,
            w.in_los,
            w.nmac,
            w.conflict,
        ]
        out[:n] = np.where(act[:, None], np.stack(cols, axis=1), 0.0)
        low = np.array(STATE_LOW, float)
        return np.clip(out, low, 1.0).astype(np.float32).reshape(-1)

    # ---------------------------------------------------------------- pickling
    def __getstate__(self) -> dict:
        """Everything but the renderer (pygame fonts and surfaces do not pickle): a pickled
        or deep-copied env makes a new one at its first ``render()``, so its first frame
        has no trails from before the copy. The world pickles itself."""
        state = self.__dict__.copy()
        state["_renderer"] = None
        return state
