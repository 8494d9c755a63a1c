"""The four kinds of parts a world is built from, as code: Autopilot, Sensor, Tracker, Resolver.

Each kind is an abstract base class: the methods a part must have (with array shapes and
units), the parameters it declares (a ``Params`` dataclass, validated by the scenario
loader like every other key) and the capabilities it declares (class attributes the world
reads instead of checking names or signatures). A part is a class registered under a name
with :func:`airspace_sim.registry.register`; the registry checks it against its kind here,
once, when it is registered (:func:`check`). A plugin may subclass these bases or only fit
them: the check is on what the class has, not on where it comes from.

Conventions everywhere: metres, seconds, radians; angles counter-clockwise from east
(negative = turn right); state ``[x, vx, y, vy, Ω]`` (m, m/s, m, m/s, rad/s), n = 5;
position measurements ``z = [x, y]`` in the world frame. ``N`` is the number of aircraft in
the world, ``k`` the number an autopilot flies. See ``docs/plugins.md`` for a worked plugin.
"""

from __future__ import annotations

import dataclasses
import inspect
import sys
import typing
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from airspace_sim.errors import UserError


@dataclass(frozen=True)
class NoParams:
    """A part without parameters."""


def param(
    default=dataclasses.MISSING,
    *,
    unit: str = "",
    doc: str = "",
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    choices: tuple | None = None,
):
    """A ``Params`` field with its unit, meaning and valid range, read by the loader.

    ``ge``/``gt``/``le``/``lt`` bound a number (≥, >, ≤, <), ``choices`` lists the allowed
    values; the field's annotation gives its type (``float``, ``int``, ``bool``, ``str``,
    ``X | None``). Example: ``lookahead_s: float = param(120.0, unit="s", gt=0, le=3600)``.
    """
    meta = {"unit": unit, "doc": doc, "ge": ge, "gt": gt, "le": le, "lt": lt, "choices": choices}
    return dataclasses.field(
        default=default, metadata={k: v for k, v in meta.items() if v not in (None, "")}
    )


def describe_range(meta) -> str | None:
    """The range of a :func:`param` field's ``metadata`` as text, e.g. ``"in (0, 180] deg"``;
    None without bounds."""
    unit = f" {meta['unit']}" if meta.get("unit") else ""
    if meta.get("choices") is not None:
        return "one of " + ", ".join(map(str, meta["choices"]))
    lo = ("[", meta["ge"]) if "ge" in meta else ("(", meta["gt"]) if "gt" in meta else None
    hi = ("]", meta["le"]) if "le" in meta else (")", meta["lt"]) if "lt" in meta else None
    if lo and hi:
        return f"in {lo[0]}{lo[1]:g}, {hi[1]:g}{hi[0]}{unit}"
    if lo:
        return f"{'≥' if lo[0] == '[' else '>'} {lo[1]:g}{unit}"
    if hi:
        return f"{'≤' if hi[0] == ']' else '<'} {hi[1]:g}{unit}"
    return None


def in_range(meta, value) -> bool:
    """Does ``value`` satisfy the bounds and choices of a :func:`param` field's metadata?"""
    if meta.get("choices") is not None and value not in meta["choices"]:
        return False
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return True
    return (
        ("ge" not in meta or value >= meta["ge"])
        and ("gt" not in meta or value > meta["gt"])
        and ("le" not in meta or value <= meta["le"])
        and ("lt" not in meta or value < meta["lt"])
    )


