"""The built-in multilayer wall: 1-D transient conduction by finite volumes.

The wall is discretised in space by the vertex-centred finite volumes of
:mod:`bayescal.simulators.fvm` (nodes on both faces and on every layer
interface) and integrated in time by an implicit one-step scheme. The
semi-discrete system ``C dT/dt = -G T + B u(t)`` is linear with constant
coefficients, so for each parameter set it is diagonalised once
(``G v = lambda C v``, a symmetric tridiagonal eigenproblem) and the
propagation over one clock step is precomputed mode by mode. A run is then
one first-order recursion (``scipy.signal.lfilter``) per slow mode plus a few
matrix products; modes that decay within one clock step are quasi-static and
folded into direct feed-through. The paper's wall over 1500 half-hourly steps
takes about 1.5 ms, set-up included (``benchmarks/bench_simulators.py``).

Time convention
---------------
Inputs are sampled at the clock's instants and linear in between (see
:mod:`bayescal.simulators.base`); outputs are the values at the instants.
All three schemes below reproduce the particular solution of a mode driven
by a linear input exactly, so within a clock step the update of each mode is
``z[k+1] = a z[k] + b0 f[k] + b1 f[k+1]`` with ``a`` the scheme's decay factor
over the step (``R(-lambda h)**M`` for ``M`` sub-steps of length ``h``) and
``b0``, ``b1`` following from ``a`` in closed form.

Schemes
-------
``"crank-nicolson"`` (default)
    Trapezoidal rule on ``M`` sub-steps of each clock step. ``M`` is chosen
    so that ``lambda h <= 2`` for every mode (the amplification factor is
    then non-negative: no ringing after steps or kinks of the input) and so
    that the scheme's frequency error at the shortest resolvable period is
    below a tenth of ``tolerance``. Since the sub-steps are folded into the
    per-mode coefficients, they cost nothing at run time. One plain
    Crank-Nicolson step per clock step would ring: its stiff modes flip sign
    every step after each kink of the measured input (on the Annex 58 Twin
    House wall this raised the inside-flux RMSE from 0.46 to 0.63 W/m²).
``"backward-euler"``
    Implicit Euler on sub-steps chosen for the same accuracy (first order, so
    many more of them, still free at run time); kept for comparison.
``"exact"``
    Exact integration of the semi-discrete system for piecewise-linear
    inputs (``a = exp(-lambda dt)``); only the spatial error is left.

Tolerance
---------
``tolerance`` bounds the relative error of the discrete wall's periodic
response (surface admittances, and transmittances relative to the admittance
of the same face) at every period from two clock steps up to steady state.
The vertex-centred scheme's surface admittance has relative error
``(dx / delta)**2 / 4`` to leading order (``delta`` the penetration depth),
so each layer's cells are at most ``1.8 sqrt(tolerance) delta`` wide, with
``delta`` taken at the period of two clock steps; at longer periods the
error falls in proportion to the period. The time scheme gets a tenth of
the tolerance. Steady state is exact on any mesh. With the default 1e-2 the
paper wall's step response is within 1e-4 W/m² per kelvin of the exact one
and its 24 h transmittance within 0.03 %. Periods shorter than two clock steps are
not resolved by the clock and not covered.

Initial condition
-----------------
The wall starts in steady state for the boundary conditions of the first
sample. Discard a warm-up of a few time constants of the wall (days for
heavy walls) before comparing with measurements.

Boundary conditions and outputs
-------------------------------
``boundary="surface"`` imposes the surface temperatures ``temp_surf_out``
and ``temp_surf_in``. The surface fluxes are the energy-consistent ones of
the scheme: conduction through the first cell plus storage in the surface
half cell, whose temperature rate is the mean of the slopes of the two clock
intervals beside the instant (one-sided at the ends of the run). Over a run
that starts and ends in steady state, the trapezoidal sum of
``heat_flux_out - heat_flux_in`` then equals the change of stored heat
exactly. ``boundary="air"`` imposes ``temp_air_out`` and ``temp_air_in``
through the surface resistances ``r_se`` and ``r_si`` and adds the absorbed
solar irradiance ``solar_absorptance * poa_global_out`` at the outside face.

Outputs: ``heat_flux_in`` (positive wall -> room), ``heat_flux_out``
(positive outside -> wall, absorbed solar included), ``temp_surf_out``,
``temp_surf_in`` and, for interface ``i`` between layers ``i-1`` and ``i``
(layers counted from 0 at the outside), ``temp_interface_i`` and
``heat_flux_interface_i`` (positive outside -> inside; the flux leaving the
outer layer, i.e. conduction in its last cell less the storage of its half
cell at the interface node).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.linalg import eigh_tridiagonal
from scipy.signal import lfilter

from bayescal.errors import SimulatorError
from bayescal.simulators.base import Forcing, check_parameters
from bayescal.simulators.fvm import LAYER_PROPERTIES, Layer, Mesh, build_mesh

SCHEMES = ("crank-nicolson", "backward-euler", "exact")
BOUNDARIES = ("surface", "air")
WALL_TARGETS = ("r_se", "r_si", "solar_absorptance")
_WHO = "MultilayerWall"
# Below this value of lambda*dt the per-mode coefficients use their Taylor series.
_SMALL_RATE_STEP = 1e-3
# Modes whose per-step decay factor is below this are treated as quasi-static.
_NEGLIGIBLE_DECAY = 1e-18
# Cell width / (sqrt(tolerance) * penetration depth): the leading admittance error
# (dx/delta)^2/4 is then 0.81 tolerance, leaving room for the higher-order terms.
_CELL_FACTOR = 1.8


#: The wall's derived quantities: name -> (unit, description).
WALL_DERIVED = {
    "R_wall": ("m²·K/W", "thermal resistance of the layers, surface to surface"),
    "U_value": ("W/(m²·K)", "thermal transmittance with the surface resistances r_si, r_se"),
    "areal_heat_capacity": ("J/(m²·K)", "sum of density x specific heat x thickness of the layers"),
}


@dataclass(frozen=True)
class WallState:
    """Physical description of the wall for one parameter set.

    Parameters
    ----------
    layers
        Layers from the outside face to the inside face.
    r_se
        Outside surface resistance. [m²·K/W]
    r_si
        Inside surface resistance. [m²·K/W]
    solar_absorptance
        Solar absorptance of the outside face. [-]
    """

    layers: tuple[Layer, ...]
    r_se: float
    r_si: float
    solar_absorptance: float


@dataclass(frozen=True)
class Propagator:
    """Modal form of the discretised wall for one parameter set and clock step.

    Only the slow modes (those that do not decay within one clock step)
    carry a state: ``z[k] = decay * z[k-1] + b_start * f[k-1] + b_end * f[k]``
    with modal forcing ``f = u @ modal_forcing.T``, starting from the steady
    state ``z[0] = f[0] / rates``. The fast modes are quasi-static and folded
    into the feed-through maps. Outputs:
    ``y[k] = z[k] @ out_state.T + u[k] @ out_input.T + u[k-1] @ out_previous.T
    + du[k] @ out_rate.T``, with ``u[-1] = u[0]`` and ``du`` the inputs' rates.

    Attributes
    ----------
    rates
        Decay rates ``lambda`` of the slow modes, shape ``(n_slow,)``. [1/s]
    decay, b_start, b_end
        Per-mode step coefficients, shape ``(n_slow,)``; ``b_*`` in [s].
    modal_forcing
        Shape ``(n_slow, n_inputs)``. [W/(m²·K) per J^½]
    out_state
        Shape ``(n_outputs, n_slow)``.
    out_input, out_previous, out_rate
        Shape ``(n_outputs, n_inputs)`` each.
    mesh
        The mesh used.
    substeps
        Sub-steps per clock step of the time scheme.
    max_rate
        Largest modal decay rate of the mesh. [1/s]
    """

    rates: np.ndarray
    decay: np.ndarray
    b_start: np.ndarray
    b_end: np.ndarray
    modal_forcing: np.ndarray
    out_state: np.ndarray
    out_input: np.ndarray
    out_previous: np.ndarray
    out_rate: np.ndarray
    mesh: Mesh
    substeps: int
    max_rate: float


class MultilayerWall:
    """1-D transient conduction through a layered wall (the built-in wall simulator).

    Parameters
    ----------
    layers
        Layers from the outside face to the inside face; names must be unique.
    parameters
        Calibration parameter name -> target(s) it sets: ``"layer.property"``
        with property one of ``thickness``, ``conductivity``, ``density``,
        ``specific_heat``, or one of ``r_se``, ``r_si``, ``solar_absorptance``
        (the latter three with ``boundary="air"`` only). Example:
        ``{"k_cb": ["concrete.conductivity"],
        "cp_fb": ["fb_out.specific_heat", "fb_in.specific_heat"]}``.
    boundary
        ``"surface"`` (imposed surface temperatures) or ``"air"`` (imposed air
        temperatures through surface resistances).
    r_se
        Outside surface resistance, used with ``boundary="air"``. [m²·K/W]
    r_si
        Inside surface resistance, used with ``boundary="air"``. [m²·K/W]
    solar_absorptance
        Solar absorptance of the outside face; > 0 needs ``boundary="air"``
        and the input ``poa_global_out``. [-]
    outputs
        Names of the series returned (see the module docstring).
    scheme
        ``"crank-nicolson"``, ``"backward-euler"`` or ``"exact"``.
    tolerance
        Relative error bound of the periodic response down to the period of
        two clock steps (see the module docstring). [-]
    cells
        Number of cells per layer; overrides the choice from ``tolerance``.
    """

    def __init__(
        self,
        layers: Sequence[Layer],
        *,
        parameters: Mapping[str, str | Sequence[str]] | None = None,
        boundary: Literal["surface", "air"] = "surface",
        r_se: float = 0.04,
        r_si: float = 0.13,
        solar_absorptance: float = 0.0,
        outputs: Sequence[str] = ("heat_flux_in",),
        scheme: Literal["crank-nicolson", "backward-euler", "exact"] = "crank-nicolson",
        tolerance: float = 1e-2,
        cells: Sequence[int] | None = None,
    ) -> None:
        self._nominal = WallState(tuple(layers), float(r_se), float(r_si), float(solar_absorptance))
        self._boundary = _check_choice(boundary, BOUNDARIES, "boundary")
        self._scheme = _check_choice(scheme, SCHEMES, "scheme")
        self._tolerance = _check_tolerance(tolerance)
        _check_layers(self._nominal.layers)
        _check_wall_values(self._nominal, self._boundary, "constructor argument")
        self._cells = _check_cells(cells, len(self._nominal.layers), self._boundary)
        self._targets = _parse_targets(parameters or {}, self._nominal.layers, self._boundary)
        self._outputs = _check_outputs(tuple(outputs), len(self._nominal.layers))
        solar = self._nominal.solar_absorptance > 0 or any(
            "solar_absorptance" in t for t in self._targets.values()
        )
        if self._boundary == "surface":
            self._inputs: tuple[str, ...] = ("temp_surf_out", "temp_surf_in")
        else:
            self._inputs = ("temp_air_out", "temp_air_in") + (("poa_global_out",) if solar else ())

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the calibration parameters ``simulate`` accepts."""
        return tuple(self._targets)

    @property
    def input_names(self) -> tuple[str, ...]:
        """Glossary names of the boundary-condition series needed."""
        return self._inputs

    @property
    def output_names(self) -> tuple[str, ...]:
        """Names of the series returned."""
        return self._outputs

    @property
    def layers(self) -> tuple[Layer, ...]:
        """Nominal layers, outside first."""
        return self._nominal.layers

    def wall_state(self, parameters: Mapping[str, float]) -> WallState:
        """The wall with calibration parameter values substituted.

        Parameters
        ----------
        parameters
            Parameter name -> value in physical units; names not given keep
            their nominal values.
        """
        check_parameters(parameters, self.parameter_names, _WHO)
        return _substitute(self._nominal, self._targets, parameters, self._boundary)

    @property
    def derived_units(self) -> dict[str, tuple[str, str]]:
        """The wall's physical summaries (:class:`~bayescal.simulators.base.Derivable`)."""
        return dict(WALL_DERIVED)

    def derived(self, parameters: Mapping[str, float]) -> dict[str, float]:
        """Thermal resistance, U-value and areal heat capacity at ``parameters``.

        ``R_wall`` is the layers' resistance surface to surface, ``U_value``
        adds the surface resistances ``r_si`` and ``r_se`` (EN ISO 6946), and
        ``areal_heat_capacity`` is the sum of density x specific heat x
        thickness of the layers.
        """
        state = self.wall_state(parameters)
        r_wall = sum(la.thickness / la.conductivity for la in state.layers)
        return {
            "R_wall": r_wall,
            "U_value": 1.0 / (r_wall + state.r_si + state.r_se),
            "areal_heat_capacity": sum(
                la.density * la.specific_heat * la.thickness for la in state.layers
            ),
        }

    def propagator(self, parameters: Mapping[str, float], step: float) -> Propagator:
        """Precomputed modal propagation for one parameter set and clock step.

        Parameters
        ----------
        parameters
            Parameter name -> value in physical units.
        step
            Clock step. [s]
        """
        state = self.wall_state(parameters)
        mesh = _wall_mesh(state.layers, step, self._tolerance, self._cells)
        return _build_propagator(
            state,
            mesh,
            self._boundary,
            self._outputs,
            len(self._inputs),
            self._scheme,
            self._tolerance,
            step,
        )

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        """Run once over the forcing's clock.

        Parameters
        ----------
        parameters
            Calibration parameter values in physical units; names not given
            keep the nominal values.
        forcing
            Boundary conditions (``input_names``) on the study clock.

        Returns
        -------
        dict
            Output name -> series of length ``forcing.n``. [W/m² or °C]
        """
        forcing.require(self._inputs, _WHO)
        prop = self.propagator(parameters, forcing.step)
        inputs = np.column_stack([forcing[name] for name in self._inputs])
        values = run_propagator(prop, inputs, forcing.step).T
        return {name: values[i].copy() for i, name in enumerate(self._outputs)}


