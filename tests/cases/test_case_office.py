"""The office example at reduced size: screen --apply, then run to the report.

The full-size study (36 days, 21 candidates, 220 screening runs, 150 design runs)
is ``scripts/office_case_study.py`` (docs/case-studies.md). Here: five days (two
of warm-up, two of training, one held out), five candidates, three Morris
trajectories (18 EnergyPlus runs), 16 design runs, short chains; about a minute
on the 2-core machine.

The reduced study calibrates on the electricity meter and the two zone
temperatures, not on gas: over two weekdays the gas meter's night hours (the
water heater alone) hardly vary between runs, and the point-wise
standardisation of so short a design turns the meter noise there into huge
standardised residuals (the measurement precision lambda* collapses to 1e-6 and
the calibration learns nothing). The full-size study, 27 training days with
weekends and night set-back, calibrates on all four outputs.

Checked: the screening ranks what matters above what does not (the furnaces'
burner efficiency has no effect on electricity or on the temperatures, the
lighting and plug loads do), ``--apply`` marks exactly the proposal, ``run``
calibrates exactly those parameters, the calibrated model fits the zone
temperatures better than the nominal one (training days and the held-out day)
and the Guideline 14 columns are there, the monthly ones undefined for a window
inside one month.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayescal.config import load_study
from bayescal.examples import copy_example
from bayescal.pipeline import Options, run
from bayescal.pipeline.screen import screen

pytest.importorskip("pyenergyplus", reason="the office example runs EnergyPlus")
pytest.importorskip("SALib", reason="screening needs SALib")

KEEP = ("lighting", "plug_loads", "heating_setpoint", "burner_efficiency", "ground_temperature")
OUTPUTS = ("electricity", "temp_air_in_core", "temp_air_in_south")
SMALL = {
    "periods": 'length = "1D"\nwarmup = "2D"\ntest_samples = 24\n',
    "screening": "trajectories = 3\nthreshold = 0.2\nbootstrap = 50\nmax_parameters = 4\n",
    "design": "runs = 16\n",
    "emulator": "pca_variance = 0.99\nburn = 20\nsamples = 20\n",
    "calibration": "chains = 4\nburn = 200\nsamples = 300\nmax_samples = 300\n",
    "predict": "draws = 20\n",
    "outputs": "calibrate = [" + ", ".join(f'"{o}"' for o in OUTPUTS) + "]\n",
}


def _shrink(text: str) -> str:
    """The example's study with five candidates, five days and small settings."""
    blocks = re.split(r"(?m)^(?=\[)", text)
    out = []
    for block in blocks:
        header = re.match(r"\[([a-z_.]+)\]", block)
        name = header[1] if header else ""
        if name.startswith("parameters.") and name.split(".", 1)[1] not in KEEP:
            continue
        if name.startswith("outputs.errors.") and name.rsplit(".", 1)[1] not in OUTPUTS:
            continue
        if name in SMALL:
            block = f"[{name}]\n{SMALL[name]}\n"
        if name == "data":
            block = block.replace('step = "1h"', 'step = "1h"\nend = "2013-03-14T01:00:00"')
        out.append(block)
    return "".join(out)


@pytest.mark.slow
def test_office_screen_then_calibrate(tmp_path: Path) -> None:
    folder = copy_example("office", tmp_path / "office")
    path = folder / "study.toml"
    path.write_text(_shrink(path.read_text(encoding="utf-8")), encoding="utf-8")
    study = load_study(folder)
    assert study.candidates == KEEP
    assert study.calibrated == ()
    options = Options(backend="processes", jobs=2, chains_backend="serial")

    screened = screen(study, options=options, apply=True)
    assert screened.runs.n_failed == 0
    assert screened.design.runs == 3 * (len(KEEP) + 1)
    mu_star = {ix.output: dict(zip(ix.names, ix.mu_star, strict=True)) for ix in screened.indices}
    assert set(mu_star) == set(OUTPUTS)
    for output, effects in mu_star.items():
        # the furnaces burn gas only: no effect on these outputs, ranked below the loads
        assert effects["burner_efficiency"] < 1e-9 * max(effects.values()), output
    assert mu_star["electricity"]["plug_loads"] > mu_star["electricity"]["lighting"] > 0.0
    for zone in ("temp_air_in_core", "temp_air_in_south"):
        assert max(mu_star[zone], key=mu_star[zone].__getitem__) == "heating_setpoint"
    proposed = {"plug_loads", "lighting", "heating_setpoint", "ground_temperature"}
    assert set(screened.proposal.selected) == proposed
    raw = tomllib.loads(path.read_text(encoding="utf-8"))["parameters"]
    assert {n for n, p in raw.items() if not p["screen"]} == proposed

    res = run(load_study(folder), until="report", options=options)
    assert res.posterior is not None
    assert set(res.posterior.names) == proposed
    assert res.report is not None
    assert res.report.is_file()
    metrics = pd.read_csv(res.context.out / "metrics.csv").set_index(["output", "model", "window"])
    monthly = ["cv_rmse_monthly", "nmbe_monthly", "guideline14_monthly"]
    assert set(monthly) <= set(metrics.columns)
    # both windows lie inside March: one month, the monthly criteria are undefined
    assert (metrics["n_months"] == 1).all()
    assert metrics[["cv_rmse_monthly", "nmbe_monthly"]].isna().all().all()
    for window in ("train", "test"):
        for zone in ("temp_air_in_core", "temp_air_in_south"):
            nominal = metrics.loc[(zone, "nominal", window), "cv_rmse"]
            calibrated = metrics.loc[(zone, "calibrated", window), "cv_rmse"]
            assert calibrated < 0.7 * nominal, (zone, window, nominal, calibrated)
        # hourly electricity of the calibrated model: Guideline 14's hourly criteria hold
        row = metrics.loc[("electricity", "calibrated", window)]
        assert row["cv_rmse"] < 30.0
        assert abs(row["nmbe"]) < 10.0
        assert bool(row["guideline14"])
    assert np.isfinite(metrics["cv_rmse"]).all()
