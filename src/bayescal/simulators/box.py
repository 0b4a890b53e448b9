"""The IEA Annex 58 round-robin test box: one air node, six finite-volume faces, a window.

The box of the paper's "Test Box" case (Tables 5–7): a 96 cm inner cube, all six
faces the same 12 cm homogeneous construction, one 60 × 60 cm window with a
52 × 52 cm glazed part, on a stand so that the ground is neglected except as a
long-wave and solar-reflecting surface seen by the faces.

Model
-----
Nodes
    One well-mixed air node (capacity of the inner air volume ``side³ · rho_c_air``
    plus an optional ``c_internal``) and, for each face, the vertex-centred
    finite-volume mesh of the wall (:mod:`bayescal.simulators.fvm`, outside node
    first) scaled by the face's opaque area. All faces share the wall's
    properties; they differ in orientation, solar gains, sky view and inside
    surface coefficient.
Areas
    Every face has the inner area ``side²`` (edges and corners are not
    modelled, as in a one-dimensional simulation program built on inner
    dimensions). The window's 60 × 60 cm frame band around the glazing
    (0.0896 m² by default) is modelled as wall: the front face's opaque area is
    ``side² - glazed_side²``.
Window
    Massless double glazing between the air node and the outside:
    ``1/U = 1/h_in_wall + r_glass + r_ag + 1/h_out`` with the same exterior
    convection as the walls and long-wave exchange with emissivity
    ``emissivity_glass``. Solar transmittance ``t_w`` at normal incidence times
    the incidence-angle modifier of two clear panes
    (:func:`~bayescal.simulators.solar.double_glazing_iam`) for the beam, and
    times its hemispherical average for sky and ground diffuse light.
    ``window_model = "transmittance"`` (the paper's, default): solar absorbed
    in the panes is neglected, and the transmitted power is absorbed at the
    inside surfaces of the five other faces in proportion to their areas (a
    cavity absorbs nearly all the light that enters it).
    ``window_model = "layers"``: the glazing reflects ``reflectance_w`` at
    normal incidence and absorbs the rest, ``1 - t_w - reflectance_w`` (0
    where negative), in its outer pane with one pane's angular dependence
    (:func:`~bayescal.simulators.solar.pane_absorptance_iam`); that power
    enters the glazing's outside equivalent temperature (sol-air), so that the
    share ``U / h_out`` of it flows inwards (the secondary heat gain of the
    EnergyPlus, ESP-r and ISO 52016 window models). The transmitted beam
    falls on the faces its direction reaches through the glazed square, the
    diffuse light on the five faces in proportion to their areas; they absorb
    ``absorptivity_in`` of it and reflect the rest diffusely, shared as in an
    integrating sphere between the faces (absorbing ``absorptivity_in``) and
    the glazing, which sends light back out or absorbs it
    (:mod:`~bayescal.simulators.box_solar`). With 0.4 about 6 % of the
    transmitted power reaches the glazing again (about 4 % sent back out, 2 %
    absorbed in it), as the inside faces of EnergyPlus's box, with its full
    interior distribution, miss 6 % of it. Transmittance keeps the two-pane
    angular modifier and absorptance takes one pane's, so the reflectance they
    leave (``1 - T - A``) is not a Fresnel curve off normal incidence (0.061
    at 45°, 0.097 at 60° for the defaults); the window's solar balance is
    right at normal incidence and approximate beyond.
Exterior surfaces
    Absorbed solar ``absorptivity · G_face`` (pvlib's transposition); convection
    ``h_c = h_out_a + h_out_b · v`` (ISO 6946 annex C: 4 + 4 v); long-wave
    exchange ``emissivity · sigma · F (T⁴ - T_s⁴)`` with the sky (view factor
    ``F_sky = (1 + cos tilt)/2``) and with the ground at air temperature
    (``(1 - cos tilt)/2``). By default (``sky_air_split``) the sky view is
    divided as in EnergyPlus: ``beta = sqrt(F_sky)`` of it at the sky
    temperature, the rest, the sky near the horizon, at air temperature (a wall
    sees 0.354 sky, a roof 1). The exchange is written ``h_r (T - T_s)`` with the
    exact secant coefficient ``h_r = emissivity sigma F (T² + T_s²)(T + T_s)``
    evaluated with the surface temperature of the previous step (lagged one
    step): the step is then linear, and energy is conserved exactly by the
    discrete scheme. The sky temperature comes from ``ir_horizontal`` when
    given, else from Berdahl & Martin's clear-sky emissivity when
    ``relative_humidity`` is given, else from Swinbank's formula.
Inside surfaces
    Constant combined (convective + long-wave) coefficients to the air node,
    the ISO 6946 inside surface resistances for a heated space: walls
    ``1/0.13``, ceiling (heat up) ``1/0.10``, floor (heat down) ``1/0.17`` W/(m²·K).
Time stepping
    Backward Euler on the forcing clock, refined to at most ``max_step``
    seconds with boundary conditions interpolated linearly between samples.
    The matrix changes each step only on the diagonal entries of the six
    outside-surface nodes and (free-float) of the air node; each step solves
    with a factorisation made once per run and a Woodbury correction of rank 6
    or 7 (:class:`~bayescal.simulators.diagonal_update.DiagonalUpdateSolver`).
Modes
    ``"coheating"``: the inside air temperature ``temp_air_in`` is imposed; the
    output ``heating_power`` [W] is the heat that must be added to the air node
    to follow it (negative when it must be removed). ``"freefloat"``: the
    heat input ``heat_input`` [W] (optional, 0 when absent) is imposed; the
    output is ``temp_air_in``.
Initial condition
    The steady state with the first sample's temperatures, wind, sky and
    control input and no sun. Sample 0 of the output is that state.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from scipy.constants import Stefan_Boltzmann, zero_Celsius
from scipy.linalg import solve

from bayescal.errors import SimulatorError
from bayescal.simulators import box_solar, solar
from bayescal.simulators.base import Forcing, check_parameters
from bayescal.simulators.box_flows import BoxRun, Drivers
from bayescal.simulators.diagonal_update import DiagonalUpdateSolver
from bayescal.simulators.fvm import Layer, Mesh, build_mesh

FACES = ("front", "side_cw", "back", "side_ccw", "roof", "floor")
"""Face names: ``front`` holds the window and faces ``window_azimuth``;
``side_cw``/``back``/``side_ccw`` face 90°/180°/270° clockwise from it."""

MODES = ("coheating", "freefloat")

RHO_C_AIR = 1.204 * 1006.0
"""Volumetric heat capacity of air at 20 °C and 101.325 kPa. [J/(m³·K)]"""

DEFAULTS: dict[str, float] = {
    "k_wall": 0.125,
    "d_wall": 2250.0,
    "c_wall": 800.0,
    "r_ag": 0.26,
    "t_w": 0.61,
    "emissivity": 0.85,
    "absorptivity": 0.4,
    "thickness": 0.12,
    "side": 0.96,
    "glazed_side": 0.52,
    "r_glass": 0.008,
    "emissivity_glass": 0.84,
    "h_in_wall": 1.0 / 0.13,
    "h_in_ceiling": 1.0 / 0.10,
    "h_in_floor": 1.0 / 0.17,
    "h_out_a": 4.0,
    "h_out_b": 4.0,
    "albedo": 0.2,
    "reflectance_w": 0.075,
    "absorptivity_in": 0.4,
    "c_internal": 0.0,
    "ua_leak": 0.0,
}
"""Nominal values (paper's Table 5 for the first seven). Units: ``k_wall``
[W/(m·K)], ``d_wall`` [kg/m³], ``c_wall`` [J/(kg·K)], ``r_ag`` and ``r_glass``
(both panes) [m²·K/W], ``t_w``, emissivities, ``absorptivity``, ``albedo`` [-],
``reflectance_w`` (the window's normal-incidence solar reflectance; 0.075 as the
outer pane of ``models/test_box.epJSON``) and ``absorptivity_in`` (the inside
faces' solar absorptance) [-], both read by ``window_model = "layers"`` only,
``thickness``, ``side`` (inner edge) and ``glazed_side`` [m], ``h_in_*`` and
``h_out_a`` [W/(m²·K)], ``h_out_b`` [J/(m³·K)], ``c_internal`` [J/K] (extra
capacity on the air node), ``ua_leak`` [W/K] (air leakage or thermal bridges
from the air node to outside air)."""

_POSITIVE = (
    *("k_wall", "d_wall", "c_wall", "thickness", "side"),
    *("h_in_wall", "h_in_ceiling", "h_in_floor"),
)
_NON_NEGATIVE = ("r_ag", "r_glass", "h_out_a", "h_out_b", "c_internal", "ua_leak", "glazed_side")
_FRACTIONS = (
    *("t_w", "reflectance_w", "emissivity", "absorptivity", "absorptivity_in"),
    *("emissivity_glass", "albedo"),
)
PAPER_PARAMETERS = ("k_wall", "d_wall", "r_ag", "t_w")
N_EXT = 7  # exterior surfaces: six faces and the window


@dataclass(frozen=True)
class Geometry:
    """Orientation and areas of the box's exterior surfaces (six faces, then the window).

    Attributes
    ----------
    tilt, azimuth
        Tilt and azimuth of each exterior surface, shape ``(7,)``. [°]
    area
        Opaque area of each face, shape ``(6,)``. [m²]
    window_area
        Glazed area. [m²]
    h_in
        Inside surface coefficient of each face, shape ``(6,)``. [W/(m²·K)]
    solar_share
        Share of the transmitted solar power (``window_model = "layers"``: of its
        diffuse part) that falls first on each face's inside surface, in
        proportion to the areas of the five faces other than the front, shape
        ``(6,)``. [-]
    f_sky, f_air
        Long-wave view factors at the sky temperature and at outside air
        temperature (ground, and the sky near the horizon when the sky view is
        split), shape ``(7,)`` (:func:`~bayescal.simulators.solar.longwave_view_factors`). [-]
    """

    tilt: np.ndarray
    azimuth: np.ndarray
    area: np.ndarray
    window_area: float
    h_in: np.ndarray
    solar_share: np.ndarray
    f_sky: np.ndarray
    f_air: np.ndarray


def box_geometry(
    values: Mapping[str, float], window_azimuth: float, sky_air_split: bool = True
) -> Geometry:
    """Geometry of the box from its constants (see :data:`DEFAULTS`)."""
    side, glazed = values["side"], values["glazed_side"]
    offsets = np.array([0.0, 90.0, 180.0, 270.0, 0.0, 0.0, 0.0])
    azimuth = (window_azimuth + offsets) % 360.0
    tilt = np.array([90.0, 90.0, 90.0, 90.0, 0.0, 180.0, 90.0])
    inner = np.full(6, side**2)
    area = inner.copy()
    area[0] -= glazed**2
    h_in = np.array([values["h_in_wall"]] * 4 + [values["h_in_ceiling"], values["h_in_floor"]])
    receiving = inner * (np.arange(6) != 0)
    views = np.array([solar.longwave_view_factors(t, sky_air_split) for t in tilt])
    return Geometry(
        tilt=tilt,
        azimuth=azimuth,
        area=area,
        window_area=glazed**2,
        h_in=h_in,
        solar_share=receiving / receiving.sum(),
        f_sky=views[:, 0],
        f_air=views[:, 1],
    )


def steady_ua(
    values: Mapping[str, float], wind_speed: float = 0.0, temp_radiant: float = 10.0
) -> float:
    """Steady heat-loss coefficient of the box, air node to outside. [W/K]

    Long-wave exchange is linearised as ``4 emissivity sigma T_m³`` with sky and
    ground both at outside air temperature.

    Parameters
    ----------
    values
        Box constants (all keys of :data:`DEFAULTS`).
    wind_speed
        Wind speed. [m/s]
    temp_radiant
        Mean temperature ``T_m`` of the linearisation. [°C]
    """
    geo = box_geometry(values, 180.0)
    h_c = float(solar.exterior_convection(wind_speed, values["h_out_a"], values["h_out_b"]))
    rad = 4.0 * Stefan_Boltzmann * (temp_radiant + zero_Celsius) ** 3
    r_wall = values["thickness"] / values["k_wall"]
    h_out = h_c + values["emissivity"] * rad
    ua_faces = geo.area / (1.0 / geo.h_in + r_wall + 1.0 / h_out)
    h_out_w = h_c + values["emissivity_glass"] * rad
    r_w = 1.0 / values["h_in_wall"] + values["r_glass"] + values["r_ag"] + 1.0 / h_out_w
    return float(ua_faces.sum() + geo.window_area / r_w + values["ua_leak"])


@dataclass(frozen=True)
class System:
    """The assembled linear system of the box (faces, then the air node).

    Attributes
    ----------
    mesh
        Mesh of one face, per unit area.
    capacity
        Node heat capacities, shape ``(n_nodes,)``. [J/K]
    conduction
        Conductance matrix without exterior or window terms, shape
        ``(n_nodes, n_nodes)``. [W/K]
    outside, inside
        Node index of each face's outside and inside surface, shape ``(6,)``.
    air
        Index of the air node (the last).
    """

    mesh: Mesh
    capacity: np.ndarray
    conduction: np.ndarray
    outside: np.ndarray
    inside: np.ndarray
    air: int


def assemble(values: Mapping[str, float], geo: Geometry, cells: int) -> System:
    """Stack six copies of the wall mesh and the air node into one system."""
    layer = Layer("wall", values["thickness"], values["k_wall"], values["d_wall"], values["c_wall"])
    mesh = build_mesh([layer], cells=[cells])
    m = mesh.capacity.size
    n = 6 * m + 1
    air = n - 1
    outside = np.arange(6) * m
    inside = outside + m - 1
    g_face = mesh.conduction_matrix().toarray()
    conduction = np.zeros((n, n))
    capacity = np.empty(n)
    for f in range(6):
        block = slice(f * m, (f + 1) * m)
        conduction[block, block] = geo.area[f] * g_face
        capacity[block] = geo.area[f] * mesh.capacity
    g_in = geo.area * geo.h_in
    conduction[inside, inside] += g_in
    conduction[air, air] += g_in.sum()
    conduction[inside, air] -= g_in
    conduction[air, inside] -= g_in
    capacity[air] = values["side"] ** 3 * RHO_C_AIR + values["c_internal"]
    return System(mesh, capacity, conduction, outside, inside, air)


class TestBox:
    """The Annex 58 round-robin test box (module docstring), a :class:`Simulator`.

    Parameters
    ----------
    mode
        ``"coheating"`` (imposed ``temp_air_in``, output ``heating_power``) or
        ``"freefloat"`` (optional ``heat_input``, output ``temp_air_in``).
    latitude
        Site latitude, north positive. [°]
    longitude
        Site longitude, east positive. [°]
    altitude
        Site altitude. [m]
    window_azimuth
        Azimuth the window faces, clockwise from north. [°]
    parameters
        Names of the calibration parameters ``simulate`` accepts (any keys of
        :data:`DEFAULTS`); default the paper's four.
    cells
        Finite-volume cells across the wall.
    max_step
        Longest time step; the forcing step is divided evenly below it. [s]
    sky_model
        Sky-diffuse transposition model (``"isotropic"``, ``"haydavies"``,
        ``"perez"``).
    sky_air_split
        Divide each face's long-wave sky view between the sky temperature and
        the air temperature as EnergyPlus does
        (:func:`~bayescal.simulators.solar.longwave_view_factors`); ``False``
        puts the whole sky view at the sky temperature.
    window_model
        ``"transmittance"`` (the paper's): the glazing transmits ``t_w`` and
        absorbs nothing, the inside faces absorb all the light that enters;
        ``"layers"``: the glazing also absorbs, the beam falls where the sun's
        direction takes it and the inside faces reflect (module docstring,
        "Window").
    **constants
        Values overriding :data:`DEFAULTS` (units there).
    """

    __test__ = False  # not a pytest test class despite its name

    def __init__(
        self,
        *,
        mode: str,
        latitude: float,
        longitude: float,
        altitude: float = 0.0,
        window_azimuth: float = 180.0,
        parameters: tuple[str, ...] = PAPER_PARAMETERS,
        cells: int = 20,
        max_step: float = 600.0,
        sky_model: str = "haydavies",
        sky_air_split: bool = True,
        window_model: str = "transmittance",
        **constants: float,
    ) -> None:
        if mode not in MODES:
            raise SimulatorError(f"TestBox mode must be one of {MODES}, got {mode!r}")
        if sky_model not in solar.SKY_MODELS:
            raise SimulatorError(f"unknown sky_model {sky_model!r}; use one of {solar.SKY_MODELS}")
        if window_model not in box_solar.WINDOW_MODELS:
            raise SimulatorError(
                f"unknown window_model {window_model!r}; use one of {box_solar.WINDOW_MODELS}"
            )
        if int(cells) < 1 or not max_step > 0:
            raise SimulatorError(
                f"cells must be >= 1 and max_step > 0, got {cells!r}, {max_step!r}"
            )
        check_parameters(constants, tuple(DEFAULTS), "TestBox")
        unknown = sorted(set(parameters) - set(DEFAULTS))
        if unknown:
            raise SimulatorError(
                f"TestBox has no parameter(s) {unknown}; choose among {sorted(DEFAULTS)}"
            )
        self.mode = mode
        self.latitude = float(latitude)
        self.longitude = float(longitude)
        self.altitude = float(altitude)
        self.window_azimuth = float(window_azimuth)
        self.cells = int(cells)
        self.max_step = float(max_step)
        self.sky_model = sky_model
        self.sky_air_split = bool(sky_air_split)
        self.window_model = window_model
        self.constants = {**DEFAULTS, **{k: float(v) for k, v in constants.items()}}
        self._parameters = tuple(parameters)
        _check_values(self.constants, self.window_model)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the calibration parameters."""
        return self._parameters

    @property
    def input_names(self) -> tuple[str, ...]:
        """Required boundary conditions."""
        control = ("temp_air_in",) if self.mode == "coheating" else ()
        return ("temp_air_out", "ghi", "dhi", "wind_speed", *control)

    @property
    def optional_input_names(self) -> tuple[str, ...]:
        """Boundary conditions used when present."""
        control = ("heat_input",) if self.mode == "freefloat" else ()
        return ("ir_horizontal", "relative_humidity", *control)

    @property
    def output_names(self) -> tuple[str, ...]:
        """The mode's output."""
        return ("heating_power",) if self.mode == "coheating" else ("temp_air_in",)

    def values(self, parameters: Mapping[str, float] | None = None) -> dict[str, float]:
        """Constants with ``parameters`` (calibration parameters only) applied."""
        parameters = dict(parameters or {})
        check_parameters(parameters, self._parameters, "TestBox")
        values = {**self.constants, **{k: float(v) for k, v in parameters.items()}}
        _check_values(values, self.window_model)
        return values

    def steady_ua(
        self,
        parameters: Mapping[str, float] | None = None,
        *,
        wind_speed: float = 0.0,
        temp_radiant: float = 10.0,
    ) -> float:
        """Steady heat-loss coefficient, air node to outside (:func:`steady_ua`). [W/K]"""
        return steady_ua(self.values(parameters), wind_speed, temp_radiant)

    derived_units: ClassVar[Mapping[str, tuple[str, str]]] = {  # Derivable's summaries
        "UA": ("W/K", "steady heat-loss coefficient, air node to outside, without wind"),
        "R_wall": ("m²·K/W", "thermal resistance of the walls (thickness / k_wall)"),
    }

    def derived(self, parameters: Mapping[str, float]) -> dict[str, float]:
        """Steady heat-loss coefficient and the walls' resistance at ``parameters``."""
        values = self.values(parameters)
        r_wall = values["thickness"] / values["k_wall"]
        return {"UA": steady_ua(values, 0.0, 10.0), "R_wall": r_wall}

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        """Run once; outputs at the forcing's instants (see the module docstring)."""
        run = self.run(parameters, forcing)
        k = _substeps(forcing.step, self.max_step)
        name = self.output_names[0]
        series = run.heat_to_air if self.mode == "coheating" else run.temp_air_in
        return {name: series[::k].copy()}

    def run(self, parameters: Mapping[str, float], forcing: Forcing) -> BoxRun:
        """Run once and return every node temperature and energy flow (:class:`BoxRun`)."""
        values = self.values(parameters)
        forcing.require(list(self.input_names), "TestBox")
        if forcing.n < 2:
            raise SimulatorError(f"TestBox needs at least 2 forcing samples, got {forcing.n}")
        k = _substeps(forcing.step, self.max_step)
        dt = forcing.step / k
        series = forcing.refined(k, self.input_names + self.optional_input_names).series
        offsets = (np.arange(series["ghi"].size) * dt * 1e9).astype("timedelta64[ns]")
        times = np.asarray(forcing.start, dtype="datetime64[ns]") + offsets
        geo = box_geometry(values, self.window_azimuth, self.sky_air_split)
        drivers = self._drivers(values, geo, series, times)
        system = assemble(values, geo, self.cells)
        return _march(values, geo, system, drivers, dt, self.mode)

    def _drivers(
        self,
        values: Mapping[str, float],
        geo: Geometry,
        series: Mapping[str, np.ndarray],
        times: np.ndarray,
    ) -> Drivers:
        temp_out = series["temp_air_out"]
        if "ir_horizontal" in series:
            temp_sky = solar.sky_temperature_from_ir(series["ir_horizontal"])
        elif "relative_humidity" in series:
            temp_sky = solar.sky_temperature_berdahl_martin(temp_out, series["relative_humidity"])
        else:
            temp_sky = solar.sky_temperature_swinbank(temp_out)
        sky = solar.sun_and_sky(
            times, series["ghi"], series["dhi"], self.latitude, self.longitude, self.altitude
        )
        planes = [
            solar.plane_irradiance(
                float(t), float(a), sky, albedo=values["albedo"], model=self.sky_model
            )
            for t, a in zip(geo.tilt[:6], geo.azimuth[:6], strict=True)
        ]
        solar_out = values["absorptivity"] * geo.area * np.column_stack([p.total for p in planes])
        solar_in, returned, absorbed = box_solar.window_solar(
            values, geo, planes[0], sky, self.window_azimuth, self.window_model
        )
        if self.mode == "coheating":
            control = series["temp_air_in"]
        else:
            control = series.get("heat_input", np.zeros_like(temp_out))
        return Drivers(
            temp_out=temp_out,
            temp_sky=temp_sky,
            h_conv=solar.exterior_convection(
                series["wind_speed"], values["h_out_a"], values["h_out_b"]
            ),
            solar_out=solar_out,
            solar_in=solar_in,
            solar_returned=returned,
            window_absorbed=absorbed,
            control=control,
        )


def _check_values(values: Mapping[str, float], window_model: str = "transmittance") -> None:
    for name in _POSITIVE:
        if not values[name] > 0:
            raise SimulatorError(f"TestBox: {name} must be > 0, got {values[name]!r}")
    for name in _NON_NEGATIVE:
        if not values[name] >= 0:
            raise SimulatorError(f"TestBox: {name} must be >= 0, got {values[name]!r}")
    for name in _FRACTIONS:
        if not 0 <= values[name] <= 1:
            raise SimulatorError(f"TestBox: {name} must be in [0, 1], got {values[name]!r}")
    passed = values["t_w"] + values["reflectance_w"]
    if window_model == "layers" and not 0.05 <= passed <= 1.0:
        raise SimulatorError(
            f"TestBox: t_w + reflectance_w must be in [0.05, 1] (the glazing absorbs the rest; "
            f"glass reflects at least 4 %), got {values['t_w']!r} + {values['reflectance_w']!r}"
        )
    if values["glazed_side"] >= values["side"]:
        raise SimulatorError(
            f"TestBox: glazed_side ({values['glazed_side']!r} m) must be smaller than "
            f"side ({values['side']!r} m)"
        )


def _substeps(step: float, max_step: float) -> int:
    return max(1, int(np.ceil(step / max_step - 1e-9)))


@dataclass(frozen=True)
class _Exterior:
    """Exterior coefficients of the seven exterior surfaces at one instant."""

    h_out: np.ndarray  # total coefficient, shape (7,) [W/(m²·K)]
    num: np.ndarray  # sum of coefficient x driving temperature, shape (7,) [W/m²]


def _radiation_constants(values: Mapping[str, float], geo: Geometry) -> tuple[np.ndarray, ...]:
    """``emissivity * F * sigma`` to the sky and to the air temperature, shape ``(7,)`` each."""
    eps = np.array([values["emissivity"]] * 6 + [values["emissivity_glass"]])
    return eps * geo.f_sky * Stefan_Boltzmann, eps * geo.f_air * Stefan_Boltzmann


def _exterior(rad: tuple[np.ndarray, ...], d: Drivers, j: int, t_surf: np.ndarray) -> _Exterior:
    """Convective plus secant long-wave coefficients given surface temperatures ``t_surf``."""
    c_sky, c_air = rad
    ts = t_surf + zero_Celsius
    ts2 = ts * ts
    tsky = d.temp_sky[j] + zero_Celsius
    tair = d.temp_out[j] + zero_Celsius
    h_sky = c_sky * (ts2 + tsky * tsky) * (ts + tsky)
    h_air = c_air * (ts2 + tair * tair) * (ts + tair)
    h_out = d.h_conv[j] + h_sky + h_air
    num = (d.h_conv[j] + h_air) * d.temp_out[j] + h_sky * d.temp_sky[j]
    num[6] += d.window_absorbed[j]
    return _Exterior(h_out, num)


def _window_u(values: Mapping[str, float], h_out: float | np.ndarray) -> float | np.ndarray:
    """Window transmittance, air node to the outside equivalent temperature. [W/(m²·K)]"""
    return 1.0 / (1.0 / values["h_in_wall"] + values["r_glass"] + values["r_ag"] + 1.0 / h_out)


def _window_surface(values: Mapping[str, float], ext: _Exterior, temp_air: float) -> float:
    """Outside glass temperature given the air temperature and exterior coefficients. [°C]"""
    t_eq = ext.num[6] / ext.h_out[6]
    return float(t_eq + _window_u(values, ext.h_out[6]) / ext.h_out[6] * (temp_air - t_eq))


def _air_row(
    a: np.ndarray,
    b: np.ndarray,
    sys: System,
    values: Mapping[str, float],
    mode: str,
    window_conductance: float,
    t_eq: float,
    temp_out: float,
    control: float,
) -> None:
    """Window, leakage and control terms of the air node's equation (in place)."""
    if mode == "coheating":
        a[sys.air, :] = 0.0
        a[sys.air, sys.air] = 1.0
        b[sys.air] = control
    else:
        a[sys.air, sys.air] += window_conductance + values["ua_leak"]
        b[sys.air] += window_conductance * t_eq + values["ua_leak"] * temp_out + control


def _steady_matrix(
    values: Mapping[str, float], geo: Geometry, sys: System, d: Drivers, ext: _Exterior, mode: str
) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state matrix and right-hand side at sample 0, without sun."""
    a, b = sys.conduction.copy(), np.zeros(sys.capacity.size)
    a[sys.outside, sys.outside] += geo.area * ext.h_out[:6]
    b[sys.outside] = geo.area * ext.num[:6]
    g_w = geo.window_area * _window_u(values, ext.h_out[6])
    t_eq = ext.num[6] / ext.h_out[6]
    _air_row(a, b, sys, values, mode, float(g_w), t_eq, d.temp_out[0], d.control[0])
    return a, b


def _initial(
    values: Mapping[str, float],
    geo: Geometry,
    sys: System,
    d: Drivers,
    mode: str,
    rad: tuple[np.ndarray, ...],
) -> tuple[np.ndarray, _Exterior]:
    """Steady state with the first sample's conditions and no sun.

    The secant long-wave coefficients depend on the surface temperatures; a
    fixed-point iteration from surfaces at air temperature converges to
    round-off in a few sweeps (the coefficients change by ~1 % per kelvin).
    """
    t_surf = np.full(N_EXT, d.temp_out[0])
    for _ in range(8):
        ext = _exterior(rad, d, 0, t_surf)
        x = solve(*_steady_matrix(values, geo, sys, d, ext, mode))
        t_surf = np.append(x[sys.outside], _window_surface(values, ext, x[sys.air]))
    ext = _exterior(rad, d, 0, t_surf)
    return solve(*_steady_matrix(values, geo, sys, d, ext, mode)), ext


def _stepper(
    values: Mapping[str, float],
    geo: Geometry,
    sys: System,
    ext: _Exterior,
    dt: float,
    mode: str,
) -> DiagonalUpdateSolver:
    """Backward-Euler matrix with the initial exterior coefficients, factorised."""
    a0 = np.diag(sys.capacity / dt) + sys.conduction
    base = geo.area * ext.h_out[:6]
    a0[sys.outside, sys.outside] += base
    if mode == "coheating":
        a0[sys.air, :] = 0.0
        a0[sys.air, sys.air] = sys.capacity[sys.air] / dt  # scaled identity row
        return DiagonalUpdateSolver.build(a0, sys.outside, base)
    g_w = geo.window_area * float(_window_u(values, ext.h_out[6]))
    a0[sys.air, sys.air] += g_w
    a0[sys.air, sys.air] += values["ua_leak"]
    return DiagonalUpdateSolver.build(a0, np.append(sys.outside, sys.air), np.append(base, g_w))


def _march(
    values: Mapping[str, float],
    geo: Geometry,
    sys: System,
    d: Drivers,
    dt: float,
    mode: str,
) -> BoxRun:
    """Backward-Euler time stepping (module docstring)."""
    n, nn = d.temp_out.size, sys.capacity.size
    free = mode == "freefloat"
    rad = _radiation_constants(values, geo)
    x, ext = _initial(values, geo, sys, d, mode, rad)
    solver = _stepper(values, geo, sys, ext, dt, mode)
    cap_dt = sys.capacity / dt
    leak = values["ua_leak"]
    diagonal = solver.base.copy()
    temps, h_out, num = np.empty((n, nn)), np.empty((n, N_EXT)), np.empty((n, N_EXT))
    temps[0], h_out[0], num[0] = x, ext.h_out, ext.num
    t_surf = np.empty(N_EXT)
    for j in range(1, n):
        t_surf[:6] = x[sys.outside]
        t_surf[6] = _window_surface(values, ext, x[sys.air])
        ext = _exterior(rad, d, j, t_surf)
        rhs = cap_dt * x
        rhs[sys.outside] += geo.area * ext.num[:6] + d.solar_out[j]
        rhs[sys.inside] += d.solar_in[j]
        diagonal[:6] = geo.area * ext.h_out[:6]
        if free:
            g_w = geo.window_area * _window_u(values, ext.h_out[6])
            diagonal[6] = g_w
            rhs[sys.air] += g_w * ext.num[6] / ext.h_out[6] + leak * d.temp_out[j] + d.control[j]
        else:
            rhs[sys.air] = cap_dt[sys.air] * d.control[j]
        x = solver.solve(rhs, diagonal)
        temps[j], h_out[j], num[j] = x, ext.h_out, ext.num
    return _account(values, geo, sys, d, dt, temps, h_out, num, mode)


def _account(
    values: Mapping[str, float],
    geo: Geometry,
    sys: System,
    d: Drivers,
    dt: float,
    temps: np.ndarray,
    h_out: np.ndarray,
    num: np.ndarray,
    mode: str,
) -> BoxRun:
    """Energy flows of every step from the solved temperatures."""
    t_air = temps[:, sys.air]
    u_w = _window_u(values, h_out[:, 6])
    window = geo.window_area * u_w * (num[:, 6] / h_out[:, 6] - t_air)
    leak = values["ua_leak"] * (d.temp_out - t_air)
    to_surfaces = (geo.area * geo.h_in * (t_air[:, None] - temps[:, sys.inside])).sum(axis=1)
    rate = np.zeros_like(t_air)
    rate[1:] = sys.capacity[sys.air] * np.diff(t_air) / dt
    # Coheating: the heat the air node needs to follow the imposed temperature;
    # free-float: the imposed heat input itself.
    heat_to_air = rate + to_surfaces - window - leak if mode == "coheating" else d.control
    exterior = geo.area * (num[:, :6] - h_out[:, :6] * temps[:, sys.outside]) + d.solar_out
    # The initial state is a steady state without sun: its solar flows are zero.
    exterior[0] -= d.solar_out[0]
    transmitted = d.solar_in.sum(axis=1) + d.solar_returned
    transmitted[0] = 0.0
    returned = d.solar_returned.copy()
    returned[0] = 0.0
    return BoxRun(
        dt=dt,
        temperatures=temps,
        capacity=sys.capacity,
        heat_to_air=heat_to_air,
        exterior=exterior,
        window=window,
        leak=leak,
        solar_transmitted=transmitted,
        solar_returned=returned,
        solar_glazing=geo.window_area * d.window_absorbed,
    )
