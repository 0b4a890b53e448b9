"""``scripts/twinhouse_sensors.py``: the Twin House variants with two calibrated sensors.

* Every variant's study text, built from the shipped example, loads: the temperature
  calibrated with its error model (or held out, ``flux-only``) and the boundary flux
  held out with its stated accuracy.
* The boundary flux's column (17) is mapped without a sign flip: on the training days
  it rises with the temperature drop across the EPS (outside surface minus the
  boundary), as the wall's ``heat_flux_interface_2`` (positive outside -> inside) does.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from paths import REPO, SHARED_DATA

sys.path.insert(0, str(REPO / "scripts"))

import twinhouse_sensors as script

from bayescal.config import load_study
from bayescal.examples import path as example_path

TWINHOUSE_FILE = SHARED_DATA / "annex58-twinhouse-n2-exp1" / "validationdataN2Exp1.txt"


@pytest.mark.parametrize("temp", sorted(script.TEMP_MODELS))
def test_every_variant_loads_with_the_boundary_flux_held_out(tmp_path: Path, temp: str) -> None:
    text = (example_path("twinhouse") / "study.toml").read_text(encoding="utf-8")
    (tmp_path / "study.toml").write_text(script.variant_text(text, temp), encoding="utf-8")
    study = load_study(tmp_path)
    assert "heat_flux_interface_2" in study.outputs.held_out
    assert study.data.columns["heat_flux_interface_2"].source == 17
    assert study.data.columns["heat_flux_interface_2"].sign == 1
    errors = study.outputs.errors
    if temp == "flux-only":
        assert study.outputs.calibrate == ["heat_flux_in"]
        assert "temp_interface_2" in study.outputs.held_out
    else:
        assert study.outputs.calibrate == ["heat_flux_in", "temp_interface_2"]
        assert errors["temp_interface_2"].model == ("white" if temp == "white" else "ar1")
        assert bool(errors["temp_interface_2"].discrepancy) is (temp == "ar1")
    assert errors["heat_flux_in"].model == "ar1"


@pytest.mark.shared_data
def test_the_boundary_flux_is_positive_outside_to_inside() -> None:
    if not TWINHOUSE_FILE.is_file():
        pytest.skip(f"{SHARED_DATA} is absent: the Annex 58 measurements are not in a fresh clone")
    data = np.loadtxt(TWINHOUSE_FILE, skiprows=2)
    day = data[:, 0] / 86400.0  # days since 1 Jan 2013 00:00 local time
    train = (day >= 237.0) & (day < 264.0)  # 26 Aug - 21 Sep: the training days
    drop = data[train, 18] - data[train, 16]  # outside surface minus the boundary [K]
    assert np.corrcoef(data[train, 17], drop)[0, 1] > 0.9
