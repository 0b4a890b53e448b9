"""Tests of the FMU simulator adapter with FMUs the test suite compiles itself.

``fmu_build.py`` compiles a one-node RC model (``tests/helpers/fmu_src``) into an FMI 2.0
co-simulation FMU (kelvin, interpolates its input) and an FMI 3.0 one (°C, holds
its input over a step). References are the closed-form solutions of
``rc_reference.py``.
"""

from __future__ import annotations

import multiprocessing
import pickle
import zipfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fmpy", reason="FMPy is an optional dependency (bayescal[fmu])")

import fmu_build
from bayescal.errors import ConfigError, SimulatorError
from bayescal.simulators import fmu as fmu_module
from bayescal.simulators.base import Forcing, Simulator
from bayescal.simulators.fmu import FmuSimulator
from rc_reference import rc_exact, rc_numerical

STEP = 600.0  # [s]
R, C, T0 = 0.5, 2.0e4, 20.0  # [m²K/W], [J/(m²K)], [°C]: tau = 1e4 s, 16.7 steps
# The FMUs integrate with RK4 sub-steps of at most tau/200: local error ~(1/200)^5/120 of
# the driving difference (~30 K), i.e. ~1e-13 K per sub-step and ~1e-10 K over a day.
TOL_T = 1e-9  # [K]
TOL_Q = TOL_T / R  # [W/m²]


