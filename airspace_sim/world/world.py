"""The airspace world: aircraft, surveillance, tracking and conflict avoidance, stepped together.

    from airspace_sim.world import World
    world = World(scenario, seed=None)     # seed None → scenario.seed
    while not world.done:
        world.step()                       # or world.step(heading_rate) for RL agents
    print(world.metrics())

One step (``dt`` seconds) is six phases, each with one owner; no phase reaches back into an
earlier one and no part calls back into the world (``docs/dataflow.md``):

1. commands: the autopilots' turn rates (:mod:`.autopilots`), the CDA policy's override
   (:class:`~.policy.AvoidancePolicy`: advice while in conflict, a held heading while a turn
   back to the route is not clear), then the RL agents' finite ``heading_rate``; each turn
   rate clipped to the aircraft's ``max_turn_rate``;
   aircraft that may change speed (``AircraftSpec.speed_range`` > 0) take the policy's
   advised speed (their own otherwise) within ``max_acceleration``;
2. motion: the step's speed, heading ``h → h + ω·dt``; the body flies the chord of that arc
   (velocity ``v·sinc(ωdt/2)`` at heading ``h + ωdt/2``), integrated as chipmunk does
   (``p + v·dt``) by the airspace (:mod:`.bodies`): pymunk's sensor circles (the largest
   distance plus a margin) give candidate pairs, found again when an aircraft may have
   flown half the margin, and an exact numba pass over them the pairs in loss of
   separation, NMAC and sensor range; route aircraft past their last waypoint leave (``active`` False);
   aircraft of kinematic autopilots (recorded traffic, :mod:`airspace_sim.recorded`) fly
   the autopilot's velocity instead and come and go as its ``presence`` says;
3. surveillance: at scan steps every tracking ownship (avoiding or RL) measures the
   intruders in range (:mod:`.sensors`, world-frame positions with noise σ);
4. tracking: the track table (:mod:`.trackers`) steps every (ownship, intruder) filter,
   drops stale tracks and starts new ones;
5. detection: the CDA policy runs each ownship's resolver on its confirmed tracks →
   ``advice``, ``conflict`` (used by the next step's commands);
6. metrics (:mod:`.metrics`).

The scenario comes validated from :mod:`airspace_sim.scenarios` (the one validation pass);
the world trusts it. Determinism: every random number is a function of (seed, aircraft or
pair, step) (:mod:`.streams`), and nothing is shared between worlds, so a scenario and seed
give the same positions, tracks and metrics bit for bit, however worlds are interleaved.
"""

from __future__ import annotations

import numpy as np

from airspace_sim import registry
from airspace_sim.dynamics import presets
from airspace_sim.errors import UserError
from airspace_sim.geometry import wrap_angle
from airspace_sim.world import flight, streams
from airspace_sim.world import snapshot as snapshots
from airspace_sim.world.autopilots import AutopilotContext, FlightState, RouteAutopilot
from airspace_sim.world.bodies import LOS, NMAC, RANGE, Airspace
from airspace_sim.world.metrics import WorldMetrics
from airspace_sim.world.policy import AvoidancePolicy
from airspace_sim.world.trackers import TrackTable, mode_names

_EPS = np.finfo(float).eps  #: what np.sinc puts for a zero argument


