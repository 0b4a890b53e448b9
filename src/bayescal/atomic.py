"""Atomic file writing: a file either holds its complete new content or is untouched.

This is bayescal's one file writer. Every file bayescal writes (cached
simulator runs, failure records, MCMC checkpoints, the design, fitted
emulators, posteriors, reports) goes through these helpers so that a
crash, a ``kill -9`` or a full disk never leaves a half-written file under
the final name, and a resumed study can trust every file it finds.

The recipe (POSIX semantics; also used on Windows where ``os.replace`` is
atomic on one volume):

1. write the content to a temporary file in the *same* folder (same file
   system, so the rename cannot turn into a copy), named
   ``.<name>.<random>.tmp`` so that it is hidden and never mistaken for an
   artefact;
2. flush Python's buffer and ``os.fsync`` the file, so the data are on disk
   before the name points to them;
3. ``os.replace`` the temporary file onto the final name (atomic: readers
   see the old file or the new one, never a mixture);
4. ``fsync`` the folder, so the rename itself survives a power cut (skipped
   where folders cannot be opened, i.e. on Windows).

If anything fails before step 3 the temporary file is removed and the
exception propagates; the final name keeps its previous content, if any. An
:class:`OSError` (a full disk, a read-only folder) names the final path, not
the temporary one, whatever step raised it.

The new file gets the permissions a plain ``open()`` would give it (``0666``
less the umask), not the ``0600`` of :func:`tempfile.mkstemp`. Libraries that
write by file name (netCDF through h5netcdf) use :func:`atomic_write_path`,
which follows the same recipe with a temporary *name* instead of a stream.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import tempfile
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = [
    "atomic_write",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_npz",
    "atomic_write_path",
    "atomic_write_text",
    "fsync_directory",
    "read_json",
    "read_npz",
]

TEMP_SUFFIX = ".tmp"


def fsync_directory(folder: str | os.PathLike[str]) -> None:
    """Flush a folder's entries (renames, new files) to disk.

    Parameters
    ----------
    folder
        The folder whose entries to flush.

    Notes
    -----
    A no-op where a folder cannot be opened for reading (Windows).
    """
    if os.name == "nt":  # folders cannot be opened there; NTFS journals the rename
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _temporary(final: Path) -> tuple[int, str]:
    """A hidden temporary file beside ``final`` with the umask's permissions."""
    final.parent.mkdir(parents=True, exist_ok=True)
    fd, temp_name = tempfile.mkstemp(prefix=f".{final.name}.", suffix=TEMP_SUFFIX, dir=final.parent)
    try:
        # mkstemp creates the file 0600; give it the mode a plain open() would (umask).
        os.fchmod(fd, 0o666 & ~_umask())
    except BaseException:
        os.close(fd)
        os.unlink(temp_name)
        raise
    return fd, temp_name


@contextlib.contextmanager
def _naming(final: Path) -> Iterator[None]:
    """Re-raise an OSError of writing ``final`` with ``final`` as its file name (a write
    on a full disk names no file; mkstemp names the temporary one)."""
    try:
        yield
    except OSError as exc:
        if exc.errno is None or exc.filename == str(final):
            raise
        raise OSError(exc.errno, exc.strerror, str(final)) from exc


@contextlib.contextmanager
def _removed_on_error(temp_name: str) -> Iterator[None]:
    """Remove the temporary file if the block raises (anything, KeyboardInterrupt too)."""
    try:
        yield
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temp_name)
        raise


def _commit(temp_name: str, final: Path) -> Path:
    os.replace(temp_name, final)
    fsync_directory(final.parent)
    return final


