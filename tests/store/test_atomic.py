"""Atomic file writing: complete new content or the old file, never a partial file."""

from __future__ import annotations

import errno
import os
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from bayescal import atomic as io


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(io.TEMP_SUFFIX))


def test_bytes_text_json_round_trip(tmp_path: Path) -> None:
    io.atomic_write_bytes(tmp_path / "a.bin", b"\x00\x01binary")
    io.atomic_write_text(tmp_path / "sub" / "b.txt", "température\n")
    io.atomic_write_json(tmp_path / "c.json", {"x": [1, 2.5], "name": "°C"})
    assert (tmp_path / "a.bin").read_bytes() == b"\x00\x01binary"
    assert (tmp_path / "sub" / "b.txt").read_text(encoding="utf-8") == "température\n"
    assert io.read_json(tmp_path / "c.json") == {"x": [1, 2.5], "name": "°C"}
    assert _leftovers(tmp_path) == []


def test_npz_round_trip_is_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    arrays = {"x": rng.normal(size=(3, 4)), "names": np.array(["a", "bb"]), "k": np.int64(3)}
    for compress in (False, True):
        path = io.atomic_write_npz(tmp_path / f"r{compress}.npz", arrays, compress=compress)
        back = io.read_npz(path)
        assert path.name == f"r{compress}.npz"  # numpy would append .npz to a str name
        np.testing.assert_array_equal(back["x"], arrays["x"])  # bit-for-bit
        assert back["names"].tolist() == ["a", "bb"]
        assert int(back["k"]) == 3


def test_rewrite_replaces_content(tmp_path: Path) -> None:
    target = tmp_path / "f.txt"
    io.atomic_write_text(target, "old")
    io.atomic_write_text(target, "new")
    assert target.read_text() == "new"
    assert _leftovers(tmp_path) == []


def test_error_while_writing_leaves_old_file_and_no_temp(tmp_path: Path) -> None:
    target = tmp_path / "f.json"
    io.atomic_write_text(target, "old")

    def half_then_fail(stream) -> None:
        stream.write(b'{"partial": ')
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        io.atomic_write(target, half_then_fail)
    assert target.read_text() == "old"
    assert _leftovers(tmp_path) == []
    with pytest.raises(ValueError, match="Out of range float"):
        io.atomic_write_json(tmp_path / "nan.json", {"x": float("nan")})
    assert not (tmp_path / "nan.json").exists()


def test_an_error_names_the_final_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A write on a full disk names no file, mkstemp names the hidden temporary one: the
    error names the artefact, so that its one-line message does."""
    target = tmp_path / "emulator.nc"
    io.atomic_write_text(target, "old")

    def full(stream) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    with pytest.raises(OSError, match="No space left") as info:
        io.atomic_write(target, full)
    assert info.value.errno == errno.ENOSPC
    assert info.value.filename == str(target)
    assert target.read_text() == "old"
    assert _leftovers(tmp_path) == []

    def refuse(*args: object, **kwargs: object) -> tuple[int, str]:
        raise PermissionError(errno.EACCES, "Permission denied", str(tmp_path / ".x.tmp"))

    monkeypatch.setattr(io.tempfile, "mkstemp", refuse)
    with pytest.raises(PermissionError) as denied:
        io.atomic_write_text(target, "new")
    assert denied.value.filename == str(target)


def test_fsyncs_file_and_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    synced: list[int] = []
    real_fsync = os.fsync

    def spy(fd: int) -> None:
        synced.append(fd)
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", spy)
    io.atomic_write_bytes(tmp_path / "x", b"data")
    expected = 1 if os.name == "nt" else 2  # the file, then its folder (not on Windows)
    assert len(synced) == expected


def test_process_killed_before_rename_leaves_no_partial_file(tmp_path: Path) -> None:
    # A real crash: the writing process dies (os._exit) after the data are in the
    # temporary file but before the rename. The final name must keep its old content.
    target = tmp_path / "run.npz"
    io.atomic_write_text(target, "old")
    script = textwrap.dedent(
        f"""
        import os
        import numpy as np
        from bayescal import atomic as io
        os.replace = lambda *args: os._exit(9)
        io.atomic_write_npz({str(target)!r}, {{"x": np.arange(10_000.0)}})
        """
    )
    done = subprocess.run([sys.executable, "-c", script], check=False, timeout=60)
    assert done.returncode == 9
    assert target.read_text() == "old"
    leftovers = _leftovers(tmp_path)
    assert len(leftovers) == 1  # the orphaned temporary file, hidden and marked .tmp
    assert leftovers[0].startswith(".run.npz.")


def test_atomic_files_get_the_usual_permissions(tmp_path: Path) -> None:
    # A report folder is often shared or served: files must not stay 0600 (mkstemp's mode).
    old = os.umask(0o022)
    try:
        path = io.atomic_write_text(tmp_path / "report.html", "<html></html>")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644


def test_files_written_by_name_get_the_usual_permissions(tmp_path: Path) -> None:
    # netCDF libraries open (or recreate) the file by name; the mode must not stay 0600.
    def recreate(temp: Path) -> None:
        temp.unlink()
        temp.write_bytes(b"CDF")
        os.chmod(temp, 0o600)

    old = os.umask(0o022)
    try:
        path = io.atomic_write_path(tmp_path / "posterior.nc", recreate)
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    assert path.read_bytes() == b"CDF"
    assert _leftovers(tmp_path) == []


def test_failed_write_by_name_leaves_no_temp(tmp_path: Path) -> None:
    def fail(temp: Path) -> None:
        temp.write_bytes(b"half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        io.atomic_write_path(tmp_path / "emulator.nc", fail)
    assert list(tmp_path.iterdir()) == []
