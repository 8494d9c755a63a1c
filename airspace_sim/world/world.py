"""The airspace world: aircraft, surveillance, tracking and conflict avoidance, stepped together.

    from airspace_sim.world import World
    world = World(scenario, seed=None)     # seed None → scenario.seed
    while world.time < scenario.duration:
        world.step()                       # or world.step(heading_rate) for RL agents
    print(world.metrics())

One step (``dt`` seconds), in this order:

1. commands: each aircraft's autopilot (``straight``, ``route``, ``markov``, or a plugin)
   gives a turn rate; an avoiding ownship in conflict turns by its resolver advice instead,
   and turns back toward its route only when that turn is clear (:mod:`.control`; policy
   knobs ``scenario.resolver.search_deg``, ``turn_preference``, ``confirm_s``,
   ``resume_margin``, ``resume_decay_s``, ``side_memory_s``); an RL agent's finite
   ``heading_rate`` overrides both. Every turn rate is clipped to the aircraft's
   ``max_turn_rate`` (so the heading changes by at most ``max_turn_rate·dt``).
2. motion: constant speed, heading ``h → h + ω·dt``; the body flies the chord of that arc
   (velocity ``v·sinc(ωdt/2)`` at heading ``h + ωdt/2``), integrated by pymunk
   (:mod:`.bodies`); pymunk's collision handlers update the pairs in loss of separation,
   NMAC and sensor range. Route aircraft past their last waypoint leave (``active`` False).
3. surveillance: at scan steps every tracking ownship (avoiding or RL) measures the
   intruders in range (:mod:`.sensors`, world-frame positions with noise σ).
4. tracking: the single batched track table (:mod:`.trackers`) steps all (ownship,
   intruder) filters, drops stale tracks and starts new ones.
5. detection: each ownship's resolver runs on its tracks → ``advice``, ``conflict`` (used
   by the next step's commands).
6. metrics (:mod:`.metrics`).

Determinism: every random number is a function of (seed, aircraft or pair, step)
(:mod:`.streams`), and nothing is shared between worlds, so a scenario and seed give the
same positions, tracks and metrics bit for bit, however worlds are interleaved.
"""

from __future__ import annotations

import math

import numpy as np

from airspace_sim import registry
from airspace_sim.dynamics import presets
from airspace_sim.errors import UserError
from airspace_sim.world import streams
from airspace_sim.world.autopilots import AutopilotContext, FlightState, wrap
from airspace_sim.world.bodies import LOS, NMAC, RANGE, Airspace
from airspace_sim.world.control import Avoidance, Encounters, gather
from airspace_sim.world.metrics import Metrics
from airspace_sim.world.trackers import TrackTable

#: Number of predicted points per track in :meth:`World.snapshot`.
PREDICTION_POINTS = 6
#: rad: an autopilot turn smaller than this per step is "on course" (a route autopilot's
#: atan2 gives ~1e-16 rad/s on a straight leg, which must not count as turning back)
TURN_TOLERANCE = 1e-9


def _predict(x: np.ndarray, horizon: float, n_points: int) -> np.ndarray:
    """Coordinated-turn extrapolation of (P, 5) states at ``horizon·k/n_points`` s, (P, S, 2)."""
    t = horizon * np.arange(1, n_points + 1) / n_points
    w = x[:, 4:5]
    wt = w * t
    s = t * np.sinc(wt / np.pi)  # sin(ωt)/ω, exact at ω = 0
    c = t * np.sin(wt / 2.0) * np.sinc(wt / (2.0 * np.pi))  # (1 − cos ωt)/ω
    px = x[:, 0:1] + x[:, 1:2] * s - x[:, 3:4] * c
    py = x[:, 2:3] + x[:, 3:4] * s + x[:, 1:2] * c
    return np.stack([px, py], axis=-1)


