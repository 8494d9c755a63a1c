"""What a scenario is: typed, validated sections, as loaded from a TOML file.

Every field has a unit in its name or docstring (metres, seconds, degrees only where the
name says ``_deg``). :mod:`airspace_sim.scenarios.loader` turns a TOML table into these
dataclasses and rejects unknown keys, wrong types and out-of-range values with one line
naming file, key and value. The world (:mod:`airspace_sim.world`) consumes a
:class:`Scenario` and never reads TOML itself.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class Separation:
    """Separation standards."""

    r_safe: float = 3000.0  #: protected-zone radius in metres (loss of separation inside)
    nmac: float = 152.4  #: near mid-air collision distance in metres (500 ft)


@dataclass
class SensorSpec:
    """How every ownship observes intruders."""

    kind: str = "radar"  #: registry name of the sensor
    range: float = 40000.0  #: surveillance range in metres
    sigma: float = 50.0  #: position noise standard deviation per axis in metres (R = σ² I)
    detection_probability: float = 1.0  #: probability a target in range is reported per scan
    period: float = 1.0  #: seconds between scans (a multiple of the world's dt)
    drop_after_misses: int = 5  #: consecutive missed scans after which a track is dropped
    #: the sensor's own parameters (its ``Params``; validated by the loader)
    params: dict = field(default_factory=dict)


@dataclass
class TrackerSpec:
    """The tracker each ownship runs for every intruder in range."""

    kind: str = "imm"  #: registry name of the tracker ("imm", or a plugin such as "kalman")
    model: str = "realistic"  #: dynamics preset the tracker's mode filters use
    #: the tracker's own parameters (its ``Params``, e.g. the kalman tracker's
    #: ``sigma_accel``; validated by the loader)
    params: dict = field(default_factory=dict)


@dataclass
class ResolverSpec:
    """Conflict detection and avoidance."""

    kind: str = "bands"  #: registry name: "none", "seed", "bands", ...
    lookahead: float = 120.0  #: look-ahead in seconds
    margin: float = 0.1  #: extra fraction of r_safe kept clear
    #: the resolver's own parameters (its ``Params``; validated by the loader, which also
    #: fills r_safe, lookahead_s, margin and dt from the scenario where the Params has them)
    params: dict = field(default_factory=dict)
    #: half-width in degrees of the heading range searched for a clear heading; the aircraft
    #: turns toward the chosen heading at its turn-rate limit (world CDA policy)
    search_deg: float = 90.0
    #: side of the avoidance turn, kept for the whole conflict episode: "right" (prefer a
    #: right turn, rules of the air), "nearest" (the resolver's choice) or "none" (no
    #: commitment: the resolver's advice every step)
    turn_preference: str = "right"
    #: seconds a track must exist before the resolver uses it (fresh tracks' velocities are
    #: poor)
    confirm_s: float = 5.0
    #: extra fraction of r_safe (on top of margin) that a turn back toward the route must
    #: keep clear over the look-ahead (wide, so ownships do not turn back into traffic;
    #: measurements in docs/tuning.md)
    resume_margin: float = 1.5
    #: seconds (> 0) off the route over which resume_margin shrinks linearly to 0 (unset:
    #: never); random traffic needs it, or aircraft wait for a clearance that never opens
    #: (docs/tuning.md)
    resume_decay_s: float | None = None
    #: "bands-probabilistic": seconds over which each intruder mode's prediction is judged
    #: (unset: the look-ahead), at this many evenly spaced times
    probability_horizon_s: float | None = None
    probability_samples: int = 10
    #: seconds the committed turn side is remembered after a conflict ends
    side_memory_s: float = 30.0


@dataclass
class AircraftSpec:
    """One aircraft placed by hand."""

    id: str
    position: tuple[float, float]  #: metres, east and north
    heading_deg: float  #: degrees, counter-clockwise from east
    speed: float  #: ground speed in m/s
    autopilot: str = "straight"  #: registry name: "straight", "markov", "route"
    waypoints: list[tuple[float, float]] = field(default_factory=list)  #: metres, for "route"
    controlled: bool = False  #: an RL agent in the PettingZoo env
    max_turn_rate_deg: float = 3.0  #: turn-rate limit in degrees per second
    avoid: bool = True  #: runs the resolver (background traffic may be non-cooperative)
    #: what a "recorded" autopilot flies (an :class:`airspace_sim.recorded.autopilot.Recording`;
    #: set from a [recorded] section, never read from a file)
    recording: Any = None


@dataclass
class TrafficSpec:
    """Generated traffic added to the hand-placed aircraft."""

    pattern: str = "none"  #: "none", "ring" (converging on the centre) or "random" (square sector)
    count: int = 0  #: number of generated aircraft
    radius: float = 20000.0  #: ring radius in metres ("ring")
    sector: float = 60000.0  #: side of the square sector in metres ("random")
    #: "random": no two aircraft may start on straight paths that lose separation within
    #: this many seconds (0: only the initial separation is checked)
    spawn_clear_s: float = 0.0
    speed: float = 230.0  #: ground speed in m/s
    speed_spread: float = 0.0  #: generated speeds uniform in speed ± speed_spread, m/s
    autopilot: str = "route"  #: autopilot of generated aircraft
    max_turn_rate_deg: float = 3.0  #: turn-rate limit in degrees per second
    controlled: int = 0  #: how many generated aircraft are RL agents (the first ones)


@dataclass
class RecordedSpec:
    """Recorded flights replayed in the world (:mod:`airspace_sim.recorded`,
    ``docs/real-traffic.md``); their positions are in the local frame every other aircraft
    of the scenario uses too (metres east and north of the frame centre)."""

    #: trajectory file (OpenSky / traffic CSV, Parquet, JSON; relative to the scenario file),
    #: or "traffic:NAME" for a sample of the traffic wheel (e.g. "traffic:switzerland");
    #: "" (the default): no recorded traffic
    file: str = ""
    start_s: float = 0.0  #: seconds into the recording (after its first sample) at world time 0
    centre_lat_deg: float | None = None  #: local frame centre, degrees (default: the data's)
    centre_lon_deg: float | None = None
    flights: list[str] = field(default_factory=list)  #: only these ids / icao24 / callsigns
    min_altitude_ft: float | None = None  #: samples below this altitude are dropped
    max_altitude_ft: float | None = None  #: samples above this altitude are dropped
    max_gap_s: float = 60.0  #: longer silences take the aircraft out of the world
    #: velocities from the "reported" ground speed and track, or differenced "positions"
    #: (for data whose track disagrees with its positions)
    velocity: str = "reported"
    #: recorded aircraft track the others and run the detection (alerts); they never fly
    #: the advice
    track: bool = True


@dataclass
class Scenario:
    """A whole scenario. ``source`` is the file it came from (for error messages)."""

    name: str
    description: str = ""
    seed: int = 0
    dt: float = 1.0  #: world step in seconds
    duration: float = 600.0  #: seconds of simulated time
    model: str = "realistic"  #: dynamics preset for Markov autopilots
    separation: Separation = field(default_factory=Separation)
    sensor: SensorSpec = field(default_factory=SensorSpec)
    tracker: TrackerSpec = field(default_factory=TrackerSpec)
    resolver: ResolverSpec = field(default_factory=ResolverSpec)
    traffic: TrafficSpec = field(default_factory=TrafficSpec)
    aircraft: list[AircraftSpec] = field(default_factory=list)
    recorded: RecordedSpec = field(default_factory=RecordedSpec)  #: recorded traffic added
    source: str = "<memory>"

    @property
    def n_steps(self) -> int:
        """Number of world steps in ``duration``."""
        return int(round(self.duration / self.dt))
