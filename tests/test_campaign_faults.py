"""Campaign faults (issue 11): a killed parent leaves no workers, a full disk and damaged state
files stop with one clear line or are repaired, and nothing already computed is lost."""

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from _tables import pids_where, same_rows

from airspace_sim.encounters.campaign import run_campaign
from airspace_sim.errors import UserError
from airspace_sim.experiments.sweep import run_sweep

RUNS, CHUNK, RES = 8, 2, "seed"


def campaign(out, **kw):
    return run_campaign(out, RUNS, RES, chunk_size=CHUNK, progress=False, **kw)


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    """A finished campaign: (table, folder holding out and its parts)."""
    d = tmp_path_factory.mktemp("pristine")
    return campaign(d / "c.parquet"), d


def _copy(pristine, tmp_path) -> Path:
    shutil.copytree(pristine[1], tmp_path / "c", dirs_exist_ok=True)
    return tmp_path / "c" / "c.parquet"


def _children(pid: int) -> list[int]:
    """Pids whose parent is ``pid``."""
    return pids_where(lambda stat, cmd: int(stat.rsplit(")", 1)[1].split()[1]) == pid)


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


def _start(cmd: list[str], parts: Path, tmp_path: Path, want_children: int):
    """Start ``cmd``; return (process, its children) once a part is saved and the children
    (workers, resource tracker) exist."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(cmd, cwd=tmp_path, env=env, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline:
        kids = _children(proc.pid)
        if list(parts.glob("part-*.parquet")) and len(kids) >= want_children:
            return proc, kids
        if proc.poll() is not None:
            pytest.fail(f"finished before it could be killed (rc {proc.returncode})")
        time.sleep(0.05)
    proc.kill()
    pytest.fail("no part written in 240 s")


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM], ids=["SIGKILL", "SIGTERM"])
def test_killed_parent_leaves_no_workers_and_resumes(tmp_path, pristine, sig):
    out = tmp_path / "k.parquet"
    parts = out.with_name(out.name + ".parts")
    cmd = [sys.executable, "-m", "airspace_sim", "encounters", "--runs", "40", "--chunk-size"]
    cmd += ["1", "--resolver", RES, "--workers", "2", "--out", str(out), "--no-progress"]
    proc, _ = _start(cmd, parts, tmp_path, want_children=2)
    kids = _children(proc.pid)  # the workers and multiprocessing's resource tracker
    os.kill(proc.pid, sig)
    proc.wait(timeout=120)  # a cold numba cache on a loaded host can take a while
    deadline = time.monotonic() + 5
    while any(_alive(k) for k in kids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not [k for k in kids if _alive(k)], "workers outlived their parent by 5 s"
    saved = {p.name: p.read_bytes() for p in parts.glob("part-*.parquet")}
    assert saved
    t = run_campaign(out, RUNS, RES, chunk_size=1, progress=False)
    assert same_rows(t, pristine[0])
    for name, data in saved.items():  # nothing computed was lost or run again
        assert (parts / name).read_bytes() == data


@pytest.mark.slow
def test_killed_sweep_resumes_to_the_same_rows(tmp_path):
    grid = ["resolver.kind=bands,none"]
    ref = run_sweep("head_on", grid, "0-2", tmp_path / "ref.parquet", steps=60, progress=False)
    out = tmp_path / "s.parquet"
    parts = out.with_name(out.name + ".parts")
    cmd = [sys.executable, "-m", "airspace_sim", "sweep", "head_on", "--grid", grid[0]]
    cmd += ["--seeds", "0-2", "--steps", "60", "--out", str(out), "--no-progress"]
    proc, _ = _start(cmd, parts, tmp_path, want_children=0)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=120)  # a cold numba cache on a loaded host can take a while
    n = len(list(parts.glob("part-*.parquet")))
    assert n >= 1
    assert same_rows(run_sweep("head_on", grid, "0-2", out, steps=60, progress=False), ref)


# ------------------------------------------------------------------ full disk
def test_full_disk_mocked_write_stops_clearly_and_resumes(tmp_path, pristine, monkeypatch):
    out = tmp_path / "f.parquet"
    parts = out.with_name(out.name + ".parts")
    real = os.write
    calls = {"n": 0}

    def write(fd, data):
        try:
            target = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:
            target = ""
        if target.startswith(str(parts)):
            calls["n"] += 1
            if calls["n"] >= 3:  # the manifest and one part fit, then the disk is full
                real(fd, bytes(data)[: len(data) // 2])
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, data)

    monkeypatch.setattr(os, "write", write)
    with pytest.raises(UserError) as e:
        campaign(out)
    msg = str(e.value)
    assert "the disk is full" in msg and "\n" not in msg
    assert "2 finished runs are safe" in msg and "rerun" in msg
    monkeypatch.setattr(os, "write", real)
    assert json.loads((parts / "manifest.json").read_text())["seed"] == 0
    assert not list(parts.glob(".*")), "a temporary file was left behind"
    assert len(list(parts.glob("part-*.parquet"))) == 1
    assert same_rows(campaign(out), pristine[0])


def _mount_tmpfs(path: Path, size: str) -> bool:
    path.mkdir(parents=True, exist_ok=True)
    r = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True
    )
    return r.returncode == 0


def test_full_disk_real_tmpfs(tmp_path, pristine):
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("needs root to mount a small tmpfs")
    mnt = tmp_path / "small"
    if not _mount_tmpfs(mnt, "40k"):
        pytest.skip("cannot mount a tmpfs here")
    try:
        out = mnt / "t.parquet"
        with pytest.raises(UserError, match="the disk is full") as e:
            campaign(out)
        assert "\n" not in str(e.value)
        parts = out.with_name(out.name + ".parts")
        assert json.loads((parts / "manifest.json").read_text())["frame"] == "relative"
        assert not list(parts.glob(".*"))
        saved = {p.name: p.read_bytes() for p in parts.glob("part-*.parquet")}
        subprocess.run(["mount", "-o", "remount,size=4m", str(mnt)], check=True)
        assert same_rows(campaign(out), pristine[0])
        for name, data in saved.items():
            assert (parts / name).read_bytes() == data
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


# ------------------------------------------------------------------ damaged state files
def _state_files(out: Path) -> list[str]:
    parts = out.with_name(out.name + ".parts")
    names = [out.name] + [f"{parts.name}/{p.name}" for p in sorted(parts.iterdir())]
    return names


def test_every_state_file_is_listed(pristine):
    names = _state_files(pristine[1] / "c.parquet")
    assert len(names) == 1 + 1 + RUNS // CHUNK  # final, manifest, parts


@pytest.mark.parametrize("keep", [0.0, 0.5])
def test_truncated_state_files_are_repaired(tmp_path, pristine, keep):
    for name in _state_files(pristine[1] / "c.parquet"):
        case = tmp_path / name.replace("/", "_")
        out = _copy(pristine, case)
        path = out.parent / name
        data = path.read_bytes()
        path.write_bytes(data[: int(len(data) * keep)])
        others = {
            p: p.read_bytes()
            for p in out.with_name(out.name + ".parts").glob("part-*.parquet")
            if p != path
        }
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            t = campaign(out)
        assert same_rows(t, pristine[0]), name
        assert same_rows(pq.read_table(out), pristine[0]), name
        for p, b in others.items():  # intact parts kept as they were: nothing recomputed
            assert p.read_bytes() == b, (name, p)
        text = " ".join(str(w.message) for w in caught)
        if name.endswith("manifest.json"):
            assert "manifest.json: damaged; rewritten" in text, name
        elif name.startswith("c.parquet.parts/part-"):
            assert "damaged" in text and Path(str(path) + ".damaged").exists(), name


def test_damaged_manifest_with_foreign_parts_names_the_folder(tmp_path, pristine):
    out = _copy(pristine, tmp_path)
    parts = out.with_name(out.name + ".parts")
    (parts / "manifest.json").write_bytes(b"")
    with pytest.raises(UserError, match="made with other settings") as e:
        run_campaign(out, RUNS, RES, seed=1, chunk_size=CHUNK, progress=False)
    assert "delete it" in str(e.value) and str(parts) in str(e.value)
    # the parts are untouched
    assert len(list(parts.glob("part-*.parquet"))) == RUNS // CHUNK


def test_part_from_other_settings_is_named(tmp_path, pristine):
    out = _copy(pristine, tmp_path)
    other = tmp_path / "o.parquet"
    run_campaign(other, 2, RES, seed=5, chunk_size=CHUNK, progress=False)
    src = next(other.with_name(other.name + ".parts").glob("part-*.parquet"))
    dst = out.with_name(out.name + ".parts") / "part-zz-from-elsewhere.parquet"
    shutil.copy(src, dst)
    with pytest.raises(UserError, match="part-zz-from-elsewhere.parquet: made with other"):
        campaign(out)


def test_lost_local_worker_is_replaced_without_duplicates(tmp_path, pristine):
    """kill -9 of one worker: the pool breaks, a new one runs what had not come back."""
    import threading

    me = os.getpid()
    killed = []

    def kill_one():
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not killed:
            for pid in pids_where(
                lambda stat, cmd: (
                    int(stat.rsplit(")", 1)[1].split()[1]) == me and b"spawn_main" in cmd
                )
            ):
                time.sleep(0.5)  # let it start a unit
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
                return
            time.sleep(0.02)

    t = threading.Thread(target=kill_one)
    t.start()
    out = tmp_path / "w.parquet"
    table = run_campaign(out, RUNS, RES, chunk_size=1, workers=2, progress=False)
    t.join()
    assert killed
    assert same_rows(table, pristine[0])
