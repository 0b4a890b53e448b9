"""The output folder itself: who may write it (a lock) and what to do when it cannot be written.

:class:`OutputLock` is held by ``bayescal run``, ``bayescal screen`` and
``bayescal report`` for as long as they write a study's output folder. It is an advisory lock
(``fcntl.flock``) on ``bayescal.lock`` in the folder, which also records who
holds it (process, host, command, start time). A second run of the same study
finds the lock held and stops with a :class:`~bayescal.errors.OutputError`
naming the holder (exit status 2 on the command line). The operating system
drops the lock when its process ends, however it ends, so the lock of a killed
run is *stale*: the file is still there, nobody holds it, and the next run takes
it over and says so.

:func:`output_error` turns an :class:`OSError` of the output side (permission
denied, read-only file system, disk full, quota, a path too long, a file where
the folder should be) into one line naming the path and what to do; the files
already written stay as they are (every file is written atomically).
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import socket
import sys
import time
from pathlib import Path
from typing import IO, Any, Final

from bayescal.errors import OutputError

__all__ = ["LOCK_FILE", "OutputLock", "is_output_error", "output_error"]

LOCK_FILE: Final = "bayescal.lock"

try:  # POSIX
    import fcntl
except ImportError:  # pragma: no cover - Windows: no lock, a run is not refused
    fcntl = None  # type: ignore[assignment]


def _within(path: str | os.PathLike[str] | None, folder: Path) -> bool:
    if path is None:
        return False
    try:
        return Path(os.path.abspath(path)).is_relative_to(os.path.abspath(folder))
    except (TypeError, ValueError):
        return False


_FULL = (errno.ENOSPC, errno.EDQUOT)


def is_output_error(exc: OSError, folder: Path) -> bool:
    """Whether ``exc`` comes from writing ``folder`` (its path is there, or the disk is
    full or read-only, which says nothing of a path)."""
    named = _within(exc.filename, folder) or _within(exc.filename2, folder)
    return named or (exc.filename is None and exc.errno in (*_FULL, errno.EROFS))


def output_error(exc: OSError, folder: Path, *, still_needed: float | None = None) -> OutputError:
    """One line for an OSError of the output side: the path, what happened, what to do.

    Parameters
    ----------
    exc
        The error; its ``filename`` names the path (the folder if it does not).
    folder
        The output folder.
    still_needed
        Bytes the study is estimated to write still (for a full disk: what to free). [B]
    """
    path = Path(exc.filename) if exc.filename is not None else folder
    code = exc.errno
    kept = "the stages and runs completed so far are kept; run again to resume"
    if code in (errno.EEXIST, errno.ENOTDIR) or (path == folder and os.path.isfile(folder)):
        files = [p for p in (folder, *folder.parents) if os.path.isfile(p)]
        where = files[0] if files else path
        return OutputError(
            f"{where} exists and is not a folder",
            hint="set study.output_dir to a folder, or move the file away",
        )
    if code in (errno.EACCES, errno.EPERM):
        return OutputError(
            f"cannot write {path}: permission denied",
            hint=f"make {folder} writable, or set study.output_dir to a folder you can write; "
            + kept,
        )
    if code == errno.EROFS:
        return OutputError(
            f"cannot write {path}: the file system is read-only",
            hint=f"set study.output_dir to a folder on a writable disk; {kept}",
        )
    if code in _FULL:
        what = "the disk quota is exhausted" if code == errno.EDQUOT else "the disk is full"
        need = ""
        if still_needed is not None and still_needed > 0:
            need = f" at least {_size(still_needed)}"
        return OutputError(
            f"cannot write {path}: {what}",
            hint=f"free{need} on the disk of {folder} (old output folders, simulations/ of "
            f"studies you no longer need) or set study.output_dir to another disk; {kept}",
        )
    if code == errno.ENAMETOOLONG:
        return OutputError(
            f"cannot write {path}: the path is too long for the file system",
            hint="set study.output_dir to a shorter path",
        )
    return OutputError(
        f"cannot write {path}: {exc.strerror or exc}", hint=f"check {folder}; {kept}"
    )


def _size(size: float) -> str:
    for unit, scale in (("TiB", 2.0**40), ("GiB", 2.0**30), ("MiB", 2.0**20), ("KiB", 2.0**10)):
        if size >= scale:
            return f"{size / scale:.3g} {unit}"
    return f"{size:.0f} B"


class OutputLock:
    """The lock of an output folder, held while a command writes it.

    Use as a context manager::

        with OutputLock(out, command="run") as lock:
            ...  # lock.took_over says whether a stale lock was taken over

    Raises
    ------
    OutputError
        On entry, if another process holds the lock (naming it), or if the
        folder cannot be written.
    """

    def __init__(self, folder: Path, *, command: str = "run") -> None:
        self.folder = Path(folder)
        self.path = self.folder / LOCK_FILE
        self.command = command
        self.took_over: dict[str, Any] | None = None
        self._stream: IO[str] | None = None

    def __enter__(self) -> OutputLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def acquire(self) -> None:
        """Take the lock, or raise naming who holds it."""
        if fcntl is None:  # pragma: no cover - no advisory locks here
            return
        self.folder.mkdir(parents=True, exist_ok=True)
        for _ in range(5):  # the holder may remove the file between open and lock
            stream = open(self.path, "a+", encoding="utf-8")  # noqa: SIM115 - held open
            try:
                fcntl.flock(stream.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _read(stream)
                stream.close()
                raise OutputError(
                    f"{self.folder} is in use by another bayescal {holder.get('command', 'run')}"
                    f" ({_describe(holder)})",
                    hint="wait for it to finish, or stop it; two runs of one study at once "
                    "would overwrite each other's files",
                ) from None
            if not _same_file(stream, self.path):
                stream.close()
                continue
            previous = _read(stream)
            if previous:
                self.took_over = previous
            stream.seek(0)
            stream.truncate()
            stream.write(json.dumps(_me(self.command)) + "\n")
            stream.flush()
            self._stream = stream
            return
        raise OutputError(
            f"cannot take the lock {self.path}: it keeps changing"
        )  # pragma: no cover

    def release(self) -> None:
        """Remove the lock file and let go of the lock."""
        stream, self._stream = self._stream, None
        if stream is None:
            return
        with contextlib.suppress(OSError):
            if _same_file(stream, self.path):
                self.path.unlink()
        stream.close()  # closing drops the flock

    def describe_taken_over(self) -> str:
        """``"took over the lock of process 123 on host (bayescal run, started ...),
        which is no longer running"``, or ``""``."""
        if not self.took_over:
            return ""
        return (
            f"took over the stale lock of {_describe(self.took_over)}, which is no longer "
            "running (killed?); its completed work is reused"
        )


def _me(command: str) -> dict[str, Any]:
    return {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "command": command,
        "argv": " ".join(sys.argv[:4]),
        "started": time.strftime("%Y-%m-%d %H:%M:%S"),
    }


def _read(stream: IO[str]) -> dict[str, Any]:
    try:
        stream.seek(0)
        found = json.loads(stream.read() or "{}")
    except (OSError, ValueError):
        return {}
    return found if isinstance(found, dict) else {}


def _describe(holder: dict[str, Any]) -> str:
    if not holder:
        return "a process that did not say who it is"
    parts = [f"process {holder.get('pid', '?')}"]
    if holder.get("host") and holder.get("host") != socket.gethostname():
        parts.append(f"on {holder['host']}")
    if holder.get("started"):
        parts.append(f"started {holder['started']}")
    return " ".join(parts)


def _same_file(stream: IO[str], path: Path) -> bool:
    try:
        mine, there = os.fstat(stream.fileno()), os.stat(path)
    except OSError:
        return False
    return (mine.st_dev, mine.st_ino) == (there.st_dev, there.st_ino)