def run_propagator(prop: Propagator, inputs: np.ndarray, step: float) -> np.ndarray:
    """Integrate the modal system from steady state and evaluate the outputs.

    Parameters
    ----------
    prop
        The precomputed propagation.
    inputs
        Input values at the instants, shape ``(n, n_inputs)``. [°C or W/m²]
    step
        Clock step. [s]

    Returns
    -------
    numpy.ndarray
        Outputs at the instants, shape ``(n, n_outputs)``.
    """
    n = inputs.shape[0]
    if n == 0:
        return np.zeros((0, prop.out_state.shape[0]))
    previous = np.concatenate([inputs[:1], inputs[:-1]])
    values = (
        inputs @ prop.out_input.T
        + previous @ prop.out_previous.T
        + input_rates(inputs, step) @ prop.out_rate.T
    )
    if prop.rates.size:
        forcing = prop.modal_forcing @ inputs.T  # (n_slow, n): one contiguous row per mode
        values += (prop.out_state @ _modal_states(prop, forcing)).T
    return values


def _modal_states(prop: Propagator, forcing: np.ndarray) -> np.ndarray:
    """Slow-mode states from the steady state of the first sample, shape ``(n_slow, n)``.

    ``z[k] = decay z[k-1] + b_start f[k-1] + b_end f[k]`` is a first-order
    filter of the modal forcing; its initial condition gives ``z[0] = f[0] / rate``.
    """
    states = np.empty_like(forcing)
    initial = np.empty(1)
    for j in range(forcing.shape[0]):
        f = forcing[j]
        initial[0] = f[0] / prop.rates[j] - prop.b_end[j] * f[0]
        states[j], _ = lfilter(
            [prop.b_end[j], prop.b_start[j]], [1.0, -prop.decay[j]], f, zi=initial
        )
    return states


