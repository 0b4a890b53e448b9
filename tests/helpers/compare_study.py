"""Tiny study folders of the virtual wall for ``bayescal compare`` (variants of one problem).

The "measured" inside heat flux carries AR(1) noise (lag-1 correlation
``PHI`` from one half-hour to the next), so a study that models its errors as
AR(1) should beat one that assumes white noise on the training periods alone.
Every variant gets its own copy of the same data file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from bayescal.simulators.base import Forcing
from virtual_wall import PER_DAY, STEP, paper_wall, virtual_experiment

PHI = 0.9
#: Training days, and one day each of warm-up and test window.
DAYS = 6

STUDY = """
[study]
name = "{name}"
seed = 11

[data]
file = "wall.csv"
time_column = "time"
time_zone = "UTC"
step = "30min"

[data.columns.temp_surf_out]
source = "T_se"
unit = "degC"

[data.columns.temp_surf_in]
source = "T_si"
unit = "degC"

[data.columns.heat_flux_in]
source = "q_si"
unit = "W/m2"

[simulator]
type = "wall"
boundary = "surface"
outputs = ["heat_flux_in"]

[[simulator.layers]]
name = "board_out"
thickness = 0.027
conductivity = 0.0316
density = 116.6
specific_heat = 840.0

[[simulator.layers]]
name = "concrete"
thickness = 0.15
conductivity = 0.12
density = 552.0
specific_heat = 800.0

[[simulator.layers]]
name = "board_in"
thickness = 0.027
conductivity = 0.0316
density = 116.6
specific_heat = 840.0

[parameters.k_cb]
unit = "W/(m·K)"
nominal = 0.12
prior = {{ distribution = "uniform", lower = 0.08, upper = 0.16 }}
targets = ["concrete.conductivity"]

[parameters.cp_cb]
unit = "J/(kg·K)"
nominal = 800.0
prior = {{ distribution = "uniform", lower = 640.0, upper = 960.0 }}
targets = ["concrete.specific_heat"]

[outputs]
calibrate = ["heat_flux_in"]

[outputs.errors.heat_flux_in]
model = "{model}"

[periods]
length = "1D"
warmup = "1D"
test_samples = 48

[design]
runs = 8

[emulator]
pca_components = 2
burn = 60
samples = 20

[calibration]
chains = 4
burn = 150
samples = 200
max_samples = 200
"""


#: The truth of :func:`wall_data` (the boards' specific heat as the study has them).
TRUTH = {"k_cb": 0.124, "cp_cb": 845.41, "cp_fb": 840.0}


def wall_data(
    seed: int = 3,
    days: int = DAYS,
    phi: float = PHI,
    truth: dict[str, float] | None = None,
    test_days: int = 1,
) -> pd.DataFrame:
    """Surface temperatures and the inside heat flux with AR(1) noise, half-hourly.

    One day of warm-up, ``days`` training days and ``test_days`` test days; the
    flux is the wall's at ``truth`` (default :data:`TRUTH`; a truth without
    ``cp_fb`` keeps the study's boards, 840 J/(kg·K)).
    """
    truth = {**TRUTH, **(truth or {})}
    ve = virtual_experiment(
        seed=seed,
        truth=truth,
        runs=5,
        periods=days,
        warmup_days=1,
        test_days=test_days,
        noise_phi=phi,
    )
    n = ve.layout.n_total
    times = pd.date_range("2012-02-01", periods=n, freq="30min")
    assert n == PER_DAY * (days + 1 + test_days)
    return pd.DataFrame(
        {
            "time": times.strftime("%Y-%m-%dT%H:%M:%S"),
            "T_se": np.round(ve.boundary["temp_surf_out"], 6),
            "T_si": np.round(ve.boundary["temp_surf_in"], 6),
            "q_si": np.round(ve.measured["heat_flux_in"], 6),
        }
    )


def write_variant(folder: Path, data: pd.DataFrame, model: str = "white") -> Path:
    """A study folder named ``folder`` with ``data`` and the error model ``model``."""
    folder.mkdir(parents=True, exist_ok=True)
    data.to_csv(folder / "wall.csv", index=False)
    (folder / "study.toml").write_text(
        STUDY.format(name=folder.name, model=model), encoding="utf-8"
    )
    return folder


#: SD of the interface thermometer's noise in :func:`two_sensor_data`. [K]
TEMP_SD = 0.05


def two_sensor_data(seed: int = 3, days: int = DAYS, bias: float = 0.0) -> pd.DataFrame:
    """:func:`wall_data` with white flux noise and ``T_12``, the temperature at the
    concrete / inside-board interface (the wall's ``temp_interface_2``) at the truth
    with white noise of SD :data:`TEMP_SD`, plus ``bias`` [K]: a thermometer that
    reads off by a constant, which no parameter of the model can explain (model error
    the calibration may absorb into the parameters the flux also depends on)."""
    data = wall_data(seed, days, phi=0.0)
    wall = paper_wall(outputs=("temp_interface_2",))  # the study's layers and parameters
    bc = {"temp_surf_out": data["T_se"].to_numpy(), "temp_surf_in": data["T_si"].to_numpy()}
    clean = wall.simulate(TRUTH, Forcing(STEP, bc))["temp_interface_2"]
    rng = np.random.default_rng([seed, 12])
    return data.assign(T_12=np.round(clean + bias + rng.normal(0.0, TEMP_SD, clean.size), 6))


def write_sensors_variant(folder: Path, data: pd.DataFrame, outputs: tuple[str, ...]) -> Path:
    """A study folder of :func:`two_sensor_data` calibrating ``outputs`` (white errors)."""
    text = STUDY.format(name=folder.name, model="white")
    text = text.replace(
        'outputs = ["heat_flux_in"]', 'outputs = ["heat_flux_in", "temp_interface_2"]'
    )
    text = text.replace(
        "[simulator]",
        '[data.columns.temp_interface_2]\nsource = "T_12"\nunit = "degC"\n\n[simulator]',
    )
    listed = ", ".join(f'"{name}"' for name in outputs)
    text = text.replace('calibrate = ["heat_flux_in"]', f"calibrate = [{listed}]")
    if "heat_flux_in" not in outputs:
        text = text.replace('[outputs.errors.heat_flux_in]\nmodel = "white"\n', "")
    if "temp_interface_2" in outputs:
        text += '\n[outputs.errors.temp_interface_2]\nmodel = "white"\n'
    folder.mkdir(parents=True, exist_ok=True)
    data.to_csv(folder / "wall.csv", index=False)
    (folder / "study.toml").write_text(text, encoding="utf-8")
    return folder
