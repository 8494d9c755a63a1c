"""Encounters in the world frame: the ownship moves and can only turn (``docs/paper-notes.md`` §3).

Differences from the paper's relative frame (:mod:`.relative`):

- The ownship flies at ``own_speed`` (V_cruise) from the origin with a random heading,
  straight (``own_motion="straight"``) or on the preset's own mode chain (``"markov"``)
  whenever it is not avoiding. It avoids by changing its **own heading**, at most
  ``max_turn_rate·ΔT`` per step (a turn-rate limit, not the paper's π/4 per step), integrated
  exactly as a coordinated turn over the step.
- The intruder's *world* speed is uniform in ``[V_cruise, 2·V_cruise]``; its heading is the
  one that makes its initial **relative** velocity aim at a uniform point of the
  ``aim_radius`` disc (as in the relative frame), i.e. ``v_i = v_o + s·u`` with
  ``s = −v_o·u + √((v_o·u)² + |v_i|² − |v_o|²) ≥ 0``. It then flies the preset's jump-Markov
  model in the world frame. It does not react, so its whole trajectory is drawn before the
  encounter (and an oracle can be asked about it, :mod:`.oracle` helpers below).
- Two IMMs watch it, fed the same noise: the **world-frame** tracker gets
  ``z = p_intruder + n`` (the ownship knows its own motion, so its turns are not seen as
  intruder turns), the **relative-frame** tracker gets ``z − p_own`` and tracks the
  relative state as the paper does. ``driver`` says which one the resolver sees (default
  world). Both are scored: position RMSE, mode accuracy and **false detections during own
  manoeuvres** (steps within ``false_detection_window_s`` after an own turn where the
  intruder's true mode is straight but argmax μ says turn).

Resolvers come from the registry; heading changes are clamped to the turn-rate limit. The
``seed`` resolver applies the paper's θ as the heading change, ``seed-world`` the exact
heading change that puts the relative velocity on the tangent
(:func:`airspace_sim.avoidance.heading.tangent_heading_change`), ``bands`` the band search.
"""

from __future__ import annotations

import numpy as np

from airspace_sim.dynamics import models
from airspace_sim.dynamics.markov import mode_cdf, next_modes
from airspace_sim.encounters.relative import (
    POS,
    STRAIGHT,
    VEL,
    EncounterBatch,
    EncounterConfig,
    EncounterMetrics,
    TrackerMetrics,
    _oracle_choice,
    _recent,
    _segment_min,
    draw_encounters,
    initial_covariance,
    initial_geometry,
    make_imm,
    make_resolver,
    mode_predictions,
    segment_distance_to_origin,
)
from airspace_sim.errors import UserError


def intruder_initial_velocity(
    own_velocity: np.ndarray, aim_dir: np.ndarray, speed: np.ndarray
) -> np.ndarray:
    """World velocity (B, 2) of speed ``speed`` whose velocity relative to ``own_velocity``
    points along the unit vectors ``aim_dir``."""
    a = np.einsum("bi,bi->b", own_velocity, aim_dir)
    disc = a**2 + speed**2 - np.einsum("bi,bi->b", own_velocity, own_velocity)
    s = -a + np.sqrt(np.maximum(disc, 0.0))
    return own_velocity + s[:, None] * aim_dir


def world_setup(seed: int, indices, cfg: EncounterConfig):
    """Draws, own initial state (B, 5), intruder world truth (T, B, 5) and modes (T, B)."""
    preset = cfg.model()
    dt, T = preset.dt, cfg.n_steps()
    draws = draw_encounters(seed, indices, cfg)
    B = len(draws["speed"])
    rates = np.asarray(preset.turn_rates, dtype=float)
    F = models.transition(rates, dt)
    cdf = mode_cdf(preset.transition_matrix)
    p0, u = initial_geometry(draws, cfg)
    own = np.zeros((B, 5))
    h = draws["own_heading"]
    own[:, 1], own[:, 3] = cfg.own_speed * np.cos(h), cfg.own_speed * np.sin(h)
    xi = np.zeros((B, 5))
    xi[:, POS] = p0
    xi[:, VEL] = intruder_initial_velocity(own[:, VEL], u, draws["speed"])
    q = np.full(B, STRAIGHT, dtype=np.int64)
    truth = np.empty((T, B, 5))
    modes = np.empty((T, B), dtype=np.int64)
    truth[0], modes[0] = xi, q
    for k in range(1, T):
        if cfg.intruder_turns:
            q = next_modes(cdf, q, draws["mode_u"][:, k])
        xi = np.einsum("bij,bj->bi", F[q], xi) + draws["w"][:, k]
        xi[:, 4] = rates[q]
        truth[k], modes[k] = xi, q
    return draws, own, truth, modes