class World:
    """A running airspace scenario (see the module docstring for the step).

    Parameters
    ----------
    scenario : :class:`airspace_sim.scenarios.Scenario`, as the loader returns it.
    seed : int, optional; default ``scenario.seed``. Seeds generated traffic
        (``build_aircraft(scenario, np.random.default_rng(seed))``), the Markov pilots,
        detections and measurement noise.
    aircraft : list of :class:`AircraftSpec`, optional; if given, used instead of
        ``build_aircraft(scenario, ...)``.

    Attributes (arrays indexed by aircraft, N = ``len(world.ids)``; read-only by convention)
    ------------------------------------------------------------------------------------
    dt, time : s.  step_count : int.  ids : list[str] (N).
    positions (N, 2) m; velocities (N, 2) m/s; headings (N,) rad CCW from east;
    speeds (N,) m/s; nominal_speeds (N,) m/s, each aircraft's own (the scenario's) speed,
    which it keeps unless the CDA policy advises another; speed_range (N,) the fraction of it
    the policy may take off or add (0: heading only); max_acceleration (N,) m/s²;
    max_turn_rate (N,) rad/s; turn_rates (N,) rad/s flown in the last step;
    active, controlled, avoid (N,) bool; modes (N,) int true Markov mode over the last step
    (−1 for non-Markov aircraft); in_los, nmac (N,) bool; advice (N,) rad resolver heading
    change for the coming step; conflict (N,) bool; r_safe, nmac_distance, sensor_range (m)
    and lookahead (s): the one source of these for every observer; tracks :
    :class:`TrackTable`; policy : :class:`AvoidancePolicy`.
    """

    def __init__(self, scenario, seed: int | None = None, aircraft=None):
        self.scenario = sc = scenario
        self.seed = int(sc.seed if seed is None else seed)
        self.dt = dt = float(sc.dt)
        if aircraft is None:
            from airspace_sim.scenarios import build_aircraft

            aircraft = build_aircraft(sc, np.random.default_rng(self.seed))
        self.specs = list(aircraft)
        n = self.n = len(self.specs)
        self.ids = [a.id for a in self.specs]
        self.time = 0.0
        self.step_count = 0

        # kinematic state
        self.positions = np.array([a.position for a in self.specs], dtype=float).reshape(n, 2)
        self.headings = wrap_angle(np.radians([a.heading_deg for a in self.specs]))
        self.speeds = np.array([a.speed for a in self.specs], dtype=float)
        self.nominal_speeds = self.speeds.copy()
        self.speed_range = np.array([a.speed_range for a in self.specs], dtype=float)
        self.max_acceleration = np.array([a.max_acceleration for a in self.specs], dtype=float)
        self.max_turn_rate = np.radians([a.max_turn_rate_deg for a in self.specs]).astype(float)
        self.controlled = np.array([a.controlled for a in self.specs], dtype=bool)
        self.avoid = np.array([a.avoid for a in self.specs], dtype=bool)
        self.active = np.ones(n, dtype=bool)
        #: (N,) bool, aircraft taken out of play by :meth:`retire`; they never come back,
        #: whatever their recording says (``active`` has one owner: the step, which honours it)
        self.retired = np.zeros(n, dtype=bool)
        self.turn_rates = np.zeros(n)
        self.velocities = self._velocities()
        self.r_safe = float(sc.separation.r_safe)
        self.nmac_distance = float(sc.separation.nmac)
        self.sensor_range = float(sc.sensor.range)

        # parts
        self.keys = streams.aircraft_keys(self.seed, n)
        self.pilot_preset = presets.get(sc.model, dt=dt)
        # mode_accuracy compares the tracker's modes with these, by name (a tracker model with
        # as many modes but other meanings, e.g. imm-ct, has no accuracy against them)
        self._traffic_mode_names = mode_names(self.pilot_preset)
        ctx = AutopilotContext(
            dt=dt, preset=self.pilot_preset, keys=self.keys, start_positions=self.positions.copy()
        )
        #: (members (k,) int, autopilot) per autopilot name, in name order
        self.autopilots = []
        for name in sorted({a.autopilot for a in self.specs}):
            members = np.array(
                [i for i, a in enumerate(self.specs) if a.autopilot == name], dtype=np.int64
            )
            specs = [self.specs[i] for i in members]
            ap = registry.build("autopilot", name, members, specs, ctx, params=None)
            self.autopilots.append((members, ap))
        self._one_route = self._only_route(self.autopilots, n)
        self.modes = np.full(n, -1, dtype=np.int64)
        self._has_plan = np.zeros(n, dtype=bool)
        for members, ap in self.autopilots:
            self._has_plan[members] = ap.has_plan
        #: (members, autopilot) of the kinematic autopilots (recorded traffic); ``moved``
        #: (N,) bool marks their aircraft, which no resolver or agent steers
        self._kinematic = [(m, ap) for m, ap in self.autopilots if ap.kinematic]
        self.moved = np.zeros(n, dtype=bool)
        for members, _ in self._kinematic:
            self.moved[members] = True
        self._read_modes()
        self.sensor = registry.build(
            "sensor", sc.sensor.kind, sc.sensor, dt, params=sc.sensor.params
        )
        self.tracker_preset = presets.get(sc.tracker.model, dt=dt)
        self.tracks = TrackTable.build(
            n,
            sc.tracker.kind,
            self.tracker_preset,
            sc.sensor.sigma,
            sc.sensor.drop_after_misses,
            self.sensor.period_steps * dt,
            params=sc.tracker.params,
        )
        self.trackers_on = self.controlled | self.avoid  # ownships that track intruders
        flies_advice = self.avoid & ~self.controlled & ~self.moved
        #: (N,) bool: aircraft whose speed the CDA policy may change
        self.speed_controlled = flies_advice & (self.speed_range > 0.0)
        span = np.where(self.speed_controlled, self.speed_range, 0.0) * self.nominal_speeds
        limits = np.stack([self.nominal_speeds - span, self.nominal_speeds + span], axis=1)
        self.policy = AvoidancePolicy(
            sc, dt, flies_advice, self.trackers_on, limits, self.max_acceleration
        )
        self.metrics_acc = WorldMetrics(n, self.r_safe, self.nmac_distance, dt)
        self.active[self.moved] = False  # kinematic aircraft come in where recorded now
        self._presence()
        self.airspace = Airspace(
            self.positions, self.r_safe, self.nmac_distance, self.sensor_range, in_space=self.active
        )
        self.in_los = np.zeros(n, dtype=bool)
        self.nmac = np.zeros(n, dtype=bool)
        # the phases after motion, for the initial positions (no tracking errors recorded)
        self._update_contact_flags()
        scan = self._surveillance()
        self.tracks.update(self.time, *scan, self.active, self._truth_for_tracker())
        self._detection()
        self._record_metrics(tracking=False)

    def __setstate__(self, state):
        """Unpickle; the scan's pair keys that an older checkpoint kept are not used."""
        state.pop("_last_pairs", None)
        if "_traffic_mode_names" not in state:
            state["_traffic_mode_names"] = mode_names(state["pilot_preset"])
        self.__dict__.update(state)
        if "_one_route" not in state:
            self._one_route = self._only_route(self.autopilots, self.n)
        if "nominal_speeds" not in state:  # before speed advice: every speed is its own
            self.nominal_speeds = np.array([a.speed for a in self.specs], dtype=float)
            self.speed_range = np.zeros(self.n)
            self.max_acceleration = np.zeros(self.n)
            self.speed_controlled = np.zeros(self.n, dtype=bool)

    @staticmethod
    def _only_route(autopilots, n):
        """The route autopilot when it alone flies every aircraft, in order (then the
        commands and captures need no gather or scatter per group), else None."""
        if len(autopilots) == 1:
            members, ap = autopilots[0]
            if type(ap) is RouteAutopilot and np.array_equal(members, np.arange(n)):
                return ap
        return None

    # ------------------------------------------------------------ read-only
    @property
    def advice(self) -> np.ndarray:
        """(N,) rad: the CDA policy's heading change for the coming step."""
        return self.policy.advice

    @property
    def lookahead(self) -> float:
        """s: the resolver's look-ahead (the CDA policy's; the one value every observer uses)."""
        return self.policy.lookahead_s

    @property
    def conflict(self) -> np.ndarray:
        """(N,) bool: a conflict is predicted at the current heading."""
        return self.policy.conflict

    # ------------------------------------------------------------------ step
    def step(self, heading_rate=None) -> None:
        """Advance the world by ``dt`` (the six phases of the module docstring).

        heading_rate : (N,) rad/s, optional. For controlled (RL) aircraft, a finite entry is
            the commanded turn rate (clipped to ±max_turn_rate); NaN = fly the built-in
            autopilot and (for ``avoid`` aircraft) resolver. Entries of other aircraft are
            ignored.
        """
        rate = self._commands(heading_rate)
        self._motion(rate)
        scan = self._surveillance()
        self.tracks.update(self.time, *scan, self.active, self._truth_for_tracker())
        self._detection()
        self._record_metrics()

    def _detection(self) -> None:
        """Phase 5: advice and conflict flags for the coming step (the CDA policy)."""
        self.policy.advise(
            self.tracks, self.positions, self.velocities, self.active, self.max_turn_rate * self.dt
        )

    def flight_state(self) -> FlightState:
        """The true kinematic state as autopilots see it (arrays, not copies)."""
        return FlightState(
            self.positions, self.headings, self.speeds, self.max_turn_rate, self.dt, self.step_count
        )

    def _commands(self, heading_rate) -> np.ndarray:
        """Phase 1: (N,) turn rates, rad/s, clipped to the limits (0 for inactive)."""
        n = self.n
        state = self.flight_state()
        if self._one_route is not None:  # one route autopilot flies everyone, in order
            rate, desired = self._one_route.commands(state)
        else:
            rate = np.zeros(n)
            desired = np.full(n, np.nan)
            for members, ap in self.autopilots:
                rate[members] = ap.turn_rate(state)
                desired[members] = ap.desired_heading(state)
        self._read_modes()
        # agent: RL agents whose command is flown this step; an avoiding agent that leaves
        # a step to the built-in pilot flies the resolver too (avoid); recorded (kinematic)
        # aircraft never do: they fly their recording
        agent, avoid = np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        hr = rate
        if heading_rate is not None:
            hr = np.asarray(heading_rate, dtype=float).reshape(-1)
            if hr.shape != (n,):
                raise UserError(f"heading_rate: expected shape ({n},), got {hr.shape}")
            if flight.agent_masks(hr, self.controlled, self.avoid, self.moved, agent, avoid):
                raise UserError("heading_rate: contains an infinite value (use NaN for 'built-in')")
        else:
            agent[:] = False
            avoid = None
        if not self.controlled.any():
            avoid = None
        elif avoid is None:
            avoid = self.avoid & ~self.moved
        rate = self.policy.override(
            rate, desired, self.active, self.velocities, self.max_turn_rate * self.dt, avoid
        )
        out = np.empty(n)
        flight.turn_commands(rate, hr, agent, self.max_turn_rate, self.active, out)
        if self.speed_controlled.any():
            self._speed_commands()
        return out

    def _speed_commands(self) -> None:
        """Phase 1, speed: each speed-controlled aircraft's speed for the coming step, the
        CDA policy's advised speed (its own where there is none, clipped to its limits)
        approached by at most ``max_acceleration·dt``."""
        target = self.policy.speed_target
        target = np.where(np.isfinite(target), target, self.nominal_speeds)
        lo, hi = self.policy.speed_limits[:, 0], self.policy.speed_limits[:, 1]
        step = self.max_acceleration * self.dt
        change = np.clip(np.clip(target, lo, hi) - self.speeds, -step, step)
        m = self.speed_controlled & self.active
        self.speeds = np.where(m, self.speeds + change, self.speeds)

    def _motion(self, rate) -> None:
        """Phase 2: fly the chord of each arc for ``dt``; finished route aircraft leave."""
        dt = self.dt
        if self._kinematic:
            self._motion_kinematic(rate)
            return
        n = self.n
        turn, mid, y = np.empty(n), np.empty(n), np.empty(n)
        flight.arc_terms(rate, self.headings, dt, turn, mid, y)
        # np.sinc(turn / 2π) as numpy computes it (sin(πx)/(πx), eps at 0), numpy's sin and cos
        v, headings, flown = np.empty((n, 2)), np.empty(n), np.empty(n)
        flight.chords(
            self.speeds, np.sin(y), y, np.cos(mid), np.sin(mid), self.active, self.headings,
            turn, dt, v, headings, flown,
        )  # fmt: skip
        self.airspace.set_velocities(v)
        self.airspace.step(dt, self.positions)
        self.headings = headings
        self.turn_rates = rate
        self.metrics_acc.motion(flown, turn, self.policy.following)
        self._after_motion()

    def _motion_kinematic(self, rate) -> None:
        """:meth:`_motion` of a world with kinematic autopilots (recorded traffic), whose
        aircraft fly their own velocities over the step."""
        dt = self.dt
        turn = rate * dt
        mid = self.headings + 0.5 * turn
        # np.sinc(turn / 2π) as numpy computes it (π·x, eps at 0), without its overhead
        y = np.pi * (turn / (2.0 * np.pi))
        y[y == 0.0] = _EPS
        chord = self.speeds * (np.sin(y) / y)
        v = np.empty((self.n, 2))
        np.multiply(chord, np.cos(mid), out=v[:, 0])
        np.multiply(chord, np.sin(mid), out=v[:, 1])
        v, turn, rate = self._kinematic_motion(v, turn, rate)
        v[~self.active] = 0.0
        self.airspace.set_velocities(v)
        self.airspace.step(dt, self.positions)
        self.headings = wrap_angle(self.headings + turn)
        self.turn_rates = rate
        self.metrics_acc.motion(
            np.where(self.active, self.speeds * dt, 0.0), turn, self.policy.following
        )
        self._after_motion()

    def _after_motion(self) -> None:
        """The end of phase 2: time, waypoint captures (finished aircraft leave), recorded
        traffic's arrivals and departures, velocities and contact flags."""
        self.step_count += 1
        self.time = self.step_count * self.dt
        state = self.flight_state()
        if self._one_route is not None:
            finished = self._one_route.after_step(state)
        else:
            finished = np.zeros(self.n, dtype=bool)
            for members, ap in self.autopilots:
                finished[members] = ap.after_step(state)
        gone = finished & self.active
        if gone.any():
            self.metrics_acc.finished(self.time, gone)
            self.active[gone] = False
            self.airspace.remove(np.flatnonzero(gone))
        if self._kinematic:
            arrive, leave = self._presence()
            self.airspace.remove(leave)
            self.airspace.add(arrive, self.positions[arrive])
        self.velocities = self._velocities()
        self._update_contact_flags()

    def _kinematic_motion(self, v, turn, rate):
        """The kinematic autopilots' aircraft fly their own velocities over the step:
        ``(v (N, 2) m/s, turn (N,) rad, rate (N,) rad/s)`` with their rows replaced. Their
        heading becomes the direction of the step flown and their speed its length / dt."""
        state = self.flight_state()
        v = v.copy()
        for members, ap in self._kinematic:
            v[members] = ap.velocity(state)
        m = self.moved & self.active
        speed = np.hypot(v[:, 0], v[:, 1])
        heading = np.where(m & (speed > 0), np.arctan2(v[:, 1], v[:, 0]), self.headings)
        turn = np.where(m, wrap_angle(heading - self.headings), turn)
        self.speeds = np.where(m, speed, self.speeds)
        return v, turn, np.where(m, turn / self.dt, rate)

    def _presence(self):
        """Bring in the kinematic autopilots' aircraft that are recorded now and take out
        those that are not or were retired (``active``, and position, heading and speed of
        the arrivals).
        Returns ``(arrive, leave)`` (int arrays) for the airspace."""
        state = self.flight_state()
        arrive, leave = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
        for members, ap in self._kinematic:
            present, pos, vel = ap.presence(state)
            present = present & ~self.retired[members]
            new = present & ~self.active[members]
            gone = ~present & self.active[members]
            a = members[new]
            self.positions[a] = pos[new]
            self.headings[a] = np.arctan2(vel[new, 1], vel[new, 0])
            self.speeds[a] = np.hypot(vel[new, 0], vel[new, 1])
            self.active[a] = True
            self.active[members[gone]] = False
            arrive.append(a)
            leave.append(members[gone])
        return np.concatenate(arrive), np.concatenate(leave)

    def _update_contact_flags(self) -> None:
        """``in_los`` and ``nmac`` (N,) from the airspace's pair sets."""
        flight.pair_flags(*self.airspace.pair_arrays(LOS), self.in_los)
        flight.pair_flags(*self.airspace.pair_arrays(NMAC), self.nmac)

    def _surveillance(self):
        """Phase 3: ``(scanned, owner (D,), intruder (D,), z (D, 2) m)`` of this step."""
        none = np.zeros(0, np.int64)
        if not self.sensor.scans(self.step_count):
            return False, none, none, np.zeros((0, 2))
        i, j = self.airspace.pair_arrays(RANGE)
        owner, intruder, pk = streams.directed_pairs(i, j, self.trackers_on, self.active, self.keys)
        pk.flags.writeable = False
        z, det = self.sensor.measure(owner, intruder, self.positions, pk, self.step_count)
        if np.all(det):  # (every pair, as a radar with detection probability 1 gives)
            return True, owner, intruder, z
        return True, owner[det], intruder[det], z[det]

    def _record_metrics(self, tracking: bool = True) -> None:
        """Phase 6: contacts, conflicts and (``tracking``) track errors."""
        m = self.metrics_acc
        sp = self.airspace
        m.contacts(self.positions, sp.pairs, sp.began, sp.pair_arrays(RANGE))
        m.conflicts(self.conflict)
        m.safety(
            self.time,
            self.positions,
            self.velocities,
            self.active,
            self.policy.following,
            self.lookahead,
        )
        view = self.tracks.view()
        if not tracking or not len(view.owner):
            return
        est_mode = true_mode = None
        # (np.take: a row gather ten times faster than fancy indexing; no intruder flies a
        # Markov mode when no aircraft does)
        modes = self.modes
        if (modes >= 0).any() and self.tracks.mode_names == self._traffic_mode_names:
            markov = np.take(modes, view.intruder) >= 0
            mu = view.mu[markov]
            if markov.any() and np.isfinite(mu).all():
                est_mode = np.argmax(mu, axis=1)
                true_mode = modes[view.intruder[markov]]
        m.track_states(view.x, view.intruder, self.positions, est_mode, true_mode)

    def _velocities(self) -> np.ndarray:
        """(N, 2) m/s from speeds and headings (0 for aircraft that left)."""
        v = np.empty((self.n, 2))
        flight.velocity_rows(
            self.speeds, np.cos(self.headings), np.sin(self.headings), self.active, v
        )
        return v

    def _truth_for_tracker(self):
        """:meth:`_true_states` for a tracker that ``uses_truth``, else None (not built)."""
        return self._true_states() if self.tracks.tracker.uses_truth else None

    def _true_states(self) -> np.ndarray:
        """(N, 5) true ``[x, vx, y, vy, Ω]``."""
        truth = np.empty((self.n, 5))
        truth[:, 0], truth[:, 2] = self.positions[:, 0], self.positions[:, 1]
        truth[:, 1], truth[:, 3] = self.velocities[:, 0], self.velocities[:, 1]
        truth[:, 4] = self.turn_rates
        return truth

    def _read_modes(self) -> None:
        for members, ap in self.autopilots:
            if ap.has_modes:
                self.modes[members] = ap.modes

    # --------------------------------------------------------------- outputs
    @property
    def everybody_left(self) -> bool:
        """Nobody is flying and nobody can come: never while recorded traffic is in the
        world, which may still arrive (its aircraft come and go as their data say)."""
        return not (self.active.any() or self._kinematic)

    @property
    def done(self) -> bool:
        """Simulated time reached the scenario's duration, or :attr:`everybody_left`."""
        return self.step_count >= self.scenario.n_steps or self.everybody_left

    def run(self, steps: int | None = None) -> dict:
        """Step ``steps`` times (default: until :attr:`done`); return :meth:`metrics`."""
        if steps is None:
            while not self.done:
                self.step()
        else:
            for _ in range(int(steps)):
                self.step()
        return self.metrics()

    def retire(self, indices) -> None:
        """Take aircraft out of play now (``active`` False, out of the pymunk space): the
        env's ``ended="leave"`` for agents whose episode ended; a retired recorded aircraft
        stays out though its recording goes on. indices : (k,) int."""
        idx = np.asarray(indices, dtype=np.int64).reshape(-1)
        self.retired[idx] = True
        idx = idx[self.active[idx]]
        if idx.size:
            self.active[idx] = False
            self.airspace.remove(idx)
            self.velocities = self._velocities()
            self._update_contact_flags()

    def index(self, aircraft_id: str) -> int:
        """Index of the aircraft called ``aircraft_id``."""
        try:
            return self.ids.index(aircraft_id)
        except ValueError:
            raise UserError(f"no aircraft {aircraft_id!r}") from None

    def progress(self) -> np.ndarray:
        """(N,) planned distance covered so far per aircraft, m (NaN: no plan, e.g. Markov)."""
        state = self.flight_state()
        out = np.full(self.n, np.nan)
        for members, ap in self.autopilots:
            out[members] = ap.progress(state)
        return out

    def metrics(self) -> dict:
        """Metrics of the run so far (definitions in :mod:`airspace_sim.world.metrics`):
        ``steps``, ``time_s``, ``aircraft``, ``los_events``, ``los_pairs``,
        ``los_duration_s``, ``worst_intrusion``, ``nmac_events``, ``nmac_pairs``,
        ``min_separation_m``, ``alerts``, ``conflict_s``, ``extra_path_m``,
        ``extra_path_pct``, ``avoidance_turn_deg``, ``track_rmse_m``, ``mode_accuracy``,
        ``track_steps``, and the safety metrics ``wcv_events``, ``wcv_pairs``,
        ``wcv_duration_s``, ``induced_los_pairs``, ``flight_hours``,
        ``alerts_per_flight_hour``, ``first_alert_s``, ``arrived``, ``not_arrived``,
        ``arrival_delay_mean_s``, ``arrival_delay_max_s``."""
        # a slowed aircraft's delay is against its own speed, not the speed it arrived at
        planned = np.where(self.speed_controlled, self.nominal_speeds, np.nan)
        return self.metrics_acc.report(
            self.step_count, self.time, self.progress(), self._has_plan, planned
        )

    def snapshot(self, prediction_points: int = snapshots.PREDICTION_POINTS):
        """The world now, as a read-only :class:`~airspace_sim.world.snapshot.Snapshot`."""
        return snapshots.snapshot(self, prediction_points)
