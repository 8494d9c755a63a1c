"""The PettingZoo :class:`~pettingzoo.ParallelEnv` over :class:`airspace_sim.world.World`.

Agents are the aircraft the scenario marks ``controlled``; every other aircraft is
background traffic flown by the world's autopilots and resolver. Each agent commands a
heading rate (rad/s) every step; see :mod:`.spaces` for the observation layout and action
spaces and :mod:`.rewards` for the reward terms.

An agent's episode ends (``terminations``) on an NMAC, on reaching its route's last
waypoint, or when the world takes the aircraft out of play; every agent is truncated after
``max_cycles`` steps. Agents that ended leave ``env.agents``; their aircraft is then flown
by the world's built-in autopilot and resolver.

The env is a thin layer over :class:`~airspace_sim.world.World`: route progress (waypoint,
cross-track error, bearing and distance to the waypoint, arrival) is the world's route
autopilot's (:meth:`RouteAutopilot.route_geometry`, its capture rule: within one step's
travel of the waypoint or past it abeam); ``r_safe``, the sensor range and the resolver
look-ahead that scale the observations are the world's. An agent whose autopilot is not
``route`` has no waypoint (``has_waypoint`` 0, no progress or deviation terms).

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

from airspace_sim.env import rewards as rw
from airspace_sim.env import spaces as sp
from airspace_sim.errors import UserError
from airspace_sim.world.autopilots import RouteAutopilot
from airspace_sim.world.snapshot import live_tracks

RENDER_FPS = 10


def load_scenario(scenario, overrides=()):
    """A :class:`Scenario` from a name, a path or a Scenario object (with overrides)."""
    from airspace_sim.scenarios import Scenario, from_dict, load

    overrides = [overrides] if isinstance(overrides, str) else list(overrides or ())
    if isinstance(scenario, Scenario):
        if not overrides:
            return scenario
        data = _as_table(scenario)
        return from_dict(data, source=scenario.source, overrides=overrides)
    if isinstance(scenario, (str, os.PathLike)):
        return load(scenario, overrides)
    raise UserError(
        f"scenario: expected a scenario name, a path or a Scenario, got {type(scenario).__name__}"
    )


def _as_table(obj):
    """A Scenario as the TOML-like table the loader reads."""
    if dataclasses.is_dataclass(obj):
        from airspace_sim.scenarios.loader import INTERNAL_FIELDS

        return {
            f.name: _as_table(getattr(obj, f.name))
            for f in dataclasses.fields(obj)
            if (type(obj).__name__, f.name) not in INTERNAL_FIELDS
        }
    if isinstance(obj, (list, tuple)):
        return [_as_table(v) for v in obj]
    if isinstance(obj, dict):
        return {k: _as_table(v) for k, v in obj.items()}
    return obj


def select_agents(scenario, agents=None):
    """The scenario with its ``controlled`` marks set by ``agents``.

    ``agents`` None keeps the scenario's marks, or, if it marks none, controls the first
    aircraft. An int n controls the first n aircraft (hand-placed, then generated); a list
    of ids controls exactly those (hand-placed or generated ``traffic`` ids are both
    accepted as long as the generated ones are the first of the traffic).
    """
    from airspace_sim.scenarios import build_aircraft

    hand = list(scenario.aircraft)
    t = scenario.traffic
    n_gen = t.count if t.pattern != "none" else 0
    n_total = len(hand) + n_gen
    if agents is None:
        if any(a.controlled for a in hand) or (n_gen and t.controlled > 0):
            return scenario
        agents = 1
    if isinstance(agents, (int, np.integer)) and not isinstance(agents, bool):
        n = int(agents)
        if not 1 <= n <= n_total:
            raise UserError(f"agents: expected 1..{n_total} aircraft, got {n}")
        new_hand = [dataclasses.replace(a, controlled=i < n) for i, a in enumerate(hand)]
        n_gen_ctrl = max(0, n - len(hand))
    else:
        wanted = [str(a) for a in agents]
        if not wanted:
            raise UserError("agents: expected at least one aircraft id, got none")
        ids = [a.id for a in build_aircraft(scenario, scenario.seed)]
        unknown = [a for a in wanted if a not in ids]
        if unknown:
            raise UserError(f"agents: unknown aircraft {unknown[0]!r} (known: {', '.join(ids)})")
        new_hand = [dataclasses.replace(a, controlled=a.id in wanted) for a in hand]
        gen_ids = ids[len(hand) :]
        chosen = [i for i, a in enumerate(gen_ids) if a in wanted]
        n_gen_ctrl = len(chosen)
        if chosen and chosen != list(range(n_gen_ctrl)):
            raise UserError(
                f"agents: generated aircraft can be agents only from the first one "
                f"({gen_ids[0]}) on, got {', '.join(gen_ids[i] for i in chosen)}"
            )
    traffic = dataclasses.replace(t, controlled=min(n_gen_ctrl, n_gen))
    return dataclasses.replace(scenario, aircraft=new_hand, traffic=traffic)


class AirspaceParallelEnv(ParallelEnv):
    """Multi-agent airspace env (PettingZoo parallel API).

    Parameters
    ----------
    scenario : a scenario name (file stem in ``scenarios/``), a path or a Scenario.
    render_mode : "rgb_array", "human" or None.
    max_cycles : steps before every agent is truncated; None = the scenario's duration.
    overrides : list of ``"key=value"`` applied to the scenario (as ``--set``).
    seed : default world seed for the first ``reset()`` without a seed (None = the
        scenario's seed).
    n_intruders : K, number of intruder rows in the observation.
    discrete_actions : Discrete(5) actions instead of a continuous turn rate.
    reward : dict of reward term weights (see :mod:`airspace_sim.env.rewards`).
    agents : which aircraft are agents (see :func:`select_agents`).
    render_size : (width, height) of rendered frames in pixels.
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
    ):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise UserError(
                f"render_mode: expected one of {', '.join(self.metadata['render_modes'])} "
                f"or None, got {render_mode!r}"
            )
        if int(n_intruders) < 0:
            raise UserError(f"n_intruders: expected a non-negative integer, got {n_intruders}")
        if max_cycles is not None and int(max_cycles) < 1:
            raise UserError(f"max_cycles: expected a positive integer, got {max_cycles}")
        self.scenario = select_agents(load_scenario(scenario, overrides), agents)
        self.render_mode = render_mode
        self.max_cycles = int(max_cycles) if max_cycles is not None else self.scenario.n_steps
        self.discrete_actions = bool(discrete_actions)
        self.reward_weights = rw.merge_weights(reward)
        self.render_size = tuple(int(v) for v in render_size)
        self._default_seed = self.scenario.seed if seed is None else int(seed)
        self._seed_rng = None  # draws world seeds for reset(seed=None) after the first
        self._renderer = None

        self.world = w = self._make_world(self._default_seed)
        self._index = {aid: i for i, aid in enumerate(w.ids)}
        self.possible_agents = [aid for aid, c in zip(w.ids, w.controlled) if c]
        if not self.possible_agents:
            raise UserError(f"{self.scenario.source}: no controlled aircraft to be agents")
        self._agent_idx = np.array([self._index[a] for a in self.possible_agents], dtype=np.int64)
        self._slot = {a: k for k, a in enumerate(self.possible_agents)}  # row in _route arrays
        self._max_rate = {a: float(w.max_turn_rate[self._index[a]]) for a in self.possible_agents}
        self.observation_layout = sp.ObservationLayout(
            n_intruders=int(n_intruders),
            n_modes=w.tracks.n_modes,
            sensor_range=w.sensor_range,
            r_safe=w.r_safe,
            lookahead=float(w.lookahead),
        )
        # spaces are built once: observation_space(a) returns the same object every call
        self.observation_spaces = {a: self.observation_layout.space() for a in self.possible_agents}
        self.action_spaces = {
            a: sp.action_space(self._max_rate[a], self.discrete_actions)
            for a in self.possible_agents
        }
        low, high = self.observation_layout.bounds()
        n_ag = len(self.possible_agents)
        self.state_space = spaces.Box(np.tile(low, n_ag), np.tile(high, n_ag), dtype=np.float32)
        self.agents = []

    # ---------------------------------------------------------------- spaces
    def observation_space(self, agent):
        return self.observation_spaces[agent]

    def action_space(self, agent):
        return self.action_spaces[agent]

    # ----------------------------------------------------------------- world
    def _make_world(self, seed):
        from airspace_sim.world import World

        return World(self.scenario, seed=seed)

    def _route_progress(self):
        """Route geometry of every possible agent from the world's route autopilots, (A,)
        arrays in ``possible_agents`` order: ``(index, done, cross_track m, bearing rad,
        distance m)`` as :meth:`RouteAutopilot.route_geometry` (index 0, not done, no
        waypoint ahead for an agent that flies another autopilot)."""
        w = self.world
        n = w.n
        index, done = np.zeros(n, np.int64), np.zeros(n, bool)
        cross, bearing, dist = np.zeros(n), np.zeros(n), np.full(n, np.nan)
        state = w.flight_state()
        for members, ap in w.autopilots:
            if isinstance(ap, RouteAutopilot):
                g = ap.route_geometry(state)
                index[members], done[members], cross[members], bearing[members], dist[members] = g
        i = self._agent_idx
        return index[i], done[i], cross[i], bearing[i], dist[i]

    # ----------------------------------------------------------------- reset
    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            world_seed = int(seed)
            self._seed_rng, _ = seeding.np_random(world_seed)
        elif self._seed_rng is None:
            world_seed = self._default_seed
            self._seed_rng, _ = seeding.np_random(world_seed)
        else:
            world_seed = int(self._seed_rng.integers(2**31 - 1))
        self.world = self._make_world(world_seed)
        self.world_seed = world_seed
        self.agents = list(self.possible_agents)
        self.num_cycles = 0
        self._route = self._route_progress()
        if self._renderer is not None:
            self._renderer.reset()
        obs = self._observe_all(self.agents)
        infos = {}
        for a in self.agents:
            info = self._base_info(a)
            info["reward_terms"] = rw.weighted_terms(self.reward_weights, {})
            info["arrived"] = False
            infos[a] = info
        return obs, infos

    # ------------------------------------------------------------------ step
    def step(self, actions: dict):
        if not self.agents:
            raise UserError("step() called with no live agents: call reset() first")
        w = self.world
        unknown = [a for a in actions if a not in self.possible_agents]
        if unknown:
            raise UserError(
                f"actions: unknown agent {unknown[0]!r} (agents: {', '.join(self.possible_agents)})"
            )
        rates = np.full(w.n, np.nan)
        commanded = {}
        for a in self.agents:
            if a in actions and actions[a] is not None:
                r = sp.decode_action(a, actions[a], self._max_rate[a], self.discrete_actions)
                rates[self._index[a]] = r
                commanded[a] = r
        w.step(rates)
        self.num_cycles += 1

        prev_index, prev_dist = self._route[0], self._route[4]
        self._route = self._route_progress()
        index, done, cross, _, dist = self._route
        acting = list(self.agents)
        rewards, terms, truncs, infos = {}, {}, {}, {}
        for a in acting:
            i, k = self._index[a], self._slot[a]
            arrived = bool(done[k])  # an acting agent had not finished before this step
            # distance gained toward the same waypoint (none on the step it changes)
            progress = 0.0
            if index[k] == prev_index[k] and np.isfinite(dist[k]) and np.isfinite(prev_dist[k]):
                progress = (prev_dist[k] - dist[k]) / (sp.V_REF * w.dt)
            rate = commanded.get(a, w.turn_rates[i])
            values = {
                "los": 0.0 - w.in_los[i],
                "nmac": 0.0 - w.nmac[i],
                "conflict": 0.0 - w.conflict[i],
                "heading_change": -((rate / self._max_rate[a]) ** 2) if self._max_rate[a] else 0,
                "deviation": -min(abs(cross[k]) / w.r_safe, 1.0),
                "progress": float(progress),
                "arrival": float(arrived),
            }
            t = rw.weighted_terms(self.reward_weights, values)
            rewards[a] = float(sum(t.values()))
            terms[a] = bool(w.nmac[i] or arrived or not w.active[i])
            truncs[a] = bool(self.num_cycles >= self.max_cycles)
            info = self._base_info(a)
            info["reward_terms"] = t
            info["arrived"] = arrived
            infos[a] = info
        self.agents = [a for a in acting if not (terms[a] or truncs[a])]
        obs = self._observe_all(acting)
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terms, truncs, infos

    # ----------------------------------------------------------- observation
    def _observe_all(self, agents) -> dict:
        """Observations of ``agents`` (see :mod:`.spaces` for the layout), batched."""
        agents = list(agents)
        if not agents:
            return {}
        w = self.world
        lay = self.observation_layout
        idx = np.array([self._index[a] for a in agents], dtype=np.int64)
        pos, vel = w.positions[idx], w.velocities[idx]
        heading, speed, advice = w.headings[idx], w.speeds[idx], w.advice[idx]
        max_rate = np.array([self._max_rate[a] for a in agents])
        slot = np.array([self._slot[a] for a in agents], dtype=np.int64)
        _, _, cross, bearing, dist = (g[slot] for g in self._route)
        has_wp = np.isfinite(dist)
        rel_b = bearing - heading
        dist = np.where(has_wp, dist, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            rate = np.where(max_rate > 0, w.turn_rates[idx] / max_rate, 0.0)
        own = np.stack(
            [
                speed / sp.V_REF,
                np.sin(heading),
                np.cos(heading),
                rate,
                cross / (10 * lay.r_safe),
                np.where(has_wp, np.sin(rel_b), 0.0),
                np.where(has_wp, np.cos(rel_b), 1.0),
                np.where(has_wp, dist / (2 * lay.sensor_range), 0.0),
                has_wp.astype(float),
                np.where(np.isfinite(advice), advice / math.pi, 0.0),
                w.conflict[idx].astype(float),
                w.in_los[idx].astype(float),
            ],
            axis=1,
        )
        tr = live_tracks(w)
        slot_of = np.full(w.n, -1, dtype=np.int64)  # aircraft -> row in this batch
        slot_of[idx] = np.arange(len(idx))
        rows = np.flatnonzero(slot_of[tr.owner] >= 0)
        intr = sp.encode_intruders_batch(
            lay, slot_of[tr.owner[rows]], pos, vel, heading, tr.x[rows], tr.P[rows], tr.mu[rows]
        )
        obs = sp.finish(lay, own, intr)
        return {a: obs[k] for k, a in enumerate(agents)}

    def _base_info(self, a) -> dict[str, Any]:
        w = self.world
        i = self._index[a]
        return {
            "time": float(w.time),
            "step": int(w.step_count),
            "conflict": bool(w.conflict[i]),
            "in_los": bool(w.in_los[i]),
            "nmac": bool(w.nmac[i]),
            "advice": float(w.advice[i]),
            "waypoint_index": int(self._route[0][self._slot[a]]),
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
        """Global state: every agent's observation, concatenated in ``possible_agents`` order."""
        obs = self._observe_all(self.agents)
        zero = np.zeros(self.observation_layout.size, np.float32)
        return np.concatenate([obs.get(a, zero) for a in self.possible_agents])

    # ---------------------------------------------------------------- pickling
    def __getstate__(self) -> dict:
        """Everything but the renderer (pygame fonts and surfaces do not pickle): a pickled
        or deep-copied env makes a new one at its first ``render()``, so its first frame
        has no trails from before the copy. The world pickles itself."""
        state = self.__dict__.copy()
        state["_renderer"] = None
        return state