def run_world(
    seed: int,
    indices,
    resolver: str = "bands",
    cfg: EncounterConfig | None = None,
    record: bool = False,
    driver: str = "world",
) -> EncounterBatch:
    """Run encounters ``indices`` of campaign ``seed`` together in the world frame.

    ``metrics``: as :func:`~airspace_sim.encounters.relative.run_relative` for the tracker
    that drives the resolver (``driver``: ``"world"`` or ``"relative"``), plus
    ``rel_*`` / ``world_*`` copies of each tracker's ``position_rmse_m``,
    ``mode_accuracy``, ``false_detections`` and ``own_turn_straight_steps``.

    ``trace`` (``record=True``), (T, B, ...): ``own`` (5) ownship state, ``intruder`` (5)
    intruder world truth, ``z`` (2) world measurement, ``estimate`` (5) world tracker,
    ``estimate_rel`` (5) relative tracker, ``mu`` / ``mu_rel`` (M), ``mode`` (true),
    ``heading_change`` (rad, commanded at that step), ``own_turn_rate`` (rad/s over the
    step ending there), ``conflict``, ``active``, ``time`` (T,).
    """
    if driver not in ("world", "relative"):
        raise UserError(f"run_world: driver must be 'world' or 'relative', got {driver!r}")
    cfg = cfg or EncounterConfig()
    preset = cfg.model()
    indices = np.asarray(list(indices), dtype=np.int64)
    B = indices.size
    if B == 0:
        raise UserError("run_world: no encounters to run")
    dt, T = preset.dt, cfg.n_steps()
    draws, own, truth, modes = world_setup(seed, indices, cfg)
    rates = np.asarray(preset.turn_rates, dtype=float)
    own_cdf = mode_cdf(preset.transition_matrix)
    sigma = cfg.sigma()
    res = make_resolver(resolver, cfg, dt)
    probabilistic = res.uses_mode_predictions
    window = int(round(cfg.false_detection_window_s / dt))
    max_step = np.full(B, cfg.max_turn_rate * dt)
    target_limit = np.full(B, max(cfg.target_heading_limit, cfg.max_turn_rate * dt))

    P0 = initial_covariance(cfg)
    err0 = np.einsum("ij,bj->bi", np.linalg.cholesky(P0), draws["e0"])
    est_w0 = truth[0] + err0
    est_r0 = est_w0.copy()
    est_r0[:, :4] -= own[:, :4]
    imm_w = make_imm(preset, est_w0, P0, preset.mu0())
    imm_r = make_imm(preset, est_r0, P0, preset.mu0())

    met = EncounterMetrics(B, cfg.r_safe)
    trk_w, trk_r = TrackerMetrics(B), TrackerMetrics(B)
    active = np.ones(B, dtype=bool)
    last_turn = np.full(B, -(10**9), dtype=np.int64)
    prev_rel = truth[0][:, POS] - own[:, POS]
    met.min_sep = np.hypot(prev_rel[:, 0], prev_rel[:, 1])
    cmd = np.zeros(B)
    q_own = np.full(B, STRAIGHT, dtype=np.int64)
    valid = np.ones((B, 1), dtype=bool)
    if record:
        M = imm_w.M
        tr = {
            "own": np.full((T, B, 5), np.nan),
            "intruder": truth.copy(),
            "z": np.full((T, B, 2), np.nan),
            "estimate": np.full((T, B, 5), np.nan),
            "estimate_rel": np.full((T, B, 5), np.nan),
            "mu": np.full((T, B, M), np.nan),
            "mu_rel": np.full((T, B, M), np.nan),
            "mode": modes.copy(),
            "heading_change": np.zeros((T, B)),
            "own_turn_rate": np.zeros((T, B)),
            "conflict": np.zeros((T, B), dtype=bool),
            "active": np.zeros((T, B), dtype=bool),
            "time": np.arange(T) * dt,
        }
        tr["own"][0], tr["estimate"][0], tr["estimate_rel"][0] = own, imm_w.x, imm_r.x
        tr["mu"][0], tr["mu_rel"][0], tr["active"][0] = imm_w.mu, imm_r.mu, True
    for k in range(1, T):
        # ownship: the heading change commanded last step, flown as a turn over this step
        if cfg.own_motion == "markov":
            q_own = next_modes(own_cdf, q_own, draws["own_mode_u"][:, k])
            free = np.clip(rates[q_own] * dt, -max_step, max_step)
            turn = np.where(cmd != 0.0, cmd, np.where(active, free, 0.0))
        else:
            turn = cmd
        w_own = turn / dt
        own = np.einsum("bij,bj->bi", models.transition(w_own, dt), own)
        own[:, 4] = w_own
        last_turn = np.where(turn != 0.0, k, last_turn)
        own_turning = _recent(last_turn, k, window)

        xi, q = truth[k], modes[k]
        z = xi[:, POS] + sigma * draws["v"][:, k]
        z_rel = z - own[:, POS]
        imm_w.step(z)
        imm_r.step(z_rel)
        rel_true = xi[:, POS] - own[:, POS]
        trk_w.update(active, imm_w.x[:, POS], xi[:, POS], z, imm_w.mu, q, own_turning)
        trk_r.update(active, imm_r.x[:, POS], rel_true, z_rel, imm_r.mu, q, own_turning)
        d = segment_distance_to_origin(prev_rel, rel_true)
        met.min_sep = np.where(active, np.minimum(met.min_sep, d), met.min_sep)
        met.steps += active
        prev_rel = rel_true

        if driver == "world":
            rel_pos = imm_w.x[:, POS] - own[:, POS]
            rel_vel = imm_w.x[:, VEL] - own[:, VEL]
            imm_d, is_rel = imm_w, False
        else:
            rel_pos, rel_vel = imm_r.x[:, POS], imm_r.x[:, VEL]
            imm_d, is_rel = imm_r, True
        kwargs = {}
        if probabilistic:
            kwargs["mode_predictions"] = (
                mode_predictions(imm_d, cfg, dt)
                if is_rel
                else mode_predictions(imm_d, cfg, dt, own[:, POS], own[:, VEL])
            )
        out = res.resolve(
            own[:, VEL], rel_pos[:, None, :], rel_vel[:, None, :], valid, target_limit, **kwargs
        )
        cmd = np.where(
            active, np.clip(np.asarray(out.heading_change, dtype=float), -max_step, max_step), 0.0
        )
        conflict = np.asarray(out.conflict, dtype=bool) & active
        met.n_manoeuvres += cmd != 0.0
        met.heading_change += np.abs(cmd)
        if record:
            tr["own"][k], tr["z"][k] = own, z
            tr["estimate"][k], tr["estimate_rel"][k] = imm_w.x, imm_r.x
            tr["mu"][k], tr["mu_rel"][k] = imm_w.mu, imm_r.mu
            tr["heading_change"][k], tr["own_turn_rate"][k] = cmd, w_own
            tr["conflict"][k], tr["active"][k] = conflict, active
        r = np.hypot(rel_true[:, 0], rel_true[:, 1])
        receding = np.einsum("bi,bi->b", rel_true, xi[:, VEL] - own[:, VEL]) > 0
        active &= ~((r > cfg.start_radius) & receding)
        if not active.any():
            break
    metrics = met.result()
    tw, trr = trk_w.result(), trk_r.result()
    metrics.update(tw if driver == "world" else trr)
    for key in (
        "position_rmse_m",
        "mode_accuracy",
        "false_detections",
        "own_turn_straight_steps",
        "quiet_false_detections",
        "quiet_straight_steps",
    ):
        metrics[f"world_{key}"] = tw[key]
        metrics[f"rel_{key}"] = trr[key]
    return EncounterBatch(indices, metrics, tr if record else None, dt, cfg)