@pytest.fixture(scope="session")
def fmus(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    if not fmu_build.have_compiler():
        pytest.skip("gcc is needed to build the test FMUs")
    out = tmp_path_factory.mktemp("fmus")
    return {v: fmu_build.build_rc_fmu(v, out) for v in ("2.0", "3.0")}


@pytest.fixture
def forcing() -> Forcing:
    rng = np.random.default_rng(7)
    t = np.arange(145) * STEP
    u = 5.0 + 8.0 * np.sin(2 * np.pi * t / 86400.0) + rng.normal(0.0, 1.0, t.size)
    return Forcing(step=STEP, series={"temp_air_out": u})


def rc2(fmus: dict[str, Path], **kw) -> FmuSimulator:
    """The FMI 2.0 FMU, with its kelvin temperatures converted."""
    options = {
        "parameters": {"R": "R", "C": "C", "T0": "T0"},
        "inputs": {"T_out": "temp_air_out"},
        "outputs": {"heat_flux_out": "q", "temp_node": "T"},
        "units": {"T_out": "K", "T": "K"},
    }
    options.update(kw)
    return FmuSimulator(fmus["2.0"], **options)


def rc3(fmus: dict[str, Path], **kw) -> FmuSimulator:
    options = {
        "parameters": {"R": "R", "C": "C", "T0": "T0"},
        "inputs": {"T_out": "temp_air_out"},
        "outputs": {"heat_flux_out": "q", "temp_node": "T"},
    }
    options.update(kw)
    return FmuSimulator(fmus["3.0"], **options)


def test_reference_solutions_agree(forcing: Forcing) -> None:
    u = forcing["temp_air_out"]
    exact, _ = rc_exact(u, STEP, R, C, T0)
    numerical, _ = rc_numerical(u, STEP, R, C, T0)
    # DOP853 at rtol = atol = 1e-12 per segment: ~1e-11 K per step, ~1e-9 K in total.
    np.testing.assert_allclose(exact, numerical, rtol=0, atol=1e-8)


def test_fmi2_interpolated_input_matches_exact_solution(
    fmus: dict[str, Path], forcing: Forcing
) -> None:
    sim = rc2(fmus)
    assert isinstance(sim, Simulator)
    out = sim.simulate({"R": R, "C": C, "T0": T0 + 273.15}, forcing)  # T0 is in kelvin
    temp, q = rc_exact(forcing["temp_air_out"], STEP, R, C, T0)
    np.testing.assert_allclose(out["temp_node"], temp, rtol=0, atol=TOL_T)
    np.testing.assert_allclose(out["heat_flux_out"], q, rtol=0, atol=TOL_Q)
    # Holding the input instead is ~0.4 W/m² off here: the input slopes reached the FMU.
    _, q_hold = rc_exact(forcing["temp_air_out"], STEP, R, C, T0, hold=True)
    assert np.max(np.abs(out["heat_flux_out"] - q_hold)) > 1e3 * TOL_Q


def test_fmi3_held_input_matches_exact_solution(fmus: dict[str, Path], forcing: Forcing) -> None:
    out = rc3(fmus).simulate({"R": R, "C": C, "T0": T0}, forcing)
    temp, q = rc_exact(forcing["temp_air_out"], STEP, R, C, T0, hold=True)
    np.testing.assert_allclose(out["temp_node"], temp, rtol=0, atol=TOL_T)
    np.testing.assert_allclose(out["heat_flux_out"], q, rtol=0, atol=TOL_Q)


def test_fmi3_substeps_approach_linear_input(fmus: dict[str, Path], forcing: Forcing) -> None:
    theta = {"R": R, "C": C, "T0": T0}
    _, q = rc_exact(forcing["temp_air_out"], STEP, R, C, T0)
    err = {
        m: np.max(np.abs(rc3(fmus, substeps=m).simulate(theta, forcing)["heat_flux_out"] - q))
        for m in (1, 10)
    }
    # Holding a linear input over sub-steps of h/m lags it by h/(2m): first order in
    # 1/m, so ten sub-steps cut the error about tenfold (0.15 leaves room for the
    # second-order remainder).
    assert err[10] < 0.15 * err[1]
    assert err[1] > 1e3 * TOL_Q


def test_parameters_take_effect(fmus: dict[str, Path], forcing: Forcing) -> None:
    sim = rc3(fmus)
    out = sim.simulate({"R": 1.5, "C": 5.0e4, "T0": 12.0}, forcing)
    _temp, q = rc_exact(forcing["temp_air_out"], STEP, 1.5, 5.0e4, 12.0, hold=True)
    np.testing.assert_allclose(out["heat_flux_out"], q, rtol=0, atol=TOL_T / 1.5)  # as above
    default = sim.simulate({}, forcing)  # the FMU's start values: R = 0.5, C = 2e4, T0 = 20
    _, q_default = rc_exact(forcing["temp_air_out"], STEP, R, C, T0, hold=True)
    np.testing.assert_allclose(default["heat_flux_out"], q_default, rtol=0, atol=TOL_Q)


def test_one_parameter_sets_several_variables(fmus: dict[str, Path], forcing: Forcing) -> None:
    sim = rc3(fmus, parameters={"x": ["R", "C"]}, start_values={"T0": 15.0})
    out = sim.simulate({"x": 100.0}, forcing)  # R = 100, C = 100: tau = 1e4 s
    _, q = rc_exact(forcing["temp_air_out"], STEP, 100.0, 100.0, 15.0, hold=True)
    np.testing.assert_allclose(out["heat_flux_out"], q, rtol=0, atol=TOL_T / 100.0)


def test_start_time_offset(fmus: dict[str, Path], forcing: Forcing) -> None:
    theta = {"R": R, "C": C, "T0": T0}
    shifted = rc3(fmus, start_time=59 * 86400.0).simulate(theta, forcing)
    _, q = rc_exact(forcing["temp_air_out"], STEP, R, C, T0, hold=True)
    # The model is time-invariant; the FMU rejects communication points that do not
    # follow its start time, so this also checks start_time reached it.
    np.testing.assert_allclose(shifted["heat_flux_out"], q, rtol=0, atol=TOL_Q)


def test_single_sample(fmus: dict[str, Path]) -> None:
    one = Forcing(step=STEP, series={"temp_air_out": np.array([4.0])})
    out = rc3(fmus).simulate({"T0": 10.0}, one)
    np.testing.assert_allclose(out["heat_flux_out"], [(4.0 - 10.0) / R], rtol=1e-15)


def test_pickles_small_and_runs_in_another_process(fmus: dict[str, Path], forcing: Forcing) -> None:
    sim = rc2(fmus)
    assert len(pickle.dumps(sim)) < 2000  # the path and the mappings only
    theta = {"R": 0.7, "C": 3.0e4, "T0": 290.0}
    here = sim.simulate(theta, forcing)
    with ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        there = pool.submit(sim.simulate, theta, forcing).result(timeout=120)
    np.testing.assert_array_equal(here["heat_flux_out"], there["heat_flux_out"])  # same code


def test_fmu_is_extracted_once(fmus: dict[str, Path], forcing: Forcing) -> None:
    sim = rc3(fmus)
    sim.simulate({}, forcing)
    entries = [k for k in fmu_module._EXTRACTED if k[0] == sim.path]
    rc3(fmus).simulate({}, forcing)
    assert [k for k in fmu_module._EXTRACTED if k[0] == sim.path] == entries
    assert len(entries) == 1


# -- errors ----------------------------------------------------------------------------


def test_failing_fmu_reports_its_log(fmus: dict[str, Path], forcing: Forcing) -> None:
    with pytest.raises(
        SimulatorError, match=r"FMU 'RCNode' failed: .*FMU log: parameter R must be positive"
    ):
        rc3(fmus).simulate({"R": -1.0}, forcing)
    with pytest.raises(SimulatorError, match=r"fmi2ExitInitializationMode failed.*R must be"):
        rc2(fmus).simulate({"R": 0.0}, forcing)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"parameters": {"R": "Rr"}}, r"has no variable 'Rr' \(for parameter 'R'\).*\['R'"),
        ({"inputs": {"Tout": "temp_air_out"}}, r"has no variable 'Tout' \(for input\)"),
        ({"inputs": {"T": "temp_air_out"}}, r"variable 'T' is not an input"),
        ({"outputs": {"q": "heat_flux"}}, r"has no variable 'heat_flux' \(for output 'q'\)"),
        ({"parameters": {"R": "q"}}, r"'q' \(for parameter 'R'\) cannot be set"),
        ({"start_values": {"T": 3.0}}, r"'T' \(for start value\) cannot be set"),
    ],
)
def test_bad_variable_names(fmus: dict[str, Path], change: dict, message: str) -> None:
    with pytest.raises(SimulatorError, match=message):
        rc3(fmus, **change)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"units": {"T_out": "furlong"}}, "unknown unit 'furlong'"),
        ({"units": {"R": "K"}}, "no input or output"),
        ({"substeps": 0}, "substeps must be a positive integer"),
        ({"outputs": {}}, "at least one output"),
        ({"parameters": {"not a name": "R"}}, "is not a valid name"),
    ],
)
def test_bad_configuration(fmus: dict[str, Path], change: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        rc3(fmus, **change)


def test_unknown_parameter_and_missing_series(fmus: dict[str, Path], forcing: Forcing) -> None:
    with pytest.raises(SimulatorError, match=r"has no parameter\(s\) \['K'\]"):
        rc3(fmus).simulate({"K": 1.0}, forcing)
    other = Forcing(step=STEP, series={"ghi": forcing["temp_air_out"]})
    with pytest.raises(SimulatorError, match=r"needs boundary condition\(s\) \['temp_air_out'\]"):
        rc3(fmus).simulate({}, other)


def test_missing_file_and_missing_binary(fmus: dict[str, Path], tmp_path: Path) -> None:
    with pytest.raises(SimulatorError, match="cannot read FMU"):
        FmuSimulator(tmp_path / "nope.fmu", parameters={}, inputs={}, outputs={"q": "q"})
    stripped = tmp_path / "nobinary.fmu"
    with zipfile.ZipFile(fmus["3.0"]) as src, zipfile.ZipFile(stripped, "w") as dst:
        for item in src.infolist():
            if not item.filename.startswith("binaries/"):
                dst.writestr(item, src.read(item))
    with pytest.raises(SimulatorError, match="has no binary for this platform"):
        FmuSimulator(stripped, parameters={}, inputs={}, outputs={"q": "q"})
    broken = tmp_path / "broken.fmu"
    broken.write_bytes(b"not a zip file")
    with pytest.raises(SimulatorError, match="not a valid FMU"):
        FmuSimulator(broken, parameters={}, inputs={}, outputs={"q": "q"})
