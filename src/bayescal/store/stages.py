"""The stage record of a study's output folder: ``stages.json``.

When a stage finishes, its key (:mod:`bayescal.pipeline.keys`) with a digest of
each input of the key, the files it wrote with their size and SHA-256, how long
it ran and when it finished are recorded in ``stages.json`` (written atomically
after the stage's own files); a stage run again names the inputs that changed.
A later run reuses a stage when its recorded key equals the key it would
compute now and all its files exist; otherwise it runs the stage again, and
with it every stage after it. A file whose size or checksum is no longer the
recorded one (a disk that filled, a copy interrupted, a bit flipped) is
*damaged* (:meth:`StageLog.damaged`): the runner says so and computes the stage
again, never using it. Records written before checksums were kept have none;
their files are checked by loading them.
"""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import Any, Final

from bayescal.atomic import atomic_write_json, read_json

__all__ = ["RECORD", "STAGES", "StageLog", "StageRun", "file_sha256"]

#: Stages in order (``--from`` takes one of these).
STAGES: Final = ("design", "simulate", "emulator", "calibrate", "discrepancy", "predict", "report")
RECORD: Final = "stages.json"
_FINISHED = "%Y-%m-%dT%H:%M:%S%z"


@dataclass(frozen=True)
class StageRun:
    """How a recorded stage ran.

    Attributes
    ----------
    seconds
        Wall time of the stage. [s]
    finished
        When it finished (the local time of the machine, with its UTC offset),
        ``None`` where the record does not say.
    """

    seconds: float
    finished: datetime | None


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
        rec = self.records.get(stage) or {}
        return rec.get("key") == key and self.finished(stage)

    def finished(self, stage: str) -> bool:
        """Whether ``stage`` is recorded as finished (with any key) and its files are all there."""
        rec = self.records.get(stage)
        if not rec:
            return False
        return all((self.folder / f).exists() for f in rec.get("files", []))

    def last_run(self, stage: str) -> StageRun | None:
        """How ``stage`` ran when it was recorded; ``None`` if the record does not say."""
        rec = self.records.get(stage) or {}
        try:
            seconds = float(rec["seconds"])
        except (KeyError, TypeError, ValueError):
            return None
        try:
            finished: datetime | None = datetime.strptime(str(rec["finished"]), _FINISHED)
        except (KeyError, ValueError):
            finished = None
        return StageRun(seconds, finished)

    def damaged(self, stage: str) -> list[str]:
        """The files of ``stage`` whose size or SHA-256 differ from those recorded when
        they were written (none where the record keeps no checksums); a missing file
        is not damaged but absent (:meth:`finished` says so)."""
        rec = self.records.get(stage) or {}
        sums = rec.get("sha256")
        if not isinstance(sums, dict):
            return []
        recorded = rec.get("sizes")
        sizes: dict[str, Any] = recorded if isinstance(recorded, dict) else {}
        bad = []
        for name, expected in sorted(sums.items()):
            path = self.folder / name
            try:
                resized = sizes.get(name) is not None and path.stat().st_size != sizes[name]
                if resized or file_sha256(path) != expected:
                    bad.append(name)
            except FileNotFoundError:
                continue
            except OSError:
                bad.append(name)
        return bad

    def changed_inputs(self, stage: str, key: str, inputs: Mapping[str, str]) -> list[str] | None:
        """The names of the inputs of ``stage`` whose digest differs from the recorded
        one (:func:`bayescal.pipeline.keys.stage_inputs`), in the order of ``inputs``
        then the recorded ones no longer there; ``[]`` where the recorded key is ``key``
        or the stage is not recorded, ``None`` where the record keeps no inputs (written
        by an earlier bayescal)."""
        rec = self.records.get(stage) or {}
        if not rec or rec.get("key") == key:
            return []
        old = rec.get("inputs")
        if not isinstance(old, dict):
            return None
        changed = [name for name, value in inputs.items() if old.get(name) != value]
        return changed + [name for name in old if name not in inputs]

    def finish(
        self,
        stage: str,
        key: str,
        files: Iterable[str],
        seconds: float,
        inputs: Mapping[str, str] | None = None,
    ) -> None:
        """Record ``stage`` as finished (after its files are written), with the size and
        SHA-256 of each of its files and the digests of the inputs of its key."""
        names = sorted(files)
        paths = {name: self.folder / name for name in names}
        present = {name: path for name, path in paths.items() if path.is_file()}
        self.records[stage] = {
            "key": key,
            **({"inputs": dict(inputs)} if inputs is not None else {}),
            "files": names,
            "sizes": {name: path.stat().st_size for name, path in present.items()},
            "sha256": {name: file_sha256(path) for name, path in present.items()},
            "seconds": round(float(seconds), 3),
            "finished": time.strftime(_FINISHED),
        }
        atomic_write_json(self.folder / RECORD, self.records)

    def forget_from(self, stage: str) -> None:
        """Drop the records of ``stage`` and every later stage."""
        later = STAGES[STAGES.index(stage) :]
        self.records = {k: v for k, v in self.records.items() if k not in later}
        atomic_write_json(self.folder / RECORD, self.records)


def file_sha256(path: str | os.PathLike[str]) -> str:
    """SHA-256 (hex) of a file's bytes, read in blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