class Autopilot(ABC):
    """What a group of aircraft flies when neither the resolver nor an agent overrides it.

    One object flies all ``k`` aircraft that share the autopilot's name, with arrays.
    Constructed as ``cls(members, specs, context, params)``: ``members`` (k,) int indices
    into the world's aircraft, ``specs`` their ``AircraftSpec`` (k,), ``context`` an
    :class:`airspace_sim.world.autopilots.AutopilotContext`, ``params`` a ``Params``.
    ``state`` below is the whole world's ``FlightState`` (N aircraft): index it with
    ``members``.
    """

    Params: ClassVar[type] = NoParams
    #: exposes ``modes`` (k,) int: the true Markov mode flown over the last step
    has_modes: ClassVar[bool] = False
    #: flies a plan (a route or a heading to keep): ``progress`` is meaningful and the
    #: CDA policy may resume toward ``desired_heading`` after an avoidance manoeuvre
    has_plan: ClassVar[bool] = False
    #: moves its aircraft itself along given trajectories (recorded traffic): the world
    #: flies them by :meth:`velocity` instead of by turn rate (no resolver or agent steers
    #: them) and brings them in and takes them out by :meth:`presence`
    kinematic: ClassVar[bool] = False

    @abstractmethod
    def turn_rate(self, state) -> np.ndarray:
        """(k,) commanded turn rate, rad/s (the world clips it to each aircraft's limit)."""

    @abstractmethod
    def desired_heading(self, state) -> np.ndarray:
        """(k,) heading the autopilot wants to settle on, rad; NaN for none."""

    @abstractmethod
    def after_step(self, state) -> np.ndarray:
        """(k,) bool: the aircraft finished (it leaves the world). Called after motion."""

    @abstractmethod
    def progress(self, state) -> np.ndarray:
        """(k,) planned distance covered so far, m; NaN without a plan."""

    def velocity(self, state) -> np.ndarray:
        """(k, 2) m/s each member flies over the coming step (rows of members out of the
        world are ignored). Only with ``kinematic``."""
        raise NotImplementedError(f"{type(self).__name__} is not kinematic")

    def presence(self, state):
        """At the time of ``state`` (``state.step · dt``): ``(present (k,) bool, positions
        (k, 2) m, velocities (k, 2) m/s)``; the world brings in the members that become
        present at those positions and takes out those that stop being. Only with
        ``kinematic``."""
        raise NotImplementedError(f"{type(self).__name__} is not kinematic")


class Sensor(ABC):
    """Surveillance: which pairs in range are detected on a scan, and what is measured.

    Constructed as ``cls(spec, dt, params)``: ``spec`` the scenario's ``SensorSpec``,
    ``dt`` the world step (s), ``params`` a ``Params``.
    """

    Params: ClassVar[type] = NoParams
    #: world steps between scans (≥ 1); an instance attribute is fine
    period_steps: int = 1

    @abstractmethod
    def scans(self, step: int) -> bool:
        """Does a scan happen at world step index ``step``?"""

    @abstractmethod
    def measure(self, owner, intruder, positions, pair_keys, step: int):
        """Measure the pairs in range.

        owner, intruder : (D,) int aircraft indices; positions : (N, 2) true positions, m;
        pair_keys : (D,) uint64 counter-based random keys (:mod:`airspace_sim.world.streams`);
        step : world step index. Returns ``(z (D, 2) m world-frame positions, detected (D,)
        bool)``.
        """