def input_rates(inputs: np.ndarray, step: float) -> np.ndarray:
    """Rates of change of piecewise-linear inputs at the instants.

    The mean of the slopes of the two intervals beside each instant,
    one-sided at the ends (so that the trapezoidal integral of a rate over
    the run equals the change of the input).

    Parameters
    ----------
    inputs
        Values at the instants, shape ``(n, n_inputs)``.
    step
        Clock step. [s]
    """
    rates = np.zeros_like(inputs)
    if inputs.shape[0] < 2:
        return rates
    slopes = np.diff(inputs, axis=0) / step
    rates[0] = slopes[0]
    rates[-1] = slopes[-1]
    rates[1:-1] = 0.5 * (slopes[:-1] + slopes[1:])
    return rates


# --------------------------------------------------------------------------- checks


def _check_choice(value: str, allowed: tuple[str, ...], what: str) -> str:
    if value not in allowed:
        raise SimulatorError(f"{_WHO}: {what} must be one of {list(allowed)}, got {value!r}")
    return value


def _check_tolerance(tolerance: float) -> float:
    if not (np.isfinite(tolerance) and 0 < tolerance <= 0.25):
        raise SimulatorError(
            f"{_WHO}: tolerance must be in (0, 0.25], got {tolerance!r}",
            hint="1e-2 (the default) keeps the periodic response within 1 %",
        )
    return float(tolerance)


