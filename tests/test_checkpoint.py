"""Checkpoints (:mod:`airspace_sim.world.checkpoint`): authenticated before anything is
unpickled, atomic on a full or read-only disk, saved on SIGTERM like on Ctrl-C."""

from __future__ import annotations

import errno
import json
import os
import pickle
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from test_cli_run import REPO, assert_one_line_error, cli, main_in_process

from airspace_sim.world import checkpoint


def _good(tmp_path, capsys) -> bytes:
    path = tmp_path / "good.ckpt"
    proc = main_in_process(
        capsys, "run", "head_on", "--steps", "2", "--checkpoint", str(path), "--quiet"
    )
    assert proc.returncode == 0, proc.stderr
    return path.read_bytes()


def _split(data: bytes):
    magic, fmt, mac, header, payload = data.split(b"\n", 4)
    return magic + b"\n", fmt + b"\n", mac, json.loads(header), payload


def _signed(data: bytes, *, payload=None, header_change=None, key=None) -> bytes:
    """``data`` with another payload and/or header, signed with ``key`` (default: the
    session's key): what only someone holding that key can make."""
    magic, fmt, _, header, old = _split(data)
    payload = old if payload is None else payload
    header["world_bytes"] = len(payload)
    header.update(header_change or {})
    line = json.dumps(header).encode() + b"\n"
    mac = checkpoint._mac(key or checkpoint.load_key(create=False), line, payload)
    return magic + fmt + f"mac {mac}\n".encode() + line + payload


