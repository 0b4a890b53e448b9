"""The ``[simulator]`` sections of external programs: ``type = "command"`` and ``"fmu"``.

Their targets are open (a template placeholder, an FMU variable), so any unit
is accepted for them.
"""

from __future__ import annotations

import os
from pathlib import Path, PurePosixPath
from typing import ClassVar, Literal

from pydantic import ValidationInfo, field_validator, model_validator

from bayescal.config.base import Section, field_doc, raise_problems, resolve_path
from bayescal.config.targets import SimulatorBase
from bayescal.errors import DataError
from bayescal.units import dimension_of

__all__ = ["CommandOutputs", "CommandSection", "FmuSection"]


# --------------------------------------------------------------------------- command

_RUN_FOLDER_RESERVED = ("forcing.csv", "stdout.txt", "stderr.txt")
"""Files the command simulator itself writes into each run folder."""


def _run_file(name: str, what: str) -> str:
    """A file name inside the run folder: relative, without '..', not a reserved name."""
    pure = PurePosixPath(name)
    if not name or "\\" in name or pure.is_absolute() or ".." in pure.parts:
        raise ValueError(
            f"{what} {name!r} must be a relative path inside the run folder, without '..'"
        )
    if str(pure) in (*_RUN_FOLDER_RESERVED, "."):
        raise ValueError(
            f"{what} {name!r} is reserved; the run folder holds {_RUN_FOLDER_RESERVED}"
        )
    return str(pure)


class CommandOutputs(Section):
    """``[simulator.outputs]`` (command): the CSV file the program writes and its columns."""

    file: str = field_doc(
        "CSV file (with a header line) the program writes, relative to its run folder.",
        "out.csv",
        default="out.csv",
    )
    columns: dict[str, str] = field_doc(
        "Output name (glossary name for calibrated outputs) -> column of the file.",
        {"heat_flux_out": "q"},
        min_length=1,
    )
    time_column: str | None = field_doc(
        "Column with the time since the first sample [s]; checked against the study clock.",
        "time",
        default=None,
    )

    @field_validator("file")
    @classmethod
    def _file(cls, value: str) -> str:
        return _run_file(value, "output file")


class CommandSection(SimulatorBase):
    """``type = "command"``: an external program run once per parameter set
    (:class:`bayescal.simulators.command.CommandSimulator`)."""

    type: Literal["command"] = field_doc("Simulator type.", "command")
    command: list[str] = field_doc(
        "Argument list, run without a shell in a fresh run folder. The program is a name on "
        "the PATH, an absolute path or a path relative to the study folder; arguments may "
        "hold {run_dir}, {base_dir}, {forcing_csv}, {output_csv}, {start}, {step}, {n} and "
        "{<rendered template name>}.",
        ["python3", "{base_dir}/rc_wall.py", "{output_csv}"],
        min_length=1,
    )
    templates: dict[str, str] = field_doc(
        "Template file (relative to the study folder) -> name of the rendered file in the run "
        "folder. Templates use $NAME or ${NAME} for the parameter targets, $$ for a dollar.",
        {"params.tmpl": "params.txt"},
        default_factory=dict,
    )
    inputs: list[str] = field_doc(
        "Boundary conditions written to forcing.csv (column time [s], then these, in "
        "internal units).",
        ["temp_air_out"],
        default_factory=list,
    )
    outputs: CommandOutputs = field_doc(
        "The output file and its columns.",
        {"file": "out.csv", "columns": {"heat_flux_out": "q"}, "time_column": "time"},
    )
    timeout: float = field_doc("Wall-clock limit of one run. [s]", 600.0, default=3600.0, gt=0)
    env: dict[str, str] = field_doc(
        "Environment variables added to (or replacing) the caller's.",
        {"OMP_NUM_THREADS": "1"},
        default_factory=dict,
    )

    @field_validator("command")
    @classmethod
    def _program(cls, value: list[str], info: ValidationInfo) -> list[str]:
        if not all(value):
            raise ValueError(f"arguments must not be empty, got {value!r}")
        if "/" in value[0] or (os.altsep and os.altsep in value[0]) or os.sep in value[0]:
            resolve_path(Path(value[0]), info, "a program")
        return value

    @field_validator("templates")
    @classmethod
    def _templates(cls, value: dict[str, str], info: ValidationInfo) -> dict[str, str]:
        rendered: set[str] = set()
        for source, name in value.items():
            resolve_path(Path(source), info, "a template file")
            target = _run_file(name, "rendered template name")
            if target in rendered:
                raise ValueError(f"two templates render to the same file {target!r}")
            rendered.add(target)
        return value

    @model_validator(mode="after")
    def _consistent(self) -> CommandSection:
        problems = []
        if len(set(self.inputs)) != len(self.inputs):
            problems.append(f"simulator.inputs: repeated names in {self.inputs}")
        if self.outputs.file in {_run_file(n, "") for n in self.templates.values()}:
            problems.append(
                f"simulator.outputs.file: {self.outputs.file!r} is also a rendered template"
            )
        raise_problems(problems)
        return self

    def target_kind(self, target: str) -> str | None:
        if not (target.isascii() and target.isidentifier()):
            raise ValueError(
                f"{target!r} is not a template placeholder name (letters, digits and _, not "
                "starting with a digit)"
            )
        return None

    def output_names(self) -> tuple[str, ...]:
        return tuple(self.outputs.columns)

    def input_names(self) -> tuple[str, ...]:
        return tuple(self.inputs)


