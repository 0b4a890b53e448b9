"""The design artefact: ``design.csv`` (or a ``.json`` design).

CSV is a table with a column ``run``, the physical values under the parameter
names and the normalised values under ``u:<name>``, preceded by one ``#`` line
with the format, seed, optimisation and priors as JSON (each prior with the
parameter's ``unit`` and ``description`` where the study gives them). JSON
holds the same in one document. Both read back exactly with :func:`load_design`.
"""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path
from typing import Any, Final

import numpy as np

from bayescal.atomic import atomic_write_json, atomic_write_text, read_json
from bayescal.design import Design, prior_from_spec
from bayescal.errors import ConfigError

__all__ = ["DESIGN_FORMAT", "FILE", "load_design", "save_design"]

DESIGN_FORMAT: Final = "bayescal-design/1"
#: File name in a study's output folder.
FILE: Final = "design.csv"


def _metadata(design: Design) -> dict[str, Any]:
    return {
        "format": DESIGN_FORMAT,
        "seed": design.seed,
        "optimization": design.optimization,
        "priors": {name: prior.spec() for name, prior in design.priors.items()},
    }


def save_design(design: Design, path: str | os.PathLike[str]) -> Path:
    """Write a design atomically as JSON (``.json``) or CSV (``.csv``).

    Raises
    ------
    bayescal.errors.ConfigError
        If the file name ends in neither.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".json":
        document = {**_metadata(design), "names": list(design.names)}
        document |= {"unit": design.unit.tolist(), "values": design.values.tolist()}
        return atomic_write_json(path, document)
    if suffix == ".csv":
        frame = design.to_frame()
        for j, name in enumerate(design.names):
            frame[f"u:{name}"] = design.unit[:, j]
        header = "# " + json.dumps(_metadata(design), ensure_ascii=False) + "\n"
        return atomic_write_text(path, header + frame.to_csv(lineterminator="\n"))
    raise ConfigError(f"design file must end in .json or .csv, got {path.name!r}")


def load_design(path: str | os.PathLike[str]) -> Design:
    """Read a design written by :func:`save_design`.

    Raises
    ------
    bayescal.errors.ConfigError
        If the file is not a bayescal design.
    """
    path = Path(path)
    if path.suffix.lower() == ".json":
        document = read_json(path)
        unit = np.array(document["unit"], dtype=float).reshape(-1, len(document["names"]))
    elif path.suffix.lower() == ".csv":
        with path.open(encoding="utf-8", newline="") as stream:
            document = json.loads(stream.readline().lstrip("#"))
            rows = list(csv.DictReader(stream))  # float() reads repr'd floats exactly
        columns = [f"u:{name}" for name in document["priors"]]
        unit = np.array([[float(r[c]) for c in columns] for r in rows]).reshape(-1, len(columns))
    else:
        raise ConfigError(f"design file must end in .json or .csv, got {path.name!r}")
    if document.get("format") != DESIGN_FORMAT:
        raise ConfigError(f"{path}: not a bayescal design (format {document.get('format')!r})")
    priors = {name: prior_from_spec(**spec) for name, spec in document["priors"].items()}
    return Design(priors, unit, seed=document["seed"], optimization=document["optimization"])
