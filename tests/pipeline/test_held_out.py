"""Held-out sensors: predicted with a band, never calibrated on (issue 15, Twin House column 16).

A study of the paper's wall whose data also hold the temperature at the
concrete / inside-board interface, declared ``[outputs] held_out``. The
"measurements" are the wall at a known truth plus white noise (flux SD
0.0837 W/m², interface SD 0.05 K, the stated accuracy), so the held-out band
(the simulator at posterior draws plus the sensor's noise) must cover the
interface temperature at its rate: within 3.5 binomial standard errors of
0.95 and 0.5 on the training periods (288 samples) and the test window (96).
Declaring the sensor changes no stage before ``predict``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayescal.config import load_study
from bayescal.errors import ConfigError
from bayescal.pipeline import Options, Results, run, stage_keys
from bayescal.pipeline.stages import prepare
from bayescal.simulators.base import Forcing
from bayescal.simulators.wall import MultilayerWall
from paths import FIXTURES
from virtual_wall import PAPER_TRUTH, PER_DAY, STEP, paper_wall, surface_temperatures

SERIAL = Options(backend="serial", chains_backend="serial")
DAYS = 9  # 1 warm-up, 6 training, 2 test
SD = {"heat_flux_in": float(np.sqrt(0.007)), "temp_interface_2": 0.05}

HELD_OUT = """
[outputs]
calibrate = ["heat_flux_in"]
held_out = ["temp_interface_2"]

[outputs.errors.temp_interface_2]
sd = "0.05 K"

[periods]
length = "1D"
warmup = "1D"
test_samples = 96

[design]
runs = 20

[emulator]
pca_variance = 0.999
history_periods = 1
burn = 200
samples = 100

[calibration]
chains = 4
burn = 1000
samples = 1000
max_samples = 1000

[discrepancy]
enabled = false

[predict]
method = "simulator"
runs = 40
"""


def _measuring_wall() -> MultilayerWall:
    """The paper's wall returning the inside flux and the interface temperature."""
    wall = paper_wall()
    targets = {
        "k_cb": ["concrete.conductivity"],
        "cp_cb": ["concrete.specific_heat"],
        "cp_fb": ["fb_out.specific_heat", "fb_in.specific_heat"],
    }
    return MultilayerWall(wall.layers, parameters=targets, outputs=tuple(SD))


def _study(folder: Path, tail: str = HELD_OUT) -> Path:
    """The fixture wall study on generated data with the interface temperature mapped."""
    folder.mkdir(parents=True)
    rng = np.random.default_rng(11)
    n = PER_DAY * DAYS
    bc = surface_temperatures(rng, n)
    truth = _measuring_wall().simulate(PAPER_TRUTH, Forcing(STEP, bc))
    frame = pd.DataFrame(
        {
            "time": pd.date_range("2012-02-01", periods=n, freq="30min"),
            "T_se": bc["temp_surf_out"],
            "T_si": bc["temp_surf_in"],
            "q_si": truth["heat_flux_in"] + rng.normal(0.0, SD["heat_flux_in"], n),
            "T_i2": truth["temp_interface_2"] + rng.normal(0.0, SD["temp_interface_2"], n),
        }
    )
    frame.to_csv(folder / "wall.csv", index=False, float_format="%.6f")
    text = (FIXTURES / "wall-study" / "study.toml").read_text(encoding="utf-8")
    text = text[: text.index("[outputs]")].replace(
        'outputs = ["heat_flux_in"]', 'outputs = ["heat_flux_in", "temp_interface_2"]'
    )
    text += '\n[data.columns.temp_interface_2]\nsource = "T_i2"\nunit = "degC"\n' + tail
    (folder / "study.toml").write_text(text, encoding="utf-8")
    return folder


@pytest.fixture(scope="module")
def predicted(tmp_path_factory: pytest.TempPathFactory) -> Results:
    folder = _study(tmp_path_factory.mktemp("held") / "wall")
    return run(load_study(folder), until="predict", options=SERIAL)


@pytest.mark.slow
def test_held_out_sensor_is_predicted_with_a_band_that_covers(predicted: Results) -> None:
    assert predicted.predictions is not None
    ds, m = predicted.predictions.dataset, predicted.predictions.metrics
    assert ds.attrs["held_out"] == "temp_interface_2"
    assert "temp_interface_2_calibrated_lower50" in ds
    rows = m[m["output"] == "temp_interface_2"]
    assert set(zip(rows["model"], rows["window"], strict=True)) == {
        ("nominal", "train"), ("nominal", "test"), ("calibrated", "train"), ("calibrated", "test"),
    }  # fmt: skip
    for window, n in (("train", 6 * PER_DAY), ("test", 96)):
        row = rows[(rows["model"] == "calibrated") & (rows["window"] == window)].iloc[0]
        for column, level in (("coverage95", 0.95), ("coverage50", 0.5)):
            bound = 3.5 * np.sqrt(level * (1.0 - level) / n)
            assert abs(float(row[column]) - level) < bound, (window, column, row[column])
        nominal = rows[(rows["model"] == "nominal") & (rows["window"] == window)].iloc[0]
        assert float(row["rmse"]) < float(nominal["rmse"])  # nominal k_cb 0.12, truth 0.124


def test_declaring_a_held_out_sensor_changes_no_stage_before_predict(tmp_path: Path) -> None:
    with_sensor = stage_keys(prepare(load_study(_study(tmp_path / "a"))))
    plain_tail = HELD_OUT.replace('held_out = ["temp_interface_2"]\n', "").replace(
        '[outputs.errors.temp_interface_2]\nsd = "0.05 K"\n', ""
    )
    folder = _study(tmp_path / "b", plain_tail)
    text = (folder / "study.toml").read_text(encoding="utf-8")
    # Without the sensor its column must not be mapped (it would be a boundary condition).
    text = text.replace('\n[data.columns.temp_interface_2]\nsource = "T_i2"\nunit = "degC"\n', "\n")
    (folder / "study.toml").write_text(text, encoding="utf-8")
    without = stage_keys(prepare(load_study(folder)))
    for stage in ("design", "emulator", "calibrate", "discrepancy"):
        assert with_sensor[stage] == without[stage], stage
    assert with_sensor["predict"] != without["predict"]


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (('sd = "0.05 K"\n', ""), "needs the sensor's accuracy"),
        (('method = "simulator"', 'method = "emulator"'), "set \\[predict\\] method = 'simulator'"),
        (('calibrate = ["heat_flux_in"]', 'calibrate = ["heat_flux_in", "temp_interface_2"]'),
         "also calibrated on"),
    ],
)  # fmt: skip
def test_a_held_out_sensor_needs_what_its_band_needs(
    tmp_path: Path, edit: tuple[str, str], message: str
) -> None:
    folder = _study(tmp_path / "wall", HELD_OUT.replace(*edit))
    with pytest.raises(ConfigError, match=message):
        load_study(folder)


def test_simulate_scores_the_held_out_sensor_too(tmp_path: Path) -> None:
    from bayescal.simulate import check_simulation, write_simulation

    check = check_simulation(load_study(_study(tmp_path / "wall")))
    assert set(check.train) == {"heat_flux_in", "temp_interface_2"}
    assert check.train["temp_interface_2"].n > 0
    assert np.isfinite(check.train["temp_interface_2"].rmse)
    files = write_simulation(check, tmp_path / "out")
    header = files["csv"].read_text(encoding="utf-8").splitlines()[0]
    assert "temp_interface_2_measured" in header
