"""The paper's encounter in its relative frame (paper §V–VII, ``docs/paper-notes.md`` §3).

The ownship sits at the origin of a frame that moves with it; the state of the intruder is
its position and velocity *relative* to the ownship, ``[x, vx, y, vy, Ω]`` (m, m/s, rad/s).

Geometry (paper §VI, with the choices the paper leaves open written down):

- the intruder starts on a random point of the ``start_radius`` = 4.5 km circle;
- its (relative) speed is uniform in ``[V_cruise, 2·V_cruise]`` (the preset's
  ``speed_range``), and its direction aims at a point drawn uniformly in the disc of radius
  ``aim_radius`` (default ``r_safe/2`` = 1.5 km) around the ownship, so that it becomes unsafe
  if it keeps straight (its straight-line closest approach is at most ``aim_radius``);
- it then flies the jump-Markov model of the preset (``seed``: Π per step, ω = π/4 rad/s,
  ΔT = 0.1 s, Q = v added every step), starting in mode 1 (straight);
- measurements are its position plus N(0, σ² I), σ = 50 m.

Tracking: a batched :class:`~airspace_sim.tracking.IMM` with the preset's
``imm_arguments()``. The encounter starts with an established track (the paper shows no
track initiation): the initial estimate is the true state plus a draw from ``P0`` =
diag(σ², σ_v², σ², σ_v², σ_Ω²) with σ = the measurement σ, σ_v = ``init_sigma_velocity``.

Avoidance, literally as the paper does it (§V): every step, the resolver looks at the IMM
estimate; on a predicted conflict the ownship "rotates the coordinate frame" by θ, which in
this frame rotates the intruder's **true relative velocity** by θ (``docs/paper-notes.md`` §3).
The tracker is *not* told: to it the rotation is an unmodelled manoeuvre of the intruder,
which is exactly the paper's false mode-2 detection near t = 10 s (§VII).

Any registered resolver can drive it: the frame is presented to the resolver as an
intruder at rest and an ownship moving with ``−v_rel``; a heading change ψ of that
ownship rotates ``v_rel`` by exactly ψ, so ``"seed"`` gives the paper's θ and ``"bands"``
its band choice, both as rotations of the relative velocity bounded by ``max_angle`` per
step (paper: π/4).

An encounter ends when the intruder is outside ``start_radius`` and receding, or after
``duration_s``; its metrics are frozen from then on.

All random numbers of encounter ``i`` of campaign seed ``s`` come from
``np.random.default_rng(np.random.SeedSequence([s, i]))`` and are drawn up front
(:func:`draw_encounters`), so an encounter's result does not depend on which batch, chunk
or worker runs it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from airspace_sim.dynamics import models
from airspace_sim.dynamics import presets as _presets
from airspace_sim.dynamics.markov import mode_cdf, next_modes
from airspace_sim.dynamics.truth import noise_factor
from airspace_sim.errors import UserError
from airspace_sim.tracking.prediction import relative_positions

POS = list(models.POSITION)
VEL = list(models.VELOCITY)
STRAIGHT = 0


@dataclass(frozen=True)
class EncounterConfig:
    """Settings of one family of encounters (both frames). Units: m, s, rad, m/s.

    preset : dynamics preset name (``"seed"``: the paper's numbers).
    r_safe : safety radius R_safety, m (paper 3000).
    start_radius : radius of the start circle, m (paper 4.5 km).
    aim_radius : the intruder aims at a uniform point of this disc; None → r_safe/2.
    duration_s : maximum encounter length, s.
    horizon : look-ahead of the paper's detector, steps (paper 3).
    max_angle : relative frame: bound on the per-step rotation θ, rad (paper π/4).
    max_turn_rate : world frame: ownship turn-rate limit, rad/s (seed: π/4, the model's ω).
    own_speed : world frame: ownship ground speed, m/s (V_cruise).
    own_motion : world frame: ``"straight"`` or ``"markov"`` (the ownship flies the
        preset's mode chain when it is not avoiding).
    intruder_turns : False pins the intruder to mode 1 (straight).
    process_noise : False removes the truth's process noise.
    measurement_sigma : σ of position measurements, m; None → the preset's (50 m).
        ``0`` gives exact measurements (the filter keeps the preset's R).
    init_sigma_velocity : σ of the initial track's velocity error, m/s.
    false_detection_window_s : world/relative: a step counts as "during an own manoeuvre"
        if the ownship turned within this many seconds before it.
    lookahead_s : look-ahead of every resolver whose ``Params`` has ``lookahead_s``, s.
    target_heading_limit : world frame: resolvers choose a heading change within ± this
        (rad, default π: any heading); the ownship turns toward it at ``max_turn_rate``.
    probability_horizon_s : look-ahead of the IMM mode predictions given to
        ``bands-probabilistic`` (10 points spread over it), s.
    resolver_params : per resolver name, a table of its ``Params`` values (validated).
    """

    preset: str = "seed"
    r_safe: float = 3000.0
    start_radius: float = 4500.0
    aim_radius: float | None = None
    duration_s: float = 40.0
    horizon: int = 3
    max_angle: float = math.pi / 4
    max_turn_rate: float = math.pi / 4
    own_speed: float = _presets.V_CRUISE
    own_motion: str = "straight"
    intruder_turns: bool = True
    process_noise: bool = True
    measurement_sigma: float | None = None
    init_sigma_velocity: float = 10.0
    false_detection_window_s: float = 0.5
    lookahead_s: float = 30.0
    target_heading_limit: float = math.pi
    probability_horizon_s: float = 5.0
    resolver_params: dict = field(default_factory=dict)

    def __post_init__(self):
        for key in ("r_safe", "start_radius", "duration_s", "max_angle", "own_speed"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise UserError(f"encounter config: {key} must be a positive number, got {v!r}")
        if self.start_radius <= self.r_safe:
            raise UserError(
                f"encounter config: start_radius ({self.start_radius} m) must exceed r_safe ({self.r_safe} m)"
            )
        if self.own_motion not in ("straight", "markov"):
            raise UserError(
                f"encounter config: own_motion must be 'straight' or 'markov', got {self.own_motion!r}"
            )
        if int(self.horizon) < 1:
            raise UserError(f"encounter config: horizon must be >= 1 step, got {self.horizon!r}")

    @property
    def aim(self) -> float:
        return self.r_safe / 2 if self.aim_radius is None else float(self.aim_radius)

    def model(self):
        return _presets.get(self.preset)

    def n_steps(self) -> int:
        return int(round(self.duration_s / self.model().dt)) + 1

    def sigma(self) -> float:
        p = self.model()
        return (
            p.measurement_sigma if self.measurement_sigma is None else float(self.measurement_sigma)
        )

    def to_dict(self) -> dict:
        return asdict(self)


# ----------------------------------------------------------------------------- randomness
def encounter_rng(seed: int, index: int) -> np.random.Generator:
    """The generator of encounter ``index`` of campaign ``seed`` (independent of batching)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(index)]))


def draw_encounters(seed: int, indices, cfg: EncounterConfig) -> dict:
    """Every random number of each encounter, drawn from its own generator, stacked (B, ...).

    Keys: ``start_angle``, ``speed``, ``aim`` (B, 2) aim point, ``own_heading`` (B,),
    ``mode_u`` (B, T) uniforms of the intruder's mode chain, ``own_mode_u`` (B, T),
    ``w`` (B, T, 5) process-noise increments (already scaled by ``L``, ``L Lᵀ = Q``),
    ``v`` (B, T, 2) standard-normal measurement noise, ``e0`` (B, 5) standard-normal
    initial-track error.
    """
    p = cfg.model()
    T = cfg.n_steps()
    L = noise_factor(np.asarray(p.process_noise))
    out = {
        k: []
        for k in (
            "start_angle",
            "speed",
            "aim",
            "own_heading",
            "mode_u",
            "own_mode_u",
            "w",
            "v",
            "e0",
        )
    }
    for i in indices:
        rng = encounter_rng(seed, i)
        out["start_angle"].append(rng.uniform(-np.pi, np.pi))
        out["speed"].append(rng.uniform(*p.speed_range))
        r = cfg.aim * math.sqrt(rng.random())
        phi = rng.uniform(-np.pi, np.pi)
        out["aim"].append((r * math.cos(phi), r * math.sin(phi)))
        out["own_heading"].append(rng.uniform(-np.pi, np.pi))
        out["mode_u"].append(rng.random(T))
        out["own_mode_u"].append(rng.random(T))
        w = rng.standard_normal((T, models.N_STATE))
        # per encounter (not per batch): rounding cannot depend on the batch
        out["w"].append(np.einsum("ij,tj->ti", L, w) if cfg.process_noise else np.zeros_like(w))
        out["v"].append(rng.standard_normal((T, 2)))
        out["e0"].append(rng.standard_normal(models.N_STATE))
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}


