"""``bayescal validate``: summary, one-line errors with exit status 2, --debug, --version."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from bayescal import __version__
from bayescal.cli import main
from paths import FIXTURES, REPO

FIXTURE = FIXTURES / "wall-study"
SHARED = REPO.parent / "shared" / "data"
TWIN_HOUSE = SHARED / "annex58-twinhouse-n2-exp1" / "validationdataN2Exp1.txt"
SCRIPT = Path(sys.executable).parent / "bayescal"


def _run(*args: str) -> tuple[int, str, str]:
    result = CliRunner().invoke(main, list(args))
    return result.exit_code, result.stdout, result.stderr


def test_validate_fixture_summary() -> None:
    code, out, err = _run("validate", str(FIXTURE))
    assert code == 0, err
    for expected in (
        "study 'fixture-wall'",
        "simulator: wall, surface boundaries",
        "k_cb [W/(m·K)]: nominal 0.12, uniform(0.08, 0.16) -> concrete.conductivity",
        "beta(672, 1008, a=1, b=2)",
        "boundary conditions: temp_surf_out, temp_surf_in",
        "clock: step 30min, 2012-01-31T23:00:00 to 2012-02-06T22:30:00 UTC, 288 samples (6D)",
        "warm-up 48 samples, 4 training periods of 48 samples, test window 48 samples",
        "gaps: none",
        "time: about ",
        "an order of magnitude from a per-sweep cost model",
        "plus 70 simulator runs not timed here",  # 20 design + 50 predict runs
    ):
        assert expected in out
    assert "warning" not in out


def test_validate_warns_of_a_run_of_hours(tmp_path: Path) -> None:
    folder = _copy(tmp_path)
    toml = folder / "study.toml"
    long_chains = "\n[calibration]\nchains = 10000\nburn = 900\nsamples = 100\n"
    toml.write_text(toml.read_text() + long_chains)
    code, out, err = _run("validate", str(folder))
    assert code == 0, err
    warning = [line for line in out.splitlines() if line.startswith("warning: ")]
    assert len(warning) == 1
    assert warning[0].startswith("warning: calibration.chains: the calibration alone may take")
    assert "(10000 chains × 1000 sweeps × 5 coordinates)" in warning[0]


def _copy(tmp_path: Path) -> Path:
    folder = tmp_path / "study"
    shutil.copytree(FIXTURE, folder)
    return folder


def test_config_error_is_one_line_exit_2(tmp_path: Path) -> None:
    folder = _copy(tmp_path)
    toml = folder / "study.toml"
    toml.write_text(
        toml.read_text().replace("lower = 0.08, upper = 0.16", "lower = 0.16, upper = 0.08")
    )
    code, out, err = _run("validate", str(folder))
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1
    assert err.startswith("error: ")
    assert "parameters.k_cb.prior: lower bound 0.16 >= upper bound 0.08" in err
    assert "Traceback" not in err


def test_data_error_and_gap_report(tmp_path: Path) -> None:
    folder = _copy(tmp_path)
    frame = pd.read_csv(folder / "wall.csv")
    frame.loc[60:62, "q_si"] = float("nan")
    frame.to_csv(folder / "wall.csv", index=False)
    code, out, _ = _run("validate", str(folder))
    assert code == 0
    assert "gaps: 1 (0 interpolated, 1 left missing)" in out
    assert "3 training periods of 48 samples (1 more dropped: missing data)" in out
    frame.loc[10, "T_se"] = float("nan")  # one missing boundary value, in the warm-up
    frame.to_csv(folder / "wall.csv", index=False)
    code, out, _ = _run("validate", str(folder))
    assert code == 0
    assert "gaps: 2 (0 interpolated, 2 left missing, 1 of them in boundary conditions)" in out
    # local times of the study's zone, and the line of the file
    assert "2012-02-01 05:00 – 2012-02-01 05:00 UTC+01:00" in out
    assert "file line 12" in out
    assert "data.max_gap_interpolate = '30min' interpolates them instead" in out


def test_debug_shows_the_traceback(tmp_path: Path) -> None:
    result = CliRunner().invoke(main, ["--debug", "validate", str(tmp_path)])
    assert result.exit_code == 2
    assert "Traceback" in result.stderr
    assert "ConfigError" in result.stderr


def test_version() -> None:
    code, out, _ = _run("--version")
    assert code == 0
    assert __version__ in out


def test_console_script_subprocess(tmp_path: Path) -> None:
    if not SCRIPT.is_file():
        pytest.skip(f"console script {SCRIPT} is not installed")
    ok = subprocess.run([str(SCRIPT), "validate", str(FIXTURE)], capture_output=True, text=True)
    assert ok.returncode == 0
    assert "4 training periods" in ok.stdout
    bad = subprocess.run([str(SCRIPT), "validate", str(tmp_path)], capture_output=True, text=True)
    assert bad.returncode == 2
    assert bad.stderr.startswith("error: ")
    assert bad.stderr.count("\n") == 1


def _module_env() -> dict[str, str]:
    """The environment for ``python -m bayescal``: this checkout's ``src`` first on the path
    (the interpreter's own installation may be another checkout)."""
    paths = [str(REPO / "src"), *filter(None, [os.environ.get("PYTHONPATH")])]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}


