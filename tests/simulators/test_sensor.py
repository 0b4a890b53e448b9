"""Sensor models: parameters targeting ``measured.<output>.offset`` / ``.gain``.

References: the physics simulator alone (the sensor model is an exact affine map
of its output) and a virtual experiment whose measured flux carries a known
offset (the wall example's data shifted by a stated amount).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.config import build_simulator, load_study
from bayescal.demo import TRUTH
from bayescal.pipeline import Options, run
from bayescal.simulators.wrappers import SensorModel

SERIAL = Options(backend="serial", chains_backend="serial")

SENSOR_PARAMETERS = """
[parameters.hfm_offset]
description = "zero offset of the heat-flux plate"
unit = "W/m2"
nominal = 0.0
prior = { distribution = "uniform", lower = -1.0, upper = 1.0 }
targets = ["measured.heat_flux_in.offset"]

[parameters.hfm_gain]
description = "calibration factor of the heat-flux plate"
unit = "1"
nominal = 1.0
prior = { distribution = "uniform", lower = 0.9, upper = 1.1 }
targets = ["measured.heat_flux_in.gain"]

"""

#: Short chains and a small design, as tests/pipeline/test_pipeline.py; one more parameter.
FAST = """
[design]
runs = 30

[emulator]
pca_variance = 0.999
history_periods = 1
burn = 200
samples = 200

[calibration]
chains = 4
burn = 600
samples = 900
max_samples = 900

[predict]
method = "simulator"
runs = 20
"""


def _wall_study(tmp_path: Path, parameters: str, tail: str | None = None) -> Path:
    target = tmp_path / "wall"
    result = CliRunner().invoke(main, ["init", "wall", str(target)])
    assert result.exit_code == 0, result.output
    path = target / "study.toml"
    text = path.read_text(encoding="utf-8")
    cut = text.index("[outputs]")
    text = text[:cut] + parameters + text[cut:]
    if tail is not None:
        text = text[: text.index("[design]")] + tail
    path.write_text(text, encoding="utf-8")
    return target


def test_reading_is_gain_times_simulated_plus_offset(tmp_path: Path) -> None:
    folder = _wall_study(tmp_path, SENSOR_PARAMETERS)
    study = load_study(folder)
    sim = build_simulator(study)
    assert isinstance(sim, SensorModel)
    assert sim.parameter_names == ("k_cb", "cp_cb", "cp_fb", "hfm_offset", "hfm_gain")
    physics = {k: v for k, v in TRUTH.items() if k in ("k_cb", "cp_cb", "cp_fb")}
    # The physics alone, from the same study without the sensor parameters.
    plain = load_study(_wall_study(tmp_path / "plain", ""))
    ctx = run(plain, until="design", options=SERIAL).context
    reference = build_simulator(plain).simulate(physics, ctx.measured.forcing)["heat_flux_in"]
    out = sim.simulate(physics | {"hfm_offset": 0.3, "hfm_gain": 1.05}, ctx.measured.forcing)
    # An affine map of the same floating-point series: equal to rounding.
    np.testing.assert_allclose(out["heat_flux_in"], 1.05 * reference + 0.3, rtol=0, atol=1e-12)
    # Nominal sensor = the physics itself.
    nominal = sim.simulate(physics | {"hfm_offset": 0.0, "hfm_gain": 1.0}, ctx.measured.forcing)
    np.testing.assert_array_equal(nominal["heat_flux_in"], reference)


@pytest.mark.slow
def test_a_known_plate_offset_is_recovered(tmp_path: Path) -> None:
    offset = 0.3  # W/m², added to the example's measured flux (truth: demo.TRUTH)
    only_offset = SENSOR_PARAMETERS[: SENSOR_PARAMETERS.index("[parameters.hfm_gain]")]
    folder = _wall_study(tmp_path, only_offset, FAST)
    data = folder / "data" / "wall.csv"
    frame = pd.read_csv(data)
    frame["q_si"] = frame["q_si"] + offset
    frame.to_csv(data, index=False)
    res = run(load_study(folder), until="predict", options=SERIAL)
    assert res.posterior is not None
    lower, upper = res.posterior.interval(0.95)
    names = list(res.posterior.names)
    truth = {"k_cb": TRUTH["k_cb"], "cp_cb": TRUTH["cp_cb"], "hfm_offset": offset}
    for name, value in truth.items():
        k = names.index(name)
        assert lower[k] <= value <= upper[k], (name, lower[k], upper[k])
    # The offset is separable from the physics (a constant against daily swings of
    # several W/m²): its interval is far narrower than the ±1 W/m² prior.
    k = names.index("hfm_offset")
    assert upper[k] - lower[k] < 0.2
    assert res.predictions is not None
    m = res.predictions.metrics.set_index(["model", "window"])
    # The nominal model misses the offset (MSE >= 0.3² on top of the 0.007 noise);
    # the calibrated one reaches the noise level on the held-out window.
    assert m.loc[("nominal", "test"), "mse"] > 0.05
    assert m.loc[("calibrated", "test"), "mse"] == pytest.approx(0.007, abs=3e-3)
