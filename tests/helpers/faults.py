"""Faults of the output side, injected: a folder that cannot be written, a disk that fills.

Tests run as root in some places, where a read-only folder (``chmod``) does not
stop a write; these helpers make the writes themselves fail with the errno a
real fault gives, so every test runs everywhere.
"""

from __future__ import annotations

import builtins
import errno as errnos
import io
import logging
import os
from pathlib import Path
from typing import Any

import pytest

import bayescal.atomic

_WRITE_FLAGS = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_APPEND | os.O_TRUNC


def _fault(code: int, path: object) -> OSError:
    return OSError(code, os.strerror(code), os.fspath(path))  # type: ignore[arg-type]


def refuse_writes(monkeypatch: pytest.MonkeyPatch, under: Path, code: str) -> None:
    """Every file or folder created or opened for writing at or under ``under`` fails
    with ``OSError(errno.<code>)`` (``"EACCES"``, ``"EROFS"``, ``"ENOSPC"``...)."""
    number = getattr(errnos, code)
    root = os.path.abspath(under)

    def hit(path: Any) -> bool:
        try:
            full = os.path.abspath(os.fspath(path))
        except TypeError:  # a file descriptor
            return False
        return full == root or full.startswith(root + os.sep)

    real_open, real_os_open, real_mkdir = builtins.open, os.open, os.mkdir

    def fake_open(file: Any, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
        if hit(file) and any(c in mode for c in "wax+"):
            raise _fault(number, file)
        return real_open(file, mode, *args, **kwargs)

    def fake_os_open(path: Any, flags: int, *args: Any, **kwargs: Any) -> int:
        if hit(path) and flags & _WRITE_FLAGS:
            raise _fault(number, path)
        return real_os_open(path, flags, *args, **kwargs)

    def fake_mkdir(path: Any, *args: Any, **kwargs: Any) -> None:
        if hit(path) and not os.path.isdir(path):
            raise _fault(number, path)
        real_mkdir(path, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", fake_open)
    monkeypatch.setattr(io, "open", fake_open)
    if hasattr(logging.FileHandler, "_builtin_open"):  # Python >= 3.12 keeps its own
        monkeypatch.setattr(logging.FileHandler, "_builtin_open", fake_open)
    monkeypatch.setattr(os, "open", fake_os_open)
    monkeypatch.setattr(os, "mkdir", fake_mkdir)


class DiskFills:
    """The disk fills up once ``after`` more files have been written atomically, or at
    the first file named ``at``: that write and every later one fail with ENOSPC (the
    temporary file is removed, as a failed write leaves no trace).

    :meth:`clear` frees the disk again.
    """

    def __init__(self, monkeypatch: pytest.MonkeyPatch, after: int | None = None, at: str = ""):
        self.after, self.at, self.full, self.written = after, at, False, 0
        self.freed = False
        real = bayescal.atomic._commit

        def commit(temp_name: str, final: Path) -> Path:
            if not self.freed and (
                self.full
                or (self.after is not None and self.written >= self.after)
                or (self.at and final.name == self.at)
            ):
                self.full = True
                raise OSError(errnos.ENOSPC, os.strerror(errnos.ENOSPC))
            self.written += 1
            return real(temp_name, final)

        monkeypatch.setattr(bayescal.atomic, "_commit", commit)

    def clear(self) -> None:
        """Free the disk: writes succeed again."""
        self.freed = True
