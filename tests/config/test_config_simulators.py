"""Study files for the EnergyPlus, external-command and FMU simulators, end to end.

Each fixture study (``tests/helpers/fixtures/*-study``) is loaded with ``load_study``, built
by the factory and run once at its nominal values through ``check_simulation``
or the ``bayescal simulate`` command; the outputs are compared with references
that share no code with the adapters: the built-in finite-volume wall for the
EnergyPlus wall, and the closed-form RC solution of ``rc_reference.py`` for the
external program and the FMU. Then the mistakes a user makes in those sections
must come back as one line naming the study key and the fix.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.config import build_simulator, load_study
from bayescal.errors import BayescalError, ConfigError
from bayescal.simulate import check_simulation
from bayescal.simulators.energyplus import PAPER_WALL_MODEL
from bayescal.simulators.fvm import Layer
from bayescal.simulators.wall import MultilayerWall
from paths import FIXTURES, PROGRAMS
from rc_reference import rc_exact

DATA = FIXTURES
STEP = 1800.0  # the fixtures' clock [s]
R, C, T0 = 0.5, 2.0e4, 20.0  # nominal RC wall [m²K/W], [J/(m²K)]; initial node [°C]
# Paper wall, outside to inside: (thickness [m], k [W/(m·K)], rho [kg/m³], c [J/(kg·K)]).
BOARD = (0.027, 0.0316, 116.6, 840.0)
CONCRETE = (0.15, 0.12, 552.0, 800.0)


def _copy(tmp_path: Path, name: str, extras: dict[str, Path]) -> Path:
    """A copy of fixture study ``name`` with ``extras`` (file name -> source) beside it."""
    folder = tmp_path / name
    shutil.copytree(DATA / name, folder)
    for target, source in extras.items():
        shutil.copy(source, folder / target)
    return folder


def _edit(folder: Path, old: str, new: str) -> Path:
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    assert old in text  # the edit must hit, or the test would test nothing
    path.write_text(text.replace(old, new), encoding="utf-8")
    return folder


def _build_error(folder: Path) -> str:
    """The one-line message of loading and building the study (either may raise it)."""
    with pytest.raises(BayescalError) as info:
        build_simulator(load_study(folder))
    message = str(info.value)
    assert "\n" not in message
    return message


# --------------------------------------------------------------------------- energyplus


@pytest.fixture
def eplus_study(tmp_path: Path) -> Path:
    pytest.importorskip("pyenergyplus", reason="EnergyPlus needs pyenergyplus-lbnl")
    return _copy(tmp_path, "eplus-study", {"paper_wall.epJSON": PAPER_WALL_MODEL})


def test_energyplus_study_matches_the_builtin_wall(eplus_study: Path) -> None:
    check = check_simulation(load_study(eplus_study))
    forcing = check.measured.forcing
    assert forcing.step == STEP
    layers = [Layer(n, *p) for n, p in (("fb1", BOARD), ("cb", CONCRETE), ("fb2", BOARD))]
    reference = MultilayerWall(layers, tolerance=1e-4).simulate({}, forcing)["heat_flux_in"]
    error = (check.simulated["heat_flux_in"] - reference)[48:]  # both settle within a day
    # Measured here rmse 0.0010, max 0.0016 W/m² (smooth inputs); test_energyplus.py measured
    # rmse 0.0028 and max 0.027 W/m² with 1 K steps of the inside temperature. The same
    # bounds as there, 0.01 and 0.04 W/m², far below heat-flux meter noise.
    assert np.sqrt(np.mean(error**2)) < 0.01
    assert np.max(np.abs(error)) < 0.04
    # The metrics are those of the simulated series against the measured one.
    train = check.train["heat_flux_in"]
    first = int(check.measured.layout.train_starts[0])
    window = slice(first, check.measured.layout.test_begin)
    residual = (
        check.simulated["heat_flux_in"][window] - check.measured.outputs["heat_flux_in"][window]
    )
    assert train.mse == pytest.approx(np.mean(residual**2))


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            '"Material:AeratedConcrete:Conductivity"',
            '"Material:Concrete:Conductivity"',
            r"^parameters\.k_cb\.targets: paper_wall\.epJSON has no Material named 'Concrete'; "
            r"did you mean 'AeratedConcrete'\?$",
        ),
        (
            '"Material:AeratedConcrete:Conductivity"',
            '"Material:AeratedConcrete:Conductivty"',
            r"^parameters\.k_cb\.targets: Material 'AeratedConcrete' in paper_wall\.epJSON has "
            r"no field 'Conductivty' .*did you mean 'conductivity'\?$",
        ),
        (
            '"Material:AeratedConcrete:Conductivity"',
            '"Material:AeratedConcrete:Roughness"',
            r"^parameters\.k_cb\.targets: field 'Roughness' .* is 'MediumSmooth', not a number; "
            r"calibrate one of its numeric fields \['conductivity', 'density'",
        ),
        (
            'temp_surf_out = "TempSurfOut"',
            'temp_surf_out = "TempSurfaceOut"',
            r"^simulator\.schedules\.temp_surf_out: paper_wall\.epJSON has no Schedule:File named "
            r"'TempSurfaceOut'; did you mean 'TempSurfOut'\?$",
        ),
        (
            'model = "paper_wall.epJSON"',
            'model = "nosuch.epJSON"',
            r"simulator\.model.*'nosuch\.epJSON'",
        ),
    ],
    ids=["object", "field", "text-field", "schedule", "model-file"],
)
def test_energyplus_study_errors_name_the_key(
    eplus_study: Path, old: str, new: str, message: str
) -> None:
    text = _build_error(_edit(eplus_study, old, new))
    assert re.search(message, text), text


# --------------------------------------------------------------------------- command


@pytest.fixture
def command_study(tmp_path: Path) -> Path:
    return _copy(tmp_path, "command-study", {"rc_wall.py": PROGRAMS / "rc_wall.py"})


def test_command_study_through_the_cli_matches_the_exact_solution(command_study: Path) -> None:
    result = CliRunner().invoke(main, ["simulate", str(command_study)])
    assert result.exit_code == 0, result.output
    assert "heat_flux_out" in result.output  # the metrics table
    table = np.genfromtxt(
        command_study / "out" / "simulate" / "simulation.csv", delimiter=",", names=True
    )
    check = check_simulation(load_study(command_study))
    temp, q = rc_exact(check.measured.forcing["temp_air_out"], STEP, R, C, T0)
    # The program solves the same closed form from 17-digit inputs: rounding only
    # (~1e-15 relative on ~20 K and ~40 W/m²); 1e-9 leaves ample room.
    np.testing.assert_allclose(check.simulated["temp_node"], temp, rtol=0, atol=1e-9)
    np.testing.assert_allclose(check.simulated["heat_flux_out"], q, rtol=0, atol=1e-9)
    # The CLI wrote that same run (pandas writes floats with 17 significant digits).
    np.testing.assert_allclose(table["heat_flux_out_simulated"], q, rtol=0, atol=1e-9)


def test_command_study_sets_the_parameters(command_study: Path) -> None:
    check = check_simulation(load_study(command_study), {"r_wall": 0.7, "c_wall": 3.0e4})
    _, q = rc_exact(check.measured.forcing["temp_air_out"], STEP, 0.7, 3.0e4, T0)
    np.testing.assert_allclose(check.simulated["heat_flux_out"], q, rtol=0, atol=1e-9)  # as above


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            'targets = ["C"]',
            'targets = ["Cap"]',
            r"^simulator\.templates: .*params\.tmpl: template uses placeholder\(s\) \['C'\] that "
            r"are not parameters \['R', 'Cap'\]; declare them as parameters",
        ),
        (
            '"params.tmpl"',
            '"nosuch.tmpl"',
            r"^simulator\.templates: .*nosuch\.tmpl: cannot read template",
        ),
        (
            '["python3",',
            '["no-such-program-xyz",',
            r"^simulator\.command: executable 'no-such-program-xyz' is not on the PATH; give its "
            r"absolute path",
        ),
    ],
    ids=["placeholder", "template-file", "program"],
)
def test_command_study_errors_name_the_key(
    command_study: Path, old: str, new: str, message: str
) -> None:
    text = _build_error(_edit(command_study, old, new))
    assert re.search(message, text), text


def test_cli_reports_a_build_error_in_one_line(command_study: Path) -> None:
    _edit(command_study, 'targets = ["C"]', 'targets = ["Cap"]')
    result = CliRunner().invoke(main, ["simulate", str(command_study)])
    assert result.exit_code == 2
    assert "simulator.templates" in result.output
    assert "Traceback" not in result.output


# --------------------------------------------------------------------------- fmu


@pytest.fixture(scope="module")
def rc_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("fmpy", reason="FMPy is an optional dependency (bayescal[fmu])")
    import fmu_build

    if not fmu_build.have_compiler():
        pytest.skip("gcc is needed to build the test FMU")
    return fmu_build.build_rc_fmu("2.0", tmp_path_factory.mktemp("fmu"))


@pytest.fixture
def fmu_study(tmp_path: Path, rc_fmu: Path) -> Path:
    return _copy(tmp_path, "fmu-study", {"rc.fmu": rc_fmu})


def test_fmu_study_matches_the_exact_solution(fmu_study: Path) -> None:
    check = check_simulation(load_study(fmu_study))
    temp, q = rc_exact(check.measured.forcing["temp_air_out"], STEP, R, C, T0)
    # The FMI 2.0 FMU interpolates its input and integrates with RK4 sub-steps of at most
    # tau/200 (test_fmu.py: ~1e-10 K over a day); kelvin conversions add ~1e-13 K.
    np.testing.assert_allclose(check.simulated["temp_node"], temp, rtol=0, atol=1e-8)
    np.testing.assert_allclose(check.simulated["heat_flux_out"], q, rtol=0, atol=1e-8 / R)


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            'targets = ["R"]',
            'targets = ["Rx"]',
            r"^parameters\.r_wall\.targets: .*has no variable 'Rx' \(for parameter 'r_wall'\); "
            r"did you mean \['R'",
        ),
        (
            'heat_flux_out = "q"',
            'heat_flux_out = "q_out"',
            r"^simulator\.outputs\.heat_flux_out: .*has no variable 'q_out'",
        ),
        ('fmu = "rc.fmu"', 'fmu = "nosuch.fmu"', r"simulator\.fmu.*'nosuch\.fmu'"),
    ],
    ids=["parameter", "output", "fmu-file"],
)
def test_fmu_study_errors_name_the_key(fmu_study: Path, old: str, new: str, message: str) -> None:
    text = _build_error(_edit(fmu_study, old, new))
    assert re.search(message, text), text


def test_unknown_simulator_target_kinds_are_config_errors(command_study: Path) -> None:
    # A command target must be a placeholder name; the study file is rejected on load.
    _edit(command_study, 'targets = ["R"]', 'targets = ["R-1"]')
    with pytest.raises(ConfigError, match="not a template placeholder name"):
        load_study(command_study)