# ----------------------------------------------------------------------------- geometry
def rotate(v: np.ndarray, angle) -> np.ndarray:
    """Rotate (B, 2) vectors CCW by ``angle`` (B,) radians."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[:, 0] - s * v[:, 1], s * v[:, 0] + c * v[:, 1]], axis=-1)


def segment_distance_to_origin(p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """Closest distance to the origin of the segments p0→p1, (B, 2) → (B,) metres.

    Straight-line motion between samples, so a straight encounter's minimum is its exact
    closest point of approach, not the nearest sample.
    """
    d = p1 - p0
    dd = np.einsum("bi,bi->b", d, d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(dd > 0, -np.einsum("bi,bi->b", p0, d) / dd, 0.0)
    t = np.clip(t, 0.0, 1.0)
    c = p0 + t[:, None] * d
    return np.hypot(c[:, 0], c[:, 1])


def initial_geometry(draws: dict, cfg: EncounterConfig):
    """Start positions (B, 2) on the start circle and unit aim directions (B, 2)."""
    a = draws["start_angle"]
    p0 = cfg.start_radius * np.stack([np.cos(a), np.sin(a)], axis=-1)
    d = draws["aim"] - p0
    u = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    return p0, u


def straight_cpa(p0: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Closed-form closest approach to the origin of straight motion p0 + t v, t ≥ 0 (B,)."""
    vv = np.einsum("bi,bi->b", v, v)
    t = np.clip(-np.einsum("bi,bi->b", p0, v) / vv, 0.0, None)
    c = p0 + t[:, None] * v
    return np.hypot(c[:, 0], c[:, 1])