def _check_cells(
    cells: Sequence[int] | None, n_layers: int, boundary: str
) -> tuple[int, ...] | None:
    if cells is None:
        return None
    counts = tuple(int(c) for c in cells)
    if len(counts) != n_layers or min(counts) < 1 or (boundary == "surface" and sum(counts) < 2):
        raise SimulatorError(
            f"{_WHO}: cells must give a positive count for each of the {n_layers} layers "
            f"(at least 2 cells in all with boundary='surface'), got {list(cells)}",
            hint="or leave cells out and let tolerance choose the mesh",
        )
    return counts


def _check_layers(layers: tuple[Layer, ...]) -> None:
    if not layers:
        raise SimulatorError(f"{_WHO}: a wall needs at least one layer, got none")
    if not all(isinstance(layer, Layer) for layer in layers):
        raise SimulatorError(f"{_WHO}: layers must be fvm.Layer records, got {layers!r}")
    names = [layer.name for layer in layers]
    if len(set(names)) != len(names):
        raise SimulatorError(
            f"{_WHO}: layer names must be unique, got {names}",
            hint="name repeated materials 'eps_1', 'eps_2', ...",
        )


def _check_wall_values(state: WallState, boundary: str, where: str) -> None:
    for name in ("r_se", "r_si"):
        value = getattr(state, name)
        if not (np.isfinite(value) and value > 0):
            raise SimulatorError(f"{_WHO}: {name} must be > 0 m²K/W, got {value!r} ({where})")
    alpha = state.solar_absorptance
    if not (np.isfinite(alpha) and 0 <= alpha <= 1):
        raise SimulatorError(
            f"{_WHO}: solar_absorptance must be in [0, 1], got {alpha!r} ({where})"
        )
    if boundary == "surface" and alpha > 0:
        raise SimulatorError(
            f"{_WHO}: solar_absorptance = {alpha} needs boundary='air'",
            hint="imposed surface temperatures already contain the effect of solar gains",
        )