class Tracker(ABC):
    """A table of independent filters held in stable slots (one per ownship–intruder track).

    Constructed as ``cls(preset, sigma, params)``: ``preset`` the tracker's dynamics
    :class:`~airspace_sim.dynamics.presets.Preset` at the world's dt, ``sigma`` the sensor's
    position noise σ (m), ``params`` a ``Params``. It starts with no live slots.

    Slots are lanes ``0 .. capacity-1``; ``alive`` marks the live ones. :meth:`birth` fills
    free lanes (growing capacity geometrically when none is free), :meth:`drop` frees lanes;
    neither moves any other track, so their cost is proportional to the tracks that change.
    Arrays are indexed by slot; values in free slots are unspecified.
    """

    Params: ClassVar[type] = NoParams
    #: has :meth:`predict_modes_at` (mode-conditioned predictions, paper §VI assumption 4)
    predicts_modes: ClassVar[bool] = False
    #: :meth:`step` needs the intruders' true states (perfect surveillance trackers)
    uses_truth: ClassVar[bool] = False
    #: has :attr:`gated` (the world's track table counts a rejected measurement as a miss)
    reports_gated: ClassVar[bool] = False
    #: number of modes M (1 for a single-model filter); an instance attribute is fine
    n_modes: int = 1
    #: names of the M modes, e.g. ("straight", "left", "right")
    mode_names: tuple[str, ...] = ("single",)

    @property
    @abstractmethod
    def capacity(self) -> int:
        """Number of lanes allocated."""

    @property
    @abstractmethod
    def alive(self) -> np.ndarray:
        """(capacity,) bool, read-only: live slots."""

    @abstractmethod
    def birth(self, x0, P0) -> np.ndarray:
        """Start k tracks: ``x0`` (k, n), ``P0`` (k, n, n); mode probabilities start at the
        model's own initial ones. Returns their slots (k,) int."""

    def birth_checked(self, x0, P0) -> np.ndarray:
        """:meth:`birth` of arrays the caller has already checked: ``x0`` (k, n) finite
        float64, ``P0`` (k, n, n) finite, exactly symmetric and positive definite, both
        C-contiguous (the track table's two-point initialisations). A tracker may skip its
        own input checks here; the default is :meth:`birth`."""
        return self.birth(x0, P0)

    @abstractmethod
    def drop(self, slots) -> None:
        """End the tracks in ``slots`` (k,) int (live slots)."""

    @abstractmethod
    def step(self, z, truth=None) -> None:
        """One filter cycle for every live slot.

        z : (capacity, m) measurements by slot, m; a row with NaN = no measurement
        (predict only); rows of free slots are ignored. truth : (capacity, n) true states of
        each slot's intruder, given only to trackers with ``uses_truth``.
        """

    @property
    @abstractmethod
    def x(self) -> np.ndarray:
        """(capacity, n) posterior states by slot."""

    @property
    @abstractmethod
    def P(self) -> np.ndarray:
        """(capacity, n, n) posterior covariances by slot."""

    @property
    @abstractmethod
    def mu(self) -> np.ndarray:
        """(capacity, M) mode probabilities by slot (NaN where the tracker has none)."""

    def predict_modes_at(self, steps, slots):
        """Each mode's model propagated ``steps`` (S,) increasing step counts ahead, for
        ``slots`` (R,): ``(xs (R, M, S, n), Ps (R, M, S, n, n))``. Only with
        ``predicts_modes``."""
        raise NotImplementedError(f"{type(self).__name__} does not predict modes")

    @property
    def gated(self) -> np.ndarray:
        """(capacity,) bool, read-only: the last :meth:`step` rejected the slot's (finite)
        measurement as explained by no mode (gating). Only with ``reports_gated``."""
        raise NotImplementedError(f"{type(self).__name__} does not report gating")