# ----------------------------------------------------------------------------- resolvers
def make_resolver(name: str, cfg: EncounterConfig, dt: float):
    """The registry's resolver ``name`` with this config's values for the ``Params`` fields
    it declares (``r_safe``, ``lookahead_s``, the detector's ``dt`` and ``horizon``), then
    ``cfg.resolver_params[name]`` on top, validated against its ``Params``."""
    from airspace_sim import registry
    from airspace_sim.scenarios.loader import validate_params

    Params = registry.params_class("resolver", name)
    offered = {
        "r_safe": cfg.r_safe,
        "lookahead_s": cfg.lookahead_s,
        "dt": dt,
        "horizon": int(cfg.horizon),
    }
    declared = {f.name for f in dataclasses.fields(Params) if f.init}
    table = {k: v for k, v in offered.items() if k in declared}
    extra = cfg.resolver_params.get(name, {})
    if not isinstance(extra, dict):
        raise UserError(
            f"encounter config: resolver_params[{name!r}]: expected a table, got {extra!r}"
        )
    table.update(extra)
    params = validate_params(Params, table, f"encounter config: resolver {name!r} params")
    return registry.build("resolver", name, params=params)


def make_imm(preset, x0: np.ndarray, P0: np.ndarray, mu0: np.ndarray):
    from airspace_sim.tracking import IMM

    return IMM(**preset.imm_arguments(), x0=x0, P0=P0, mu0=mu0)


def initial_covariance(cfg: EncounterConfig) -> np.ndarray:
    s = max(cfg.sigma(), 1.0)
    sv = cfg.init_sigma_velocity
    return np.diag([s**2, sv**2, s**2, sv**2, 1e-2])


