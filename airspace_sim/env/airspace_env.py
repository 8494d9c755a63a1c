"""The PettingZoo :class:`~pettingzoo.ParallelEnv` over :class:`airspace_sim.world.World`.

Agents are the aircraft the scenario marks ``controlled``; every other aircraft is
background traffic flown by the world's autopilots and resolver. Each agent commands a
heading rate (rad/s) every step; see :mod:`.spaces` for the observation layout and action
spaces and :mod:`.rewards` for the reward terms.

An agent's episode ends (``terminations``) on an NMAC, on reaching its route's last
waypoint, or when the world takes the aircraft out of play; every agent is truncated after
``max_cycles`` steps. Agents that ended leave ``env.agents``; their aircraft is then flown
by the world's built-in autopilot and resolver.

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

RENDER_FPS = 10


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


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
        return {
            f.name: _as_table(getattr(obj, f.name))
            for f in dataclasses.fields(obj)
            if f.name != "source"
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
    capture_radius : metres within which a route waypoint counts as reached (at least one
        step's travel; a waypoint passed abeam counts as reached too, as in the world).
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
        capture_radius: float = 1000.0,
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
        self.capture_radius = float(capture_radius)
        self.render_size = tuple(int(v) for v in render_size)
        self._default_seed = self.scenario.seed if seed is None else int(seed)
        self._seed_rng = None  # draws world seeds for reset(seed=None) after the first
        self._renderer = None

        self.world = self._make_world(self._default_seed)
        w = self.world
        self._index = {aid: i for i, aid in enumerate(w.ids)}
        controlled = np.asarray(w.controlled, dtype=bool)
        self.possible_agents = [aid for aid, c in zip(w.ids, controlled) if c]
        if not self.possible_agents:
            raise UserError(f"{self.scenario.source}: no controlled aircraft to be agents")
        self._agent_idx = np.array([self._index[a] for a in self.possible_agents], dtype=int)
        self._max_rate = {
            a: float(np.asarray(w.max_turn_rate)[self._index[a]]) for a in self.possible_agents
        }
        n_modes = self._n_modes()
        sc = self.scenario
        self.observation_layout = sp.ObservationLayout(
            n_intruders=int(n_intruders),
            n_modes=n_modes,
            sensor_range=float(sc.sensor.range),
            r_safe=float(sc.separation.r_safe),
            lookahead=float(sc.resolver.lookahead),
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

    def _n_modes(self) -> int:
        tr = getattr(self.world, "tracks", None)
        if tr is not None:
            return int(tr.n_modes)
        from airspace_sim.dynamics import presets

        try:
            return presets.get(self.scenario.tracker.model).n_modes
        except UserError:
            return 3

    def _routes(self):
        """Per agent: list of waypoints (m) and the start of the first leg."""
        specs = getattr(self.world, "specs", None)
        if specs is None:
            from airspace_sim.scenarios import build_aircraft

            specs = build_aircraft(self.scenario, self.scenario.seed)
        by_id = {getattr(s, "id", None): s for s in specs}
        routes = {}
        for a in self.possible_agents:
            s = by_id.get(a)
            wps = [tuple(map(float, p)) for p in getattr(s, "waypoints", [])] if s else []
            routes[a] = wps
        return routes

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
        w = self.world
        self._routes_wp = self._routes()
        self._wp_index = dict.fromkeys(self.possible_agents, 0)
        pos = np.asarray(w.positions, dtype=float)
        self._leg_start = {a: tuple(pos[self._index[a]]) for a in self.possible_agents}
        self._prev_heading = np.asarray(w.headings, dtype=float).copy()
        self._turn_rate = np.zeros(len(w.ids))
        self._prev_dist = {a: self._route_geometry(a)[2] for a in self.possible_agents}
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
        n = len(w.ids)
        rates = np.full(n, np.nan)
        commanded = {}
        for a in self.agents:
            if a in actions and actions[a] is not None:
                r = sp.decode_action(a, actions[a], self._max_rate[a], self.discrete_actions)
                rates[self._index[a]] = r
                commanded[a] = r
        unknown = [a for a in actions if a not in self._index or a not in self.possible_agents]
        if unknown:
            raise UserError(
                f"actions: unknown agent {unknown[0]!r} (agents: {', '.join(self.possible_agents)})"
            )
        w.step(rates)
        self.num_cycles += 1
        heading = np.asarray(w.headings, dtype=float)
        flown = getattr(w, "turn_rates", None)
        if flown is not None:
            self._turn_rate = np.asarray(flown, dtype=float).copy()
        else:
            self._turn_rate = _wrap(heading - self._prev_heading) / float(w.dt)
        self._prev_heading = heading.copy()

        acting = list(self.agents)
        nmac = np.asarray(w.nmac, dtype=bool)
        los = np.asarray(w.in_los, dtype=bool)
        conflict = np.asarray(w.conflict, dtype=bool)
        active = np.asarray(w.active, dtype=bool)
        rewards, terms, truncs, infos = {}, {}, {}, {}
        for a in acting:
            i = self._index[a]
            arrived = self._advance_route(a)
            cross, _, dist, has_wp = self._route_geometry(a)
            prev = self._prev_dist[a]
            progress = 0.0
            if has_wp and prev is not None and dist is not None and not arrived:
                progress = (prev - dist) / (sp.V_REF * float(w.dt))
            self._prev_dist[a] = dist
            rate = commanded.get(a, self._turn_rate[i])
            values = {
                "los": 0.0 - los[i],
                "nmac": 0.0 - nmac[i],
                "conflict": 0.0 - conflict[i],
                "heading_change": -((rate / self._max_rate[a]) ** 2) if self._max_rate[a] else 0,
                "deviation": -min(abs(cross) / self.scenario.separation.r_safe, 1.0),
                "progress": float(progress),
                "arrival": float(arrived),
            }
            t = rw.weighted_terms(self.reward_weights, values)
            rewards[a] = float(sum(t.values()))
            terms[a] = bool(nmac[i] or arrived or not active[i])
            truncs[a] = bool(self.num_cycles >= self.max_cycles)
            info = self._base_info(a)
            info["reward_terms"] = t
            info["arrived"] = bool(arrived)
            infos[a] = info
        self.agents = [a for a in acting if not (terms[a] or truncs[a])]
        obs = self._observe_all(acting)
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terms, truncs, infos

    # ----------------------------------------------------------------- route
    def _route_geometry(self, a):
        """(cross-track m, bearing to waypoint rad, distance m or None, has waypoint)."""
        i = self._index[a]
        wps = self._routes_wp[a]
        k = self._wp_index[a]
        if k >= len(wps):
            return 0.0, 0.0, None, False
        p = np.asarray(self.world.positions, dtype=float)[i]
        wp = np.asarray(wps[k])
        start = np.asarray(self._leg_start[a]) if k == 0 else np.asarray(wps[k - 1])
        leg = wp - start
        L = float(np.hypot(*leg))
        d = wp - p
        dist = float(np.hypot(*d))
        cross = 0.0 if L < 1e-9 else float((leg[0] * (p - start)[1] - leg[1] * (p - start)[0]) / L)
        return cross, math.atan2(d[1], d[0]), dist, True

    def _advance_route(self, a) -> bool:
        """Move on to the next waypoint once reached; True on reaching the last one.

        As the world's route autopilot: a waypoint is reached within
        max(capture_radius, one step's travel) of it, or once passed abeam (beyond the
        line through it perpendicular to the leg).
        """
        wps = self._routes_wp[a]
        if not wps or self._wp_index[a] >= len(wps):
            return False
        i = self._index[a]
        p = np.asarray(self.world.positions, dtype=float)[i]
        reach = max(
            self.capture_radius, float(np.asarray(self.world.speeds)[i]) * float(self.world.dt)
        )
        arrived = False
        while self._wp_index[a] < len(wps):
            k = self._wp_index[a]
            wp = np.asarray(wps[k])
            prev = np.asarray(self._leg_start[a]) if k == 0 else np.asarray(wps[k - 1])
            to_wp = wp - p
            passed = float(np.dot(to_wp, wp - prev)) < 0.0
            if np.hypot(*to_wp) > reach and not passed:
                break
            self._wp_index[a] += 1
            self._prev_dist[a] = None
            if self._wp_index[a] >= len(wps):
                arrived = True
        return arrived

    # ----------------------------------------------------------- observation
    def _observe(self, a) -> np.ndarray:
        return self._observe_all([a])[a]

    def _observe_all(self, agents) -> dict:
        """Observations of ``agents`` (see :mod:`.spaces` for the layout), batched."""
        agents = list(agents)
        if not agents:
            return {}
        w = self.world
        lay = self.observation_layout
        idx = np.array([self._index[a] for a in agents], dtype=np.int64)
        pos = np.asarray(w.positions, dtype=float)[idx]
        vel = np.asarray(w.velocities, dtype=float)[idx]
        heading = np.asarray(w.headings, dtype=float)[idx]
        speed = np.asarray(w.speeds, dtype=float)[idx]
        advice = np.asarray(w.advice, dtype=float)[idx]
        max_rate = np.array([self._max_rate[a] for a in agents])
        geo = [self._route_geometry(a) for a in agents]
        cross = np.array([g[0] for g in geo])
        rel_b = np.array([g[1] for g in geo]) - heading
        has_wp = np.array([g[3] for g in geo], dtype=bool)
        dist = np.array([g[2] if g[3] else 0.0 for g in geo])
        with np.errstate(invalid="ignore", divide="ignore"):
            rate = np.where(max_rate > 0, self._turn_rate[idx] / max_rate, 0.0)
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
                np.asarray(w.conflict, dtype=float)[idx],
                np.asarray(w.in_los, dtype=float)[idx],
            ],
            axis=1,
        )
        tr = w.tracks.view()
        owner = np.asarray(tr.owner, dtype=np.int64)
        slot_of = np.full(len(w.ids), -1, dtype=np.int64)
        slot_of[idx] = np.arange(len(idx))
        rows = np.flatnonzero(slot_of[owner] >= 0) if owner.size else owner
        mu = np.asarray(tr.mu)
        intr = sp.encode_intruders_batch(
            lay,
            slot_of[owner[rows]],
            pos,
            vel,
            heading,
            np.asarray(tr.x)[rows],
            np.asarray(tr.P)[rows],
            mu[rows] if mu.ndim == 2 else np.zeros((len(rows), 0)),
        )
        obs = sp.finish(lay, own, intr)
        return {a: obs[k] for k, a in enumerate(agents)}

    def _base_info(self, a) -> dict[str, Any]:
        w = self.world
        i = self._index[a]
        return {
            "time": float(w.time),
            "step": int(w.step_count),
            "conflict": bool(np.asarray(w.conflict)[i]),
            "in_los": bool(np.asarray(w.in_los)[i]),
            "nmac": bool(np.asarray(w.nmac)[i]),
            "advice": float(np.asarray(w.advice, dtype=float)[i]),
            "waypoint_index": int(self._wp_index[a]),
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