class Resolver(ABC):
    """Conflict detection and resolution for many ownships at once (paper §V).

    Constructed as ``cls(params)`` with a ``Params`` instance (this base's ``__init__``
    stores it as ``self.params``; ``cls()`` uses the defaults). The loader fills the
    ``Params`` fields named ``r_safe`` (m, from ``separation.r_safe``), ``lookahead_s`` (s,
    ``resolver.lookahead``), ``margin`` (``resolver.margin``) and ``dt`` (s, the world
    step) from the scenario when the dataclass declares them, then ``resolver.params`` on
    top; unknown keys and wrong types are refused there.
    """

    Params: ClassVar[type] = NoParams
    #: :meth:`resolve` uses ``mode_predictions`` (the world computes them only then)
    uses_mode_predictions: ClassVar[bool] = False
    #: :meth:`resolve` uses ``turn_rate`` (judges heading changes as flown)
    uses_turn_rate: ClassVar[bool] = False
    #: the advice is "no turn, no conflict" exactly when the current heading passes the CPA
    #: test :func:`airspace_sim.avoidance.cpa.cpa_min_ratio` with the resolver's
    #: ``params.r_safe``, ``params.lookahead_s`` and ``params.margin`` (so the world runs
    #: it only on the ownships that fail it)
    prefilter: ClassVar[bool] = False
    #: the output carries ``candidates``, ``first_clear`` and ``best_blocked`` (the CDA
    #: policy can commit a turn side; :class:`~airspace_sim.avoidance.resolvers.ResolverOutput`)
    reports_band: ClassVar[bool] = False
    #: :meth:`resolve` takes ``committed_side`` (N,) (−1 right, +1 left, 0 none), the side
    #: the CDA policy keeps, and may then search only that side (with ``reports_band``)
    uses_committed_side: ClassVar[bool] = False
    #: with ``uses_committed_side``, :meth:`resolve` also takes ``held_heading_change`` (N,)
    #: rad: the heading the CDA policy advised at the ownship's last detection in conflict
    #: (an absolute heading) minus its current heading, wrapped to [−π, π); NaN: none
    uses_held_heading: ClassVar[bool] = False
    #: :meth:`resolve` takes ``intruder_turn_rate`` (N, K) rad/s: each intruder track's
    #: estimated turn rate (the track state's Ω, CCW positive; 0 where the tracker has none)
    uses_intruder_turn_rate: ClassVar[bool] = False
    #: speed as a second control: :meth:`resolve` takes ``speed_limits`` (N, 2) m/s, the
    #: lowest and highest ground speed each ownship may fly (equal: heading only), and
    #: ``max_acceleration`` (N,) m/s², its along-track limit; the output carries
    #: ``speed_target`` (N,) m/s, the ground speed to fly with the advised heading
    advises_speed: ClassVar[bool] = False
    #: :meth:`resolve` takes ``aircraft_ids`` (N,) int, the world's index of each row's
    #: ownship, and ``intruder_ids`` (N, K) int, the aircraft each intruder slot tracks (−1:
    #: none), so it can tell which rows are each other's intruders (explicit coordination)
    uses_aircraft_ids: ClassVar[bool] = False
    #: :meth:`resolve` takes ``intruder_intent`` (N, K) rad, the heading change from each
    #: intruder track's heading to the heading that aircraft broadcasts it steers to (0: none
    #: or straight), ``intruder_turn_limit`` (N, K) rad/s, its turn-rate limit,
    #: ``intruder_intent_age_s`` (N, K) s, how long that intent has held, and
    #: ``own_intent_age_s`` (N,) s, how long the ownship's own intent has held
    uses_intruder_intent: ClassVar[bool] = False

    params: object

    def __init__(self, params=None):
        self.params = self.Params() if params is None else params

    @abstractmethod
    def resolve(
        self,
        own_velocity,
        rel_position,
        rel_velocity,
        valid,
        max_heading_change,
        *,
        mode_predictions=None,
        turn_rate=None,
    ):
        """Advice for ``N`` ownships, each with up to ``K`` intruder slots.

        own_velocity (N, 2) m/s; rel_position, rel_velocity (N, K, 2) intruder minus
        ownship, world frame, m and m/s; valid (N, K) bool; max_heading_change (N,) rad;
        mode_predictions ``(xs (N, K, M, S, 2), Ps (N, K, M, S, 2, 2), mu (N, K, M))`` or
        None; turn_rate (N,) rad/s or None. Returns a
        :class:`airspace_sim.avoidance.resolvers.ResolverOutput` with
        ``heading_change`` (N,) rad, ``|heading_change| ≤ max_heading_change``, and
        ``conflict`` (N,) bool.
        """


KINDS: dict[str, type] = {
    "autopilot": Autopilot,
    "sensor": Sensor,
    "tracker": Tracker,
    "resolver": Resolver,
}


def _abstract_names(base: type) -> list[str]:
    return sorted(base.__abstractmethods__)


#: How each kind is constructed: the number of positional arguments of ``cls(...)``.
CONSTRUCTOR_ARGS = {
    "autopilot": ("members", "specs", "context", "params"),
    "sensor": ("spec", "dt", "params"),
    "tracker": ("preset", "sigma", "params"),
    "resolver": ("params",),
}

#: Keyword arguments a method of the kind must accept (the world passes them by name).
KEYWORDS = {"resolver": {"resolve": ("mode_predictions", "turn_rate")}}
#: Keyword arguments a method must accept when the class sets a capability flag (the world
#: passes them by name only then).
FLAG_KEYWORDS = {
    "resolver": {
        "uses_committed_side": ("resolve", ("committed_side",)),
        "uses_held_heading": ("resolve", ("held_heading_change",)),
        "uses_intruder_turn_rate": ("resolve", ("intruder_turn_rate",)),
        "advises_speed": ("resolve", ("speed_limits", "max_acceleration")),
        "uses_aircraft_ids": ("resolve", ("aircraft_ids", "intruder_ids")),
        "uses_intruder_intent": (
            "resolve",
            ("intruder_intent", "intruder_turn_limit", "intruder_intent_age_s", "own_intent_age_s"),
        ),
    }
}


