"""The study-file reference, generated from the configuration models.

``python -m bayescal.config.reference > docs/study-file.md`` writes it; a test
checks that the committed file equals the generated text, so the reference
cannot drift from the code.
"""

from __future__ import annotations

import json
import types
import typing
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ByteSize
from pydantic_core import PydanticUndefined

from bayescal.clock import format_duration
from bayescal.config import data as cfg_data
from bayescal.config import energyplus as cfg_energyplus
from bayescal.config import external as cfg_external
from bayescal.config import outputs as cfg_outputs
from bayescal.config import parameters as cfg_parameters
from bayescal.config import screening as cfg_screening
from bayescal.config import simulators as cfg_simulators
from bayescal.config import study as cfg_study

_SECTIONS: list[tuple[str, type[BaseModel], str]] = [
    ("[study]", cfg_study.StudySection, ""),
    ("[data]", cfg_data.DataSection, ""),
    ("[data.columns.<glossary name>]", cfg_data.ColumnSpec, ""),
    ("[[data.exclude]]", cfg_data.ExcludeWindow, "one table per window"),
    ('[simulator] type = "wall"', cfg_simulators.WallSimulator, ""),
    ("[[simulator.layers]]", cfg_simulators.LayerSpec, "one table per layer, outside to inside"),
    ('[simulator] type = "box"', cfg_simulators.BoxSimulator, ""),
    ('[simulator] type = "energyplus"', cfg_energyplus.EnergyPlusSection, ""),
    (
        "[simulator.schedules.<glossary name>]",
        cfg_energyplus.EnergyPlusSchedule,
        "energyplus; or just the Schedule:File name",
    ),
    ("[simulator.outputs.<name>]", cfg_energyplus.EnergyPlusOutput, ""),
    ('[simulator] type = "command"', cfg_external.CommandSection, ""),
    ("[simulator.outputs]", cfg_external.CommandOutputs, ""),
    ('[simulator] type = "fmu"', cfg_external.FmuSection, ""),
    ("[parameters.<name>]", cfg_parameters.Parameter, ""),
    ('prior = { distribution = "uniform", ... }', cfg_parameters.UniformPriorSpec, ""),
    ('prior = { distribution = "beta", ... }', cfg_parameters.BetaPriorSpec, ""),
    ("[derived.<name>]", cfg_parameters.DerivedSpec, ""),
    ("[outputs]", cfg_study.OutputsSection, ""),
    ("[outputs.errors.<name>]", cfg_outputs.OutputError, ""),
    ("[periods]", cfg_study.PeriodsSection, ""),
    ("[design]", cfg_study.DesignSection, ""),
    ("[emulator]", cfg_study.EmulatorSection, ""),
    ("[calibration]", cfg_study.CalibrationSection, ""),
    ("[discrepancy]", cfg_study.DiscrepancySection, ""),
    ("[predict]", cfg_study.PredictSection, ""),
    ("[runner]", cfg_study.RunnerSection, ""),
    ("[screening]", cfg_screening.ScreeningSection, ""),
]


def documented_models() -> set[type[BaseModel]]:
    """The configuration models that have a section in the reference."""
    return {model for _, model, _ in _SECTIONS}


def reachable_models(root: type[BaseModel] = cfg_study.Study) -> set[type[BaseModel]]:
    """Every configuration model a study file can hold (through lists, dicts and unions)."""
    found: set[type[BaseModel]] = set()

    def walk(annotation: Any) -> None:
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            if annotation in found:
                return
            found.add(annotation)
            for field in annotation.model_fields.values():
                walk(field.annotation)
            return
        for arg in typing.get_args(annotation):
            walk(arg)

    for field in root.model_fields.values():
        walk(field.annotation)
    return found


def _type_name(annotation: Any) -> str:
    """Readable type: ``float``, ``str or None``, ``list[str]``, ``"a" | "b"``."""
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    if origin is typing.Annotated:
        return _type_name(args[0])
    if origin is typing.Literal:
        return " or ".join(json.dumps(a) for a in args)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in args)
    if origin is not None:
        inner = ", ".join(_type_name(a) for a in args)
        return f"{getattr(origin, '__name__', str(origin))}[{inner}]"
    names = {type(None): "None", timedelta: "duration", datetime: "instant", Path: "path"}
    names[ByteSize] = "size"
    return names.get(annotation, getattr(annotation, "__name__", str(annotation)))


def _value(value: Any) -> str:
    if isinstance(value, timedelta):
        return f"`{json.dumps(format_duration(value))}`"
    try:
        return "`" + json.dumps(value, default=str, ensure_ascii=False) + "`"
    except (TypeError, ValueError):
        return f"`{value}`"


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def section_markdown(title: str, model: type[BaseModel], note: str = "") -> str:
    """One section of the reference as a Markdown table."""
    doc = " ".join((model.__doc__ or "").split())
    lines = [f"## `{title}`", "", doc + (f" ({note})" if note else ""), ""]
    lines += ["| key | type | default | description | example |", "|---|---|---|---|---|"]
    for name, field in model.model_fields.items():
        if field.is_required():
            default = "required"
        elif field.default_factory is not None:
            default = _value(field.default_factory())  # type: ignore[call-arg]
        elif field.default is PydanticUndefined:
            default = "required"
        else:
            default = _value(field.default)
        example = ", ".join(_value(e) for e in (field.examples or []))
        lines.append(
            f"| `{name}` | {_cell(_type_name(field.annotation))} | {_cell(default)} | "
            f"{_cell(field.description or '')} | {_cell(example)} |"
        )
    return "\n".join(lines)


def study_reference_markdown() -> str:
    """The whole study-file reference."""
    head = [
        "# Study file reference (`study.toml`)",
        "",
        "Generated from `bayescal.config` by `python -m bayescal.config.reference`; do not edit.",
        "Units are given in brackets in each description. Durations are written like",
        '`"30min"`, `"1D"`, `"3h"`; instants as ISO 8601. Relative paths start at the study',
        "folder.",
        "",
    ]
    body = [section_markdown(title, model, note) for title, model, note in _SECTIONS]
    return "\n".join(head) + "\n" + "\n\n".join(body) + "\n"


if __name__ == "__main__":
    print(study_reference_markdown(), end="")
