"""The Ray backend on a local Ray with 2 CPUs: the same rows as the local backend, and a
worker killed mid-run is retried without duplicate rows."""

import os
import threading
import time

import pytest

ray = pytest.importorskip("ray")

from _tables import descends_from, pids_where, same_rows  # noqa: E402

from airspace_sim.encounters.campaign import run_campaign  # noqa: E402
from airspace_sim.experiments.sweep import run_sweep  # noqa: E402

GRID = ["resolver.kind=bands,none"]


def test_sweep_on_ray_equals_local(tmp_path, local_ray):
    kw = dict(steps=30, progress=False)
    local = run_sweep("head_on", GRID, "0-2", tmp_path / "l.parquet", **kw)
    remote = run_sweep("head_on", GRID, "0-2", tmp_path / "r.parquet", backend="ray", **kw)
    assert remote.num_rows == 6
    assert same_rows(local, remote)
    assert (tmp_path / "l.parquet").read_bytes() == (tmp_path / "r.parquet").read_bytes()


def test_encounters_on_ray_equal_local(tmp_path, local_ray):
    kw = dict(chunk_size=3, progress=False)
    local = run_campaign(tmp_path / "l.parquet", 6, "seed,none", **kw)
    remote = run_campaign(tmp_path / "r.parquet", 6, "seed,none", backend="ray", **kw)
    assert same_rows(local, remote)


def _task_pids(name: str) -> list[int]:
    """Pids of this test's own Ray workers running task ``name`` (their title is
    ``ray::<name>``; the local Ray this process started is their ancestor, so another job's
    Ray workers on the same machine are never touched)."""
    me = os.getpid()
    found = pids_where(lambda stat, cmd: cmd.startswith(f"ray::{name}".encode()))
    return [pid for pid in found if descends_from(pid, me)]


def test_lost_worker_is_retried_without_duplicates(tmp_path, local_ray):
    kw = dict(steps=120, progress=False)
    local = run_sweep("head_on", GRID, "0-3", tmp_path / "l.parquet", **kw)
    killed = []

    def kill_one():
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not killed:
            for pid in _task_pids("run_one"):
                os.kill(pid, 9)
                killed.append(pid)
                return
            time.sleep(0.02)

    t = threading.Thread(target=kill_one)
    t.start()
    remote = run_sweep("head_on", GRID, "0-3", tmp_path / "r.parquet", backend="ray", **kw)
    t.join()
    assert killed, "no Ray worker was seen running a task"
    keys = list(zip(remote.column("settings").to_pylist(), remote.column("seed").to_pylist()))
    assert len(keys) == len(set(keys)) == 8
    assert same_rows(local, remote)
