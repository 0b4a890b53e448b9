"""Checkpoints of a running chain, so that a killed MCMC resumes bit for bit.

A sampler that supports checkpoints (:class:`~bayescal.mcmc.samplers.mwg.
MetropolisWithinGibbs`) calls :meth:`ChainCheckpoint.save` between batches of
iterations with everything its loop needs to continue: the state, the
adapted proposal widths, the draws kept so far and the random generator's
state. On a later run with the same settings it calls :meth:`ChainCheckpoint.load`
and continues from there; because the generator is restored exactly, the chain
ends with the same draws as an uninterrupted one. A snapshot whose
fingerprint (sampler settings, start point, seed) differs is ignored.

Files are ``.npz`` archives (arrays plus one JSON string: no pickle, nothing
executable) written atomically.
"""

from __future__ import annotations

import json
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bayescal.atomic import atomic_write_npz

__all__ = ["ChainCheckpoint"]


@dataclass
class ChainCheckpoint:
    """Where one chain keeps its snapshot, and how often.

    Parameters
    ----------
    path
        The snapshot file (``.npz``); its folder is created when needed.
    every_seconds
        Minimum wall time between two snapshots (0: after every batch). [s]
    """

    path: Path
    every_seconds: float = 30.0
    _last: float = field(default=0.0, repr=False, compare=False)

    def due(self) -> bool:
        """Whether enough time has passed since the last snapshot."""
        return time.monotonic() - self._last >= self.every_seconds

    def save(self, arrays: dict[str, Any], meta: dict[str, Any]) -> None:
        """Write a snapshot atomically: arrays plus JSON-able ``meta``."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        payload = {f"a:{k}": np.asarray(v) for k, v in arrays.items()}
        payload["meta"] = np.array(json.dumps(meta))
        atomic_write_npz(self.path, payload)
        self._last = time.monotonic()

    def load(self, fingerprint: str) -> tuple[dict[str, np.ndarray], dict[str, Any]] | None:
        """The snapshot with ``fingerprint``, or ``None`` (missing, unreadable or stale)."""
        if not self.path.is_file():
            return None
        try:
            with np.load(self.path, allow_pickle=False) as data:
                meta = json.loads(str(data["meta"]))
                arrays = {k[2:]: data[k] for k in data.files if k.startswith("a:")}
        except (OSError, ValueError, KeyError, zipfile.BadZipFile):
            return None
        if meta.get("fingerprint") != fingerprint:
            return None
        return arrays, meta