def test_python_m_bayescal_help_lists_the_commands() -> None:
    helped = subprocess.run(
        [sys.executable, "-m", "bayescal", "--help"],
        capture_output=True,
        text=True,
        env=_module_env(),
        cwd=REPO.parent,  # not the checkout: the package comes from PYTHONPATH
        timeout=300,
    )
    assert helped.returncode == 0, helped.stderr
    assert helped.stderr == ""
    assert helped.stdout.startswith("Usage: bayescal [OPTIONS] COMMAND")
    commands = helped.stdout.split("Commands:", 1)[1]
    listed = {line.split()[0] for line in commands.splitlines() if line.strip()}
    assert {"validate", "run", "screen", "simulate", "compare", "report", "show"} <= listed


def test_python_m_bayescal_runs_the_command_line(tmp_path: Path) -> None:
    # `python -m bayescal` is the console script without it (bayescal/__main__.py).
    version = subprocess.run(
        [sys.executable, "-m", "bayescal", "--version"],
        capture_output=True,
        text=True,
        env=_module_env(),
    )
    assert version.returncode == 0, version.stderr
    assert version.stdout.strip() == f"bayescal, version {__version__}"
    ok = subprocess.run(
        [sys.executable, "-m", "bayescal", "validate", str(FIXTURE)],
        capture_output=True,
        text=True,
        env=_module_env(),
    )
    assert ok.returncode == 0, ok.stderr
    assert "4 training periods" in ok.stdout
    bad = subprocess.run(
        [sys.executable, "-m", "bayescal", "validate", str(tmp_path)],
        capture_output=True,
        text=True,
        env=_module_env(),
    )
    assert bad.returncode == 2
    assert bad.stderr.startswith("error: ")
    helped = subprocess.run(
        [sys.executable, "-m", "bayescal", "-h"], capture_output=True, text=True, env=_module_env()
    )
    assert helped.stdout.startswith("Usage: bayescal [OPTIONS] COMMAND")


TWIN_STUDY = """
[study]
name = "twin-house-west-wall"

[data]
file = "{file}"
epoch = "2013-01-01T00:00:00"
time_zone = "UTC+01:00"
step = "10min"

[data.columns.temp_surf_in]
source = 14
unit = "degC"

[data.columns.heat_flux_in]
source = 15
unit = "W/m2"

[data.columns.temp_surf_out]
source = 18
unit = "degC"

[simulator]
type = "wall"
[[simulator.layers]]
name = "ext_plaster"
thickness = 0.01
conductivity = 0.8
density = 1200
specific_heat = 1000
[[simulator.layers]]
name = "eps"
thickness = 0.08
conductivity = 0.04
density = 80
specific_heat = 840
[[simulator.layers]]
name = "former_plaster"
thickness = 0.03
conductivity = 1.0
density = 1200
specific_heat = 1000
[[simulator.layers]]
name = "brick"
thickness = 0.3
conductivity = 0.22
density = 800
specific_heat = 1000
[[simulator.layers]]
name = "int_plaster"
thickness = 0.01
conductivity = 1.0
density = 1200
specific_heat = 1000

[parameters.k_brick]
unit = "W/(m·K)"
nominal = 0.22
prior = {{ distribution = "uniform", lower = 0.15, upper = 0.3 }}
targets = ["brick.conductivity"]

[outputs]
calibrate = ["heat_flux_in"]

[periods]
length = "1D"
warmup = "2D"
test_samples = 1000
"""


def test_validate_twin_house_in_place(tmp_path: Path) -> None:
    if not SHARED.is_dir():
        pytest.skip(f"shared data folder {SHARED} is absent (a fresh clone)")
    (tmp_path / "study.toml").write_text(TWIN_STUDY.format(file=TWIN_HOUSE.as_posix()))
    code, out, err = _run("validate", str(tmp_path))
    assert code == 0, err
    # 5905 rows at 10 min from day 232 00:00 local (= 2013-08-20 23:00 UTC), no gaps.
    assert "5905 samples (41D 10min)" in out  # n samples x 10 min and "2013-08-20T23:00:00" in out
    # 5905 - 1000 test - 288 warm-up = 4617 samples: 32 whole days of 144 samples.
    assert "32 training periods of 144 samples" in out
    assert "test window 1000" in out
    assert "gaps: none" in out


def test_validate_explains_a_warm_up_longer_than_asked(tmp_path: Path) -> None:
    # 23 h of warm-up asked; the first whole daily period starts 1 h later: the grid of
    # periods ends where the test window's period begins, so 2 samples are left over.
    folder = _copy(tmp_path)
    toml = folder / "study.toml"
    toml.write_text(toml.read_text().replace('warmup = "1D"', 'warmup = "23h"'))
    code, out, err = _run("validate", str(folder))
    assert code == 0, err
    line = next(line for line in out.splitlines() if line.startswith("periods: "))
    assert line.startswith(
        "periods: warm-up 48 samples (46 of [periods] warmup = 23h + 2 left before the first "
        "whole period: the periods lie on a grid that ends where the test window's periods "
        "begin), 4 training periods of 48 samples"
    )
