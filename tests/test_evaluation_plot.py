"""Plots of a tracker evaluation (tracking.evaluation_plot) and the record they draw
(evaluation.evaluate_with_record), on flights made here.

Oracles: the record is what the figures score (every figure recomputed from it equals
``evaluate``'s), windows and rankings by counting, PNG files read back.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_tracker_evaluation import LEGS, flight, recorded_csv

from airspace_sim.dynamics import presets
from airspace_sim.tracking import evaluation, evaluation_plot


def truths():
    """Two flights of LEGS, the second mirrored and 200 s shorter."""
    t, X = flight(LEGS)
    cut = t.size - 200
    return [evaluation.Truth("f", t, X),
            evaluation.Truth("g/h 1", t[:cut], (X * [1, 1, -1, -1, -1])[:cut])]  # fmt: skip


def test_turning_window_holds_the_most_turning_steps():
    w = np.zeros(100)
    w[40:55] = math.radians(2.0)  # 15 turning steps
    w[70:75] = -math.radians(3.0)
    w[95:] = np.nan  # the truth ends
    assert evaluation_plot.turning_window(w, 20) == (35, 55)  # the first window with all 15
    assert evaluation_plot.turning_window(w, 40) == (35, 75)  # both turns: 20 steps
    assert evaluation_plot.turning_window(w, 500) == (0, 95)  # shorter: the whole truth
    w[:10] = np.nan
    assert evaluation_plot.turning_window(w, 500) == (10, 95)
    assert evaluation_plot.turning_window(np.full(5, np.nan), 3) == (0, 0)


def test_most_turning_ranks_the_segments():
    def tr(n_turning):
        w = np.zeros(60)
        w[:n_turning] = math.radians(1.5)
        return evaluation.Truth("x", np.arange(60.0), np.column_stack([np.zeros((60, 4)), w]))

    ts = [tr(0), tr(30), tr(10), tr(30)]
    assert evaluation_plot.most_turning(ts, 3) == [1, 3, 2]
    assert evaluation_plot.most_turning(ts, 0) == []


@pytest.mark.parametrize("budget", [evaluation.SMOOTHER_BATCH_BYTES, 1])
def test_the_record_is_what_the_figures_score(monkeypatch, budget):
    """Every figure recomputed from the record of all flights equals evaluate's, with the
    flights smoothed in one batch or one batch each; the shorter flight's record ends with it."""
    monkeypatch.setattr(evaluation, "SMOOTHER_BATCH_BYTES", budget)
    ts = truths()
    args = (ts, presets.get("imm-ct"), 50.0, 1.0)
    kw = dict(seed=3, cv_sigmas=(2.0, 8.0))
    ev, rec = evaluation.evaluate_with_record(*args, [1, 0], **kw)
    assert ev.to_dict() == evaluation.evaluate(*args, **kw).to_dict()
    assert rec.names == ("g/h 1", "f") and rec.mode_names == presets.get("imm-ct").mode_names()
    X, on = rec.truth, rec.evaluated

    def rmse(est):
        return evaluation._rmse((est[..., [0, 2]] - X[..., [0, 2]])[on])

    assert rmse(rec.imm) == pytest.approx(ev.pos_imm, rel=1e-12)
    assert rmse(rec.cv[..., [0, 1, 2, 3]]) == pytest.approx(ev.pos_cv, rel=1e-12)
    assert rmse(rec.smoothed) == pytest.approx(ev.pos_imm_smoothed, rel=1e-12)
    flags = evaluation._flags(rec.p_left, rec.p_right, X, on)
    assert flags["turning_flagged"] == pytest.approx(ev.turning_flagged, rel=1e-12)
    assert flags["straight_flagged"] == pytest.approx(ev.straight_flagged, rel=1e-12)
    sm = evaluation._flags(rec.smoothed_p_left, rec.smoothed_p_right, X, on)
    assert sm["turning_flagged"] == pytest.approx(ev.smoothed_turning_flagged, rel=1e-12)
    np.testing.assert_allclose(rec.mu[2:].sum(axis=-1)[np.isfinite(X[2:, :, 0])], 1.0)
    end = ts[1].t_s.size
    for a in (rec.imm, rec.mu, rec.smoothed, rec.smoothed_mu, rec.p_left, rec.smoothed_p_right):
        assert np.all(np.isnan(a[end:, 0])) and np.all(np.isfinite(a[2:end, 0]))


def test_no_record_without_flights_and_a_bad_index_is_a_user_error():
    from airspace_sim.errors import UserError

    ev, rec = evaluation.evaluate_with_record(truths(), presets.get("realistic"), 50.0, 4.0,
                                              [], smoother=False)  # fmt: skip
    assert rec.truth.shape[1] == 0 and rec.smoothed is None and ev.pos_imm_smoothed is None
    with pytest.raises(UserError, match="flights to record must be in 0..1"):
        evaluation.evaluate_with_record(truths(), presets.get("realistic"), 50.0, 4.0, [2])


def test_plots_are_written(tmp_path):
    plt_image = pytest.importorskip("matplotlib.image")
    ev, rec = evaluation.evaluate_with_record(truths(), presets.get("imm-ct"), 100.0, 4.0,
                                              [0], cv_sigmas=(2.0,))  # fmt: skip
    flight_png = evaluation_plot.plot_flight(rec, 0, tmp_path / "f.png", window_s=600)
    summary_png = evaluation_plot.plot_summary(ev, tmp_path / "s.png")
    assert plt_image.imread(flight_png).shape[:2] == (850, 1500)
    assert plt_image.imread(summary_png).shape[:2] == (450, 1200)


def test_evaluate_tracker_plot_option(tmp_path, capsys):
    from airspace_sim import cli

    csv = str(recorded_csv(tmp_path / "f.csv"))
    out = tmp_path / "plots"
    assert cli.main(["evaluate-tracker", csv, "--plot", str(out), "--plot-flights", "1"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["imm-ct-1s-1-abc123-TEST1-0_0.png", "imm-ct-1s-summary.png",
                     "imm-ct-4s-1-abc123-TEST1-0_0.png", "imm-ct-4s-summary.png"]  # fmt: skip
    assert "plots: " in capsys.readouterr().out
    for bad, message in (
        (["--plot-flights", "-1"], "--plot-flights: must be >= 0, got -1"),
        (["--plot-window", "0"], "--plot-window: must be a number of seconds > 0, got 0.0"),
        (["--plot", str(tmp_path / "f.csv" / "x")], "cannot make the folder"),
    ):
        argv = ["evaluate-tracker", csv] + (bad if bad[0] == "--plot" else ["--plot", "p"] + bad)
        assert cli.main(argv) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