def atomic_write(path: str | os.PathLike[str], write: Callable[[IO[bytes]], None]) -> Path:
    """Write a file atomically through a callback that writes to a binary stream.

    Parameters
    ----------
    path
        Final file name. Its folder is created if missing.
    write
        Called once with an open binary file; writes the whole content.

    Returns
    -------
    pathlib.Path
        The final path.
    """
    final = Path(path)
    with _naming(final):
        fd, temp_name = _temporary(final)
        with _removed_on_error(temp_name):
            with os.fdopen(fd, "wb") as stream:
                write(stream)
                stream.flush()
                os.fsync(stream.fileno())
            return _commit(temp_name, final)


def atomic_write_path(path: str | os.PathLike[str], write: Callable[[Path], None]) -> Path:
    """Write a file atomically through a callback that writes to a file *name*.

    For libraries that open the file themselves (``xarray.Dataset.to_netcdf``,
    ``arviz.InferenceData.to_netcdf``). The callback gets the temporary file's
    path (it exists, empty, with the final permissions) and may replace it.

    Parameters
    ----------
    path
        Final file name. Its folder is created if missing.
    write
        Called once with the temporary path; writes the whole content there.

    Returns
    -------
    pathlib.Path
        The final path.
    """
    final = Path(path)
    with _naming(final):
        fd, temp_name = _temporary(final)
        os.close(fd)
        with _removed_on_error(temp_name):
            mode = os.stat(temp_name).st_mode
            write(Path(temp_name))
            os.chmod(temp_name, mode)  # a library that recreated the file gets the mode back
            with open(temp_name, "rb") as stream:
                os.fsync(stream.fileno())
            return _commit(temp_name, final)


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write bytes atomically.

    Parameters
    ----------
    path
        Final file name.
    data
        The whole content.

    Returns
    -------
    pathlib.Path
        The final path.
    """

    def write(stream: IO[bytes]) -> None:
        stream.write(data)

    return atomic_write(path, write)


def atomic_write_text(path: str | os.PathLike[str], text: str, encoding: str = "utf-8") -> Path:
    """Write text atomically (no newline translation).

    Parameters
    ----------
    path
        Final file name.
    text
        The whole content.
    encoding
        Text encoding.

    Returns
    -------
    pathlib.Path
        The final path.
    """
    return atomic_write_bytes(path, text.encode(encoding))


def atomic_write_json(path: str | os.PathLike[str], obj: Any, *, indent: int | None = 2) -> Path:
    """Write a JSON document atomically (UTF-8, keys in insertion order, NaN refused).

    Parameters
    ----------
    path
        Final file name.
    obj
        A JSON-serialisable object.
    indent
        Indentation, or ``None`` for one line.

    Returns
    -------
    pathlib.Path
        The final path.
    """
    text = json.dumps(obj, indent=indent, ensure_ascii=False, allow_nan=False)
    return atomic_write_text(path, text + "\n")


def atomic_write_npz(
    path: str | os.PathLike[str], arrays: Mapping[str, Any], *, compress: bool = False
) -> Path:
    """Write a numpy ``.npz`` archive atomically.

    Parameters
    ----------
    path
        Final file name (numpy does not add ``.npz`` here: the name is kept).
    arrays
        Array name -> array (anything ``numpy.asarray`` accepts, no objects).
    compress
        Use ``numpy.savez_compressed`` instead of ``numpy.savez``.

    Returns
    -------
    pathlib.Path
        The final path.
    """
    save = np.savez_compressed if compress else np.savez
    buffer = io.BytesIO()
    contents: dict[str, Any] = {name: np.asarray(value) for name, value in arrays.items()}
    save(buffer, **contents)
    return atomic_write_bytes(path, buffer.getvalue())


def read_json(path: str | os.PathLike[str]) -> Any:
    """Read a JSON document written by :func:`atomic_write_json`."""
    return json.loads(Path(path).read_text(encoding="utf-8"))


def read_npz(path: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Read every array of an ``.npz`` archive into memory (no pickles allowed)."""
    # Read the bytes first: numpy leaves the file open when a damaged archive raises.
    data = Path(path).read_bytes()
    with np.load(io.BytesIO(data), allow_pickle=False) as archive:
        return {name: archive[name] for name in archive.files}
