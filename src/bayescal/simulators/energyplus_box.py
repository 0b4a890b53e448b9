"""The Annex 58 test box in EnergyPlus, from the shipped model ``models/test_box.epJSON``.

:func:`energyplus_test_box` (its docstring describes the model) is the
counterpart of the built-in :class:`~bayescal.simulators.box.TestBox`, with
the same parameter names, inputs and outputs.
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

from bayescal.errors import SimulatorError
from bayescal.simulators.energyplus import MODELS, EnergyPlusSimulator, FieldTarget
from bayescal.simulators.energyplus_model import load_model

__all__ = ["TEST_BOX_TARGETS", "energyplus_test_box"]


TEST_BOX_TARGETS: dict[str, tuple[str, str, str]] = {
    "k_wall": ("Material", "BoxWall", "Conductivity"),
    "d_wall": ("Material", "BoxWall", "Density"),
    "r_ag": ("WindowMaterial:Gas", "Cavity", "Thickness"),
    "t_w": ("WindowMaterial:Glazing", "OuterPane", "Solar Transmittance at Normal Incidence"),
}
"""The paper's four test-box parameters (names of :mod:`bayescal.simulators.box`) -> the
field of ``models/test_box.epJSON`` each sets (object type, name, field)."""

_BOX_CONTROL_OBJECTS = (
    "ZoneControl:Thermostat",
    "ThermostatSetpoint:SingleHeatingOrCooling",
    "ZoneHVAC:IdealLoadsAirSystem",
    "ZoneHVAC:EquipmentList",
    "ZoneHVAC:EquipmentConnections",
)


def energyplus_test_box(
    mode: Literal["coheating", "freefloat"] = "coheating",
    *,
    latitude: float | None = None,
    longitude: float | None = None,
    time_zone: float | None = None,
    altitude: float | None = None,
    window_azimuth: float = 180.0,
    heat_input: bool = False,
    outputs: Mapping[str, Sequence[Any]] | None = None,
    **options: Any,
) -> EnergyPlusSimulator:
    """The Annex 58 test box in EnergyPlus (``models/test_box.epJSON``).

    The same box as :class:`bayescal.simulators.box.TestBox`, with the same
    parameter names (:data:`TEST_BOX_TARGETS`), inputs and outputs, so that
    either can stand in for the other in a study.

    The model
    ---------
    Geometry
        One zone, a 96 cm inner cube on a stand (floor 0.5 m above the
        ground, exposed to outside air, seeing only the ground); surfaces on
        inner dimensions, as the built-in box. A 52 x 52 cm window, centred in
        the south wall; the frame band of the 60 x 60 cm opening is wall.
    Walls, roof and floor
        One 12 cm homogeneous layer ``Material BoxWall`` (``k_wall`` = 0.125
        W/(m·K), ``d_wall`` = 2250 kg/m³, 800 J/(kg·K); thermal absorptance
        0.85, solar 0.4), conduction transfer functions at 6 steps per hour.
    Window
        Two 4 mm panes at 1 W/(m·K) (``r_glass`` 0.008 m²·K/W) around a
        custom gas ``Cavity`` of conductivity 1 W/(m·K) and a viscosity high
        enough to suppress convection, so that the cavity's thickness in m is
        its resistance ``r_ag`` in m²·K/W. The pane faces towards the cavity
        have emissivity 0.001: the cavity conducts only, as ``r_ag`` in
        :mod:`~bayescal.simulators.box`. The outer pane transmits ``t_w`` at
        normal incidence (reflectance 0.075, the rest absorbed); the inner
        pane is clear (transmittance 1), so that the window's normal
        transmittance is ``t_w``. Unlike the built-in box, EnergyPlus keeps
        the solar power absorbed in the outer pane and uses its own angular
        dependence (one pane instead of two).
    Surface coefficients
        Inside: the built-in box's combined coefficients imposed as
        convection coefficients (walls and window 1/0.13, ceiling 1/0.10,
        floor 1/0.17 W/(m²·K)); EnergyPlus adds long-wave exchange between the
        inside faces, which the built-in box folds into those coefficients.
        Outside: ``4 + 4 v`` W/(m²·K) with the weather file's wind speed ``v``
        (ISO 6946 annex C, a user curve) and EnergyPlus's long-wave exchange
        with sky, air and ground (a vertical face sees part of its sky view
        at air temperature, as the built-in box does with ``sky_air_split``).
    Control
        ``"coheating"``: an unlimited ideal-loads system holds the zone air at
        the ``TempAirIn`` schedule (``temp_air_in``); ``heating_power`` [W] is
        the heat it adds to the air (``Zone Air Heat Balance System Air
        Transfer Rate``, negative when it cools). ``"freefloat"``: no
        thermostat; ``temp_air_in`` [°C] is the zone mean air temperature,
        and with ``heat_input`` a convective heater adds the series
        ``heat_input`` [W] (schedule ``HeatInput``, design level 1 W).
    Weather
        Written from the forcing (:mod:`bayescal.simulators.epw`:
        ``temp_air_out``, ``ghi``, ``dhi``, ``wind_speed``, and
        ``relative_humidity`` and ``ir_horizontal`` where given) unless
        ``weather=`` names an EPW file.

    The model file holds both controls (thermostat and heater); this
    function removes what ``mode`` does not use. A study can use the file
    itself (``type = "energyplus"``) with both schedules mapped, or a copy
    edited to one mode; there ``r_ag`` targets ``WindowMaterial:Gas:Cavity:
    Thickness`` and so takes the unit ``m``.

    Parameters
    ----------
    mode
        ``"coheating"`` or ``"freefloat"``.
    latitude, longitude
        Site, north and east positive; default the model's (Limelette,
        Belgium: 50.69, 4.53). [°]
    time_zone
        Local standard time minus UTC; default the model's (1). [h]
    altitude
        Site elevation; default the model's (100). [m]
    window_azimuth
        Azimuth the window faces, clockwise from north. [°]
    heat_input
        Free-float only: whether the forcing has a ``heat_input`` series
        driving the heater.
    outputs
        Further outputs, name -> ``(variable, key)`` or ``(variable, key,
        scale)`` (surface temperatures, transmitted solar...).
    **options
        Further :class:`~bayescal.simulators.energyplus.EnergyPlusSimulator`
        arguments (``parameters``, ``timesteps_per_hour``, ``weather``...).

    Raises
    ------
    SimulatorError
        For an unknown mode, or ``heat_input`` with co-heating.
    """
    if mode not in ("coheating", "freefloat"):
        raise SimulatorError(f"mode must be 'coheating' or 'freefloat', got {mode!r}")
    if heat_input and mode == "coheating":
        raise SimulatorError(
            "heat_input applies to mode 'freefloat' only; the heating is the output"
        )
    model = load_model(MODELS / "test_box.epJSON")
    site = model["Site:Location"]["Limelette"]
    given = {"latitude": latitude, "longitude": longitude, "time_zone": time_zone}
    site.update({k: float(v) for k, v in given.items() if v is not None})
    if altitude is not None:
        site["elevation"] = float(altitude)
    model["Building"]["Annex 58 test box"]["north_axis"] = (float(window_azimuth) - 180.0) % 360.0
    if mode == "freefloat":
        for key in (*_BOX_CONTROL_OBJECTS, "Schedule:Constant"):
            del model[key]
        del model["Schedule:File"]["TempAirIn"]
    if not heat_input:
        del model["OtherEquipment"]
        del model["Schedule:File"]["HeatInput"]
    schedules = {"temp_air_in": "TempAirIn"} if mode == "coheating" else {}
    if heat_input:
        schedules["heat_input"] = "HeatInput"
    main = {
        "coheating": {"heating_power": ("Zone Air Heat Balance System Air Transfer Rate", "Box")},
        "freefloat": {"temp_air_in": ("Zone Mean Air Temperature", "Box")},
    }[mode]
    options.setdefault("parameters", {n: FieldTarget(*t) for n, t in TEST_BOX_TARGETS.items()})
    with tempfile.TemporaryDirectory(prefix="bayescal-test-box-") as tmp:
        path = Path(tmp) / f"test_box-{mode}.epJSON"
        path.write_text(json.dumps(model), encoding="utf-8")
        return EnergyPlusSimulator(
            path, schedules=schedules, outputs={**main, **(outputs or {})}, **options
        )
