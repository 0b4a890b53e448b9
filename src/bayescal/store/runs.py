"""The simulations of a study: ``simulations.npz`` and ``simulations.json``.

``simulations.npz`` stacks the successful runs of the design: ``indices``
(design rows that succeeded) and one array ``output:<name>`` of shape
``(R_ok, n)`` per simulated output, in the output's unit.
``simulations.json`` lists the runs' cache keys and failures, the counts of
the run that produced them, and ``units`` and ``descriptions`` of the outputs
(:mod:`bayescal.glossary`). The per-run cache (``simulations/``) belongs to
:mod:`bayescal.runner`.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, Final

from bayescal.atomic import atomic_write_json, atomic_write_npz, read_json, read_npz
from bayescal.design import Design
from bayescal.glossary import GLOSSARY
from bayescal.runner import RunFailure, RunResults

__all__ = ["ARRAYS_FILE", "FILES", "RECORD_FILE", "load_simulations", "save_simulations"]

#: File names in a study's output folder.
ARRAYS_FILE: Final = "simulations.npz"
RECORD_FILE: Final = "simulations.json"
FILES: Final = (ARRAYS_FILE, RECORD_FILE)


def save_simulations(folder: str | os.PathLike[str], sims: RunResults) -> list[str]:
    """Write the stacked runs and their record into ``folder`` atomically.

    Returns
    -------
    list of str
        The names of the files written (relative to ``folder``).
    """
    out = Path(folder)
    arrays: dict[str, Any] = {f"output:{k}": v for k, v in sims.outputs.items()}
    arrays["indices"] = sims.indices
    atomic_write_npz(out / ARRAYS_FILE, arrays)
    known = [name for name in sims.outputs if name in GLOSSARY]
    meta = {
        "keys": list(sims.keys),
        "failures": [dataclasses.asdict(f) for f in sims.failures],
        "n_run": sims.n_run,
        "n_cached": sims.n_cached,
        "n_attempts": sims.n_attempts,
        "units": {name: GLOSSARY[name].unit for name in known},
        "descriptions": {name: GLOSSARY[name].description for name in known},
    }
    atomic_write_json(out / RECORD_FILE, meta)
    return list(FILES)


def load_simulations(folder: str | os.PathLike[str], design: Design) -> RunResults:
    """Read the runs written by :func:`save_simulations` (of ``design``)."""
    out = Path(folder)
    arrays = read_npz(out / ARRAYS_FILE)
    meta = read_json(out / RECORD_FILE)
    outputs = {k.split(":", 1)[1]: v for k, v in arrays.items() if k.startswith("output:")}
    return RunResults(
        design=design,
        indices=arrays["indices"],
        outputs=outputs,
        keys=tuple(meta["keys"]),
        failures=tuple(RunFailure(**f) for f in meta["failures"]),
        n_run=0,
        n_cached=int(arrays["indices"].size),
        n_attempts=0,
    )