def own_paths(own0: np.ndarray, rate: float, duration: float, times: np.ndarray) -> np.ndarray:
    """Ownship positions (T, B, 2) at ``times`` (T,): turn at ``rate`` rad/s for ``duration``
    s from ``own0`` (B, 5), then straight at constant speed (exact arcs)."""
    v = np.hypot(own0[:, 1], own0[:, 3])
    psi0 = np.arctan2(own0[:, 3], own0[:, 1])
    t = np.minimum(times, duration)[:, None]
    rest = np.maximum(times - duration, 0.0)[:, None]
    if rate == 0.0 or duration == 0.0:
        arc_x, arc_y, psi1 = v * t * np.cos(psi0), v * t * np.sin(psi0), psi0 + 0 * t
    else:
        psi1 = psi0 + rate * t
        arc_x = v / rate * (np.sin(psi1) - np.sin(psi0))
        arc_y = v / rate * (np.cos(psi0) - np.cos(psi1))
    x = own0[:, 0] + arc_x + v * rest * np.cos(psi1)
    y = own0[:, 2] + arc_y + v * rest * np.sin(psi1)
    return np.stack([x, y], axis=-1)


def oracle_world(
    seed: int,
    indices,
    cfg: EncounterConfig | None = None,
    n_durations: int = 41,
    fractions=(1.0, 0.5),
) -> dict:
    """Could any ownship turn within the turn-rate limit have avoided LoS? (B,) metrics.

    Perfect knowledge of the intruder's (non-reacting) world trajectory. Candidates: turn
    left or right at ``fraction·max_turn_rate`` from t = 0 for τ on a grid of
    ``n_durations`` values in [0, min(π/rate, duration)], then fly straight. The clear
    candidate with the least heading change is kept (else the one keeping the largest
    separation), with the simulations' end rule. ``los`` True: no candidate of this
    open-loop family clears the encounter (an upper bound on "unavoidable").
    """
    cfg = cfg or EncounterConfig()
    preset = cfg.model()
    dt, T = preset.dt, cfg.n_steps()
    draws, own, truth, modes = world_setup(seed, indices, cfg)
    times = np.arange(T) * dt
    seps, costs, steps = [], [], []
    for frac in fractions:
        rate = frac * cfg.max_turn_rate
        taus = np.linspace(0.0, min(np.pi / rate, cfg.duration_s), n_durations)
        for sign in (-1.0, 1.0):
            for tau in taus:
                if tau == 0.0 and (sign > 0 or frac != fractions[0]):
                    continue
                path = own_paths(own, sign * rate, tau, times)
                seps.append(_segment_min(truth[..., POS] - path, cfg.start_radius))
                costs.append(np.full(path.shape[1], rate * tau))
                steps.append(np.full(path.shape[1], round(tau / dt)))
    return _oracle_choice(np.array(seps), np.array(costs), cfg.r_safe, np.array(steps))