# ----------------------------------------------------------------------------- metrics
class EncounterMetrics:
    """Per-encounter accumulators (B,) for one tracker/frame."""

    def __init__(self, B: int, r_safe: float):
        self.r_safe = r_safe
        self.min_sep = np.full(B, np.inf)
        self.n_manoeuvres = np.zeros(B, dtype=np.int64)
        self.heading_change = np.zeros(B)
        self.steps = np.zeros(B, dtype=np.int64)

    def result(self) -> dict:
        return {
            "min_separation_m": self.min_sep.copy(),
            "los": self.min_sep < self.r_safe,
            "intrusion_depth": np.maximum(0.0, 1.0 - self.min_sep / self.r_safe),
            "n_manoeuvres": self.n_manoeuvres.copy(),
            "heading_change_rad": self.heading_change.copy(),
            "steps": self.steps.copy(),
        }


class TrackerMetrics:
    """Tracking accumulators (B,): errors, mode identification, false detections."""

    def __init__(self, B: int):
        self.se_pos = np.zeros(B)
        self.se_meas = np.zeros(B)
        self.correct = np.zeros(B, dtype=np.int64)
        self.n = np.zeros(B, dtype=np.int64)
        self.false_det = np.zeros(B, dtype=np.int64)
        self.own_turn_straight = np.zeros(B, dtype=np.int64)
        self.quiet_false_det = np.zeros(B, dtype=np.int64)
        self.quiet_straight = np.zeros(B, dtype=np.int64)
        self.straight = np.zeros(B, dtype=np.int64)

    def update(self, active, est_pos, true_pos, z, mu, q, own_turning):
        a = active
        e = est_pos - true_pos
        m = z - true_pos
        self.se_pos += np.where(a, e[:, 0] ** 2 + e[:, 1] ** 2, 0.0)
        self.se_meas += np.where(a, m[:, 0] ** 2 + m[:, 1] ** 2, 0.0)
        est_mode = np.argmax(mu, axis=1)
        self.correct += a & (est_mode == q)
        self.n += a
        eligible = a & own_turning & (q == STRAIGHT)
        self.own_turn_straight += eligible
        self.false_det += eligible & (est_mode != STRAIGHT)
        quiet = a & ~own_turning & (q == STRAIGHT)
        self.quiet_straight += quiet
        self.quiet_false_det += quiet & (est_mode != STRAIGHT)
        self.straight += a & (q == STRAIGHT)

    def result(self, prefix: str = "") -> dict:
        n = np.maximum(self.n, 1)
        return {
            f"{prefix}position_rmse_m": np.sqrt(self.se_pos / n),
            f"{prefix}measurement_rmse_m": np.sqrt(self.se_meas / n),
            f"{prefix}mode_accuracy": self.correct / n,
            f"{prefix}false_detections": self.false_det.copy(),
            f"{prefix}own_turn_straight_steps": self.own_turn_straight.copy(),
            f"{prefix}quiet_false_detections": self.quiet_false_det.copy(),
            f"{prefix}quiet_straight_steps": self.quiet_straight.copy(),
            f"{prefix}true_straight_fraction": self.straight / n,
        }


@dataclass
class EncounterBatch:
    """Results of B encounters: ``metrics`` dict of (B,) arrays; ``trace`` per-step arrays
    (T, B, ...) if recorded (keys documented in the run function)."""

    indices: np.ndarray
    metrics: dict
    trace: dict | None = None
    dt: float = 0.1
    config: EncounterConfig | None = None


