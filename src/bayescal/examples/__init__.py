"""Worked examples shipped with bayescal (study folders copied by ``bayescal init``)."""

from __future__ import annotations

import shutil
from pathlib import Path

from bayescal.errors import ConfigError

__all__ = ["EXAMPLES_DIR", "available", "copy_example", "path"]

EXAMPLES_DIR = Path(__file__).resolve().parent


def available() -> list[str]:
    """Names of the shipped examples (folders holding a ``study.toml``)."""
    return sorted(p.parent.name for p in EXAMPLES_DIR.glob("*/study.toml"))


def path(name: str) -> Path:
    """Folder of the example ``name``."""
    return EXAMPLES_DIR / name


def copy_example(name: str, target: Path, *, force: bool = False) -> Path:
    """Copy the shipped example ``name`` to the folder ``target`` (a new study folder).

    Parameters
    ----------
    name
        One of :func:`available`.
    target
        Destination folder (created if missing).
    force
        Copy even if ``target`` exists and is not empty (files of the example
        replace files of the same name).

    Returns
    -------
    pathlib.Path
        ``target``.

    Raises
    ------
    bayescal.errors.ConfigError
        If there is no such example, or ``target`` is not empty and ``force`` is false.
    """
    names = available()
    if name not in names:
        raise ConfigError(f"no example {name!r}", hint=f"choose one of {', '.join(names)}")
    if target.exists() and any(target.iterdir()) and not force:
        raise ConfigError(
            f"{target} exists and is not empty", hint="choose a new folder or pass --force"
        )
    shutil.copytree(
        path(name),
        target,
        dirs_exist_ok=True,
        ignore=shutil.ignore_patterns("out", "__pycache__"),
    )
    return target
