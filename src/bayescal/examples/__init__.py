"""Worked examples shipped with bayescal (study folders copied by ``bayescal init``)."""

from __future__ import annotations

from pathlib import Path

EXAMPLES_DIR = Path(__file__).resolve().parent


def available() -> list[str]:
    """Names of the shipped examples (folders holding a ``study.toml``)."""
    return sorted(p.parent.name for p in EXAMPLES_DIR.glob("*/study.toml"))


def path(name: str) -> Path:
    """Folder of the example ``name``."""
    return EXAMPLES_DIR / name