def allowed_outputs(n_layers: int) -> tuple[str, ...]:
    """Output names available for a wall of ``n_layers`` layers."""
    names = ["heat_flux_in", "heat_flux_out", "temp_surf_out", "temp_surf_in"]
    for i in range(1, n_layers):
        names += [f"temp_interface_{i}", f"heat_flux_interface_{i}"]
    return tuple(names)


def _check_outputs(outputs: tuple[str, ...], n_layers: int) -> tuple[str, ...]:
    allowed = allowed_outputs(n_layers)
    bad = [name for name in outputs if name not in allowed]
    if bad or not outputs or len(set(outputs)) != len(outputs):
        raise SimulatorError(
            f"{_WHO}: outputs must be distinct names from {list(allowed)}, got {list(outputs)}"
        )
    return outputs


def _parse_targets(
    parameters: Mapping[str, str | Sequence[str]], layers: tuple[Layer, ...], boundary: str
) -> dict[str, tuple[str, ...]]:
    layer_names = {layer.name for layer in layers}
    parsed: dict[str, tuple[str, ...]] = {}
    for name, targets in parameters.items():
        items = (targets,) if isinstance(targets, str) else tuple(targets)
        if not items:
            raise SimulatorError(f"{_WHO}: parameter {name!r} has no target")
        for target in items:
            _check_target(name, target, layer_names, boundary)
        parsed[str(name)] = items
    return parsed