# --------------------------------------------------------------------------- fmu


class FmuSection(SimulatorBase):
    """``type = "fmu"``: a co-simulation FMU, FMI 2.0 or 3.0
    (:class:`bayescal.simulators.fmu.FmuSimulator`)."""

    path_keys: ClassVar[tuple[str, ...]] = ("fmu",)

    type: Literal["fmu"] = field_doc("Simulator type.", "fmu")
    fmu: Path = field_doc(
        "The .fmu file (or an extracted FMU folder), relative to the study folder (or absolute).",
        "wall.fmu",
    )
    inputs: dict[str, str] = field_doc(
        "FMU input variable -> boundary condition (glossary name) that feeds it.",
        {"T_out": "temp_air_out"},
        default_factory=dict,
    )
    outputs: dict[str, str] = field_doc(
        "Output name (glossary name for calibrated outputs) -> FMU variable.",
        {"heat_flux_out": "q"},
        min_length=1,
    )
    start_values: dict[str, float] = field_doc(
        "Further FMU variables fixed for every run (in the FMU's units).",
        {"T0": 293.15},
        default_factory=dict,
    )
    units: dict[str, str] = field_doc(
        "FMU input or output variable -> the unit it uses (see bayescal.units), converted "
        "from and to internal units; variables not listed are passed unchanged. Parameters "
        "are never converted.",
        {"T_out": "K", "T": "K"},
        default_factory=dict,
    )
    start_time: float = field_doc("FMU time of the first sample. [s]", 0.0, default=0.0)
    substeps: int = field_doc("Communication steps per study time step.", 4, default=1, ge=1)
    tolerance: float | None = field_doc(
        "Relative tolerance of the FMU's solver; its default if omitted. [-]",
        1e-6,
        default=None,
        gt=0,
    )

    @field_validator("fmu")
    @classmethod
    def _fmu(cls, value: Path, info: ValidationInfo) -> Path:
        return resolve_path(value, info, "an FMU file")

    @model_validator(mode="after")
    def _consistent(self) -> FmuSection:
        problems = []
        connected = {*self.inputs, *self.outputs.values()}
        for var, unit in self.units.items():
            if var not in connected:
                problems.append(
                    f"simulator.units.{var}: {var!r} is no FMU input or output of this section"
                )
            try:
                dimension_of(unit)
            except DataError as exc:
                problems.append(f"simulator.units.{var}: {exc.one_line()}")
        raise_problems(problems)
        return self

    def target_kind(self, target: str) -> str | None:
        if not target.strip():
            raise ValueError("an FMU variable name must not be empty")
        if target in self.start_values:
            raise ValueError(f"{target!r} is also fixed in simulator.start_values; remove it there")
        return None

    def output_names(self) -> tuple[str, ...]:
        return tuple(self.outputs)

    def input_names(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(self.inputs.values()))