def _accepts(func, n_positional: int, keywords=()) -> str | None:
    """None if ``func`` can be called with ``n_positional`` arguments and ``keywords``,
    else what is wrong (one phrase)."""
    try:
        sig = inspect.signature(func)
    except (TypeError, ValueError):
        return None  # builtins without a signature: nothing to check
    try:
        sig.bind(*range(n_positional), **{k: None for k in keywords})
    except TypeError as exc:
        return str(exc)
    return None


def _check_params_types(params: type, where: str) -> None:
    """Every ``Params`` field has a type the scenario loader can validate."""
    from airspace_sim.scenarios.loader import describe

    try:
        hints = typing.get_type_hints(params)
    except Exception as exc:  # noqa: BLE001 - an annotation that does not resolve
        raise UserError(f"{where}: Params annotations do not resolve: {exc}") from None
    for f in dataclasses.fields(params):
        try:
            describe(hints[f.name])
        except TypeError:
            raise UserError(
                f"{where}: Params.{f.name}: type {hints[f.name]!r} cannot be read from a "
                f"scenario (use float, int, bool, str, X | None, tuple or list of those)"
            ) from None


def origin(obj) -> str:
    """Where a part comes from, for messages: ``module.Class`` and its file when known."""
    module = getattr(obj, "__module__", None) or "?"
    text = f"{module}.{getattr(obj, '__qualname__', type(obj).__name__)}"
    path = getattr(sys.modules.get(module), "__file__", None)
    return f"{text} in {path}" if path else text


def check(kind: str, cls, name: str) -> None:
    """Raise a one-line :class:`UserError` unless ``cls`` fits the protocol of ``kind``.

    Checks that it is a class, has every method and property of the protocol, that its
    constructor takes the kind's arguments (:data:`CONSTRUCTOR_ARGS`) and its methods the
    keywords the world passes (:data:`KEYWORDS`, and :data:`FLAG_KEYWORDS` for the flags it
    sets), that ``Params`` is a dataclass and that the
    capability flags are booleans. Done once, at registration, never at run time.
    """
    base = KINDS[kind]
    where = f"{kind} {name!r} ({origin(cls)})"
    if not inspect.isclass(cls):
        raise UserError(f"{where}: a part must be a class, got {type(cls).__name__}")
    missing = []
    for attr in _abstract_names(base):
        impl = inspect.getattr_static(cls, attr, None)
        if impl is None or getattr(impl, "__isabstractmethod__", False):
            missing.append(attr)
    if missing:
        raise UserError(
            f"{where}: does not fit the {base.__name__} protocol: missing {', '.join(missing)}"
        )
    args = CONSTRUCTOR_ARGS[kind]
    problem = _accepts(cls, len(args))
    if problem:
        raise UserError(
            f"{where}: does not fit the {base.__name__} protocol: the constructor must take "
            f"({', '.join(args)}): {problem}"
        )
    for method, keywords in KEYWORDS.get(kind, {}).items():
        problem = _accepts(getattr(cls, method), 6 if method == "resolve" else 0, keywords)
        if problem:
            raise UserError(
                f"{where}: does not fit the {base.__name__} protocol: {method}() must accept "
                f"the keyword arguments {', '.join(keywords)}: {problem}"
            )
    for flag, (method, keywords) in FLAG_KEYWORDS.get(kind, {}).items():
        if getattr(cls, flag, False) is not True:
            continue
        problem = _accepts(getattr(cls, method), 6 if method == "resolve" else 0, keywords)
        if problem:
            raise UserError(
                f"{where}: does not fit the {base.__name__} protocol: with {flag}, {method}() "
                f"must accept the keyword arguments {', '.join(keywords)}: {problem}"
            )
    params = getattr(cls, "Params", NoParams)
    if not (inspect.isclass(params) and dataclasses.is_dataclass(params)):
        raise UserError(f"{where}: Params must be a dataclass, got {params!r}")
    _check_params_types(params, where)
    for flag, value in vars(base).items():
        if isinstance(value, bool) and not isinstance(getattr(cls, flag, value), bool):
            raise UserError(f"{where}: {flag} must be True or False, got {getattr(cls, flag)!r}")