def _check_target(name: str, target: str, layer_names: set[str], boundary: str) -> None:
    if target in WALL_TARGETS:
        if boundary == "surface":
            raise SimulatorError(
                f"{_WHO}: parameter {name!r} targets {target!r}, "
                "which has no effect with boundary='surface'",
                hint="use boundary='air' or drop the parameter",
            )
        return
    layer, _, prop = target.partition(".")
    if layer not in layer_names or prop not in LAYER_PROPERTIES:
        raise SimulatorError(
            f"{_WHO}: parameter {name!r} has target {target!r}; expected 'layer.property' "
            f"with layer in {sorted(layer_names)} and property in {list(LAYER_PROPERTIES)}, "
            f"or one of {list(WALL_TARGETS)}"
        )


def _substitute(
    nominal: WallState,
    targets: Mapping[str, tuple[str, ...]],
    parameters: Mapping[str, float],
    boundary: str,
) -> WallState:
    layer_values: dict[str, dict[str, float]] = {layer.name: {} for layer in nominal.layers}
    wall_values = {name: float(getattr(nominal, name)) for name in WALL_TARGETS}
    for name, value in parameters.items():
        for target in targets[name]:
            _check_value(name, target, float(value))
            if target in WALL_TARGETS:
                wall_values[target] = float(value)
            else:
                layer, _, prop = target.partition(".")
                layer_values[layer][prop] = float(value)
    layers = tuple(_with_values(layer, layer_values[layer.name]) for layer in nominal.layers)
    return WallState(
        layers, wall_values["r_se"], wall_values["r_si"], wall_values["solar_absorptance"]
    )


def _with_values(layer: Layer, values: Mapping[str, float]) -> Layer:
    if not values:
        return layer
    return Layer(
        layer.name,
        thickness=values.get("thickness", layer.thickness),
        conductivity=values.get("conductivity", layer.conductivity),
        density=values.get("density", layer.density),
        specific_heat=values.get("specific_heat", layer.specific_heat),
    )


def _check_value(name: str, target: str, value: float) -> None:
    if target == "solar_absorptance":
        ok, expected = 0 <= value <= 1, "in [0, 1]"
    else:
        ok, expected = value > 0, "> 0"
    if not ok:
        raise SimulatorError(
            f"{_WHO}: parameter {name!r} = {value!r} sets {target!r}, which must be {expected}",
            hint="check the prior bounds of this parameter",
        )