def mode_predictions(imm, cfg: EncounterConfig, dt: float, own_pos=None, own_vel=None):
    """``(xs, Ps, mu)`` for ``bands-probabilistic``: (B, 1, M, S, 2), (B, 1, M, S, 2, 2), (B, 1, M).

    Each mode's IMM prediction over ``probability_horizon_s`` (S = 10 points spread over it);
    a world-frame tracker's predictions are made relative by subtracting the ownship's
    straight-line prediction (``own_pos``, ``own_vel`` (B, 2)).
    """
    steps = max(1, int(round(min(cfg.lookahead_s, cfg.probability_horizon_s) / dt)))
    stride = max(1, steps // 10)
    at = np.arange(stride, steps + 1, stride)
    xs, Ps = relative_positions(*imm.predict_modes_at(at), at * dt, own_pos, own_vel)
    return xs[:, None], Ps[:, None], np.asarray(imm.mu)[:, None]


def _end_mask(r: np.ndarray, start_radius: float) -> np.ndarray:
    """(T, ...) True while the encounter is running (the rule of the simulations: it ends
    after the first step outside ``start_radius`` with the range growing)."""
    grow = np.zeros_like(r, dtype=bool)
    grow[1:] = (r[1:] > start_radius) & (r[1:] > r[:-1])
    ended = np.logical_or.accumulate(grow, axis=0)
    running = np.ones_like(ended)
    running[1:] = ~ended[:-1]
    return running


def _segment_min(rel: np.ndarray, start_radius: float) -> np.ndarray:
    """Minimum separation (...) over the running part of relative tracks rel (T, ..., 2)."""
    r = np.hypot(rel[..., 0], rel[..., 1])
    run = _end_mask(r, start_radius)
    d = rel[1:] - rel[:-1]
    dd = np.sum(d * d, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(dd > 0, -np.sum(rel[:-1] * d, axis=-1) / dd, 0.0)
    t = np.clip(t, 0.0, 1.0)
    c = rel[:-1] + t[..., None] * d
    seg = np.hypot(c[..., 0], c[..., 1])
    seg = np.where(run[1:], seg, np.inf)
    return np.minimum(r[0], seg.min(axis=0))


def _oracle_choice(min_sep: np.ndarray, cost: np.ndarray, r_safe: float, steps: np.ndarray) -> dict:
    """Pick, per encounter, the clear candidate of least heading change, else the one that
    keeps the largest separation. min_sep, cost, steps: (C, B)."""
    clear = min_sep >= r_safe
    key = np.where(clear, cost, np.inf)
    best_clear = np.argmin(key, axis=0)
    best_sep = np.argmax(min_sep, axis=0)
    any_clear = clear.any(axis=0)
    pick = np.where(any_clear, best_clear, best_sep)
    cols = np.arange(min_sep.shape[1])
    ms = min_sep[pick, cols]
    nan = np.full(ms.shape, np.nan)
    return {
        "min_separation_m": ms,
        "los": ms < r_safe,
        "intrusion_depth": np.maximum(0.0, 1.0 - ms / r_safe),
        "n_manoeuvres": steps[pick, cols].astype(np.int64),
        "heading_change_rad": cost[pick, cols],
        "steps": np.zeros(ms.shape, dtype=np.int64),
        "position_rmse_m": nan,
        "measurement_rmse_m": nan.copy(),
        "mode_accuracy": nan.copy(),
    }


def oracle_relative(
    seed: int, indices, cfg: EncounterConfig | None = None, n_angles: int = 72
) -> dict:
    """Could any rotation within the paper's limit have avoided LoS? (B,) metrics.

    Perfect knowledge of the intruder's future (its modes and noise): candidates rotate the
    true relative velocity by φ on a grid of ``n_angles`` over (−π, π] (and 0), reached at
    ``max_angle`` per step from t = 0, then fly on. The least-|φ| clear candidate is kept
    (else the one keeping the largest separation): ``los`` True means no candidate of this
    open-loop family clears the encounter.
    """
    cfg = cfg or EncounterConfig()
    preset = cfg.model()
    indices = np.asarray(list(indices), dtype=np.int64)
    B = indices.size
    dt, T = preset.dt, cfg.n_steps()
    draws = draw_encounters(seed, indices, cfg)
    rates = np.asarray(preset.turn_rates, dtype=float)
    F = models.transition(rates, dt)
    cdf = mode_cdf(preset.transition_matrix)
    phis = np.concatenate(
        [[0.0], np.linspace(-np.pi, np.pi, n_angles, endpoint=False) + np.pi / n_angles]
    )
    C = phis.size
    p0, u = initial_geometry(draws, cfg)
    x = np.zeros((C, B, 5))
    x[:, :, POS] = p0
    x[:, :, VEL] = draws["speed"][:, None] * u
    x = x.reshape(C * B, 5)
    remaining = np.repeat(phis, B)
    q = np.full(B, STRAIGHT, dtype=np.int64)
    rel = np.empty((T, C * B, 2))
    rel[0] = x[:, POS]
    for k in range(1, T):
        step = np.clip(remaining, -cfg.max_angle, cfg.max_angle)
        x[:, VEL] = rotate(x[:, VEL], step)
        remaining = remaining - step
        if cfg.intruder_turns:
            q = next_modes(cdf, q, draws["mode_u"][:, k])
        qq = np.tile(q, C)
        x = np.einsum("bij,bj->bi", F[qq], x) + np.tile(draws["w"][:, k], (C, 1))
        x[:, 4] = rates[qq]
        rel[k] = x[:, POS]
    ms = _segment_min(rel, cfg.start_radius).reshape(C, B)
    cost = np.abs(phis)[:, None] * np.ones((1, B))
    steps = np.ceil(cost / cfg.max_angle)
    return _oracle_choice(ms, cost, cfg.r_safe, steps)


def _recent(last_turn_step: np.ndarray, k: int, window_steps: int) -> np.ndarray:
    return (k - last_turn_step) <= window_steps


# ----------------------------------------------------------------------------- the run
def run_relative(
    seed: int,
    indices,
    resolver: str = "seed",
    cfg: EncounterConfig | None = None,
    record: bool = False,
) -> EncounterBatch:
    """Run encounters ``indices`` of campaign ``seed`` together, in the paper's relative frame.

    Returns an :class:`EncounterBatch`; ``metrics`` has (B,) arrays ``min_separation_m``,
    ``los``, ``intrusion_depth``, ``n_manoeuvres``, ``heading_change_rad`` (Σ|θ|),
    ``steps``, ``position_rmse_m``, ``measurement_rmse_m`` (2-D radial RMS),
    ``mode_accuracy`` (fraction of steps with argmax μ = true mode), ``false_detections``
    (steps within ``false_detection_window_s`` after a rotation, true mode straight,
    argmax μ a turn) and ``own_turn_straight_steps`` (their denominator).

    With ``record=True``, ``trace`` holds (T, B, ...) arrays: ``truth`` (5), ``z`` (2),
    ``estimate`` (5), ``mu`` (M), ``mode`` (true), ``conflict``, ``theta`` (rad, the
    rotation applied after that step), ``predicted`` (horizon, 2) the points C_j from the
    estimate, ``predicted_unsafe`` (horizon) |C_j| < r_safe, ``active``, and ``time`` (T,).
    """
    cfg = cfg or EncounterConfig()
    preset = cfg.model()
    indices = np.asarray(list(indices), dtype=np.int64)
    B = indices.size
    if B == 0:
        raise UserError("run_relative: no encounters to run")
    dt, T = preset.dt, cfg.n_steps()
    draws = draw_encounters(seed, indices, cfg)
    rates = np.asarray(preset.turn_rates, dtype=float)
    F = models.transition(rates, dt)
    cdf = mode_cdf(preset.transition_matrix)
    sigma = cfg.sigma()
    res = make_resolver(resolver, cfg, dt)
    probabilistic = res.uses_mode_predictions
    window = int(round(cfg.false_detection_window_s / dt))

    p0, u = initial_geometry(draws, cfg)
    x = np.zeros((B, models.N_STATE))
    x[:, POS] = p0
    x[:, VEL] = draws["speed"][:, None] * u
    q = np.full(B, STRAIGHT, dtype=np.int64)
    x[:, 4] = rates[q]
    P0 = initial_covariance(cfg)
    x_est0 = x + np.einsum("ij,bj->bi", np.linalg.cholesky(P0), draws["e0"])
    imm = make_imm(preset, x_est0, P0, preset.mu0())

    met = EncounterMetrics(B, cfg.r_safe)
    trk = TrackerMetrics(B)
    active = np.ones(B, dtype=bool)
    last_turn = np.full(B, -(10**9), dtype=np.int64)
    prev_pos = x[:, POS].copy()
    met.min_sep = np.hypot(prev_pos[:, 0], prev_pos[:, 1])
    H = int(cfg.horizon)
    if record:
        tr = {
            "truth": np.full((T, B, 5), np.nan),
            "z": np.full((T, B, 2), np.nan),
            "estimate": np.full((T, B, 5), np.nan),
            "mu": np.full((T, B, imm.M), np.nan),
            "mode": np.zeros((T, B), dtype=np.int64),
            "conflict": np.zeros((T, B), dtype=bool),
            "theta": np.zeros((T, B)),
            "predicted": np.full((T, B, H, 2), np.nan),
            "predicted_unsafe": np.zeros((T, B, H), dtype=bool),
            "active": np.zeros((T, B), dtype=bool),
            "time": np.arange(T) * dt,
        }
        tr["truth"][0], tr["estimate"][0], tr["mu"][0] = x, imm.x, imm.mu
        tr["mode"][0], tr["active"][0] = q, True
    zeros_valid = np.ones((B, 1), dtype=bool)
    max_turn = np.full(B, cfg.max_angle)
    for k in range(1, T):
        if cfg.intruder_turns:
            q = next_modes(cdf, q, draws["mode_u"][:, k])
        x = np.einsum("bij,bj->bi", F[q], x) + draws["w"][:, k]
        x[:, 4] = rates[q]
        pos = x[:, POS]
        z = pos + sigma * draws["v"][:, k]
        imm.step(z)
        est = imm.x
        est_pos, est_vel = est[:, POS], est[:, VEL]
        own_turning = _recent(last_turn, k, window)
        trk.update(active, est_pos, pos, z, imm.mu, q, own_turning)
        # separation over the segment flown in (k-1, k]
        d = segment_distance_to_origin(prev_pos, pos)
        met.min_sep = np.where(active, np.minimum(met.min_sep, d), met.min_sep)
        met.steps += active
        prev_pos = pos.copy()
        # avoidance on the estimate: the frame seen as an intruder at rest and an ownship
        # moving with -v_rel, whose heading change rotates v_rel by the same angle
        kwargs = {}
        if probabilistic:
            kwargs["mode_predictions"] = mode_predictions(imm, cfg, dt)
        out = res.resolve(
            -est_vel, est_pos[:, None, :], est_vel[:, None, :], zeros_valid, max_turn, **kwargs
        )
        theta = np.where(active, np.asarray(out.heading_change, dtype=float), 0.0)
        conflict = np.asarray(out.conflict, dtype=bool) & active
        turned = theta != 0.0
        met.n_manoeuvres += turned
        met.heading_change += np.abs(theta)
        last_turn = np.where(turned, k, last_turn)
        # the paper's frame rotation: the intruder's true relative velocity turns by θ
        x[:, VEL] = rotate(x[:, VEL], theta)
        if record:
            cj = (
                est_pos[:, None, :]
                + np.arange(1, H + 1)[None, :, None] * (est_vel * dt)[:, None, :]
            )
            tr["truth"][k], tr["z"][k], tr["estimate"][k], tr["mu"][k] = x, z, est, imm.mu
            tr["mode"][k], tr["conflict"][k], tr["theta"][k] = q, conflict, theta
            tr["predicted"][k] = cj
            tr["predicted_unsafe"][k] = np.hypot(cj[..., 0], cj[..., 1]) < cfg.r_safe
            tr["active"][k] = active
        # end of the encounter: outside the start circle and receding
        r = np.hypot(pos[:, 0], pos[:, 1])
        receding = np.einsum("bi,bi->b", pos, x[:, VEL]) > 0
        active &= ~((r > cfg.start_radius) & receding)
        if not active.any():
            break
    metrics = met.result()
    metrics.update(trk.result())
    return EncounterBatch(indices, metrics, tr if record else None, dt, cfg)
