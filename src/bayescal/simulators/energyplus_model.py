"""An EnergyPlus model as an epJSON dictionary: reading it and finding its objects and fields.

Object types and names are case-insensitive in EnergyPlus, and fields are
named in the IDD (``"Specific Heat"``) or in epJSON (``"specific_heat"``);
these helpers follow both rules.
"""

from __future__ import annotations

import json
import re
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any, cast

from bayescal.errors import SimulatorError
from bayescal.simulators.energyplus_run import check_errors, run_energyplus

__all__ = ["energyplus_field_key", "find_object", "first_object", "load_model", "objects_of"]


def load_model(path: Path) -> dict[str, Any]:
    """An EnergyPlus model as an epJSON dictionary (IDF files are converted by EnergyPlus)."""
    if not path.is_file():
        raise SimulatorError(f"EnergyPlus model {str(path)!r} does not exist")
    suffix = path.suffix.lower()
    if suffix == ".epjson":
        text = path.read_text(encoding="utf-8")
    elif suffix == ".idf":
        with tempfile.TemporaryDirectory(prefix="bayescal-convert-") as tmp:
            run_energyplus(["--convert-only", "-d", tmp, str(path.resolve())], 120.0, Path(tmp))
            converted = Path(tmp) / f"{path.stem}.epJSON"
            if not converted.is_file():
                check_errors(Path(tmp) / "eplusout.err", source=str(path))
                raise SimulatorError("EnergyPlus did not convert the IDF file", source=str(path))
            text = converted.read_text(encoding="utf-8")
    else:
        raise SimulatorError(
            f"EnergyPlus model must be .epJSON or .idf, got {path.name!r}", source=str(path)
        )
    try:
        model = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SimulatorError(f"invalid epJSON: {exc}", source=str(path)) from None
    if not isinstance(model, dict):
        raise SimulatorError("an epJSON model must be a JSON object", source=str(path))
    return model


def energyplus_field_key(field: str) -> str:
    """epJSON key of a field named as in the IDD (``"Specific Heat"`` -> ``"specific_heat"``)."""
    return re.sub(r"[^0-9a-z]+", "_", field.strip().lower()).strip("_")


def objects_of(model: Mapping[str, Any], object_type: str) -> dict[str, Any]:
    """All objects of a type (case-insensitive), name -> fields."""
    for key, objects in model.items():
        if key.lower() == object_type.lower():
            return cast(dict[str, Any], objects)
    return {}


def first_object(model: Mapping[str, Any], object_type: str) -> dict[str, Any]:
    """A copy of the fields of the first object of a type, or ``{}``."""
    return dict(next(iter(objects_of(model, object_type).values()), {}))


def find_object(model: Mapping[str, Any], object_type: str, name: str) -> dict[str, Any]:
    """The fields of the named object (EnergyPlus names are case-insensitive)."""
    objects = objects_of(model, object_type)
    for key, fields in objects.items():
        if key.lower() == name.lower():
            return cast(dict[str, Any], fields)
    known = sorted(objects)[:10]
    raise SimulatorError(
        f"the model has no {object_type} named {name!r}",
        hint=f"{object_type} objects in the model: {known}" if known else None,
    )