# --------------------------------------------------------------------------- numerics


def _wall_mesh(
    layers: tuple[Layer, ...], step: float, tolerance: float, cells: tuple[int, ...] | None
) -> Mesh:
    """Mesh whose surface-admittance error at the period ``2 step`` is ``tolerance``."""
    return build_mesh(
        layers,
        cells=cells,
        period=2.0 * step,
        cells_per_depth=1.0 / (_CELL_FACTOR * math.sqrt(tolerance)),
        min_cells=2,
    )


def _half_cell_capacity(layers: tuple[Layer, ...], mesh: Mesh) -> np.ndarray:
    """Heat capacity of each half cell, shape ``(n_cells,)``. [J/(m²·K)]"""
    counts = np.diff(mesh.interface_nodes)
    rc = np.repeat([layer.density * layer.specific_heat for layer in layers], counts)
    return 0.5 * rc * mesh.dx


@dataclass(frozen=True)
class _Nodal:
    """Nodal system ``C_u dT_u/dt = -G_uu T_u + B u`` and the node maps."""

    unknown: np.ndarray  # indices of the unknown nodes
    capacity: np.ndarray  # C_u
    diag: np.ndarray  # diagonal of G_uu
    off: np.ndarray  # off-diagonal of G_uu
    b: np.ndarray  # (n_u, n_in)
    imposed: np.ndarray  # (n_nodes, n_in): node temperatures fixed by the inputs


def _nodal_system(state: WallState, mesh: Mesh, boundary: str, n_inputs: int) -> _Nodal:
    g = mesh.conductance
    n_nodes = mesh.n_nodes
    main = np.zeros(n_nodes)
    main[:-1] += g
    main[1:] += g
    imposed = np.zeros((n_nodes, n_inputs))
    if boundary == "surface":
        unknown = np.arange(1, n_nodes - 1)
        b = np.zeros((unknown.size, n_inputs))
        b[0, 0] += g[0]
        b[-1, 1] += g[-1]
        imposed[0, 0] = imposed[-1, 1] = 1.0
    else:
        unknown = np.arange(n_nodes)
        main[0] += 1.0 / state.r_se
        main[-1] += 1.0 / state.r_si
        b = np.zeros((n_nodes, n_inputs))
        b[0, 0] = 1.0 / state.r_se
        b[-1, 1] = 1.0 / state.r_si
        if n_inputs > 2:
            b[0, 2] = state.solar_absorptance
    off = -g[unknown[:-1]]
    return _Nodal(unknown, mesh.capacity[unknown], main[unknown], off, b, imposed)


