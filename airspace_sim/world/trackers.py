"""The world's track table: every (ownship, intruder) track of the world in one tracker.

A *track* is a slot ``s`` of a :class:`airspace_sim.parts.Tracker` with ``owner[s]`` (the
aircraft that tracks), ``intruder[s]`` (the aircraft tracked) and the tracker's estimate
``x[s]`` ``[x, vx, y, vy, Ω]`` (m, m/s, m, m/s, rad/s, WORLD frame), ``P[s]`` (5, 5) and
``mu[s]`` (M,). ONE tracker object holds every track of the world in stable slots: a birth
fills free slots, a drop frees slots, no other track moves, so the bookkeeping of a step
costs O(tracks that change) plus a few vectorised passes over the slots (no per-pair
Python objects, no sort of all tracks).

Track life cycle (per scan):

1. every live track is stepped with its measurement (none: predict only; between scans
   every track is predicted only); ``misses`` counts consecutive scans that brought the
   track no measurement it used: no detection, or a detection its tracker *gated* (no mode
   explains it, :attr:`airspace_sim.parts.Tracker.gated`, for trackers that
   ``reports_gated``). A gated update is a miss because a track that has lost its target
   (e.g. a jump in a recording, or a manoeuvre its modes cannot follow) is otherwise
   detected every scan, gates every measurement and never drops, while its target goes
   untracked;
2. tracks with ``misses ≥ drop_after_misses``, or whose owner or intruder left the world,
   are dropped: a track detected on every scan whose measurements are all gated from scan
   ``k`` on is dropped at scan ``k + drop_after_misses − 1``, and the next two detections
   start a new one (pending at the scan after the drop, started at the one after that);
3. a detection without a track is *pending*; the next detection of the same pair within
   ``drop_after_misses`` scans starts the track by two-point initialisation
   (:func:`airspace_sim.tracking.initialisation.two_point_initialisation`: position = last
   measurement, velocity = difference / Δt, covariance from σ with a manoeuvre allowance).
   A tracker that ``uses_truth`` needs no initialisation: its track starts at the first
   detection.

API used by the world
---------------------
``TrackTable(n_aircraft, tracker, sigma, drop_after_misses, scan_period_s,
turn_rate_sigma=...)`` with ``tracker`` a constructed :class:`~airspace_sim.parts.Tracker`
(:func:`make_tracker` builds one from the registry; :meth:`TrackTable.build` does both
from a tracker kind and its preset);
``update(time, scanned, det_owner, det_intruder, z, alive, truth_states)`` once per world
step; ``view()`` → :class:`TrackView`, read-only dense arrays over the live tracks in slot
order (``slots``, ``owner``, ``intruder``, ``misses``, ``age``, ``x``, ``mu``, and ``P``
computed when first read), the same object until the next update; ``len(table)``,
``mode_names``, ``n_modes``, ``predicts_modes``, ``predict_modes_at(steps, slots)``.

Built-in trackers (registry kind ``"tracker"``): ``"imm"`` (:class:`ImmTracker`, the
preset's matched IMM) and ``"truth"`` (:class:`TruthTracker`, perfect surveillance: the
intruders' true states, for benchmarks and baselines).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from airspace_sim import parts
from airspace_sim.dynamics.presets import Preset
from airspace_sim.errors import UserError
from airspace_sim.registry import register
from airspace_sim.tracking.imm import SlotIMM
from airspace_sim.tracking.initialisation import two_point_initialisation
from airspace_sim.tracking.keymap import KeyMap
from airspace_sim.tracking.slots import Slots

#: Velocity variance added at track start for a manoeuvring target, (m/s)².
MANOEUVRE_VELOCITY_VAR = 10.0**2

#: Smallest initial turn-rate standard deviation of a new track, rad/s.
MIN_TURN_RATE_SIGMA = float(np.radians(3.0))


def _ro(a: np.ndarray) -> np.ndarray:
    v = a.view()
    v.flags.writeable = False
    return v


@njit(cache=True)
def _measurements_by_slot(Z, detected, slot_of_det, z, untracked):  # pragma: no cover
    """Z (capacity, 2) ← NaN and ``detected`` (capacity,) ← False, then row
    ``slot_of_det[d]`` ← z[d] and ``detected`` ← True where that is ≥ 0 (one pass; numpy's
    row scatter is several times slower). Writes the detections without a track
    (``slot_of_det`` < 0) into ``untracked`` (D,), in order, and returns their number."""
    Z[:] = np.nan
    detected[:] = False
    k = 0
    for d in range(slot_of_det.size):
        s = slot_of_det[d]
        if s >= 0:
            Z[s, 0] = z[d, 0]
            Z[s, 1] = z[d, 1]
            detected[s] = True
        else:
            untracked[k] = d
            k += 1
    return k


@njit(cache=True)
def _advance(
    live, owner, intruder, misses, age, detected, gated, scanned, drop_after, aircraft, out
):  # pragma: no cover - compiled
    """One step of the per-slot bookkeeping (capacity,) arrays, in place, in one pass:
    ``age`` + 1; on a scan ``misses`` + 1, or 0 for the slots ``detected`` (capacity,)
    bool whose measurement the tracker used (not ``gated``, (capacity,) bool). Writes the
    live slots to drop (too many misses, or owner or intruder gone) into ``out``
    (capacity,) and returns their number (an int, not an array: every array a numba
    function returns costs a boxing and a ``_numba_unpickle`` call of its type)."""
    k = 0
    for s in range(live.size):
        age[s] += 1
        if scanned:
            misses[s] = 0 if detected[s] and not gated[s] else misses[s] + 1
        if live[s] and (
            misses[s] >= drop_after or not aircraft[owner[s]] or not aircraft[intruder[s]]
        ):
            out[k] = s
            k += 1
    return k


@njit(cache=True)
def _lookup_by_previous(
    owner, intruder, n, prev_rank, prev_slot, key, rank, slot, unknown
):  # pragma: no cover - compiled
    """The tracks of this scan's detections (D,) ``owner``, ``intruder`` from the previous
    update's detections, by one merge: ``key`` (D,) ← ``owner·n + intruder``, ``rank``
    (D,) ← each pair's rank ``[owner > intruder]·n² + min·n + max`` (the world's detection
    order: the pairs ``owner < intruder`` by pair, then the others by pair), ``slot`` (D,)
    ← the slot its track had at the end of the previous update (−1: none) where the pair
    was among that update's detections ``prev_rank`` (P,) (increasing) with ``prev_slot``
    (P,); the others' indices go to ``unknown`` (D,) for the caller to ask the index.
    Sequential reads only, where the index's hash table (2 MB at 1000 aircraft) is read
    at random and, after the rest of a step, from memory. Returns ``(unknown, ordered)``:
    the number of those and whether the ranks increase; from the first that does not,
    every detection is unknown."""
    nn = n * n
    c, p = 0, prev_rank.size
    u = 0
    ordered = True
    last = -1
    for d in range(owner.size):
        o, i = owner[d], intruder[d]
        key[d] = o * n + i
        r = (nn if o > i else 0) + min(o, i) * n + max(o, i)
        rank[d] = r
        if r <= last:
            ordered = False
        last = r
        if ordered:
            while c < p and prev_rank[c] < r:
                c += 1
            if c < p and prev_rank[c] == r:
                slot[d] = prev_slot[c]
                c += 1
                continue
        slot[d] = -1
        unknown[u] = d
        u += 1
    return u, ordered


@njit(cache=True)
def _without_dropped(slot_of_det, drop, mark, out):  # pragma: no cover - compiled
    """``out`` (D,) ← ``slot_of_det`` (D,) with −1 where that slot is among ``drop`` (k,)
    (``mark`` (capacity,) bool scratch, all False before and after)."""
    for k in range(drop.size):
        mark[drop[k]] = True
    for d in range(slot_of_det.size):
        s = slot_of_det[d]
        out[d] = -1 if s < 0 or mark[s] else s
    for k in range(drop.size):
        mark[drop[k]] = False


def mode_names(preset: Preset) -> tuple[str, ...]:
    """Names of the preset's modes: straight, left, right for the 3-mode presets of known
    rates 0, +ω, −ω (the traffic's modes); else :meth:`Preset.mode_names`."""
    w = preset.turn_rates
    if preset.n_modes == 3 and not preset.estimated().any() and w[0] == 0 and w[1] == -w[2] > 0:
        return ("straight", "left", "right")
    return preset.mode_names()


@register("tracker", "imm")
class ImmTracker(parts.Tracker):
    """The IMM of the preset's tracker model (:meth:`Preset.filter_model`: the preset's
    own matched IMM unless it names another) with R = σ² I, in slots
    (:class:`~airspace_sim.tracking.imm.SlotIMM`); tracks start at that model's ``mu0``.

    Arrays are read-only views of the IMM's buffers, valid until the next step, birth or
    drop (:class:`SlotIMM`); free slots hold NaN.
    """

    @dataclass(frozen=True)
    class Params:
        kernel: str = parts.param(
            "auto",
            doc="IMM step kernel (same bits either way, see tracking.IMM)",
            choices=("auto", "generated", "loops"),
        )

    predicts_modes = True
    reports_gated = True

    def __init__(self, preset: Preset, sigma: float, params=None):
        p = preset.with_(measurement_sigma=max(float(sigma), 1e-3)).filter_model()
        if p.n_state != 5:
            # the track table and the avoidance read [x, vx, y, vy, Ω] tracks
            raise UserError(
                f"tracker model {p.name!r}: its filter state has {p.n_state} components "
                "(along-track acceleration); the world's tracks are [x, vx, y, vy, Ω]: use it "
                "with evaluate-tracker, or pick a 5-state tracker model"
            )
        self.params = self.Params() if params is None else params
        self.imm = SlotIMM(**p.imm_arguments(), kernel=self.params.kernel)
        self._mu0 = p.mu0()
        self.n_modes = p.n_modes
        self.mode_names = mode_names(p)

    capacity = property(lambda self: self.imm.capacity, doc="Number of lanes allocated.")
    alive = property(lambda self: self.imm.alive, doc="(capacity,) bool: live slots.")
    x = property(lambda self: self.imm.x, doc="(capacity, 5) posterior states by slot.")
    P = property(lambda self: self.imm.P, doc="(capacity, 5, 5) posterior covariances.")
    mu = property(lambda self: self.imm.mu, doc="(capacity, M) mode probabilities by slot.")
    gated = property(lambda self: self.imm.gated, doc="(capacity,) bool: measurement gated.")

    def birth(self, x0, P0) -> np.ndarray:
        return self.imm.birth(x0, P0, self._mu0)

    def birth_checked(self, x0, P0) -> np.ndarray:
        if not self.__dict__.get("_mu0_checked"):  # mu0's checks, once (they only raise)
            self.imm._initial(np.zeros((1, self.imm.n)), np.eye(self.imm.n), self._mu0, "")
            self._mu0_checked = True
        # the rows of mu0 as SlotIMM._initial makes them (the same numpy operations)
        mu0 = np.broadcast_to(np.array(self._mu0, dtype=float), (x0.shape[0], self.n_modes))
        mu0 = mu0.copy()
        return self.imm.birth_checked(x0, P0, np.ascontiguousarray(mu0 / mu0.sum(axis=1)[:, None]))

    def drop(self, slots) -> None:
        self.imm.drop(slots)

    def step(self, z, truth=None) -> None:
        self.imm.step(z)

    def predict_modes_at(self, steps, slots):
        return self.imm.predict_modes_at(steps, slots)


@register("tracker", "truth")
class TruthTracker(parts.Tracker):
    """Perfect surveillance: each track holds its intruder's true state, ``P`` = 0 and
    ``mu`` = NaN (no mode estimate; ``n_modes`` is the preset's)."""

    uses_truth = True

    def __init__(self, preset: Preset, sigma: float, params=None):
        self.params = parts.NoParams() if params is None else params
        self.n_modes = preset.n_modes
        self.mode_names = mode_names(preset)
        self._slots = Slots()
        self._x = np.zeros((0, 5))
        self._P = np.zeros((0, 5, 5))
        self._mu = np.zeros((0, self.n_modes))

    capacity = property(lambda self: self._slots.capacity, doc="Number of lanes allocated.")
    alive = property(lambda self: _ro(self._slots.alive), doc="(capacity,) bool: live slots.")
    x = property(lambda self: _ro(self._x), doc="(capacity, 5) true states by slot.")
    P = property(lambda self: _ro(self._P), doc="(capacity, 5, 5) zeros.")
    mu = property(lambda self: _ro(self._mu), doc="(capacity, M) NaN.")

    def birth(self, x0, P0) -> np.ndarray:
        x0 = np.asarray(x0, dtype=float).reshape(-1, 5)
        k = x0.shape[0]
        need = self._slots.capacity_for(k)
        if need > self.capacity:
            old = self.capacity
            x = np.full((need, 5), np.nan)
            x[:old] = self._x
            self._x = x
            self._P = np.zeros((need, 5, 5))
            self._mu = np.full((need, self.n_modes), np.nan)
            self._slots.grow(need)
        slots = self._slots.take(k)
        self._x[slots] = x0
        return slots

    def drop(self, slots) -> None:
        s = self._slots.release(slots, "truth tracker drop")
        self._x[s] = np.nan

    def step(self, z, truth=None) -> None:
        if truth is None:
            raise UserError("truth tracker: step needs the intruders' true states")
        live = self._slots.alive
        self._x[live] = np.asarray(truth, dtype=float)[live]


def make_tracker(kind: str, preset: Preset, sigma: float, params=None) -> parts.Tracker:
    """The registered tracker ``kind`` for ``preset`` (at the world's dt) and sensor σ (m).

    ``params``: an instance of the class's ``Params``, a dict of its fields, or None (the
    defaults).
    """
    from airspace_sim import registry

    return registry.build("tracker", kind, preset, sigma, params=params)


#: Largest tracker capacity whose views are gathered into kept buffers in one numba pass
#: (:class:`_LiveTracks`): that saves a dozen numpy calls per step, which is what a small
#: world's step costs (``docs/env-speed.md``); a large table's gathers cost the same either
#: way, and its buffers would hold memory between steps.
KEPT_VIEW_MAX_SLOTS = 4096


class TrackView:
    """Read-only dense arrays over the live tracks of a :class:`TrackTable`, in slot order
    (``P`` live tracks): ``slots``, ``owner``, ``intruder``, ``misses``, ``age`` (steps
    since the track started) (P,) int; ``x`` (P, 5); ``mu`` (P, M); ``P`` (P, 5, 5),
    gathered when first read. Valid until the table's next update: for the built-in
    trackers the arrays are views of buffers the table keeps and gathers into again at the
    next :meth:`TrackTable.view` (:class:`_LiveTracks`, one numba pass), so a caller that
    keeps them past an update copies them."""

    __slots__ = ("slots", "owner", "intruder", "misses", "age", "x", "mu", "_live", "_P")

    def __init__(self, table: TrackTable):
        t = table.tracker
        self._P = None
        alive = t.alive
        if type(t) in (ImmTracker, TruthTracker) and alive.size <= KEPT_VIEW_MAX_SLOTS:
            self._live, fields = table._gather_live_view(alive)
        else:  # a large table or another tracker: numpy's gathers of whatever its arrays are
            self._live = t
            s = np.flatnonzero(alive)
            # (np.take: a row gather several times faster than fancy indexing)
            arrays = (table._owner, table._intruder, table._misses, table._age, t.x, t.mu)
            fields = (_ro(s),) + tuple(_ro(np.take(a, s, axis=0)) for a in arrays)
        (self.slots, self.owner, self.intruder, self.misses, self.age, self.x, self.mu) = fields

    @property
    def P(self) -> np.ndarray:
        if self._P is None:
            if isinstance(self._live, _LiveTracks):
                self._P = self._live.gather_P()
            else:
                self._P = _ro(np.take(self._live.P, self.slots, axis=0))
        return self._P

    def __len__(self) -> int:
        return int(self.slots.size)


@njit(cache=True)
def _gather_live(alive, owner, intruder, misses, age, x, mu, o_slots, o_owner, o_intruder,
                 o_misses, o_age, o_x, o_mu):  # fmt: skip  # pragma: no cover - compiled
    """The live slots' rows of the (capacity,) bookkeeping and the tracker's ``x``, ``mu``
    written densely into the ``o_`` buffers, in slot order; returns their number."""
    k = 0
    for s in range(alive.size):
        if alive[s]:
            o_slots[k] = s
            o_owner[k] = owner[s]
            o_intruder[k] = intruder[s]
            o_misses[k] = misses[s]
            o_age[k] = age[s]
            for c in range(x.shape[1]):
                o_x[k, c] = x[s, c]
            for m in range(mu.shape[1]):
                o_mu[k, m] = mu[s, m]
            k += 1
    return k


@njit(cache=True)
def _gather_rows3(P, slots, out):  # pragma: no cover - compiled
    """``out[k] = P[slots[k]]`` for (S, a, b) ``P``."""
    for k in range(slots.size):
        s = slots[k]
        for a in range(P.shape[1]):
            for b in range(P.shape[2]):
                out[k, a, b] = P[s, a, b]


class _LiveTracks:
    """The buffers a :class:`TrackTable`'s views are gathered into, kept across updates
    (one numba pass per view instead of a gather and a read-only wrapper per array), with
    the read-only views of their first ``P`` rows kept while ``P`` does not change."""

    def __init__(self, capacity: int, n_modes: int):
        self.capacity = capacity
        self.n_modes = n_modes
        i64 = np.int64
        self.arrays = (
            np.empty(capacity, i64),
            np.empty(capacity, i64),
            np.empty(capacity, i64),
            np.empty(capacity, i64),
            np.empty(capacity, i64),
            np.empty((capacity, 5)),
            np.empty((capacity, n_modes)),
        )
        self.P_buf = np.empty((capacity, 5, 5))
        self.count = -1
        self.views = None
        self.P_view = None
        self.tracker = None

    def gather(self, table: TrackTable, alive, x, mu):
        """``(slots, owner, intruder, misses, age, x, mu)`` of the live tracks, read-only
        views of the buffers, gathered now from the table and its tracker's ``alive``,
        ``x``, ``mu``."""
        self.tracker = table.tracker
        if not (alive.shape[0] == x.shape[0] == mu.shape[0] == self.capacity):
            raise ValueError("track views: the tracker's arrays are not of its capacity")
        k = _gather_live(
            alive, table._owner, table._intruder, table._misses, table._age, x, mu,
            *self.arrays,
        )  # fmt: skip
        if k != self.count:
            self.count = k
            self.views = tuple(_ro(a[:k]) for a in self.arrays)
            self.P_view = _ro(self.P_buf[:k])
        return self.views

    def gather_P(self) -> np.ndarray:
        _gather_rows3(self.tracker.P, self.views[0], self.P_buf)
        return self.P_view


class TrackTable:
    """All tracks of a world (see the module docstring).

    n_aircraft : N; tracker : a constructed :class:`~airspace_sim.parts.Tracker` with no
    live slot; sigma : sensor position σ, m; drop_after_misses : scans; scan_period_s : s
    between scans; turn_rate_sigma : initial Ω standard deviation of a new track, rad/s
    (:meth:`build` takes the preset's fastest turn, at least 3°/s).
    """

    # ``gated`` of a tracker that never gates, resized by :meth:`update`; the class default
    # serves tables pickled before it existed (checkpoints)
    _no_gate = np.zeros(0, dtype=np.bool_)
    # the slots :func:`_advance` drops, resized by :meth:`update` (class default: as above)
    _drop_buf = np.zeros(0, dtype=np.int64)
    # the last update's detections (:func:`_lookup_by_previous`): pair ranks, increasing,
    # and their slots at its end (derived from the index, not pickled); a mark per slot
    _prev_rank = np.zeros(0, dtype=np.int64)
    _prev_slot = np.zeros(0, dtype=np.int64)
    _mark = np.zeros(0, dtype=np.bool_)
    # the slots detected this update (:func:`_measurements_by_slot`), sized with ``_z``
    _detected = np.zeros(0, dtype=np.bool_)

    def __init__(
        self,
        n_aircraft: int,
        tracker: parts.Tracker,
        sigma: float,
        drop_after_misses: int,
        scan_period_s: float,
        turn_rate_sigma: float = MIN_TURN_RATE_SIGMA,
    ):
        if not isinstance(tracker, parts.Tracker):
            raise UserError(f"TrackTable: tracker must be a parts.Tracker, got {tracker!r}")
        self.n = int(n_aircraft)
        self.tracker = tracker
        self.sigma = float(sigma)
        self.drop_after = max(1, int(drop_after_misses))
        self.scan_period_s = float(scan_period_s)
        self._omega_var = float(turn_rate_sigma) ** 2
        # per-slot bookkeeping, sized like the tracker (free slots: owner = intruder = 0)
        self._owner = np.zeros(0, dtype=np.int64)
        self._intruder = np.zeros(0, dtype=np.int64)
        self._misses = np.zeros(0, dtype=np.int64)
        self._age = np.zeros(0, dtype=np.int64)
        # live tracks' slots by key owner·N + intruder
        self._index = KeyMap()
        # pending detections (sorted by key): last measurement and its time
        self._pend_key = np.zeros(0, dtype=np.int64)
        self._pend_z = np.zeros((0, 2))
        self._pend_t = np.zeros(0)
        self._z = np.zeros((0, 2))
        self._view = None

    @classmethod
    def build(
        cls,
        n_aircraft: int,
        kind: str,
        preset: Preset,
        sigma: float,
        drop_after_misses: int,
        scan_period_s: float,
        params=None,
    ) -> TrackTable:
        """The table of the registered tracker ``kind`` (:func:`make_tracker`), with the
        initial Ω σ from the fastest turn of ``preset``'s tracker model (at least 3°/s)."""
        rates = np.abs(np.asarray(preset.filter_model().turn_rates, dtype=float))
        omega = max(float(rates.max(initial=0.0)), MIN_TURN_RATE_SIGMA)
        tracker = make_tracker(kind, preset, sigma, params)
        return cls(n_aircraft, tracker, sigma, drop_after_misses, scan_period_s, omega)

    # ------------------------------------------------------------------ views
    def __len__(self) -> int:
        return len(self._index)

    @property
    def n_modes(self) -> int:
        return int(self.tracker.n_modes)

    @property
    def mode_names(self) -> tuple[str, ...]:
        return tuple(self.tracker.mode_names)

    @property
    def predicts_modes(self) -> bool:
        return bool(self.tracker.predicts_modes)

    def predict_modes_at(self, steps, slots):
        """The tracker's mode-conditioned predictions for ``slots`` (R,) at ``steps`` (S,):
        ``(xs (R, M, S, 5), Ps (R, M, S, 5, 5))`` (:meth:`parts.Tracker.predict_modes_at`)."""
        return self.tracker.predict_modes_at(steps, slots)

    def view(self) -> TrackView:
        """The live tracks as dense read-only arrays (:class:`TrackView`), slot order."""
        if self._view is None:
            self._view = TrackView(self)
        return self._view

    def _gather_live_view(self, alive):
        """``(buffers, fields)``: the view buffers (:class:`_LiveTracks`, (re)made for the
        tracker's capacity and modes) and the live tracks (``alive`` the tracker's)
        gathered into them."""
        t = self.tracker
        x, mu = t.x, t.mu
        cap, m = mu.shape
        live = self.__dict__.get("_live")
        if live is None or live.capacity != cap or live.n_modes != m:
            live = self._live = _LiveTracks(cap, m)
        return live, live.gather(self, alive, x, mu)

    def __getstate__(self) -> dict:
        """The table without its view and view buffers (derived state: pickled arrays are
        no longer views of the buffers), made again at the next :meth:`view`."""
        state = self.__dict__.copy()
        state.pop("_live", None)
        state.pop("_tracks_of_view", None)  # snapshot.live_tracks' of the kept views
        for name in ("_drop_buf", "_mark", "_prev_rank", "_prev_slot", "_detected"):  # scratch
            state.pop(name, None)
        state["_view"] = None
        return state

    # ----------------------------------------------------------------- update
    def update(
        self, time: float, scanned: bool, det_owner, det_intruder, z, alive, truth_states=None
    ) -> None:
        """One world step of the table.

        time : s, now. scanned : a scan happened now. det_owner, det_intruder (D,) int and
        z (D, 2) m: this scan's detections. alive : (N,) bool aircraft still in the world.
        truth_states : (N, 5) true ``[x, vx, y, vy, Ω]`` (needed by trackers that
        ``uses_truth``).
        """
        self._view = None
        t = self.tracker
        if t.uses_truth and truth_states is None:
            raise UserError("TrackTable.update: this tracker needs truth_states")
        z = np.asarray(z, dtype=float).reshape(-1, 2)
        det_owner = np.ascontiguousarray(det_owner, dtype=np.int64)
        det_intruder = np.ascontiguousarray(det_intruder, dtype=np.int64)
        D = det_owner.size
        if det_intruder.size != D or z.shape[0] != D:
            raise UserError(f"TrackTable.update: {D} owners, {det_intruder.size} intruders, "
                            f"{z.shape[0]} measurements")  # fmt: skip
        # −1: no track; the previous update's detections first, then the index
        det_key, rank, slot_of_det, new = np.empty((4, D), np.int64)
        prev_rank, prev_slot = self._prev_rank, self._prev_slot
        # (kept only by an update that completes)
        self._prev_rank = self._prev_slot = np.zeros(0, dtype=np.int64)
        n_ask, ordered = 0, True
        if D:
            n_ask, ordered = _lookup_by_previous(
                det_owner, det_intruder, self.n, prev_rank, prev_slot, det_key, rank,
                slot_of_det, new,
            )  # fmt: skip
        if n_ask:
            ask = new[:n_ask]
            slot_of_det[ask] = self._index.get(det_key[ask])
        untracked = -1  # (not counted yet)
        drop = slot_of_det[:0]  # the slots dropped
        after = slot_of_det  # the detections' slots after this update (−1: none)
        # 1. step every live track (NaN row: no measurement)
        if len(self):
            cap = t.capacity
            if self._z.shape[0] != cap:
                self._z = np.empty((cap, 2))
            if self._detected.size != cap:
                self._detected = np.empty(cap, dtype=np.bool_)
            untracked = _measurements_by_slot(self._z, self._detected, slot_of_det, z, new)
            truth = np.asarray(truth_states)[self._intruder] if t.uses_truth else None
            t.step(self._z, truth)
            # 2. age, misses (a gated measurement is a miss), drop
            if t.reports_gated:
                gated = np.asarray(t.gated, dtype=np.bool_)
            else:
                if self._no_gate.size != cap:
                    self._no_gate = np.zeros(cap, dtype=np.bool_)
                gated = self._no_gate
            if self._drop_buf.size != cap:
                self._drop_buf = np.empty(cap, dtype=np.int64)
            n_drop = _advance(
                np.asarray(t.alive), self._owner, self._intruder, self._misses, self._age,
                self._detected, gated, bool(scanned), self.drop_after,
                np.asarray(alive, dtype=np.bool_), self._drop_buf,
            )  # fmt: skip
            if n_drop:
                drop = self._drop_buf[:n_drop].copy()
                if self._mark.size != cap:
                    self._mark = np.zeros(cap, dtype=np.bool_)
                after = np.empty_like(slot_of_det)
                _without_dropped(slot_of_det, drop, self._mark, after)
                self._drop(drop)
        # 3. births
        if untracked < 0:  # no track stepped: every detection is new
            untracked = D
            new = np.arange(D)
        if untracked:
            new = new[:untracked]
            self._births(time, det_key[new], z[new], truth_states)
            if ordered:
                if after is slot_of_det:
                    after = slot_of_det.copy()
                after[new] = self._index.get(det_key[new])
        if D == 0 and prev_rank.size:  # between scans: the last scan's, less the drops
            rank, after = prev_rank, prev_slot
            if drop.size:
                after = np.empty_like(prev_slot)
                _without_dropped(prev_slot, drop, self._mark, after)
        if ordered:  # (else the next update asks the index for every detection)
            self._prev_rank, self._prev_slot = rank, after

    def _drop(self, slots: np.ndarray) -> None:
        self.tracker.drop(slots)
        self._index.delete(self._owner[slots] * self.n + self._intruder[slots])
        self._owner[slots] = 0
        self._intruder[slots] = 0

    def _start(self, keys: np.ndarray, x0, P0, checked: bool = False) -> None:
        """Start tracks for the (sorted, new) ``keys`` (k,) from x0 (k, 5), P0 (k, 5, 5)
        (``checked``: through :meth:`parts.Tracker.birth_checked`)."""
        t = self.tracker
        slots = np.asarray(t.birth_checked(x0, P0) if checked else t.birth(x0, P0), np.int64)
        cap = self.tracker.capacity
        if self._owner.size < cap:
            for name in ("_owner", "_intruder", "_misses", "_age"):
                a = getattr(self, name)
                b = np.zeros(cap, dtype=np.int64)
                b[: a.size] = a
                setattr(self, name, b)
        self._owner[slots] = keys // self.n
        self._intruder[slots] = keys % self.n
        self._misses[slots] = 0
        self._age[slots] = 0
        self._index.put(keys, slots)

    def _births(self, time, keys, z, truth_states) -> None:
        """The detections without a track, keys (k,) and z (k, 2): a second detection
        within the pending window starts a track, the others are (or refresh) pending.
        One numba pass over the sorted keys and the pending detections
        (:func:`_pending_births`); where that declines (repeated keys, a pending detection
        not older than ``time``, initial covariances near the limits of the checks it
        leaves out), :meth:`_births_reference`, the same rule in numpy."""
        if self.tracker.uses_truth:
            self._births_reference(time, keys, z, truth_states)
            return
        order = np.argsort(keys, kind="stable")
        keys, z = keys[order], np.ascontiguousarray(z[order])
        k, n_pend = keys.size, self._pend_key.size
        start = np.empty(k, np.int64)
        x0, P0 = np.empty((k, 5)), np.empty((k, 5, 5))
        pend = (np.empty(n_pend + k, np.int64), np.empty((n_pend + k, 2)), np.empty(n_pend + k))
        n_start, n_new = _pending_births(
            float(time), self.drop_after * self.scan_period_s + 1e-9, keys, z,
            self._pend_key, self._pend_z, self._pend_t, max(self.sigma, 1.0) ** 2,
            self._omega_var, MANOEUVRE_VELOCITY_VAR, start, x0, P0, *pend,
        )  # fmt: skip
        if n_start < 0:
            self._births_reference(time, keys, z, truth_states)
            return
        if n_start:
            self._start(start[:n_start], x0[:n_start], P0[:n_start], checked=True)
        self._pend_key, self._pend_z, self._pend_t = (a[:n_new] for a in pend)

    def _births_reference(self, time, keys, z, truth_states) -> None:
        """:meth:`_births` in numpy (the reference for :func:`_pending_births`)."""
        order = np.argsort(keys, kind="stable")
        keys, z = keys[order], z[order]
        if self.tracker.uses_truth:  # no initialisation needed: start at once
            x0 = np.asarray(truth_states, dtype=float)[keys % self.n]
            self._start(keys, x0, np.zeros((keys.size, 5, 5)))
            return
        # expire stale pending detections
        max_age = self.drop_after * self.scan_period_s + 1e-9
        fresh = (time - self._pend_t) <= max_age
        if not fresh.all():
            self._pend_key, self._pend_z, self._pend_t = (
                self._pend_key[fresh],
                self._pend_z[fresh],
                self._pend_t[fresh],
            )
        prev = _sorted_lookup(self._pend_key, keys)
        two = prev >= 0
        if two.any():
            two[two] = time - self._pend_t[prev[two]] > 0
        if two.any():
            p = prev[two]
            s2 = max(self.sigma, 1.0) ** 2
            x0, P0 = two_point_initialisation(
                self._pend_z[p],
                z[two],
                time - self._pend_t[p],
                s2 * np.eye(2),
                omega=0.0,
                omega_var=self._omega_var,
                extra_velocity_var=MANOEUVRE_VELOCITY_VAR,
            )
            self._start(keys[two], x0, P0)
            gone = np.ones(self._pend_key.size, dtype=bool)
            gone[p] = False
            self._pend_key, self._pend_z, self._pend_t = (
                self._pend_key[gone],
                self._pend_z[gone],
                self._pend_t[gone],
            )
        # the others become (or refresh) pending detections
        rest = ~two
        if rest.any():
            old = prev[rest]
            refresh = old >= 0
            self._pend_z[old[refresh]] = z[rest][refresh]
            self._pend_t[old[refresh]] = time
            add = ~refresh
            if add.any():
                nk = keys[rest][add]
                pos = np.searchsorted(self._pend_key, nk)
                self._pend_key = np.insert(self._pend_key, pos, nk)
                self._pend_z = np.insert(self._pend_z, pos, z[rest][add], axis=0)
                self._pend_t = np.insert(self._pend_t, pos, time)


#: :func:`_pending_births` starts a track without the tracker's checks of its initial
#: covariance (:meth:`parts.Tracker.birth_checked`) only when the covariance's smallest
#: eigenvalue is certainly above this fraction of its largest: per axis
#: ``[[s², s²/Δt], [s²/Δt, 2s²/Δt² + q]]`` is positive definite for every Δt > 0
#: (determinant ``s⁴/Δt² + s²q``, smallest eigenvalue at least determinant / trace), and
#: far above the error of a numerical eigenvalue check (~1e-15 of the largest) it cannot
#: be judged otherwise. Other starts take the numpy path and its checks.
_CHECKED_MIN_RATIO = 1e-9


@njit(cache=True)
def _pending_births(
    time, max_age, keys, z, pend_key, pend_z, pend_t, s2, omega_var, extra_var,
    start, x0, P0, new_key, new_z, new_t,
):  # fmt: skip  # pragma: no cover - compiled
    """:meth:`TrackTable._births_reference` as one merge of the sorted detection ``keys``
    (k,) (positions ``z`` (k, 2) m) with the pending detections ``pend_key`` (p,) sorted,
    ``pend_z`` (p, 2) m, ``pend_t`` (p,) s.

    A pending detection older than ``max_age`` s is forgotten; a key that has a pending
    detection becomes a track start (``start``, ``x0`` (k, 5), ``P0`` (k, 5, 5) filled from
    0: two-point initialisation with R = s2·I m², Ω = 0, Ω variance ``omega_var``,
    velocity allowance ``extra_var`` (m/s)², the same arithmetic as
    :func:`~airspace_sim.tracking.initialisation.two_point_initialisation`); the other keys
    join the pending ones in ``new_key``, ``new_z``, ``new_t`` (sorted). Returns
    ``(track starts, pending detections)``, or ``(-1, -1)`` with nothing written where
    the reference path must decide: repeated keys, a pending detection not older than
    ``time`` (it would be refreshed), an initial covariance not certainly positive definite
    (:data:`_CHECKED_MIN_RATIO`) or a start that is not finite.
    """
    k, p = keys.size, pend_key.size
    for q in range(1, k):
        if keys[q] <= keys[q - 1]:
            return -1, -1
    # first pass: decide, without writing, whether this path applies
    i = 0
    for q in range(k):
        while i < p and (pend_key[i] < keys[q] or not (time - pend_t[i]) <= max_age):
            i += 1
        if i < p and pend_key[i] == keys[q]:
            d = time - pend_t[i]
            if not d > 0.0:
                return -1, -1
            # the per-axis block's trace and determinant (the latter as a sum of positive
            # terms), and the turn-rate variance: eigenvalues certainly well apart from 0
            trace = s2 + (2.0 * s2 / (d * d) + extra_var)
            det = s2 * s2 / (d * d) + s2 * extra_var
            big = max(trace, omega_var)
            if not (big < 1e300 and det / trace >= _CHECKED_MIN_RATIO * big):
                return -1, -1
            if not (omega_var >= _CHECKED_MIN_RATIO * big and extra_var >= 0.0):
                return -1, -1
            i += 1
    n_start = 0
    n_new = 0
    i = 0
    for q in range(k + 1):
        # pending detections before this key stay, if fresh
        while i < p and (q == k or pend_key[i] < keys[q]):
            if (time - pend_t[i]) <= max_age:
                new_key[n_new] = pend_key[i]
                new_z[n_new, 0] = pend_z[i, 0]
                new_z[n_new, 1] = pend_z[i, 1]
                new_t[n_new] = pend_t[i]
                n_new += 1
            i += 1
        if q == k:
            break
        if i < p and pend_key[i] == keys[q] and (time - pend_t[i]) <= max_age:
            d = time - pend_t[i]
            b = n_start
            start[b] = keys[q]
            x0[b, 0] = z[q, 0]
            x0[b, 2] = z[q, 1]
            x0[b, 1] = (z[q, 0] - pend_z[i, 0]) / d
            x0[b, 3] = (z[q, 1] - pend_z[i, 1]) / d
            x0[b, 4] = 0.0
            P0[b] = 0.0
            rd = s2 / d
            vv = 2.0 * s2 / (d * d) + extra_var
            for a in range(2):
                pa, va = 2 * a, 2 * a + 1  # x, vx; y, vy
                P0[b, pa, pa] = s2
                P0[b, pa, va] = rd
                P0[b, va, pa] = rd
                P0[b, va, va] = vv
            P0[b, 4, 4] = omega_var
            n_start += 1
            i += 1
        else:  # a stale pending detection of this key is passed over by the loop above
            if i < p and pend_key[i] == keys[q]:
                i += 1
            new_key[n_new] = keys[q]
            new_z[n_new, 0] = z[q, 0]
            new_z[n_new, 1] = z[q, 1]
            new_t[n_new] = time
            n_new += 1
    for b in range(n_start):
        for c in range(5):
            if not np.isfinite(x0[b, c]):
                return -1, -1
            for e in range(5):
                if not np.isfinite(P0[b, c, e]):
                    return -1, -1
    return n_start, n_new


def _sorted_lookup(sorted_keys: np.ndarray, query: np.ndarray) -> np.ndarray:
    """For each query key, its index in ``sorted_keys`` (sorted, unique), or −1."""
    if sorted_keys.size == 0 or query.size == 0:
        return np.full(query.size, -1, dtype=np.int64)
    pos = np.minimum(np.searchsorted(sorted_keys, query), sorted_keys.size - 1)
    return np.where(sorted_keys[pos] == query, pos, -1)