class World:
    """A running airspace scenario (see the module docstring for the step).

    Parameters
    ----------
    scenario : :class:`airspace_sim.scenarios.Scenario`
    seed : int, optional; default ``scenario.seed``. Seeds generated traffic
        (``build_aircraft(scenario, np.random.default_rng(seed))``), the Markov pilots,
        detections and measurement noise.
    aircraft : list of :class:`AircraftSpec`, optional; if given, used instead of
        ``build_aircraft(scenario, ...)``.

    Attributes (arrays indexed by aircraft, N = ``len(world.ids)``; read-only by convention)
    ------------------------------------------------------------------------------------
    dt, time : s.  step_count : int.  ids : list[str] (N).
    positions (N, 2) m; velocities (N, 2) m/s; headings (N,) rad CCW from east;
    speeds (N,) m/s; max_turn_rate (N,) rad/s; turn_rates (N,) rad/s flown in the last step;
    active, controlled, avoid (N,) bool; modes (N,) int true Markov mode over the last step
    (−1 for non-Markov aircraft); in_los, nmac (N,) bool; advice (N,) rad resolver heading
    change for the coming step; conflict (N,) bool; tracks : :class:`TrackTable`.
    """

    def __init__(self, scenario, seed: int | None = None, aircraft=None):
        self.scenario = sc = scenario
        self.seed = int(sc.seed if seed is None else seed)
        self.dt = float(sc.dt)
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise UserError(f"{sc.source}: dt: must be a positive number of seconds, got {sc.dt!r}")
        if aircraft is None:
            from airspace_sim.scenarios import build_aircraft

            aircraft = build_aircraft(sc, np.random.default_rng(self.seed))
        self.specs = list(aircraft)
        n = self.n = len(self.specs)
        self.ids = [a.id for a in self.specs]
        if len(set(self.ids)) != n:
            dup = next(i for i in self.ids if self.ids.count(i) > 1)
            raise UserError(f"{sc.source}: aircraft id {dup!r} is used twice")
        self.time = 0.0
        self.step_count = 0

        # --- kinematic state
        self.positions = np.array([a.position for a in self.specs], dtype=float).reshape(n, 2)
        self.headings = wrap(np.radians([a.heading_deg for a in self.specs]).astype(float))
        self.speeds = np.array([a.speed for a in self.specs], dtype=float)
        self.max_turn_rate = np.radians([a.max_turn_rate_deg for a in self.specs]).astype(float)
        self.controlled = np.array([a.controlled for a in self.specs], dtype=bool)
        self.avoid = np.array([a.avoid for a in self.specs], dtype=bool)
        self.active = np.ones(n, dtype=bool)
        self.turn_rates = np.zeros(n)
        self.flown = np.zeros(n)
        bad = (
            ~np.isfinite(self.positions).all(axis=1) | ~np.isfinite(self.speeds) | (self.speeds < 0)
        )
        bad |= ~np.isfinite(self.max_turn_rate) | (self.max_turn_rate < 0)
        if bad.any():
            a = self.specs[int(np.flatnonzero(bad)[0])]
            raise UserError(
                f"{sc.source}: aircraft {a.id!r}: position, speed and "
                f"max_turn_rate_deg must be finite and non-negative"
            )
        self.velocities = self.speeds[:, None] * np.stack(
            [np.cos(self.headings), np.sin(self.headings)], axis=1
        )
        self.r_safe = float(sc.separation.r_safe)
        self.nmac_distance = float(sc.separation.nmac)
        self.sensor_range = float(sc.sensor.range)

        # --- parts
        self.keys = streams.aircraft_keys(self.seed, n)
        self.pilot_preset = presets.get(sc.model, dt=self.dt)
        ctx = AutopilotContext(
            dt=self.dt,
            preset=self.pilot_preset,
            keys=self.keys,
            start_positions=self.positions.copy(),
        )
        self.autopilots = []  # (name, members, object)
        names = sorted({a.autopilot for a in self.specs})
        for name in names:
            factory = registry.get("autopilot", name)
            members = np.array(
                [i for i, a in enumerate(self.specs) if a.autopilot == name], dtype=np.int64
            )
            self.autopilots.append(
                (name, members, factory(members, [self.specs[i] for i in members], ctx))
            )
        self.modes = np.full(n, -1, dtype=np.int64)
        self._is_markov = np.zeros(n, dtype=bool)
        self._has_plan = np.zeros(n, dtype=bool)
        for name, members, ap in self.autopilots:
            if getattr(ap, "modes", None) is not None:
                self._is_markov[members] = True
                self.modes[members] = ap.modes
            self._has_plan[members] = name in ("route", "straight")

        self.sensor = registry.get("sensor", sc.sensor.kind)(sc.sensor, self.dt)
        self.tracker_preset = presets.get(sc.tracker.model, dt=self.dt)
        self.tracks = TrackTable.build(
            n,
            sc.tracker.kind,
            self.tracker_preset,
            sc.sensor.sigma,
            sc.sensor.drop_after_misses,
            self.sensor.period_steps * self.dt,
        )
        self.avoidance = Avoidance(sc, self.dt)
        self.trackers_on = self.controlled | self.avoid  # ownships that track intruders
        self.metrics_acc = Metrics(n, self.r_safe, self.nmac_distance, self.dt)

        self.airspace = Airspace(self.positions, self.r_safe, self.nmac_distance, self.sensor_range)
        self.in_los = np.zeros(n, dtype=bool)
        self.nmac = np.zeros(n, dtype=bool)
        self.advice = np.zeros(n)
        self.conflict = np.zeros(n, dtype=bool)
        self._following = np.zeros(n, dtype=bool)
        self.off_route_s = np.zeros(n)  # seconds since the autopilot last flew it (CDA)
        self._prev_contacts = ()  # positions, LoS and NMAC keys at the previous step
        self._side = np.zeros(n)  # committed avoidance side per aircraft: −1 right, +1 left
        self._enc = Encounters(
            np.zeros(0, np.int64),
            np.zeros((0, 0), np.int64),
            np.zeros((0, 0, 2)),
            np.zeros((0, 0, 2)),
            np.zeros((0, 0), bool),
        )
        self._after_motion(initial=True)

    # ------------------------------------------------------------------ step
    def step(self, heading_rate=None) -> None:
        """Advance the world by ``dt``.

        heading_rate : (N,) rad/s, optional. For controlled (RL) aircraft, a finite entry is
            the commanded turn rate (clipped to ±max_turn_rate); NaN = fly the built-in
            autopilot / resolver. Entries of other aircraft are ignored.
        """
        n, dt = self.n, self.dt
        state = FlightState(
            self.positions, self.headings, self.speeds, self.max_turn_rate, dt, self.step_count
        )
        ap_rate = np.zeros(n)
        desired = np.full(n, np.nan)
        for _, members, ap in self.autopilots:
            ap_rate[members] = ap.turn_rate(state)
            desired[members] = ap.desired_heading(state)
            if getattr(ap, "modes", None) is not None:
                self.modes[members] = ap.modes
        rate = ap_rate.copy()
        max_dh = self.max_turn_rate * dt

        # conflict avoidance
        follow = np.zeros(n, dtype=bool)
        resuming = np.zeros(n, dtype=bool)
        if self.avoidance.overrides:
            follow = self.avoid & self.active & self.conflict & ~self.controlled
            rate = np.where(follow, self.advice / dt, rate)
            # resume toward the autopilot's heading only if that turn is clear
            resuming = (
                self.avoid
                & self.active
                & ~self.conflict
                & ~self.controlled
                & np.isfinite(desired)
                & (np.abs(ap_rate) * dt > TURN_TOLERANCE)
            )
            enc = self._enc
            if resuming.any() and enc.owners.size:
                sub = enc.subset(resuming[enc.owners])
                if sub.owners.size:
                    clear = self.avoidance.resume_clear(
                        sub, self.velocities, ap_rate[sub.owners] * dt, max_dh, self.off_route_s
                    )
                    hold = sub.owners[~clear]
                    rate[hold] = 0.0
                    follow[hold] = True

        # RL agents
        if heading_rate is not None:
            hr = np.asarray(heading_rate, dtype=float).reshape(-1)
            if hr.shape != (n,):
                raise UserError(f"heading_rate: expected shape ({n},), got {hr.shape}")
            if np.isinf(hr).any():
                raise UserError("heading_rate: contains an infinite value (use NaN for 'built-in')")
            agent = self.controlled & np.isfinite(hr)
            rate = np.where(agent, hr, rate)
            follow &= ~agent

        rate = np.clip(rate, -self.max_turn_rate, self.max_turn_rate)
        rate[~self.active] = 0.0
        self._following = follow
        # off the route until the autopilot flies it without a pending turn back
        self.off_route_s = np.where(follow | resuming, self.off_route_s + dt, 0.0)

        # motion along the chord of the arc
        turn = rate * dt
        mid = self.headings + 0.5 * turn
        chord = self.speeds * np.sinc(turn / (2.0 * np.pi))
        v = chord[:, None] * np.stack([np.cos(mid), np.sin(mid)], axis=1)
        v[~self.active] = 0.0
        self.airspace.set_velocities(v)
        self.airspace.step(dt, self.positions)
        self.headings = wrap(self.headings + turn)
        self.turn_rates = rate
        self.flown += np.where(self.active, self.speeds * dt, 0.0)
        self.metrics_acc.avoidance_turn(turn, follow)
        self.velocities = self.speeds[:, None] * np.stack(
            [np.cos(self.headings), np.sin(self.headings)], axis=1
        )
        self.time = (self.step_count + 1) * dt
        self.step_count += 1

        # route aircraft that finished leave the world
        state = FlightState(
            self.positions, self.headings, self.speeds, self.max_turn_rate, dt, self.step_count
        )
        finished = np.zeros(n, dtype=bool)
        for _, members, ap in self.autopilots:
            finished[members] = ap.after_step(state)
        gone = finished & self.active
        if gone.any():
            self.active[gone] = False
            self.velocities[gone] = 0.0
            self.airspace.remove(np.flatnonzero(gone))
        self._after_motion(initial=False)

    def _after_motion(self, initial: bool) -> None:
        n = self.n
        sp = self.airspace
        # contacts
        self.in_los[:] = False
        self.nmac[:] = False
        for kind, flag in ((LOS, self.in_los), (NMAC, self.nmac)):
            i, j = sp.pair_arrays(kind)
            flag[i] = True
            flag[j] = True
        # surveillance
        truth = np.empty((n, 5))
        truth[:, 0], truth[:, 2] = self.positions[:, 0], self.positions[:, 1]
        truth[:, 1], truth[:, 3] = self.velocities[:, 0], self.velocities[:, 1]
        truth[:, 4] = self.turn_rates
        scanned = self.sensor.scans(self.step_count)
        if scanned:
            i, j = sp.pair_arrays(RANGE)
            owner = np.concatenate([i, j])
            intruder = np.concatenate([j, i])
            keep = self.trackers_on[owner] & self.active[owner] & self.active[intruder]
            owner, intruder = owner[keep], intruder[keep]
            pk = streams.pair_keys(self.keys, owner, intruder)
            z, det = self.sensor.measure(owner, intruder, self.positions, pk, self.step_count)
            owner, intruder, z = owner[det], intruder[det], z[det]
        else:
            owner = intruder = np.zeros(0, np.int64)
            z = np.zeros((0, 2))
        self.tracks.update(self.time, scanned, owner, intruder, z, self.active, truth)
        # detection and advice for the coming step
        runs = self.trackers_on & self.active
        t = self.tracks.view()
        ok = t.age >= self.avoidance.confirm_steps  # confirmed tracks only
        self._enc = gather(t.owner[ok], t.x[ok], self.positions, self.velocities, runs)
        self._enc_track_rows = np.flatnonzero(ok)  # enc.rows index these table rows
        self.advice, self.conflict = self.avoidance.advise(
            self._enc,
            self.velocities,
            self.max_turn_rate * self.dt,
            n,
            self._side,
            self.mode_predictions,
        )
        self.conflict &= self.active
        # metrics
        m = self.metrics_acc
        m.contacts(
            self.positions,
            sp.pairs[LOS],
            sp.began[LOS],
            sp.pairs[NMAC],
            sp.began[NMAC],
            sp.pairs[RANGE],
            *self._prev_contacts,
        )
        self._prev_contacts = (self.positions.copy(), sp.pairs[LOS].copy(), sp.pairs[NMAC].copy())
        m.conflicts(self.conflict)
        if not initial and len(t):
            x = t.x
            est_mode = true_mode = None
            mk = self._is_markov[t.intruder]
            if mk.any() and self.tracks.n_modes:
                mu = t.mu[mk]
                if mu.shape[1] == self.tracks.n_modes and np.isfinite(mu).all():
                    est_mode = np.argmax(mu, axis=1)
                    true_mode = self.modes[t.intruder[mk]]
            m.tracking(x[:, (0, 2)], self.positions[t.intruder], est_mode, true_mode)

    def mode_predictions(self, enc, times_s, chunk: int = 4096):
        """Relative mode-conditioned predictions of the tracks in ``enc`` (paper §VI, 4).

        ``times_s`` (S,) seconds ahead (rounded to whole steps). Returns ``(xs, Ps, mu)``:
        (n_own, K, M, S, 2) intruder-minus-ownship positions in m, the ownship flying
        straight; (n_own, K, M, S, 2, 2) their covariances, m²; (n_own, K, M) mode
        probabilities; zeros in unused slots. S is the number of distinct whole steps in
        ``times_s``. None if the tracker has no mode predictions (``truth``). Rows are
        predicted ``chunk`` at a time, so memory stays bounded.
        """
        if not self.tracks.predicts_modes:
            return None
        steps = np.unique(np.maximum(1, np.rint(np.asarray(times_s) / self.dt))).astype(np.int64)
        t = steps * self.dt
        n_own, K = enc.valid.shape
        view = self.tracks.view()
        mu_all = view.mu
        M = mu_all.shape[1]
        xs = np.zeros((n_own, K, M, steps.size, 2))
        Ps = np.zeros((n_own, K, M, steps.size, 2, 2))
        mu = np.zeros((n_own, K, M))
        oi, ki = np.nonzero(enc.valid)
        rows = self._enc_track_rows[enc.rows[oi, ki]]
        for a in range(0, rows.size, chunk):
            sl = slice(a, a + chunk)
            x, P = self.tracks.predict_modes_at(steps, view.slots[rows[sl]])
            own = enc.owners[oi[sl]]
            straight = (
                self.positions[own][:, None, :]
                + t[None, :, None] * self.velocities[own][:, None, :]
            )  # (r, S, 2)
            xs[oi[sl], ki[sl]] = x[..., (0, 2)] - straight[:, None]
            Ps[oi[sl], ki[sl]] = P[..., (0, 2), :][..., (0, 2)]
            mu[oi[sl], ki[sl]] = mu_all[rows[sl]]
        return xs, Ps, mu

    # --------------------------------------------------------------- outputs
    @property
    def done(self) -> bool:
        """Simulated time reached the scenario's duration, or nobody is flying."""
        return self.step_count >= self.scenario.n_steps or not self.active.any()

    def run(self, steps: int | None = None) -> dict:
        """Step ``steps`` times (default: until :attr:`done`); return :meth:`metrics`."""
        if steps is None:
            while not self.done:
                self.step()
        else:
            for _ in range(int(steps)):
                self.step()
        return self.metrics()

    def index(self, aircraft_id: str) -> int:
        """Index of the aircraft called ``aircraft_id``."""
        try:
            return self.ids.index(aircraft_id)
        except ValueError:
            raise UserError(f"no aircraft {aircraft_id!r}") from None

    def progress(self) -> np.ndarray:
        """(N,) planned distance covered so far per aircraft, m (NaN: no plan, e.g. Markov)."""
        state = FlightState(
            self.positions, self.headings, self.speeds, self.max_turn_rate, self.dt, self.step_count
        )
        out = np.full(self.n, np.nan)
        for _, members, ap in self.autopilots:
            out[members] = ap.progress(state)
        return out

    def metrics(self) -> dict:
        """Metrics of the run so far (definitions in :mod:`airspace_sim.world.metrics`):
        ``steps``, ``time_s``, ``aircraft``, ``los_events``, ``los_pairs``,
        ``los_duration_s``, ``worst_intrusion``, ``nmac_events``, ``nmac_pairs``,
        ``min_separation_m``, ``alerts``, ``conflict_s``, ``extra_path_m``,
        ``extra_path_pct``, ``avoidance_turn_deg``, ``track_rmse_m``, ``mode_accuracy``,
        ``track_steps``."""
        return self.metrics_acc.report(
            self.step_count, self.time, self.flown, self.progress(), self._has_plan
        )

    def snapshot(self, prediction_points: int = PREDICTION_POINTS) -> dict:
        """Everything a renderer or an observer needs, as copies (N aircraft, P tracks,
        M tracker modes, S = ``prediction_points``). Units SI, angles rad CCW from east.

        =====================  ============  ================================================
        key                    shape         meaning
        =====================  ============  ================================================
        ``time``               float         simulated time, s
        ``step``               int           steps taken
        ``dt``                 float         world step, s
        ``ids``                (N,) str      aircraft ids
        ``positions``          (N, 2)        true positions, m
        ``velocities``         (N, 2)        true velocities, m/s (0 for inactive aircraft)
        ``headings``           (N,)          true headings, rad
        ``speeds``             (N,)          ground speeds, m/s
        ``turn_rates``         (N,)          turn rate flown in the last step, rad/s
        ``max_turn_rate``      (N,)          turn-rate limits, rad/s
        ``active``             (N,) bool     still flying
        ``controlled``         (N,) bool     RL agents
        ``avoid``              (N,) bool     runs the resolver
        ``modes``              (N,) int      true Markov mode over the last step, −1 if none
        ``in_los``             (N,) bool     within r_safe of another aircraft
        ``nmac``               (N,) bool     within the NMAC distance of another aircraft
        ``conflict``           (N,) bool     resolver predicts a conflict at current heading
        ``advice``             (N,)          resolver heading change for the next step, rad
        ``r_safe``             float         protected-zone radius, m (pymunk circles r/2)
        ``nmac_distance``      float         NMAC distance, m
        ``sensor_range``       float         surveillance range, m
        ``lookahead``          float         resolver look-ahead, s
        ``mode_names``         (M,) str      tracker mode names (straight, left, right)
        ``tracks``             dict          ``owner`` (P,) int, ``intruder`` (P,) int,
                                             ``x`` (P, 5) ``[x, vx, y, vy, Ω]`` (m, m/s,
                                             rad/s), ``P`` (P, 5, 5), ``mu`` (P, M),
                                             ``misses`` (P,) int, ``age`` (P,) steps
        ``track_owner`` etc.   as above      the same arrays, flat (``track_owner``,
                                             ``track_intruder``, ``track_x``, ``track_P``,
                                             ``track_mu``)
        ``predicted``          (P, S, 2)     track positions extrapolated (estimated turn
                                             rate Ω) at lookahead·k/S s, k = 1..S, m
        ``los_pairs``          (L, 2) int    aircraft index pairs (i < j) in LoS
        ``nmac_pairs``         (Q, 2) int    aircraft index pairs (i < j) in NMAC
        =====================  ============  ================================================
        """
        t = self.tracks.view()
        x = np.array(t.x)
        tracks = {
            "owner": t.owner.copy(),
            "intruder": t.intruder.copy(),
            "x": x,
            "P": np.array(t.P),
            "mu": np.array(t.mu),
            "misses": t.misses.copy(),
            "age": t.age.copy(),
        }
        los_i, los_j = self.airspace.pair_arrays(LOS)
        nm_i, nm_j = self.airspace.pair_arrays(NMAC)
        snap = {
            "time": float(self.time),
            "step": int(self.step_count),
            "dt": self.dt,
            "ids": np.array(self.ids, dtype=str),
            "positions": self.positions.copy(),
            "velocities": self.velocities.copy(),
            "headings": self.headings.copy(),
            "speeds": self.speeds.copy(),
            "turn_rates": self.turn_rates.copy(),
            "max_turn_rate": self.max_turn_rate.copy(),
            "active": self.active.copy(),
            "controlled": self.controlled.copy(),
            "avoid": self.avoid.copy(),
            "modes": self.modes.copy(),
            "in_los": self.in_los.copy(),
            "nmac": self.nmac.copy(),
            "conflict": self.conflict.copy(),
            "advice": self.advice.copy(),
            "r_safe": self.r_safe,
            "nmac_distance": self.nmac_distance,
            "sensor_range": self.sensor_range,
            "lookahead": float(self.avoidance.lookahead),
            "mode_names": np.array(self.tracks.mode_names, dtype=str),
            "tracks": tracks,
            "predicted": _predict(x, self.avoidance.lookahead, prediction_points)
            if len(x)
            else np.zeros((0, prediction_points, 2)),
            "los_pairs": np.stack([los_i, los_j], axis=1),
            "nmac_pairs": np.stack([nm_i, nm_j], axis=1),
        }
        for k in ("owner", "intruder", "x", "P", "mu"):
            snap[f"track_{k}"] = tracks[k]
        return snap