def _output_rows(
    name: str, state: WallState, mesh: Mesh, half: np.ndarray, boundary: str, n_inputs: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Coefficients of one output on node temperatures, node rates and inputs."""
    n_nodes = mesh.n_nodes
    a_t, a_dt, a_u = np.zeros(n_nodes), np.zeros(n_nodes), np.zeros(n_inputs)
    g = mesh.conductance
    if name == "temp_surf_out":
        a_t[0] = 1.0
    elif name == "temp_surf_in":
        a_t[-1] = 1.0
    elif name == "heat_flux_out" and boundary == "air":
        a_t[0], a_u[0] = -1.0 / state.r_se, 1.0 / state.r_se
        if n_inputs > 2:
            a_u[2] = state.solar_absorptance
    elif name == "heat_flux_in" and boundary == "air":
        a_t[-1], a_u[1] = 1.0 / state.r_si, -1.0 / state.r_si
    elif name == "heat_flux_out":
        a_t[0], a_t[1], a_dt[0] = g[0], -g[0], half[0]
    elif name == "heat_flux_in":
        a_t[-2], a_t[-1], a_dt[-1] = g[-1], -g[-1], -half[-1]
    else:
        i = int(name.rsplit("_", 1)[1])
        m = mesh.interface_nodes[i]
        if name.startswith("temp_"):
            a_t[m] = 1.0
        else:
            a_t[m - 1], a_t[m], a_dt[m] = g[m - 1], -g[m - 1], -half[m - 1]
    return a_t, a_dt, a_u


def _substep_count(rates: np.ndarray, scheme: str, tolerance: float, step: float) -> int:
    """Sub-steps per clock step: no ringing, and time error below ``tolerance / 10``."""
    if scheme == "exact":
        return 1
    omega_step = math.pi  # angular frequency at the period 2*step, times step
    stiff = float(rates.max()) * step
    if scheme == "crank-nicolson":
        accurate = omega_step / math.sqrt(1.2 * tolerance)  # (w h)^2 / 12 <= tol / 10
        return max(1, math.ceil(stiff / 2.0), math.ceil(accurate))
    return max(1, math.ceil(5.0 * omega_step / tolerance))  # w h / 2 <= tol / 10


def _step_coefficients(
    rates: np.ndarray, step: float, scheme: str, substeps: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-mode ``a``, ``b0``, ``b1`` of one clock step with linear forcing."""
    x = rates * step
    h = x / substeps
    if scheme == "exact":
        decay = np.exp(-x)
    elif scheme == "crank-nicolson":
        decay = np.power((1.0 - 0.5 * h) / (1.0 + 0.5 * h), substeps)
    else:
        decay = np.power(1.0 + h, -substeps)
    small = x < _SMALL_RATE_STEP
    xs = np.where(small, 1.0, x)
    b_end = np.where(small, 0.5 - x / 6 + x**2 / 24, (xs - 1.0 + decay) / xs**2) * step
    b_start = np.where(small, 0.5 - x / 3 + x**2 / 8, (1.0 - decay - decay * xs) / xs**2) * step
    return decay, b_start, b_end


def _build_propagator(
    state: WallState,
    mesh: Mesh,
    boundary: str,
    outputs: tuple[str, ...],
    n_inputs: int,
    scheme: str,
    tolerance: float,
    step: float,
) -> Propagator:
    nodal = _nodal_system(state, mesh, boundary, n_inputs)
    scale = 1.0 / np.sqrt(nodal.capacity)
    off = nodal.off * scale[:-1] * scale[1:]
    rates, vectors = eigh_tridiagonal(nodal.diag * scale**2, off)
    modes = scale[:, None] * vectors  # T_u = modes @ z
    modal_forcing = modes.T @ nodal.b
    half = _half_cell_capacity(state.layers, mesh)
    rows = [_output_rows(name, state, mesh, half, boundary, n_inputs) for name in outputs]
    a_t = np.array([r[0] for r in rows])
    a_dt = np.array([r[1] for r in rows])
    a_u = np.array([r[2] for r in rows])
    at_modes = a_t[:, nodal.unknown] @ modes
    adt_modes = a_dt[:, nodal.unknown] @ modes
    out_state = at_modes - adt_modes * rates
    out_input = a_t @ nodal.imposed + adt_modes @ modal_forcing + a_u
    substeps = _substep_count(rates, scheme, tolerance, step)
    decay, b_start, b_end = _step_coefficients(rates, step, scheme, substeps)
    slow = np.abs(decay) > _NEGLIGIBLE_DECAY
    fast_end = (out_state[:, ~slow] * b_end[~slow]) @ modal_forcing[~slow]
    fast_start = (out_state[:, ~slow] * b_start[~slow]) @ modal_forcing[~slow]
    return Propagator(
        rates=rates[slow],
        decay=decay[slow],
        b_start=b_start[slow],
        b_end=b_end[slow],
        modal_forcing=modal_forcing[slow],
        out_state=out_state[:, slow],
        out_input=out_input + fast_end,
        out_previous=fast_start,
        out_rate=a_dt @ nodal.imposed,
        mesh=mesh,
        substeps=substeps,
        max_rate=float(rates.max()),
    )
