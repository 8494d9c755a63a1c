"""``bench-world``'s growth exponents (wall clock and CPU) and its warm-up."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest

from airspace_sim.commands.bench_world import format_report, growth


def _row(n, ms, cpu_ms, tracks):
    return {
        "aircraft": n,
        "trackers": True,
        "tracks": tracks,
        "ms_per_step": ms,
        "cpu_ms_per_step": cpu_ms,
        "steps_per_second": 1000.0 / ms,
        "imm_ms_per_step": None,
    }


def test_growth_reports_wall_clock_and_cpu_exponents():
    # wall clock grows as N^1.5 (a loaded machine), CPU time linearly, tracks as N^1.25
    rows = [_row(n, 1e-3 * n**1.5, 0.1 * n, 50.0 * n**1.25) for n in (100, 1000, 10000)]
    grow = growth(rows)
    assert [(g["from"], g["to"]) for g in grow] == [(100, 1000), (1000, 10000)]
    for g in grow:
        assert g["exponent"] == pytest.approx(1.5)
        assert g["cpu_exponent"] == pytest.approx(1.0)
        assert g["cpu_time_ratio"] == pytest.approx(10.0)
        assert g["track_exponent"] == pytest.approx(1.5 / 1.25)
        assert g["cpu_track_exponent"] == pytest.approx(1.0 / 1.25)
    text = format_report(rows, grow)
    assert (
        "100 → 1000 aircraft (×10): time per step ×31.62, growth exponent 1.50, 1.20 in tracks "
        "(wall clock); CPU time per step ×10.00, growth exponent 1.00, 0.80 in tracks (CPU)"
    ) in text


def test_growth_without_track_counts_has_no_track_exponent():
    rows = [_row(n, float(n), float(n), 0.0) for n in (10, 100)]
    (g,) = growth(rows)
    assert math.isnan(g["cpu_track_exponent"]) and "in tracks" not in format_report(rows, [g])


def test_bench_world_times_no_kernel_compilation():
    """The warm-up runs past the first conflict, where the band search's kernels first run:
    no numba kernel is compiled or loaded during the timed steps. In a fresh process (in
    this one, other tests may have loaded the kernels already); with the warm-up cut to 5
    steps, 6 kernels load during the timed steps."""
    code = (
        "from airspace_sim.world.benchmark import bench_world\n"
        "r = bench_world(60, steps=3, compare_imm=False)\n"
        "print(r['warmup_steps'], r['kernels_loaded_timed'])\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    warm, loaded = map(int, proc.stdout.split())
    assert warm >= 5 and loaded == 0
