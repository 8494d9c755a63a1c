"""Recorded-flight evaluation (tracking.evaluation) on small synthetic flights made here.

Oracles: the closed-form coordinated-turn path the flights are generated from
(``geometry.coordinated_turn_positions``), the known report-time jitter, and χ² bounds.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from airspace_sim.dynamics import presets
from airspace_sim.geometry import coordinated_turn_positions
from airspace_sim.recorded import glitches
from airspace_sim.tracking import evaluation


def flight(legs, speed=120.0, dt=1.0):
    """Truth every ``dt`` s of legs [(duration s, turn rate deg/s)]: t (K,), state (K, 5)."""
    x = np.array([0.0, speed, 0.0, 0.0, 0.0])
    ts, states, t0 = [], [], 0.0
    for dur, rate in legs:
        x[4] = math.radians(rate)
        times = np.arange(0.0, dur, dt)
        pos = coordinated_turn_positions(x[None], times)[0]
        heading = math.atan2(x[3], x[1]) + x[4] * times
        st = np.stack([pos[:, 0], speed * np.cos(heading), pos[:, 1], speed * np.sin(heading),
                       np.full(times.size, x[4])], axis=1)  # fmt: skip
        ts.append(t0 + times)
        states.append(st)
        end = coordinated_turn_positions(x[None], [dur])[0, 0]
        h = math.atan2(x[3], x[1]) + x[4] * dur
        x = np.array([end[0], speed * math.cos(h), end[1], speed * math.sin(h), 0.0])
        t0 += dur
    return np.concatenate(ts), np.concatenate(states)


LEGS = [(300, 0.0), (90, 2.0), (300, 0.0), (60, -3.0), (300, 0.0)]


def test_resample_recovers_the_path_and_turn_rate():
    t, X = flight(LEGS)
    rec = np.arange(0, t[-1], 5.0).astype(int)  # 5 s reports
    (tr,) = evaluation.resample("f", t[rec], X[rec, 0], X[rec, 2], period_s=1.0)
    truth = np.interp(tr.t_s, t, X[:, 4])
    mid_turn = (tr.t_s > 320) & (tr.t_s < 370)
    straight = ((tr.t_s > 450) & (tr.t_s < 650)) | (tr.t_s > 800) & (tr.t_s < 1000)
    np.testing.assert_allclose(np.degrees(tr.state[mid_turn, 4]), 2.0, atol=0.1)
    assert np.all(np.abs(np.degrees(tr.state[straight, 4])) < 0.1)
    err = np.hypot(tr.state[:, 0] - np.interp(tr.t_s, t, X[:, 0]),
                   tr.state[:, 2] - np.interp(tr.t_s, t, X[:, 2]))  # fmt: skip
    assert np.percentile(err, 95) < 20.0
    assert np.abs(np.degrees(tr.state[:, 4] - truth))[straight].max() < 0.1


def test_retime_removes_report_time_jitter():
    rng = np.random.default_rng(1)
    t, X = flight(LEGS)
    rec = np.arange(0, t.size, 5)
    true_t = t[rec] + rng.uniform(-1.5, 1.5, rec.size)  # when the reported position was true
    true_t[0], true_t[-1] = t[rec[0]], t[rec[-1]]
    x, y = (np.interp(true_t, t, X[:, k]) for k in (0, 2))
    speed = np.full(rec.size, 120.0)
    tau, keep = evaluation.retime(t[rec], x, y, speed)
    assert keep.size >= rec.size - 2
    err = tau - true_t[keep]
    assert np.sqrt(np.mean(err[5:-5] ** 2)) < 0.3  # from 0.87 s RMS jitter


def test_track_residual_sees_a_glitch_not_a_turn():
    """Across the track from the quadratic through the neighbours: a 3 °/s turn at 240 m/s
    with 10 s between reports leaves 55 m while steady (its fourth-order term) and
    130 m where it begins and ends at once (no roll-in); a position put 1 km to the side
    has its 1 km back (its neighbours' path does not include it)."""
    t, X = flight([(200, 0.0), (120, 3.0), (200, 0.0)], speed=240.0)
    rec = np.arange(0, t.size, 10)
    x, y = X[rec, 0].copy(), X[rec, 2].copy()
    r = glitches.track_residual(t[rec], x, y)
    assert np.isnan(r[[0, 1, -2, -1]]).all() and np.nanmax(r) < 140.0
    steady = (t[rec] > 230) & (t[rec] < 290)
    np.testing.assert_allclose(r[steady], 240.0 * math.radians(3.0) ** 3 / 24 * 4e4, rtol=0.05)
    i = 30  # mid-turn
    heading = math.atan2(X[rec[i], 3], X[rec[i], 1])
    x[i] -= 1000.0 * math.sin(heading)
    y[i] += 1000.0 * math.cos(heading)
    r = glitches.track_residual(t[rec], x, y)
    assert r[i] == pytest.approx(1000.0, abs=60.0)


def test_despike_drops_the_glitches_and_nothing_else():
    """Isolated positions 0.6–3 km to the side (one of them next-but-one to another) are
    dropped; a clean flight, turns of 8 °/s at 70 m/s every 5 s included, keeps every
    position; the truth made with the glitches dropped turns as the clean one, the one
    made with them does not."""
    t, X = flight([(200, 0.0), (45, 8.0), (200, 0.0), (60, -3.0), (200, 0.0)], speed=70.0)
    rec = np.arange(0, t.size, 5)
    x, y = X[rec, 0].copy(), X[rec, 2].copy()
    assert glitches.despike(t[rec], x, y).tolist() == list(range(rec.size))
    bad = [10, 12, 60, 100]
    for i, d in zip(bad, (600.0, -3000.0, 1500.0, -800.0)):
        heading = math.atan2(X[rec[i], 3], X[rec[i], 1])
        x[i] -= d * math.sin(heading)
        y[i] += d * math.cos(heading)
    keep = glitches.despike(t[rec], x, y)
    assert sorted(set(range(rec.size)) - set(keep.tolist())) == bad
    (clean,) = evaluation.resample("f", t[rec], X[rec, 0], X[rec, 2], 1.0)
    (kept,) = evaluation.resample("f", t[rec][keep], x[keep], y[keep], 1.0)
    (raw,) = evaluation.resample("f", t[rec], x, y, 1.0)
    w = [np.degrees(tr.state[:, 4]) for tr in (clean, kept, raw)]
    assert np.abs(w[1] - w[0]).max() < 0.5 and np.abs(w[2] - w[0]).max() > 3.0
    # runs apart (a silence over RUN_GAP_S) are judged apart: their ends are not judged
    gap = np.where(np.arange(rec.size) < 60, 0.0, 2 * glitches.RUN_GAP_S)
    assert sorted(set(range(rec.size)) - set(glitches.despike(t[rec] + gap, x, y))) == [10, 12, 100]


def test_positions_interpolated_between_reports_are_left_out_of_the_truth():
    """Reports every 20 s through a 3 °/s turn at 70 m/s, and positions every 5 s put on the
    straight line between them (as in the traffic calibration samples): ``reported`` finds
    the reports (and keeps a long straight stretch whole); the truth turns at a steady 3 °/s
    at 70 m/s mid-turn, where the polygon through every position swings by 2 °/s and slows
    by 12 m/s."""
    t, X = flight([(300, 0.0), (200, 3.0), (300, 0.0)], speed=70.0)
    reports = np.arange(0, t.size, 20)
    grid = np.arange(0, t[reports[-1]] + 1, 5.0)
    x, y = (np.interp(grid, t[reports], X[reports, c]) for c in (0, 2))
    kept = glitches.reported(grid, x, y)
    straight = grid[kept] < 280.0  # the first straight leg: one run over 30 s, kept whole
    assert np.all(np.diff(grid[kept][straight]) == 5.0)
    in_turn = (grid[kept] > 320.0) & (grid[kept] < 480.0)
    assert np.all(np.isin(grid[kept][in_turn], t[reports]))  # only reports there
    (tr,) = evaluation.resample("f", grid, x, y, 1.0)
    (poly,) = evaluation.resample("f", grid, x, y, 1.0, through_reports=False)
    mid = (tr.t_s > 360) & (tr.t_s < 440)
    np.testing.assert_allclose(np.degrees(tr.state[mid, 4]), 3.0, atol=0.2)
    np.testing.assert_allclose(np.hypot(tr.state[mid, 1], tr.state[mid, 3]), 70.0, atol=1.0)
    w = np.degrees(poly.state[mid, 4])
    assert w.max() - w.min() > 1.5 and np.hypot(poly.state[mid, 1], poly.state[mid, 3]).min() < 60
    assert glitches.reported([0.0, 1, 2], [0.0, 1, 2], [0.0, 0, 0]).tolist() == [0, 2]


def test_a_last_report_off_the_track_does_not_bend_the_truth():
    """The truth ends END_TRIM_S before the last report, so a last report 500 m to the side
    (which despike cannot judge: no neighbours after it) leaves the truth as the
    clean flight's, straight, to two metres; so does the first report, once past the burn-in."""
    t, X = flight([(600, 0.0)], speed=230.0)
    rec = np.arange(0, t.size, 10)
    y = X[rec, 2].copy()
    y[[0, -1]] += 500.0
    (clean,) = evaluation.resample("f", t[rec], X[rec, 0], X[rec, 2], 1.0)
    (off,) = evaluation.resample("f", t[rec], X[rec, 0], y, 1.0)
    assert (
        t[rec][-1] - evaluation.END_TRIM_S - 3.0 < off.t_s[-1] <= t[rec][-1] - evaluation.END_TRIM_S
    )
    scored = off.t_s >= evaluation.BURN_IN_S
    # the spline through the reports carries a ripple of the off reports, shrinking by ~4 a
    # report: of 500 m, a metre or two where the truth ends and none in between
    np.testing.assert_allclose(off.state[scored][:, [0, 2]], clean.state[scored][:, [0, 2]],
                               atol=2.0)  # fmt: skip
    assert np.abs(np.degrees(off.state[scored, 4])).max() < 0.05  # a turn is 1 deg/s


@pytest.mark.parametrize("name", ["dense-turns", "imm-ct"])
def test_evaluate_flags_turns_and_nis_is_consistent(name):
    """Known-rate modes (dense-turns) and an estimated-rate mode (imm-ct: flagged by its
    probability with its own Ω̂ beyond the flag rate) both flag the turns of the right sign."""
    t, X = flight(LEGS)
    truths = [evaluation.Truth("f", t, X), evaluation.Truth("g", t, X * [1, 1, -1, -1, -1])]
    ev = evaluation.evaluate(truths, presets.get(name), 50.0, 1.0, seed=3,
                             cv_sigmas=(0.5, 2.0, 8.0))  # fmt: skip
    assert ev.n_flights == 2 and ev.cv_sigma in (0.5, 2.0, 8.0)
    assert ev.turning_flagged > 0.8 and ev.turning_flagged_wrong_sign < 0.05
    assert ev.straight_flagged < 0.05
    assert ev.pos_imm < ev.pos_cv and ev.pos_imm_turn < ev.pos_cv_turn
    # the model fits the flights (its own rates, white noise): NIS near 2, loosely
    assert 1.5 < ev.nis < 3.0
    d = ev.to_dict()
    assert d["preset"] == name and set(d["cv_grid"]) == {"0.5", "2.0", "8.0"}


@pytest.mark.parametrize("name", ["realistic", "imm-ct"])
def test_smoothed_flags_and_positions_after_the_fact(name, monkeypatch):
    """The smoothers see each whole flight: they flag more of every turn than the filter, few
    straight seconds, and follow the path closer; the CV one is the RTS smoother of the best
    CV filter (filterpy's, flight by flight), also when flights of different lengths run
    in separate batches."""
    KalmanFilter = pytest.importorskip("filterpy.kalman").KalmanFilter
    from airspace_sim.dynamics import models

    monkeypatch.setattr(evaluation, "SMOOTHER_BATCH_BYTES", 1)  # a batch per flight
    t, X = flight(LEGS)
    cut = t.size - 200
    truths = [evaluation.Truth("f", t, X),
              evaluation.Truth("g", t[:cut], (X * [1, 1, -1, -1, -1])[:cut])]  # fmt: skip
    ev = evaluation.evaluate(truths, presets.get(name), 50.0, 1.0, seed=3, cv_sigmas=(2.0, 8.0))
    assert ev.smoothed_turning_flagged > 0.75
    assert ev.smoothed_turning_flagged >= min(1.0, ev.turning_flagged + 0.1)
    assert ev.smoothed_turning_flagged_wrong_sign < 0.02 and ev.smoothed_straight_flagged < 0.02
    assert ev.pos_imm_smoothed < ev.pos_imm and ev.pos_cv_smoothed < ev.pos_cv
    assert ev.pos_imm_smoothed < ev.pos_cv_smoothed
    assert any("after the fact" in line for line in ev.lines())

    Xs = evaluation._stack(truths)
    Z = evaluation.measurements(Xs, 50.0, 3)
    R = models.measurement_noise(50.0)
    x0, P0 = evaluation._initial_state(Z, 1.0, R, 5)
    err = []
    for f, n in enumerate((t.size, cut)):
        kf = KalmanFilter(dim_x=5, dim_z=2)
        kf.x, kf.P, kf.F = x0[f].copy(), P0[f].copy(), models.constant_velocity(1.0)
        kf.Q = models.white_noise_acceleration(ev.cv_sigma, 1.0)
        kf.H, kf.R = models.position_measurement_matrix(), R
        xf, Pf, _, _ = kf.batch_filter(Z[2:n, f])
        xs = kf.rts_smoother(xf, Pf)[0]
        keep = evaluation._evaluated(Xs, 1.0)[2:n, f]
        err.append((xs - Xs[2:n, f])[keep][:, [0, 2]])
    assert ev.pos_cv_smoothed == pytest.approx(evaluation._rmse(np.concatenate(err)), rel=1e-6)


def test_smoother_batches_stay_under_their_memory_budget(monkeypatch):
    """Flights of very different lengths: every flight in exactly one batch, and a batch of
    more than one flight keeps its record (as long as its longest flight) under the budget."""
    p = presets.get("imm-ct").with_(dt=4.0, measurement_sigma=100.0).filter_model()
    lengths = np.array([40, 400, 45, 200, 50, 42])
    Z = np.full((lengths.max(), lengths.size, 2), np.nan)
    rng = np.random.default_rng(0)
    for f, n in enumerate(lengths):
        Z[:n, f] = np.cumsum(np.full((n, 2), 400.0), axis=0) + rng.normal(0, 100, (n, 2))
    x0, P0 = evaluation._initial_state(Z, 4.0, np.eye(2) * 1e4, 5)
    per_step = p.n_modes * 5 * 6 * 8 * evaluation.two_filter_records(p.n_modes)  # two filters
    monkeypatch.setattr(evaluation, "SMOOTHER_BATCH_BYTES", 3 * 45 * per_step)
    runs = evaluation._smoothed_runs(Z, x0, P0, p.mu0(), p.imm_arguments(), lengths, 4.0)
    batches = [(list(b), L) for b, L, _ in runs]
    assert sorted(f for b, _ in batches for f in b) == list(range(lengths.size))
    for b, L in batches:
        assert L == lengths[b].max()
        assert len(b) == 1 or len(b) * L * per_step <= evaluation.SMOOTHER_BATCH_BYTES
    assert [sorted(b) for b, _ in batches][:1] == [[0, 2, 5]]  # the three shortest together


def test_fixed_lag_figures_run_from_the_filter_to_the_whole_flight():
    """Lag 0 is the filter (both the IMM's and the CV filter's figures); a lag past the
    flight's end is the fixed-interval smoother."""
    t, X = flight(LEGS[:3], dt=4.0)  # a truth on the 4 s grid
    truths = [evaluation.Truth("f", t, X)]
    kw = dict(seed=2, cv_sigmas=(2.0, 8.0))
    whole = evaluation.evaluate(truths, presets.get("imm-ct"), 50.0, 4.0, **kw)
    zero = evaluation.evaluate(truths, presets.get("imm-ct"), 50.0, 4.0, smoother_lag_s=0.0, **kw)
    far = evaluation.evaluate(truths, presets.get("imm-ct"), 50.0, 4.0, smoother_lag_s=1e4, **kw)
    assert zero.pos_imm_smoothed == pytest.approx(zero.pos_imm, rel=1e-9)
    assert zero.pos_cv_smoothed == pytest.approx(zero.pos_cv, rel=1e-9)
    assert zero.smoothed_turning_flagged == zero.turning_flagged
    assert zero.smoothed_straight_flagged == zero.straight_flagged
    assert far.pos_cv_smoothed == pytest.approx(whole.pos_cv_smoothed, rel=1e-9)
    assert far.pos_imm_smoothed == pytest.approx(whole.pos_imm_smoothed, rel=1e-9)
    assert far.smoothed_turning_flagged == whole.smoothed_turning_flagged
    assert zero.smoother_lag_s == 0.0 and whole.smoother_lag_s is None
    assert any("0 s late" in line for line in zero.lines())


def test_without_the_smoother_there_are_no_smoothed_figures():
    t, X = flight(LEGS[:2])
    ev = evaluation.evaluate([evaluation.Truth("f", t, X)], presets.get("realistic"), 50.0, 1.0,
                             cv_sigmas=(2.0,), smoother=False)  # fmt: skip
    assert ev.pos_imm_smoothed is None and ev.smoothed_turning_flagged is None
    assert not any("after the fact" in line for line in ev.lines())


def test_no_long_segment_is_a_user_error():
    from airspace_sim.errors import UserError

    with pytest.raises(UserError, match="no flight segment"):
        evaluation.evaluate([], presets.get("realistic"), 50.0, 1.0)


def recorded_csv(path):
    """``path``: a traffic-style CSV of one flight of :data:`LEGS`, 5 s reports (needs the
    recorded readers' pandas and pyproj; skips without them)."""
    pytest.importorskip("airspace_sim.recorded")
    pd = pytest.importorskip("pandas")
    pyproj = pytest.importorskip("pyproj")
    t, X = flight(LEGS)
    rec = np.arange(0, t.size, 5)
    to_geo = pyproj.Transformer.from_crs(
        pyproj.CRS.from_proj4("+proj=aeqd +lat_0=47 +lon_0=8 +datum=WGS84 +units=m"),
        "EPSG:4326", always_xy=True,
    )  # fmt: skip
    lon, lat = to_geo.transform(X[rec, 0], X[rec, 2])
    track = (90.0 - np.degrees(np.arctan2(X[rec, 3], X[rec, 1]))) % 360.0
    pd.DataFrame({
        "timestamp": pd.Timestamp("2024-01-01T10:00:00Z") + pd.to_timedelta(t[rec], unit="s"),
        "icao24": "abc123", "callsign": "TEST1", "latitude": lat, "longitude": lon,
        "altitude": 30000.0, "groundspeed": np.hypot(X[rec, 1], X[rec, 3]) / 0.514444,
        "track": track,
    }).to_csv(path, index=False)  # fmt: skip
    return path


def test_evaluate_tracker_command_on_a_recorded_file(tmp_path, capsys):
    """The CLI end to end on a traffic-style CSV made here (needs the recorded readers)."""
    from airspace_sim import cli

    recorded_csv(tmp_path / "f.csv")
    out = tmp_path / "r.json"
    assert cli.main(["evaluate-tracker", str(tmp_path / "f.csv"), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    # the default preset is the one for recorded traffic
    assert "sigma=50 m, period=1 s, preset=imm-ct" in text and "sigma=100 m, period=4 s" in text
    import json

    rows = json.loads(out.read_text())
    assert [r["period_s"] for r in rows] == [1.0, 4.0] and all(r["n_flights"] == 1 for r in rows)
    assert "after the fact" in text and all(r["smoother_lag_s"] is None for r in rows)
    # no glitch in this file: keeping them changes nothing
    kept = tmp_path / "k.json"
    assert cli.main(["evaluate-tracker", str(tmp_path / "f.csv"), "--keep-glitches",
                     "--json", str(kept)]) == 0  # fmt: skip
    assert json.loads(kept.read_text()) == rows
    capsys.readouterr()
    assert cli.main(["evaluate-tracker", str(tmp_path / "f.csv"), "--lag", "12"]) == 0
    assert "12 s late (fixed-lag smoothers)" in capsys.readouterr().out
    assert cli.main(["evaluate-tracker", str(tmp_path / "f.csv"), "--lag", "-1"]) != 0
    err = capsys.readouterr().err
    assert "lag must be >= 0 s" in err and "Traceback" not in err
    assert (
        cli.main(["evaluate-tracker", str(tmp_path / "f.csv"), "--lag", "4", "--no-smoother"]) != 0
    )
    assert "--lag needs the smoothers" in capsys.readouterr().err


def filterpy_known_motion(truths, sigma, T, sa, accel, seed):
    """Position RMSE of filterpy KalmanFilters, one per flight, stepped with the turn
    written here in closed form at the truth's rate and ``accel(flight, k)`` (2,) m/s² as
    the control input; the measurements and counted seconds as the evaluation draws them."""
    from filterpy.kalman import KalmanFilter

    X = evaluation._stack(truths)
    Z = evaluation.measurements(X, sigma, seed)
    ev = evaluation._evaluated(X, T)
    R = sigma**2 * np.eye(2)
    x0, P0 = evaluation.two_point_initialisation(Z[0], Z[1], T, R, 0.0, math.radians(3) ** 2)
    q = sa**2 * np.array([[T**4 / 4, T**3 / 2], [T**3 / 2, T**2]])
    err = []
    for f in range(X.shape[1]):
        kf = KalmanFilter(dim_x=4, dim_z=2, dim_u=2)
        kf.x, kf.P, kf.R = x0[f, :4, None].copy(), P0[f, :4, :4].copy(), R
        kf.H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
        kf.Q = np.zeros((4, 4))
        kf.Q[np.ix_([0, 1], [0, 1])] = kf.Q[np.ix_([2, 3], [2, 3])] = q
        kf.B = np.array([[T**2 / 2, 0], [T, 0], [0, T**2 / 2], [0, T]])
        for k in range(2, X.shape[0]):
            if not np.isfinite(X[k, f, 0]):
                break
            w = X[k - 1, f, 4]
            s, c = (np.sin(w * T) / w, (1 - np.cos(w * T)) / w) if w else (T, 0.0)
            co, si = np.cos(w * T), np.sin(w * T)
            kf.F = np.array([[1, s, 0, -c], [0, co, 0, -si], [0, c, 1, s], [0, si, 0, co]])
            kf.predict(u=accel(f, k - 1)[:, None])
            kf.update(Z[k, f][:, None])
            if ev[k, f]:
                err.append(kf.x[[0, 2], 0] - X[k, f, [0, 2]])
    return float(np.sqrt(np.mean(np.sum(np.square(err), axis=1))))


def test_known_motion_filter_equals_filterpy():
    """The floor's filter (told the truth's turn rate) against filterpy, and with the
    along-track acceleration as input on flights whose speed changes linearly (so the
    closed-form input is the derivative the floor takes of the truth's speed)."""
    pytest.importorskip("filterpy")
    t, X = flight(LEGS)
    truths = [
        evaluation.Truth("f", t, X),
        evaluation.Truth("g", t[:900], X[:900] * [1, 1, -1, -1, -1]),
    ]
    got = evaluation.known_motion_rmse(truths, 50.0, 1.0, 0.7, seed=2)
    want = filterpy_known_motion(truths, 50.0, 1.0, 0.7, lambda f, k: np.zeros(2), seed=2)
    assert got == pytest.approx(want, rel=1e-9)
    cv = evaluation.known_motion_rmse(truths, 50.0, 1.0, 2.0, seed=2, turn_rate=False)
    ev = evaluation.evaluate(truths, presets.get("realistic"), 50.0, 1.0, seed=2, cv_sigmas=(2.0,))
    assert cv == pytest.approx(ev.pos_cv, rel=1e-9)  # the same CV filter as the IMM kernel's
    # straight, speeding up at 0.4 m/s²: x = v0 t + a t²/2
    a, v0 = 0.4, 80.0
    ts = np.arange(0.0, 400.0)
    sp = v0 + a * ts
    hd = math.radians(30.0)
    Xa = np.stack([(v0 * ts + a * ts**2 / 2) * math.cos(hd), sp * math.cos(hd),
                   (v0 * ts + a * ts**2 / 2) * math.sin(hd), sp * math.sin(hd), 0 * ts], 1)  # fmt: skip
    acc = lambda f, k: a * np.array([math.cos(hd), math.sin(hd)])  # noqa: E731
    tr = [evaluation.Truth("a", ts, Xa)]
    got = evaluation.known_motion_rmse(tr, 50.0, 1.0, 0.1, along_track=True, seed=1)
    assert got == pytest.approx(filterpy_known_motion(tr, 50.0, 1.0, 0.1, acc, seed=1), rel=1e-9)
    # and told the input, it beats the same filter without it on that flight
    assert got < evaluation.known_motion_rmse(tr, 50.0, 1.0, 0.1, seed=1)


def test_regime_sigma_uses_the_quiet_value_on_straight_seconds_only():
    t, X = flight(LEGS)
    tr = [evaluation.Truth("f", t, X)]
    same = evaluation.known_motion_rmse(tr, 50.0, 1.0, (0.5, 0.5), seed=4)
    assert same == evaluation.known_motion_rmse(tr, 50.0, 1.0, 0.5, seed=4)
    assert evaluation.known_motion_rmse(tr, 50.0, 1.0, (0.5, 3.0), seed=4) != same


def test_since_onset_counts_seconds_from_the_start_of_each_same_sign_turn():
    w = np.radians([[0.0], [0.2], [0.6], [1.0], [2.0], [-0.7], [-1.0], [0.0], [0.5], [np.nan]])
    got = evaluation.since_onset(w, 2.0)[:, 0]
    want = [np.nan, np.nan, 0, 2, 4, 0, 2, np.nan, 0, np.nan]
    np.testing.assert_array_equal(got, want)


def test_onset_bins_add_up_to_the_turning_flags():
    t, X = flight(LEGS)
    truths = [evaluation.Truth("f", t, X), evaluation.Truth("g", t, X * [1, 1, -1, -1, -1])]
    ev = evaluation.evaluate(truths, presets.get("imm-ct"), 50.0, 1.0, seed=3, cv_sigmas=(2.0,))
    shares = [b[2] for b in ev.onset]
    assert sum(shares) == pytest.approx(1.0)
    assert sum(s * f for _, _, s, f in ev.onset if s) == pytest.approx(ev.turning_flagged)
    # turns of 60-90 s: the first 15 s are flagged less than the rest (detection delay)
    assert ev.onset[0][3] < ev.onset[1][3]
    assert any("since the turn began" in line for line in ev.lines())
    assert ev.to_dict()["onset"][-1]["to_s"] is None


def test_since_turn_end_counts_seconds_from_the_end_of_the_last_turn():
    w = np.radians([[0.0], [0.2], [0.6], [-1.0], [0.1], [0.0], [0.7], [0.3], [np.nan]])
    got = evaluation.since_turn_end(w, 2.0)[:, 0]
    want = [np.inf, np.inf, np.nan, np.nan, 2, 4, np.nan, 2, 4]
    np.testing.assert_array_equal(got, want)


def test_phases_partition_the_seconds_and_their_errors():
    """Every evaluated second is in one phase, so the shares add to 1 and the phases' mean
    squared errors, weighted by their shares, give back the overall RMSEs."""
    t, X = flight(LEGS)
    truths = [evaluation.Truth("f", t, X), evaluation.Truth("g", t, X * [1, 1, -1, -1, -1])]
    ev = evaluation.evaluate(truths, presets.get("imm-ct"), 50.0, 1.0, seed=3, cv_sigmas=(2.0,))
    assert [(ph, lo) for ph, lo, *_ in ev.phases] == [
        (ph, lo) for ph in ("turn", "after") for lo in (0.0, 15.0, 30.0)
    ]
    shares = np.array([p[3] for p in ev.phases])
    assert shares.sum() == pytest.approx(1.0) and np.all(shares > 0)
    imm, cv = (np.array([p[k] for p in ev.phases]) for k in (4, 5))
    assert np.sqrt(np.sum(shares * imm**2)) == pytest.approx(ev.pos_imm, rel=1e-9)
    assert np.sqrt(np.sum(shares * cv**2)) == pytest.approx(ev.pos_cv, rel=1e-9)
    # long straight legs: the IMM's quiet mode beats a CV filter tuned for the turns
    assert imm[5] < cv[5]
    assert (
        any("by phase" in line for line in ev.lines()) and ev.to_dict()["phases"][2]["to_s"] is None
    )


def test_tuning_and_floor_scripts_run_on_flights_made_here(tmp_path, monkeypatch, capsys):
    """docs/benchmarks/tune_tracker.py (with a 4-mode candidate), tracker_floor.py,
    turn_flags_fixed_lag.py, causal_turn_detector.py, recording_glitches.py and
    turn_flag_misses.py on four traffic-style JSON files written here: the split, the
    candidate with another number of modes, the floors (told more, never worse than the CV
    filter), the flags with a delay, the causal detector (its fits' derivatives exact on a
    quadratic path), no glitch in clean flights, the misses."""
    pytest.importorskip("airspace_sim.recorded")
    pd = pytest.importorskip("pandas")
    pyproj = pytest.importorskip("pyproj")
    import json
    import sys
    from pathlib import Path

    to_geo = pyproj.Transformer.from_crs(
        pyproj.CRS.from_proj4("+proj=aeqd +lat_0=47 +lon_0=8 +datum=WGS84 +units=m"),
        "EPSG:4326", always_xy=True,
    )  # fmt: skip
    for i, sign in enumerate((1, -1, 1, -1)):
        t, X = flight([(d, sign * r) for d, r in LEGS], speed=100.0 + 10 * i)
        rec = np.arange(0, t.size, 5)
        lon, lat = to_geo.transform(X[rec, 0] + 5e3 * i, X[rec, 2])
        pd.DataFrame({
            "timestamp": 1515748470000 + 1000 * t[rec].astype(np.int64), "icao24": f"abc12{i}",
            "latitude": lat, "longitude": lon, "groundspeed": np.hypot(X[rec, 1], X[rec, 3]) / 0.514444,
            "track": (90.0 - np.degrees(np.arctan2(X[rec, 3], X[rec, 1]))) % 360.0,
            "callsign": "CALIBRA", "altitude": 3000,
        }).to_json(tmp_path / f"f{i}.json.gz", orient="records")  # fmt: skip
    bench = Path(__file__).resolve().parents[1] / "docs" / "benchmarks"
    monkeypatch.syspath_prepend(str(bench))
    for name in ("tune_tracker", "tracker_floor"):
        sys.modules.pop(name, None)
    import tracker_floor
    import tune_tracker

    assert [p.name for p in tune_tracker.split(tmp_path, "test")] == ["f1.json.gz", "f3.json.gz"]
    four = {
        "turn_rates": [0, 2, 2, 0], "estimated_turn_rate": [0, 1, 1, 0],
        "filter_mode_sigma_accel": [0.3, 1.5, 1.5, 5], "filter_mode_sigma_turn_rate": [0.3, 0.3, 1.5, 0.3],
        "sojourn_s": [120, 60, 15, 10],
        "switch_probabilities": [[0, .7, .2, .1], [.5, 0, .4, .1], [.3, .6, 0, .1], [.4, .3, .3, 0]],
    }  # fmt: skip
    tune_tracker.main([str(tmp_path), "--period", "4", "--candidate", "{}",
                       "--candidate", json.dumps(four)])  # fmt: skip
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 2 and all(ln.startswith("train 4s imm-ct") for ln in lines)
    ratios = [float(ln.split("ratio ")[1].split()[0]) for ln in lines]
    assert all(0.3 < r < 1.0 for r in ratios)  # turns the CV filter does not follow
    assert all("smoothed turning" in ln for ln in lines)
    tune_tracker.main([str(tmp_path), "--period", "4", "--preset", "imm-cta"])
    (line,) = capsys.readouterr().out.strip().splitlines()
    assert "ratio" in line and "smoothed" not in line  # no smoother for along-track models
    with pytest.raises(SystemExit, match="needs sojourn_s"):
        tune_tracker.candidate(presets.get("imm-ct"), {"turn_rates": [0, 2, 2, 0]})
    tracker_floor.main([str(tmp_path), "--split", "test", "--period", "4", "--preset", "imm-ct"])
    out = capsys.readouterr().out
    got = {ln.split(":")[0].removeprefix("test 4s "): float(ln.split("ratio ")[1].split()[0])
           for ln in out.splitlines() if "ratio" in ln}  # fmt: skip
    assert got["CV"] == 1.0 and got["rate"] < 1.0
    assert got["rate + regime"] <= got["rate"] and got["rate + along-track"] < 1.0
    assert "preset imm-ct" in got

    # turn flags with a delay: more of each turn as the lag grows
    sys.modules.pop("turn_flags_fixed_lag", None)
    import turn_flags_fixed_lag

    assert len(tune_tracker.split(tmp_path, "all")) == 4
    turn_flags_fixed_lag.main([str(tmp_path), "--split", "all", "--period", "4", "--lags", "0,12"])
    rows = [ln for ln in capsys.readouterr().out.splitlines() if ln.strip().startswith("lag")]
    turning = [float(ln.split(":")[1].split("%")[0]) for ln in rows]
    assert [ln.split(":")[0].strip() for ln in rows] == ["lag 0 s", "lag 12 s", "lag inf s"]
    assert turning[0] < turning[1] <= turning[2] + 1.0 and turning[2] > 80.0

    # a causal polynomial-fit turn detector, its best threshold at <= 2% of straight seconds
    sys.modules.pop("causal_turn_detector", None)
    import causal_turn_detector

    t = np.arange(20.0)[:, None, None]  # a quadratic path: the fit's derivatives are exact
    path = np.concatenate([3 + 2 * t + 0.5 * t**2, 1 - t - 0.25 * t**2], axis=-1)
    v = causal_turn_detector.causal_derivative(path, 6, 2, 1, 1.0)
    a = causal_turn_detector.causal_derivative(path, 6, 2, 2, 1.0)
    np.testing.assert_allclose(v[5:, 0], np.c_[2 + t[5:, 0], -1 - 0.5 * t[5:, 0]], atol=1e-9)
    np.testing.assert_allclose(a[5:, 0], np.tile([1.0, -0.5], (15, 1)), atol=1e-9)
    assert np.isnan(v[:5]).all()
    causal_turn_detector.main([str(tmp_path), "--split", "all", "--period", "4",
                               "--windows", "16,32", "--orders", "2"])  # fmt: skip
    rows = [ln for ln in capsys.readouterr().out.splitlines() if "window" in ln]
    assert [ln.split(",")[0].strip() for ln in rows] == ["window 16 s", "window 32 s"]
    flagged = [ln.split(": ")[-1] for ln in rows if "none" not in ln]
    assert flagged and all(float(f.split("/")[1].rstrip("%")) <= 2.0 for f in flagged)

    # glitches: none in these flights; a residual peak is the largest within two places
    sys.modules.pop("recording_glitches", None)
    import recording_glitches

    peaks = recording_glitches.residual_peaks(np.array([np.nan, 1.0, 5.0, 2.0, 0.0, 0.0, 3.0]))
    assert peaks.tolist() == [5.0, 3.0]
    recording_glitches.main([str(p) for p in sorted(tmp_path.glob("f*.json.gz"))])
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 4 and all(", 0 dropped;" in ln for ln in out)

    # where the running IMM misses turns: shares of the turning steps add up to 1
    sys.modules.pop("turn_flag_misses", None)
    import turn_flag_misses

    w = np.radians(np.r_[0.0, 0, 0, 1.2, 1.2, 1.2, 1.2])[:, None]  # a step in the rate
    np.testing.assert_array_equal(turn_flag_misses.rate_changed(w, 1.0, 2.0)[:, 0],
                                  [0, 0, 0, 1, 1, 0, 0])  # fmt: skip
    turn_flag_misses.main([str(tmp_path), "--split", "all", "--period", "4"])
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("all 4s imm-ct: turning flagged")
    shares = [float(ln.split(": ")[1].split("%")[0]) for ln in out[1:]]
    assert len(shares) >= 3 and sum(shares) == pytest.approx(100.0, abs=0.5)


def test_tune_tracker_splits_a_collection_file_by_flight(tmp_path, monkeypatch):
    """docs/benchmarks/tune_tracker.py on one collection file: its flights in order, even
    positions the training half, odd the test half."""
    pytest.importorskip("airspace_sim.recorded")
    pd = pytest.importorskip("pandas")
    import sys
    from pathlib import Path

    rows = []
    for i in range(5):
        for k in range(30):
            rows.append({
                "timestamp": 1515748470000 + 10000 * k, "icao24": f"abc12{i}",
                "latitude": 47.0 + 0.01 * i, "longitude": 8.0 + 0.002 * k,
                "groundspeed": 300.0, "track": 90.0, "callsign": f"T{i}", "altitude": 30000,
            })  # fmt: skip
    pd.DataFrame(rows).to_json(tmp_path / "c.json.gz", orient="records")
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[1] / "docs" / "benchmarks"))
    sys.modules.pop("tune_tracker", None)
    import tune_tracker

    for half, want in (("train", ["abc120", "abc122", "abc124"]), ("test", ["abc121", "abc123"])):
        sources = tune_tracker.split(tmp_path / "c.json.gz", half)
        assert [f.icao24 for f in tune_tracker.flights_of(sources)] == want