class _TouchOnUnpickle:
    """Unpickling this creates a file: proof that a refused file was never unpickled."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (Path.touch, (Path(self.marker),))


def test_foreign_damaged_or_tampered_files_are_refused_before_unpickling(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    good = _good(tmp_path, capsys)
    marker = tmp_path / "unpickled"
    evil = pickle.dumps(_TouchOnUnpickle(marker))
    magic, fmt, mac, header, payload = _split(good)
    flipped = bytearray(good)
    flipped[-20] ^= 0xFF
    refused = "refused: not signed with this user's checkpoint key"
    cases = {
        "random.bin": (np.random.default_rng(0).bytes(4096), "not an airspace-sim checkpoint"),
        "empty.ckpt": (b"", "not an airspace-sim checkpoint"),
        "a-pickle.pkl": (evil, "not an airspace-sim checkpoint"),
        "format2.ckpt": (
            good.replace(b"format 4\n", b"format 2\n", 1),
            "checkpoint format 2, this airspace-sim reads format 4 (written by an older",
        ),
        "format9.ckpt": (
            good.replace(b"format 4\n", b"format 9\n", 1),
            "checkpoint format 9, this airspace-sim reads format 4 (written by a newer",
        ),
        "no-mac.ckpt": (magic + fmt + b"{}\n", "damaged checkpoint header (no mac line)"),
        "truncated.ckpt": (good[: len(good) // 2], "truncated or damaged checkpoint"),
        "longer.ckpt": (good + b"x", "truncated or damaged checkpoint"),
        "header-cut.ckpt": (magic + fmt + mac + b'\n{"meta": ', "damaged checkpoint header"),
        "no-format.ckpt": (magic, "damaged checkpoint header (no format line)"),
        "flipped.ckpt": (bytes(flipped), refused),
        # a pickle that runs code, with a header that fits: only the MAC stops it
        "evil-unsigned.ckpt": (
            magic
            + fmt
            + mac
            + b"\n"
            + json.dumps({**header, "world_bytes": len(evil)}).encode()
            + b"\n"
            + evil,
            refused,
        ),
        "evil-other-key.ckpt": (_signed(good, payload=evil, key=b"k" * 32), refused),
        "meta-edited.ckpt": (
            magic
            + fmt
            + mac
            + b"\n"
            + json.dumps({**header, "meta": {**header["meta"], "seed": 7}}).encode()
            + b"\n"
            + payload,
            refused,
        ),
        "other-object.ckpt": (
            _signed(good, payload=pickle.dumps({"step_count": 3})),
            "holds a dict, not a World",
        ),
    }
    for name, (data, why) in cases.items():
        (tmp_path / name).write_bytes(data)
        proc = main_in_process(capsys, "run", "--resume", name)
        assert_one_line_error(proc, f"--resume {name}: ", why)
        assert not marker.exists(), name  # refused before unpickling anything
    # control: the same evil payload signed with the user's own key is trusted and unpickled
    # (so it is the MAC, not the header checks, that refused it above)
    (tmp_path / "evil-signed.ckpt").write_bytes(_signed(good, payload=evil))
    proc = main_in_process(capsys, "run", "--resume", "evil-signed.ckpt")
    assert_one_line_error(proc, "holds a NoneType, not a World")
    assert marker.exists()
    assert_one_line_error(
        main_in_process(capsys, "run", "--resume", "nope.pkl"), "nope.pkl", "no such file"
    )
    assert_one_line_error(
        main_in_process(capsys, "run", "--resume", str(tmp_path)), str(tmp_path), "is a folder"
    )
    # through a subprocess: exit status 2, one line, no traceback
    assert_one_line_error(
        cli("run", "--resume", "evil-other-key.ckpt", cwd=tmp_path),
        "--resume evil-other-key.ckpt: " + refused,
    )


def test_key_file_is_private_and_a_readable_one_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv(checkpoint.KEY_ENV, str(tmp_path / "keys" / "k.key"))
    monkeypatch.chdir(tmp_path)
    good = _good(tmp_path, capsys)
    key_file = tmp_path / "keys" / "k.key"
    assert stat.S_IMODE(key_file.stat().st_mode) == 0o600
    assert len(bytes.fromhex(key_file.read_text().strip())) == 32
    key_file.chmod(0o644)
    (tmp_path / "c.ckpt").write_bytes(good)
    proc = main_in_process(capsys, "run", "--resume", "c.ckpt")
    assert_one_line_error(proc, "checkpoint key", "readable by other users", "chmod 600")
    # no key at all (another machine): refused, nothing created by --resume
    monkeypatch.setenv(checkpoint.KEY_ENV, str(tmp_path / "none" / "k.key"))
    proc = main_in_process(capsys, "run", "--resume", "c.ckpt")
    assert_one_line_error(proc, "--resume c.ckpt: refused")
    assert not (tmp_path / "none").exists()


def test_key_defaults_to_xdg_data_home(tmp_path, monkeypatch):
    monkeypatch.delenv(checkpoint.KEY_ENV)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))
    assert checkpoint.key_path() == tmp_path / "airspace_sim" / "checkpoint.key"
    monkeypatch.delenv("XDG_DATA_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert checkpoint.key_path() == tmp_path / "home/.local/share/airspace_sim/checkpoint.key"


def test_resume_under_other_code_warns_once(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    good = _good(tmp_path, capsys)
    (tmp_path / "other.ckpt").write_bytes(_signed(good, header_change={"code": "0" * 16}))
    (tmp_path / "same.ckpt").write_bytes(good)
    proc = main_in_process(capsys, "run", "--resume", "other.ckpt", "--steps", "1", "--quiet")
    assert proc.returncode == 0
    assert proc.stderr.count("warning") == 1 and "other.ckpt was saved by other" in proc.stderr
    proc = main_in_process(capsys, "run", "--resume", "same.ckpt", "--steps", "1", "--quiet")
    assert proc.returncode == 0 and proc.stderr == ""


# --------------------------------------------------------------------------- full / read-only


def _fail_with(code):
    def fail(*args, **kwargs):
        raise OSError(code, os.strerror(code))

    return fail


@pytest.mark.parametrize(
    "code,why", [(errno.ENOSPC, "disk full"), (errno.EROFS, "read-only file system")]
)
def test_a_failed_checkpoint_write_keeps_the_previous_one(tmp_path, monkeypatch, capsys, code, why):
    monkeypatch.chdir(tmp_path)
    good = _good(tmp_path, capsys)  # good.ckpt at step 2
    # the disk fills (or turns read-only) while the new checkpoint is flushed (after the
    # option's probe write passed)
    real_fsync = os.fsync

    def fsync(fd):
        if os.readlink(f"/proc/self/fd/{fd}").endswith(".ckpt.tmp"):
            _fail_with(code)()
        real_fsync(fd)

    if not Path("/proc/self/fd").is_dir():
        pytest.skip("needs /proc/self/fd")
    monkeypatch.setattr(os, "fsync", fsync)
    proc = main_in_process(
        capsys, "run", "--resume", "good.ckpt", "--steps", "3", "--checkpoint", "good.ckpt"
    )
    assert_one_line_error(proc, "--checkpoint good.ckpt: cannot write the checkpoint", why)
    assert (tmp_path / "good.ckpt").read_bytes() == good  # the previous one, intact
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good.ckpt"]  # no .tmp debris


@pytest.mark.parametrize("option", ["--render", "--checkpoint", "--json"])
def test_an_unwritable_output_is_one_line_before_any_work(tmp_path, monkeypatch, capsys, option):
    import tempfile

    from airspace_sim.world import World

    monkeypatch.chdir(tmp_path)
    # the probe write into the output's folder fails as on a read-only file system (the
    # tests may run as root, for whom chmod does not make a folder read-only)
    monkeypatch.setattr(tempfile, "TemporaryFile", _fail_with(errno.EROFS))
    built = []
    monkeypatch.setattr(World, "step", lambda self, *a: built.append(1))
    proc = main_in_process(capsys, "run", "head_on", option, "out/x")
    assert_one_line_error(proc, f"{option} out/x: cannot write into", "read-only file system")
    assert not built


def test_a_full_disk_while_rendering_saves_the_checkpoint(tmp_path, monkeypatch, capsys):
    from airspace_sim.rendering import FrameWriter

    monkeypatch.chdir(tmp_path)
    real_add = FrameWriter.add

    def add(self, frame):
        if len(self.paths) == 3:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_add(self, frame)

    monkeypatch.setattr(FrameWriter, "add", add)
    proc = main_in_process(
        capsys, "run", "head_on", "--steps", "10", "--render", "f", "--checkpoint", "c.ckpt"
    )
    err = assert_one_line_error(proc, "--render f: cannot write a frame", "No space left")
    assert "checkpoint (step 3) in c.ckpt" in err  # step 3 ran; its frame failed
    world, meta = checkpoint.load(Path("c.ckpt"))
    assert world.step_count == 3 and meta["total_steps"] == 10
    monkeypatch.setattr(FrameWriter, "add", real_add)
    proc = main_in_process(capsys, "run", "--resume", "c.ckpt", "--checkpoint", "c.ckpt", "--quiet")
    assert proc.returncode == 0, proc.stderr
    assert checkpoint.load(Path("c.ckpt"))[0].step_count == 10


def test_a_real_full_device_is_one_line_and_keeps_the_checkpoint(tmp_path, monkeypatch, capsys):
    if not os.access("/dev/full", os.W_OK):
        pytest.skip("no writable /dev/full")
    monkeypatch.chdir(tmp_path)
    proc = main_in_process(
        capsys, "run", "head_on", "--steps", "3", "--json", "/dev/full", "--checkpoint", "c.ckpt"
    )
    assert_one_line_error(proc, "cannot write /dev/full", "[Errno 28]")
    assert checkpoint.load(Path("c.ckpt"))[0].step_count == 3


def test_a_format_3_checkpoint_from_before_world_retired_is_refused_in_one_line(
    tmp_path, monkeypatch, capsys
):
    """Format 3 worlds have no ``World.retired``: they would resume (with only a code
    warning) and fail on recorded traffic. A format-3 file as that code wrote it, signed
    with this user's key so that only its version can stop it, is refused before unpickling."""
    monkeypatch.chdir(tmp_path)
    good = _good(tmp_path, capsys)
    _, _, _, header, _ = _split(good)
    marker = tmp_path / "unpickled"
    payload = pickle.dumps(_TouchOnUnpickle(marker))  # what a version-3 reader would unpickle
    line = json.dumps({**header, "world_bytes": len(payload)}).encode() + b"\n"
    mac = checkpoint._mac(checkpoint.load_key(create=False), line, payload)
    old = tmp_path / "v3.ckpt"
    old.write_bytes(checkpoint.MAGIC + b"format 3\n" + f"mac {mac}\n".encode() + line + payload)
    proc = main_in_process(capsys, "run", "--resume", str(old), "--quiet")
    assert_one_line_error(
        proc,
        f"--resume {old}: checkpoint format 3, this airspace-sim reads format 4",
        "written by an older airspace-sim: rerun the scenario",
    )
    assert not marker.exists()
    assert checkpoint.FORMAT == 4


# --------------------------------------------------------------------------- SIGTERM


def test_sigterm_saves_the_checkpoint_like_ctrl_c(tmp_path):
    env = {**os.environ, "AIRSPACE_SIM_PLUGINS": ""}
    ckpt = tmp_path / "t.ckpt"
    proc = subprocess.Popen(
        [sys.executable, "-m", "airspace_sim", "run", "dense_random", "--steps", "100000"]
        + ["--checkpoint", str(ckpt), "--checkpoint-every", "3", "--quiet"],
        cwd=REPO,
        env=env,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 300
        while not ckpt.exists():  # stepping: the first periodic checkpoint is there
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr
            time.sleep(0.05)
        first = checkpoint.load(ckpt)[0].step_count
        time.sleep(0.3)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 143, err
    assert err.strip() == "airspace-sim run: terminated"
    world, meta = checkpoint.load(ckpt)
    assert world.step_count >= first and meta["total_steps"] == 100000
    assert not (tmp_path / "t.ckpt.tmp").exists()
    # and it resumes
    proc = cli("run", "--resume", str(ckpt), "--steps", "2", "--quiet")
    assert proc.returncode == 0, proc.stderr
