"""The per-run cache of :func:`bayescal.runner.run_design` and its bookkeeping.

A finished run is written at once, atomically, to ``cache_dir/runs/<key>.npz``
(outputs, parameters, metadata); a run that failed after all its attempts is
described in ``cache_dir/failures/<key>.json``. Only the calling process
writes the cache (results come back from the workers), through
:mod:`bayescal.atomic`.
"""

from __future__ import annotations

import contextlib
import json
import math
import zipfile
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from bayescal.atomic import atomic_write_json, atomic_write_npz, read_npz
from bayescal.runner.keys import RUN_FORMAT

__all__ = ["Ledger", "Progress", "load_run"]

Progress = Callable[[int, int, int], None]
"""``progress(done, failed, total)``: runs finished (including loaded from the
cache), runs failed for good, and runs in the design."""


@dataclass
class Ledger:
    """Tracks attempts, writes the cache and reports progress (caller's process only)."""

    cache_dir: Path
    parameters: dict[str, dict[str, float]]  # key -> parameter values
    weight: dict[str, int]  # key -> number of design rows with that key
    retries: int
    progress: Progress | None
    total: int
    metadata: dict[str, Any]
    outputs: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)
    errors: dict[str, list[dict]] = field(default_factory=dict)
    done: int = 0
    failed: int = 0
    attempts: int = 0

    def report(self) -> None:
        if self.progress is not None:
            self.progress(self.done, self.failed, self.total)

    def loaded(self, key: str, outputs: dict[str, np.ndarray]) -> None:
        self.outputs[key] = outputs
        self.done += self.weight[key]

    def record(self, key: str, outcome: dict) -> bool:
        """Book one attempt's outcome; ``True`` if the run should be tried again."""
        self.attempts += 1
        history = self.errors.setdefault(key, [])
        if outcome["ok"]:
            self._write_run(key, outcome, len(history) + 1)
            with contextlib.suppress(FileNotFoundError):
                (self.cache_dir / "failures" / f"{key}.json").unlink()
            self.outputs[key] = outcome["outputs"]
            self.done += self.weight[key]
            self.report()
            return False
        history.append({**outcome["error"], "seconds": _finite_or_none(outcome["seconds"])})
        if len(history) <= self.retries:
            return True
        document = {
            "format": RUN_FORMAT,
            "key": key,
            "parameters": self.parameters[key],
            "attempts": history,
            "written": datetime.now(UTC).isoformat(),
            **self.metadata,
        }
        atomic_write_json(self.cache_dir / "failures" / f"{key}.json", document)
        self.failed += self.weight[key]
        self.report()
        return False

    def _write_run(self, key: str, outcome: dict, attempts: int) -> None:
        parameters = self.parameters[key]
        metadata = {
            "format": RUN_FORMAT,
            "key": key,
            "seconds": _finite_or_none(outcome["seconds"]),
            "attempts": attempts,
            "written": datetime.now(UTC).isoformat(),
            **self.metadata,
        }
        arrays: dict[str, Any] = {f"out:{n}": v for n, v in outcome["outputs"].items()}
        arrays["parameter_names"] = np.array(list(parameters), dtype=str)
        arrays["parameter_values"] = np.array(list(parameters.values()), dtype=float)
        arrays["metadata"] = np.array(json.dumps(metadata))
        atomic_write_npz(self.cache_dir / "runs" / f"{key}.npz", arrays)


def _finite_or_none(value: float) -> float | None:
    return value if math.isfinite(value) else None


def load_run(path: Path, names: tuple[str, ...], n: int) -> dict[str, np.ndarray] | None:
    """Outputs of a cached run, or ``None`` if absent or unusable (it is then re-run).

    A truncated file is not a zip archive; a damaged byte fails the CRC-32 that the
    archive keeps of every array; an archive without the outputs, or with outputs
    of another length, is unusable too.
    """
    if not path.is_file():
        return None
    try:
        arrays = read_npz(path)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile):
        return None
    outputs = {name: arrays.get(f"out:{name}") for name in names}
    if any(v is None or v.shape != (n,) for v in outputs.values()):
        return None
    return {name: np.asarray(v, dtype=float) for name, v in outputs.items()}
