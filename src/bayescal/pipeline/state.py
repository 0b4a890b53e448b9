"""Stage bookkeeping of a study's output folder: keys, records, logging.

Every stage has a *key*: the SHA-256 of everything its result depends on (the
settings it reads and the keys of the stages before it). When a stage
finishes, its key, the time and the files it wrote are recorded in
``stages.json`` (written atomically after the stage's own files). A later run
reuses a stage when its recorded key equals the key it would compute now and
all its files exist; otherwise it runs the stage again, and with it every
stage after it.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from bayescal.atomic import atomic_write_json, read_json

__all__ = ["STAGES", "StageLog", "derived_seed", "digest", "file_logger"]

#: Stages in order (``--from`` takes one of these).
STAGES = ("design", "simulate", "emulator", "calibrate", "discrepancy", "predict", "report")
RECORD = "stages.json"


def _plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in sorted(obj.items(), key=lambda kv: str(kv[0]))}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return hashlib.sha256(np.ascontiguousarray(obj).tobytes()).hexdigest() + str(obj.shape)
    if isinstance(obj, float | int | str | bool) or obj is None:
        return obj
    if isinstance(obj, Path):
        return str(obj)
    return repr(obj)


def digest(*parts: Any) -> str:
    """SHA-256 (hex) of the canonical JSON of ``parts`` (arrays by content)."""
    text = json.dumps(_plain(list(parts)), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def derived_seed(master: int, stage: str) -> int:
    """A seed for ``stage`` derived from the study's master seed."""
    entropy = [int(master), *stage.encode()]
    return int(np.random.SeedSequence(entropy).generate_state(1)[0])


@dataclass
class StageLog:
    """The record of finished stages in ``folder/stages.json``."""

    folder: Path
    records: dict[str, dict[str, Any]] = field(default_factory=dict)

    @classmethod
    def open(cls, folder: Path) -> StageLog:
        """Read the record (an unreadable record counts as empty: everything reruns)."""
        path = folder / RECORD
        records: dict[str, dict[str, Any]] = {}
        if path.is_file():
            try:
                loaded = read_json(path)
                records = loaded if isinstance(loaded, dict) else {}
            except (OSError, ValueError):
                records = {}
        return cls(folder, records)

    def done(self, stage: str, key: str) -> bool:
        """Whether ``stage`` finished with ``key`` and its files are all there."""
        rec = self.records.get(stage)
        if not rec or rec.get("key") != key:
            return False
        return all((self.folder / f).exists() for f in rec.get("files", []))

    def finish(self, stage: str, key: str, files: Iterable[str], seconds: float) -> None:
        """Record ``stage`` as finished (after its files are written)."""
        self.records[stage] = {
            "key": key,
            "files": sorted(files),
            "seconds": round(float(seconds), 3),
            "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        atomic_write_json(self.folder / RECORD, self.records)

    def forget_from(self, stage: str) -> None:
        """Drop the records of ``stage`` and every later stage."""
        later = STAGES[STAGES.index(stage) :]
        self.records = {k: v for k, v in self.records.items() if k not in later}
        atomic_write_json(self.folder / RECORD, self.records)


def file_logger(folder: Path) -> logging.Logger:
    """The ``bayescal`` logger, writing to ``folder/bayescal.log`` (appending)."""
    logger = logging.getLogger("bayescal.run")
    logger.setLevel(logging.INFO)
    logger.propagate = False
    target = str((folder / "bayescal.log").resolve())
    for handler in list(logger.handlers):
        if getattr(handler, "baseFilename", None) != target:
            logger.removeHandler(handler)
            handler.close()
    if not logger.handlers:
        handler = logging.FileHandler(target, encoding="utf-8")
        handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
        logger.addHandler(handler)
    return logger
