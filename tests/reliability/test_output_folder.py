"""The output folder: two runs at once, a folder that cannot be written, a disk that fills.

Each failure ends in one line on stderr and exit status 2; what was completed
stays usable and a new run resumes from it.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.config import load_study
from bayescal.errors import OutputError
from bayescal.examples import copy_example
from bayescal.pipeline import Options, load_results, run
from bayescal.runner.cache import load_run
from bayescal.store.folder import LOCK_FILE, OutputLock, output_error
from bayescal.store.stages import StageLog
from faults import DiskFills

SERIAL = Options(backend="serial", chains_backend="serial")
#: Short chains: the tests look at files and stages, not at the posterior's quality.
FAST = """
[emulator]
pca_variance = 0.999
burn = 100
samples = 100

[calibration]
chains = 4
burn = 100
samples = 200
max_samples = 200

[predict]
method = "emulator"
draws = 40
"""


def _study(tmp_path: Path, name: str = "wall") -> Path:
    folder = copy_example("wall", tmp_path / name)
    text = (folder / "study.toml").read_text(encoding="utf-8")
    text = text[: text.index("[emulator]")] + FAST
    (folder / "study.toml").write_text(text, encoding="utf-8")
    return folder


def _cli(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, list(args))
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return result.exit_code, result.stdout, result.stderr


def _one_line(err: str) -> str:
    assert err.startswith("error: ")
    assert err.count("\n") == 1, err
    assert "Traceback" not in err
    return err


# --------------------------------------------------------------------------- the lock

_HOLDER = """
import sys, time
from pathlib import Path
from bayescal.store.folder import OutputLock
lock = OutputLock(Path(sys.argv[1]), command=sys.argv[2])
lock.acquire()
print("locked", flush=True)
time.sleep(600)
"""


def _hold(out: Path, command: str = "run") -> subprocess.Popen[str]:
    """Another process that holds the output folder's lock (as ``command``) until killed."""
    out.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    proc = subprocess.Popen(
        [sys.executable, "-c", _HOLDER, str(out), command],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_a_second_run_says_who_holds_the_folder_and_a_stale_lock_is_taken_over(
    tmp_path: Path,
) -> None:
    folder = _study(tmp_path)
    out = folder / "out"
    holder = _hold(out)
    try:
        code, out_text, err = _cli("run", str(folder), "--until", "design")
        assert code == 2
        assert out_text == ""
        line = _one_line(err)
        assert f"{out} is in use by another bayescal run (process {holder.pid} started" in line
        assert "wait for it to finish" in line
        assert not (out / "design.csv").exists()
    finally:
        holder.send_signal(signal.SIGKILL)  # killed: its lock file stays behind, unheld
        holder.wait()
        assert holder.stdout is not None
        holder.stdout.close()
    assert (out / LOCK_FILE).is_file()
    code, out_text, err = _cli("run", str(folder), "--until", "design")
    assert code == 0, err
    assert f"took over the stale lock of process {holder.pid}" in out_text
    assert (out / "design.csv").is_file()
    assert not (out / LOCK_FILE).exists()  # a run that ends lets go of its lock


def _kill(proc: subprocess.Popen[str]) -> None:
    proc.send_signal(signal.SIGKILL)  # killed: its lock file stays behind, unheld
    proc.wait()
    assert proc.stdout is not None
    proc.stdout.close()


def test_screen_and_run_exclude_each_other(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``bayescal screen`` takes the lock ``run`` takes: a screen is refused while a run
    holds the folder, a run while a screen does, each naming the other; nothing of the
    refused command is written."""
    from bayescal.pipeline import screen as screening

    folder = _study(tmp_path)
    out = folder / "out"
    holder = _hold(out, "run")
    try:
        code, out_text, err = _cli("screen", str(folder))
        assert code == 2
        assert out_text == ""
        line = _one_line(err)
        assert f"{out} is in use by another bayescal run (process {holder.pid} started" in line
        assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE]  # no simulations/
    finally:
        _kill(holder)
    refused: list[str] = []
    real_run_design = screening.run_design

    def run_meanwhile(*args: object, **kwargs: object) -> object:
        """A ``run`` of the same study while the screen simulates."""
        with pytest.raises(OutputError) as info:
            run(load_study(folder), until="design", options=SERIAL)
        refused.append(info.value.one_line())
        return real_run_design(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(screening, "run_design", run_meanwhile)
    code, out_text, err = _cli("screen", str(folder))
    assert code == 0, err
    assert f"took over the stale lock of process {holder.pid}" in out_text  # the killed run's
    assert len(refused) == 1  # the run was tried once, and refused naming this screen
    assert f"{out} is in use by another bayescal screen (process {os.getpid()} " in refused[0]
    assert not (out / "design.csv").exists()
    assert (out / "screening" / "morris.csv").is_file()
    assert not (out / LOCK_FILE).exists()  # the screen let go of it


def test_the_lock_is_exclusive_within_one_process_too(tmp_path: Path) -> None:
    with OutputLock(tmp_path, command="report") as first:
        assert first.took_over is None
        with pytest.raises(OutputError, match=r"in use by another bayescal report \(process"):
            OutputLock(tmp_path).acquire()
        study = load_study(_study(tmp_path / "s"))
        other = OutputLock(study.root / "out")
        other.acquire()  # another folder is free
        other.release()
    with OutputLock(tmp_path) as again:  # released on exit, and removed: not stale
        assert again.took_over is None


# --------------------------------------------------------------------------- unwritable


def test_output_errors_name_the_path_and_the_remedy(tmp_path: Path) -> None:
    out = tmp_path / "out"
    cases = {
        errno.EACCES: "permission denied; make",
        errno.EROFS: "the file system is read-only",
        errno.ENOSPC: "the disk is full; free at least 1 MiB on the disk of",
        errno.EDQUOT: "the disk quota is exhausted",
        errno.ENAMETOOLONG: "the path is too long",
        errno.EIO: "cannot write",
    }
    for code, text in cases.items():
        exc = OSError(code, os.strerror(code), str(out / "emulator.nc"))
        message = output_error(exc, out, still_needed=2**20).one_line()
        assert text in message, (code, message)
        assert str(out / "emulator.nc") in message
        assert "\n" not in message


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root writes read-only folders")
def test_a_read_only_output_folder_for_real(tmp_path: Path) -> None:
    folder = _study(tmp_path)
    out = folder / "out"
    out.mkdir()
    out.chmod(0o555)
    try:
        code, _, err = _cli("run", str(folder), "--until", "design")
    finally:
        out.chmod(0o755)
    assert code == 2
    assert "permission denied" in _one_line(err)


def test_a_log_file_that_fails_mid_run_stops_quietly(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """logging prints a traceback for every record it cannot write; ours stops instead."""
    from bayescal.pipeline.run import file_logger

    class FullDisk:
        def write(self, text: str) -> int:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def flush(self) -> None:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    logger = file_logger(tmp_path)
    handler = logger.handlers[0]
    real = handler.stream  # type: ignore[attr-defined]
    handler.stream = FullDisk()  # type: ignore[attr-defined]  # every write now fails
    try:
        logger.info("first")
        logger.info("second")
        assert "Traceback" not in capsys.readouterr().err
        assert file_logger(tmp_path).handlers[0] is not handler  # a new run opens it afresh
    finally:
        real.close()
        file_logger(tmp_path).handlers[0].close()


# --------------------------------------------------------------------------- a full disk


def test_a_disk_full_midway_through_the_simulations_resumes(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = _study(tmp_path)
    disk = DiskFills(monkeypatch, after=12)  # design.csv, stages.json and 10 runs fit
    code, _, err = _cli("run", str(folder), "--until", "simulate", "--backend", "serial", "-q")
    assert code == 2
    line = _one_line(err)
    assert "the disk is full; free at least" in line
    assert "run again to resume" in line
    runs = sorted((folder / "out" / "simulations" / "runs").glob("*.npz"))
    assert len(runs) == 10
    assert not list((folder / "out").rglob("*.tmp"))  # no half-written file anywhere
    assert StageLog.open(folder / "out").finished("design")
    assert not (folder / "out" / LOCK_FILE).exists()
    disk.clear()
    written = disk.written
    res = run(load_study(folder), until="simulate", options=SERIAL)
    assert res.reused == ("design",)
    assert res.simulations is not None
    assert res.simulations.n_cached == 10  # the ten runs on disk are reused, not redone
    assert res.simulations.n_run == 20
    assert disk.written - written == 20 + 3  # 20 runs, the two stacked files, stages.json


def test_a_disk_full_at_the_emulator_keeps_the_stages_before_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = _study(tmp_path, "full")
    clean = _study(tmp_path, "clean")
    disk = DiskFills(monkeypatch, at="emulator.nc")
    code, _, err = _cli("run", str(folder), "--until", "calibrate", "--backend", "serial", "-q")
    assert code == 2
    assert "emulator.nc: the disk is full" in _one_line(err)
    shown = load_results(load_study(folder))  # what was completed can be shown
    assert shown.simulations is not None
    assert shown.missing()[0] == "emulator"
    disk.clear()
    resumed = run(load_study(folder), until="calibrate", options=SERIAL)
    assert resumed.reused == ("design", "simulate")
    reference = run(load_study(clean), until="calibrate", options=SERIAL)
    assert resumed.posterior is not None
    assert reference.posterior is not None
    np.testing.assert_array_equal(resumed.posterior.draws, reference.posterior.draws)
    record = json.loads((folder / "out" / "stages.json").read_text())
    assert list(record) == ["design", "simulate", "emulator", "calibrate"]


def _mount_tmpfs(path: Path, size: str) -> bool:
    path.mkdir()
    if os.name != "posix" or os.geteuid() != 0:
        return False
    done = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
        capture_output=True,
        check=False,
    )
    return done.returncode == 0


def test_a_real_small_file_system_fills_and_the_run_resumes_elsewhere(tmp_path: Path) -> None:
    """The same on a 600 kB tmpfs (where the machine lets us mount one)."""
    small = tmp_path / "small"
    if not _mount_tmpfs(small, "600k"):
        pytest.skip("cannot mount a tmpfs here (needs root and mount rights)")
    try:
        folder = _study(tmp_path)
        path = folder / "study.toml"
        text = path.read_text().replace('output_dir = "out"', f'output_dir = "{small}"')
        # the estimate (about 26 MiB) would refuse the 600 kB disk before the run starts
        path.write_text(text + '\n[runner]\nmax_disk = "1GiB"\n')
        code, _, err = _cli("run", str(folder), "--until", "simulate", "--backend", "serial", "-q")
        assert code == 2
        assert "the disk is full; free at least" in _one_line(err)
        assert not list(small.rglob("*.tmp"))
        cached = list((small / "simulations" / "runs").glob("*.npz"))
        assert cached  # some runs fitted and are whole
        for file in cached:  # the wall example's record: 1644 samples
            assert load_run(file, ("heat_flux_in",), 1644) is not None
    finally:
        _unmount(small)


def _unmount(path: Path) -> None:
    """Unmount ``path``; the in-process run's log file there is closed first.

    ``file_logger`` keeps the ``bayescal.run`` handler open between runs in a
    process, so ``bayescal.log`` on the tmpfs would keep it busy and a plain
    ``umount`` fail; a mount left behind breaks pytest's removal of old
    ``tmp_path`` folders in a later session (EBUSY, an error under
    ``filterwarnings = error``). A lazy unmount is the last resort.
    """
    logger = logging.getLogger("bayescal.run")
    for handler in list(logger.handlers):
        if str(getattr(handler, "baseFilename", "")).startswith(str(path.resolve())):
            logger.removeHandler(handler)
            handler.close()
    if subprocess.run(["umount", str(path)], check=False).returncode != 0:
        subprocess.run(["umount", "-l", str(path)], check=False)
