"""The EnergyPlus adapter: the paper's wall against exact and built-in references.

Each EnergyPlus run of the wall takes about 1–2 s (a child process, EnergyPlus
itself about 0.3 s for 20 days at 10-minute steps). References are
independent of the adapter: the EN ISO 13786 transfer matrices of
``tests/helpers/iso13786.py`` and the built-in finite-volume wall.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest

import iso13786 as iso
from bayescal.errors import SimulatorError
from bayescal.simulators.base import Forcing, Simulator
from bayescal.simulators.energyplus import (
    PAPER_WALL_MODEL,
    EnergyPlusSimulator,
    ScheduleInput,
    paper_wall_simulator,
)
from bayescal.simulators.energyplus_run import error_messages

pytest.importorskip("pyenergyplus", reason="EnergyPlus adapter needs pyenergyplus-lbnl")


ALGORITHMS = ("ConductionTransferFunction", "ConductionFiniteDifference")
# (thickness [m], k [W/(m·K)], rho [kg/m³], c [J/(kg·K)]), outside to inside (method.md §8).
BOARD = (0.027, 0.0316, 116.6, 840.0)
CONCRETE = (0.15, 0.12, 552.0, 800.0)
PAPER_WALL = (BOARD, CONCRETE, BOARD)
DAY = 86400.0
STEP = 1800.0
START = np.datetime64("2021-03-01T00:00")


def _forcing(temp_out: np.ndarray, temp_in: np.ndarray) -> Forcing:
    return Forcing(STEP, {"temp_surf_out": temp_out, "temp_surf_in": temp_in}, start=START)


def _errors(q: np.ndarray, reference: np.ndarray, keep: np.ndarray) -> tuple[float, float]:
    e = q[keep] - reference[keep]
    return float(np.sqrt(np.mean(e**2))), float(np.max(np.abs(e)))


def test_reference_matches_method_table() -> None:
    # Guard on the reference itself: method.md §8, surface to surface, 24 h.
    props = iso.periodic_properties(PAPER_WALL[::-1], DAY)
    assert props["abs_Y12"] == pytest.approx(0.109436, abs=1e-6)
    assert props["time_shift_h"] == pytest.approx(-7.804, abs=1e-3)


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_sinusoid_matches_iso13786(algorithm: str) -> None:
    # Outside surface 10 + 10 sin(2 pi t / 24 h), inside 20 °C, 15 days half-hourly.
    n = 48 * 15
    t = np.arange(n) * STEP
    omega = 2 * np.pi / DAY
    sim = paper_wall_simulator(algorithm=algorithm)
    q = sim.simulate({}, _forcing(10 + 10 * np.sin(omega * t), np.full(n, 20.0)))["heat_flux_in"]

    # Exact periodic response to the linearly interpolated samples (both simulators'
    # input convention): steady part U (10 - 20), periodic part Y12 * 10 sin.
    u_value = 1 / sum(d / k for d, k, _, _ in PAPER_WALL)

    def y12(omegas: np.ndarray) -> np.ndarray:
        return -1 / iso.wall_matrix(PAPER_WALL, 1j * omegas)[0, 1]

    response = iso.sampled_response(y12, omega, STEP, images=200)
    exact = u_value * (10 - 20) + 10 * np.imag(response * np.exp(1j * omega * t))
    rmse, worst = _errors(q, exact, t >= 5 * DAY)  # 5 days: initial transient < 1e-4 W/m²
    # Measured: CTF (6 steps/h) rmse 0.003, max 0.005 W/m²; CondFD (20 steps/h, fully
    # implicit, first order in time) rmse 0.016, max 0.023 W/m², against an amplitude of
    # 1.09 W/m². Bounds about 3x the measured values, far below heat-flux meter noise.
    bound = {"ConductionTransferFunction": 0.01, "ConductionFiniteDifference": 0.05}[algorithm]
    assert rmse < bound
    assert worst < 2 * bound


@pytest.mark.parametrize("algorithm", ALGORITHMS)
def test_agrees_with_builtin_wall(algorithm: str) -> None:
    wall_module = pytest.importorskip("bayescal.simulators.wall")
    from bayescal.simulators.fvm import Layer

    n = 48 * 20
    t = np.arange(n) * STEP
    d = t / DAY
    rng = np.random.default_rng(7)
    noise = np.convolve(rng.normal(0.0, 1.0, n + 10), np.ones(11) / np.sqrt(11), "valid")[:n]
    temp_out = 8 + 7 * np.sin(2 * np.pi * (d - 0.3)) + 3 * np.sin(2 * np.pi * d / 3.3) + noise
    temp_in = 20 + 1.5 * np.sin(2 * np.pi * (d - 0.1)) + 0.5 * np.sign(np.sin(2 * np.pi * d / 2.7))
    forcing = _forcing(temp_out, temp_in)
    layers = [
        Layer(name, *props) for name, props in zip(("fb1", "cb", "fb2"), PAPER_WALL, strict=True)
    ]
    wall = wall_module.MultilayerWall(layers, tolerance=1e-4)
    reference = wall.simulate({}, forcing)["heat_flux_in"]
    q = paper_wall_simulator(algorithm=algorithm).simulate({}, forcing)["heat_flux_in"]
    rmse, worst = _errors(q, reference, d >= 2)  # both start in steady state; 2 days spare
    # Measured over 18 days (flux std 1.6 W/m²): CTF rmse 0.0028, max 0.027 W/m²;
    # CondFD rmse 0.0165, max 0.068 W/m² (the maxima at the 1 K steps of the inside
    # temperature). Bounds about 3x the measured values.
    bound = {"ConductionTransferFunction": 0.01, "ConductionFiniteDifference": 0.05}[algorithm]
    assert rmse < bound
    assert worst < 4 * bound


def test_conductivity_changes_steady_flux_as_u_predicts() -> None:
    n = 48 * 2
    forcing = _forcing(np.zeros(n), np.full(n, 20.0))
    sim = paper_wall_simulator()
    for k_cb in (0.12, 0.24):
        q = sim.simulate({"k_cb": k_cb}, forcing)["heat_flux_in"]
        resistance = 2 * BOARD[0] / BOARD[1] + CONCRETE[0] / k_cb
        # Steady state from the start (the warm-up days hold the first values). Measured
        # relative error 4e-6 (CTF truncation and warm-up convergence); 1e-4 allows 25x.
        np.testing.assert_allclose(q, -20.0 / resistance, rtol=1e-4)


def test_simulator_protocol_and_pickle() -> None:
    sim = paper_wall_simulator(algorithm="ConductionFiniteDifference")
    assert isinstance(sim, Simulator)
    assert sim.input_names == ("temp_surf_out", "temp_surf_in")
    assert sim.output_names == ("heat_flux_in",)
    assert sim.nominal["k_cb"] == pytest.approx(0.12)
    assert sim.timesteps_per_hour == 20  # EnergyPlus's minimum for the CondFD algorithm
    clone = pickle.loads(pickle.dumps(sim))
    assert clone.parameter_names == sim.parameter_names


def _broken_model(tmp_path: Path) -> Path:
    model = json.loads(PAPER_WALL_MODEL.read_text())
    model["Construction"]["PaperWall"]["layer_2"] = "NoSuchMaterial"
    path = tmp_path / "broken.epJSON"
    path.write_text(json.dumps(model))
    return path


def test_missing_material_raises_with_energyplus_text(tmp_path: Path) -> None:
    sim = EnergyPlusSimulator(
        _broken_model(tmp_path),
        schedules={"temp_surf_out": "TempSurfOut", "temp_surf_in": ScheduleInput("TempAirIn", 1)},
        outputs={
            "heat_flux_in": ("Surface Inside Face Conduction Heat Transfer Rate per Area", "Wall")
        },
    )
    with pytest.raises(SimulatorError, match=r"(?i)severe.*NoSuchMaterial"):
        sim.simulate({}, _forcing(np.zeros(48), np.full(48, 20.0)))


def test_timeout_stops_the_run() -> None:
    sim = paper_wall_simulator(timeout=0.01)
    with pytest.raises(SimulatorError, match="timeout"):
        sim.simulate({}, _forcing(np.zeros(48), np.full(48, 20.0)))


def test_unknown_targets_are_rejected_at_construction() -> None:
    with pytest.raises(SimulatorError, match="no Material named 'Concrete'"):
        paper_wall_simulator(
            parameters={"k": {"object": "Material", "name": "Concrete", "field": "Conductivity"}}
        )
    with pytest.raises(SimulatorError, match="expected a number"):
        paper_wall_simulator(
            parameters={
                "r": {"object": "Material", "name": "AeratedConcrete", "field": "Roughness"}
            }
        )
    with pytest.raises(SimulatorError, match="at least 20"):
        paper_wall_simulator(algorithm="ConductionFiniteDifference", timesteps_per_hour=6)


def test_error_messages_keep_continuation_lines() -> None:
    text = (
        "   ** Warning ** something harmless\n"
        "   ** Severe  ** GetConstructData: bad layer\n"
        "   **   ~~~   ** ..Layer=NOSUCH\n"
        "   **  Fatal  ** stopped\n"
        "   ...Summary of Errors\n"
    )
    assert error_messages(text) == [
        "** Severe  ** GetConstructData: bad layer ..Layer=NOSUCH",
        "**  Fatal  ** stopped",
    ]


def test_epw_from_forcing_is_read_by_energyplus() -> None:
    # EnergyPlus's own report of the outdoor conditions equals the forcing when the EPW
    # has one record per EnergyPlus time step.
    n = 48 * 4
    d = np.arange(n) * STEP / DAY
    series = {
        "temp_surf_out": np.full(n, 5.0),
        "temp_surf_in": np.full(n, 20.0),
        "temp_air_out": 5 + 5 * np.sin(2 * np.pi * d),
        "relative_humidity": 60 + 20 * np.sin(2 * np.pi * 1.3 * d),
        "wind_speed": 3 + np.sin(d),
        "pressure": np.full(n, 99000.0),
        "ir_horizontal": 300 + 20 * np.sin(2 * np.pi * d),
    }
    site = "Environment"
    sim = EnergyPlusSimulator(
        PAPER_WALL_MODEL,
        schedules={"temp_surf_out": "TempSurfOut", "temp_surf_in": ScheduleInput("TempAirIn", 1)},
        outputs={
            "temp_air_out": ("Site Outdoor Air Drybulb Temperature", site),
            "relative_humidity": ("Site Outdoor Air Relative Humidity", site),
            "wind_speed": ("Site Wind Speed", site),
            "pressure": ("Site Outdoor Air Barometric Pressure", site),
            "ir_horizontal": ("Site Horizontal Infrared Radiation Rate per Area", site),
        },
        timesteps_per_hour=6,
        weather_records_per_hour=6,
    )
    out = sim.simulate({}, Forcing(STEP, series, start=np.datetime64("2021-06-10T00:00")))
    # Tolerances: the EPW's rounding (0.01 K, 0.1 %, 0.01 m/s, 1 Pa, 0.1 W/m²).
    tolerance = {
        "temp_air_out": 0.006,
        "relative_humidity": 0.06,
        "wind_speed": 0.006,
        "pressure": 0.6,
        "ir_horizontal": 0.06,
    }
    for name, tol in tolerance.items():
        np.testing.assert_allclose(out[name], series[name], atol=tol, err_msg=name)


def test_in_process_runs_match_the_child_process() -> None:
    n = 48 * 3
    t = np.arange(n) * STEP
    forcing = _forcing(10 + 5 * np.sin(2 * np.pi * t / DAY), np.full(n, 20.0))
    child = paper_wall_simulator().simulate({"k_cb": 0.15}, forcing)["heat_flux_in"]
    inside = paper_wall_simulator(isolation="in-process")
    for _ in range(2):  # a second run in the same process sees no state of the first
        q = inside.simulate({"k_cb": 0.15}, forcing)["heat_flux_in"]
        np.testing.assert_array_equal(q, child)  # same program, same input: bit for bit


def test_in_process_timeout_stops_the_run() -> None:
    sim = paper_wall_simulator(isolation="in-process", timeout=1e-3)
    with pytest.raises(SimulatorError, match="timeout"):
        sim.simulate({}, _forcing(np.zeros(48 * 5), np.full(48 * 5, 20.0)))


def test_weather_file_path_is_used_with_its_time_zone() -> None:
    from pyenergyplus.dataset import weather_files

    epw = Path(weather_files["usa_il_chicago"])
    sim = paper_wall_simulator(weather=epw)
    n = 48
    # 2021-03-01 00:00 UTC is 28 February 18:00 in Chicago (UTC-6): the run starts the day
    # before, and the imposed surfaces make the weather irrelevant to the flux.
    q = sim.simulate({}, _forcing(np.zeros(n), np.full(n, 20.0)))["heat_flux_in"]
    resistance = 2 * BOARD[0] / BOARD[1] + CONCRETE[0] / CONCRETE[1]
    np.testing.assert_allclose(q, -20.0 / resistance, rtol=1e-4)  # as the steady test
