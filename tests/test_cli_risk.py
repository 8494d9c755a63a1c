"""``airspace-sim risk``: options checked before any work (one line, exit 2), and a tiny
run against its closed form (an exactly head-on pair: the unequipped pair meets at 0 m, an
NMAC in every seed; the equipped pair turns away) and against the library call, for one
and for two worker processes."""

from __future__ import annotations

import json

import pytest
from test_cli_run import main_in_process

from airspace_sim.scenarios import load
from airspace_sim.world.risk import risk_ratio

HEAD_ON = """
name = "pair"
duration = 120.0
[tracker]
kind = "truth"
[resolver]
kind = "bands"
[[aircraft]]
id = "w"
position = [-20000.0, 0.0]
heading_deg = 0.0
speed = 230.0
[[aircraft]]
id = "e"
position = [20000.0, 0.0]
heading_deg = 180.0
speed = 230.0
"""


def _one_line(proc, *needles):
    assert proc.returncode == 2, (proc.returncode, proc.stderr)
    err = proc.stderr.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert err.startswith("airspace-sim risk: error: "), err
    for needle in needles:
        assert needle in err, (needle, err)
    assert proc.stdout == ""  # nothing ran


@pytest.mark.parametrize(
    "seeds, needle",
    [
        ("0-x", "--seeds: expected e.g. 0-99, 5 or 0,3,7, got '0-x'"),
        ("3-1", "got '3-1' (at '3-1')"),
        ("0,0", "--seeds: a seed is repeated"),
        ("-1", "--seeds: seeds must be in [0, 2**63), got -1"),
    ],
)
def test_a_bad_seed_spec_is_one_line_and_exit_2(capsys, tmp_path, seeds, needle):
    out = tmp_path / "r.json"
    proc = main_in_process(capsys, "risk", "head_on", f"--seeds={seeds}", "--json", str(out))
    _one_line(proc, needle)
    assert not out.exists()


def test_other_bad_options_are_one_line(capsys, tmp_path):
    _one_line(main_in_process(capsys, "risk", "nope"), "unknown scenario 'nope'")
    _one_line(
        main_in_process(capsys, "risk", "head_on", "--set", "traffic.count=-1"), "traffic.count"
    )
    (tmp_path / "dir").mkdir()
    _one_line(
        main_in_process(capsys, "risk", "head_on", "--json", str(tmp_path / "dir")),
        "is a folder",
    )
    proc = main_in_process(capsys, "risk", "head_on", "--workers", "0")
    assert proc.returncode == 2 and "--workers" in proc.stderr


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_tiny_run_matches_the_closed_form_and_the_library(capsys, tmp_path, workers):
    path = tmp_path / "pair.toml"
    path.write_text(HEAD_ON)
    out = tmp_path / "risk.json"
    proc = main_in_process(
        capsys, "risk", str(path), "--seeds", "0,1", "--workers", workers,
        "--json", str(out), "--no-progress",
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    got = json.loads(out.read_text())
    assert got["nmac_unequipped"] == 2 and got["nmac_equipped"] == 0
    assert got["los_pairs_unequipped"] == 2 and got["risk_ratio"] == 0.0
    assert [r["seed"] for r in got["per_seed"]] == [0, 1] and got["runs"] == 2
    assert got == {"scenario": "pair", **risk_ratio(load(path), [0, 1])}
    assert "risk ratio (NMAC pairs) 0/2 = 0" in proc.stdout


def test_an_undefined_ratio_is_null_in_the_json(capsys, tmp_path):
    path = tmp_path / "apart.toml"
    path.write_text(HEAD_ON.replace("[20000.0, 0.0]", "[20000.0, 30000.0]"))
    out = tmp_path / "risk.json"
    proc = main_in_process(
        capsys, "risk", str(path), "--seeds", "0", "--json", str(out), "--set", "duration=30"
    )
    assert proc.returncode == 0, proc.stderr
    got = json.loads(out.read_text())
    assert got["nmac_unequipped"] == 0 and got["risk_ratio"] is None
    assert "0/0 (undefined)" in proc.stdout
