"""The result summary of docs/benchmarks/summarize.py: Garwood intervals against their
published values, and the grouping of resolver_candidates.py's lines."""

import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "docs", "benchmarks"))
from summarize import garwood, summarize  # noqa: E402


@pytest.mark.parametrize(
    "count, lo, hi",
    # the tabulated exact 95% Poisson limits: 0 -> (0, 3.689), 1 -> (0.0253, 5.572),
    # 5 -> (1.624, 11.668), 10 -> (4.795, 18.390)
    [(0, 0.0, 3.689), (1, 0.0253, 5.572), (5, 1.624, 11.668), (10, 4.795, 18.390)],
)
def test_garwood_matches_the_tabulated_limits(count, lo, hi):
    got = garwood(count, 1.0)
    assert got == pytest.approx((lo, hi), abs=2e-3)
    # over 32 seeds the rate's limits are the count's over 32
    assert garwood(count, 32.0) == pytest.approx((lo / 32, hi / 32), abs=1e-4)


def _row(case, seed, los, kind="k", policy="", **extra):
    row = {"case": case, "kind": kind, "policy": policy, "seed": seed, "los_pairs": los}
    row.update(nmac_pairs=0, extra_path_pct=10.0 + seed, not_arrived=seed)
    row.update(extra)
    return row


def test_rows_group_by_configuration_not_by_seed_range():
    rows = [
        _row("dense:0-1", 0, 2),
        _row("dense:0-1", 1, 0),
        _row("dense:2", 2, 1),
        _row("dense:0-1", 0, 1, set="resolver.margin=0.2"),
        _row("ring:64:0-9", 3, 0),
        _row("dense:0-1", 1, 5),  # the same seed again: the last line counts
    ]
    out = dict(summarize(rows))
    plain = out[("dense", "k", "", "")]
    assert plain["seeds"] == [0, 1, 2] and plain["los_pairs"] == 8
    assert plain["los_by_seed"] == {0: 2, 1: 5, 2: 1}
    assert plain["extra_path_pct"] == pytest.approx(11.0)
    assert out[("dense", "k", "", "resolver.margin=0.2")]["los_pairs"] == 1
    assert out[("ring:64", "k", "", "")]["los_per_seed_95"][0] == 0.0


def test_arrival_delay_is_averaged_over_the_runs_that_report_one():
    rows = [
        _row("dense:0-2", 0, 0, arrival_delay_mean_s=10.0),
        _row("dense:0-2", 1, 0, arrival_delay_mean_s=30.0),
        _row("dense:0-2", 2, 0, arrival_delay_mean_s=float("nan")),  # no aircraft arrived
        _row("dense:3", 3, 0),  # a line from before the field existed
    ]
    ((_, s),) = summarize(rows)
    assert s["arrival_delay_mean_s"] == pytest.approx(20.0)
    ((_, old),) = summarize([_row("dense:3", 3, 0)])
    assert old["arrival_delay_mean_s"] != old["arrival_delay_mean_s"]  # NaN
