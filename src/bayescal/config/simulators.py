"""The ``[simulator]`` section of the study file: one frozen model per simulator type.

:data:`SimulatorSection` is the union, told apart by ``type``: ``"wall"`` and
``"box"`` (the built-in finite-volume models, here), ``"energyplus"`` (an
EnergyPlus model, IDF or epJSON; :mod:`bayescal.config.energyplus`),
``"command"`` (any external program fed by rendered templates) and ``"fmu"``
(a co-simulation FMU; both in :mod:`bayescal.config.external`). A new
simulator type is one more class, added to the union, plus a builder in
:mod:`bayescal.config.build`. What each section tells before a run (targets
and their kinds, outputs, inputs) is defined in :mod:`bayescal.config.targets`.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import Field, field_validator, model_validator

from bayescal.config.base import IDENTIFIER, Section, field_doc, raise_problems, suggestion
from bayescal.config.energyplus import EnergyPlusSection
from bayescal.config.external import CommandSection, FmuSection
from bayescal.config.targets import SimulatorBase
from bayescal.simulators.fvm import LAYER_PROPERTIES

__all__ = ["BoxSimulator", "LayerSpec", "SimulatorSection", "WallSimulator"]


class LayerSpec(Section):
    """One layer of a wall, outside to inside."""

    name: str = field_doc("Layer name, used in targets.", "concrete")
    thickness: float = field_doc("Thickness. [m]", 0.15, gt=0)
    conductivity: float = field_doc("Thermal conductivity. [W/(m·K)]", 0.12, gt=0)
    density: float = field_doc("Density. [kg/m³]", 552.0, gt=0)
    specific_heat: float = field_doc("Specific heat capacity. [J/(kg·K)]", 800.0, gt=0)

    @field_validator("name")
    @classmethod
    def _name(cls, value: str) -> str:
        if not IDENTIFIER.match(value):
            raise ValueError(f"layer names are identifiers (letters, digits, _), got {value!r}")
        return value


class _BuiltIn(SimulatorBase):
    """What the built-in simulators (wall and box) share."""

    substeps: int = field_doc(
        "Fine steps per clock interval over which an output whose data column says "
        "aggregate = 'mean' is averaged (the simulator runs on a clock this many times "
        "finer, its boundary conditions interpolated linearly between the samples as "
        "values at the instants, and gives the mean over (t - step, t]; the first "
        "sample, with no interval before it, keeps its instantaneous value, so keep it in "
        "the warm-up; bayescal.simulators.wrappers.IntervalMeans). Used only by such "
        "outputs; a wall run then costs about this many times as much, a box run less "
        "where the clock is longer than max_step. [-]",
        12,
        default=6,
        ge=1,
        le=1000,
    )


class WallSimulator(_BuiltIn):
    """``type = "wall"``: the built-in wall (:class:`bayescal.simulators.wall.MultilayerWall`)."""

    type: Literal["wall"] = field_doc("Simulator type.", "wall")
    layers: list[LayerSpec] = field_doc(
        "Layers from the outside face to the inside face ([[simulator.layers]] tables).",
        [
            {
                "name": "concrete",
                "thickness": 0.15,
                "conductivity": 0.12,
                "density": 552.0,
                "specific_heat": 800.0,
            }
        ],
        min_length=1,
    )
    boundary: Literal["surface", "air"] = field_doc(
        "'surface': measured surface temperatures imposed on both faces; 'air': air "
        "temperatures through the surface resistances, plus absorbed solar outside.",
        "air",
        default="surface",
    )
    r_se: float = field_doc(
        "Outside surface resistance (air boundary). [m²·K/W]", 0.04, default=0.04, gt=0
    )
    r_si: float = field_doc(
        "Inside surface resistance (air boundary). [m²·K/W]", 0.13, default=0.13, gt=0
    )
    solar_absorptance: float = field_doc(
        "Solar absorptance of the outside face; > 0 needs boundary 'air' and the boundary "
        "condition poa_global_out. [-]",
        0.6,
        default=0.0,
        ge=0,
        le=1,
    )
    outputs: list[str] = field_doc(
        "Series produced: heat_flux_in, heat_flux_out, temp_surf_out, temp_surf_in, and "
        "temp_interface_<i> / heat_flux_interface_<i> at the interface between layers i-1 "
        "and i (outside layer 0).",
        ["heat_flux_in", "temp_interface_2"],
        default=["heat_flux_in"],
        min_length=1,
    )
    scheme: Literal["crank-nicolson", "backward-euler", "exact"] = field_doc(
        "Time integration scheme.", "exact", default="crank-nicolson"
    )
    tolerance: float = field_doc(
        "Relative error bound of the periodic response down to the period of two clock "
        "steps; it chooses mesh and sub-steps. [-]",
        1e-3,
        default=1e-2,
        gt=0,
        le=0.25,
    )
    cells: list[int] | None = field_doc(
        "Cells per layer, overriding tolerance.", [4, 10, 4], default=None
    )

    @model_validator(mode="after")
    def _consistent(self) -> WallSimulator:
        from bayescal.simulators.wall import allowed_outputs

        names = [layer.name for layer in self.layers]
        allowed = allowed_outputs(len(names))
        problems = [
            f"simulator.outputs: {out!r} is not a wall output{suggestion(out, allowed)}"
            for out in self.outputs
            if out not in allowed
        ]
        if len(set(names)) != len(names):
            problems.append(f"simulator.layers: layer names must be unique, got {names}")
        if len(set(self.outputs)) != len(self.outputs):
            problems.append(f"simulator.outputs: repeated names in {self.outputs}")
        if self.boundary == "surface" and self.solar_absorptance > 0:
            problems.append(
                "simulator.solar_absorptance: > 0 needs boundary = 'air' (imposed surface "
                "temperatures already contain the solar gains)"
            )
        if self.cells is not None and (len(self.cells) != len(names) or min(self.cells) < 1):
            problems.append(f"simulator.cells: one count >= 1 per layer, got {self.cells}")
        raise_problems(problems)
        return self

    def target_kinds(self) -> dict[str, str]:
        kinds = {"thickness": "length"} | {p: p for p in LAYER_PROPERTIES if p != "thickness"}
        found = {f"{layer.name}.{p}": kinds[p] for layer in self.layers for p in LAYER_PROPERTIES}
        if self.boundary == "air":  # surface resistances and solar act only with air boundaries
            found |= {"r_si": "resistance", "r_se": "resistance"}
            found["solar_absorptance"] = "dimensionless"
        return found

    def output_names(self) -> tuple[str, ...]:
        return tuple(self.outputs)

    def input_names(self) -> tuple[str, ...]:
        if self.boundary == "surface":
            return ("temp_surf_out", "temp_surf_in")
        solar = ("poa_global_out",) if self.solar_absorptance > 0 else ()
        return ("temp_air_out", "temp_air_in", *solar)


_BOX_KINDS = {"k_wall": "conductivity", "d_wall": "density", "c_wall": "specific_heat"}
_BOX_KINDS |= {"r_ag": "resistance", "r_glass": "resistance", "c_internal": "capacity"}
_BOX_KINDS |= {name: "length" for name in ("thickness", "side", "glazed_side")}
_BOX_KINDS |= {f"h_in_{s}": "coefficient" for s in ("wall", "ceiling", "floor")}
_BOX_KINDS |= {"h_out_a": "coefficient", "h_out_b": "wind_coefficient", "ua_leak": "conductance"}
"""Kinds of the box constants; the others (t_w, reflectance_w, emissivities, absorptivities,
albedo) are [-]."""


class BoxSimulator(_BuiltIn):
    """``type = "box"``: the built-in test box (:class:`bayescal.simulators.box.TestBox`)."""

    type: Literal["box"] = field_doc("Simulator type.", "box")
    mode: Literal["coheating", "freefloat"] = field_doc(
        "'coheating': indoor air temperature imposed, heating power computed; 'freefloat': "
        "indoor air temperature computed (heat_input optional).",
        "coheating",
    )
    latitude: float = field_doc("Site latitude, north positive. [°]", 50.69, ge=-90, le=90)
    longitude: float = field_doc("Site longitude, east positive. [°]", 4.53, ge=-180, le=180)
    altitude: float = field_doc("Site altitude. [m]", 100.0, default=0.0)
    window_azimuth: float = field_doc(
        "Azimuth the window faces, clockwise from north (180 = south). [°]",
        180.0,
        default=180.0,
        ge=0,
        lt=360,
    )
    constants: dict[str, float] = field_doc(
        "Values overriding the box's nominal constants (bayescal.simulators.box.DEFAULTS: "
        "k_wall [W/(m·K)], d_wall [kg/m³], c_wall [J/(kg·K)], r_ag [m²·K/W], t_w [-], "
        "emissivity [-], absorptivity [-], geometry and surface coefficients; with "
        "window_model = 'layers' also reflectance_w [-], the window's solar reflectance, "
        "and absorptivity_in [-], the inside faces' solar absorptance).",
        {"c_wall": 800.0, "emissivity": 0.85},
        default_factory=dict,
    )
    cells: int = field_doc("Finite-volume cells across the wall.", 20, default=20, ge=1)
    max_step: float = field_doc("Longest time step. [s]", 600.0, default=600.0, gt=0)
    sky_model: Literal["isotropic", "haydavies", "perez"] = field_doc(
        "Sky-diffuse transposition model.", "perez", default="haydavies"
    )
    sky_air_split: bool = field_doc(
        "Long-wave exchange of the faces: true divides each face's sky view F_sky = "
        "(1 + cos tilt)/2 as EnergyPlus does: the fraction beta = sqrt(F_sky) of it at the "
        "sky temperature (beta F_sky: 0.354 for a wall, 1 for a roof), the rest, the sky "
        "near the horizon, at air temperature; false puts the whole sky view at the sky "
        "temperature.",
        False,
        default=True,
    )
    window_model: Literal["transmittance", "layers"] = field_doc(
        "Solar physics of the window: 'transmittance' (the paper's) transmits t_w and "
        "absorbs nothing in the glazing, and the inside faces absorb all the light that "
        "enters; 'layers' also absorbs 1 - t_w - reflectance_w in the glazing (its inward "
        "share is a heat gain), sends the beam where the sun's direction takes it and lets "
        "the inside faces (absorptivity_in) reflect light back out through the window "
        "(bayescal.simulators.box, 'Window').",
        "layers",
        default="transmittance",
    )

    @field_validator("constants")
    @classmethod
    def _known_constants(cls, value: dict[str, float]) -> dict[str, float]:
        from bayescal.simulators.box import DEFAULTS

        for name in value:
            if name not in DEFAULTS:
                raise ValueError(
                    f"{name!r} is not a box constant{suggestion(name, list(DEFAULTS))}"
                )
        return value

    def target_kinds(self) -> dict[str, str]:
        from bayescal.simulators.box import DEFAULTS

        return {name: _BOX_KINDS.get(name, "dimensionless") for name in DEFAULTS}

    def output_names(self) -> tuple[str, ...]:
        return ("heating_power",) if self.mode == "coheating" else ("temp_air_in",)

    def input_names(self) -> tuple[str, ...]:
        control = ("temp_air_in",) if self.mode == "coheating" else ()
        return ("temp_air_out", "ghi", "dhi", "wind_speed", *control)


SimulatorSection = Annotated[
    Union[WallSimulator, BoxSimulator, EnergyPlusSection, CommandSection, FmuSection],  # noqa: UP007
    Field(discriminator="type"),
]
"""The simulator union; a new simulator type is one more class here."""
