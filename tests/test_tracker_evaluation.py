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


def test_no_long_segment_is_a_user_error():
    from airspace_sim.errors import UserError

    with pytest.raises(UserError, match="no flight segment"):
        evaluation.evaluate([], presets.get("realistic"), 50.0, 1.0)


def test_evaluate_tracker_command_on_a_recorded_file(tmp_path, capsys):
    """The CLI end to end on a traffic-style CSV made here (needs the recorded readers)."""
    pytest.importorskip("airspace_sim.recorded")
    pd = pytest.importorskip("pandas")
    pyproj = pytest.importorskip("pyproj")
    from airspace_sim import cli

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
    }).to_csv(tmp_path / "f.csv", index=False)  # fmt: skip
    out = tmp_path / "r.json"
    assert cli.main(["evaluate-tracker", str(tmp_path / "f.csv"), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "sigma=50 m, period=1 s, preset=realistic" in text and "sigma=100 m, period=4 s" in text
    import json

    rows = json.loads(out.read_text())
    assert [r["period_s"] for r in rows] == [1.0, 4.0] and all(r["n_flights"] == 1 for r in rows)
