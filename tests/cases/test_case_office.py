"""The office example at reduced size: screen --apply, then run to the report.

The full-size study (36 days, 21 candidates, a Sobol screening on 42 runs whose
runs start a sequential design of at most 90, ``[predict] method = "auto"``) is
``scripts/office_case_study.py`` (docs/case-studies.md). Here, the same path at
reduced size: five days (two of warm-up, two of training, one held out), five
candidates, a Sobol screening on 20 runs, a sequential design of 6 new runs and
batches of 4 up to 30 runs in all, 3 held-out runs for ``auto``'s check, short
chains; a couple of minutes on the 2-core machine.

The reduced study calibrates on the electricity meter and the two zone
temperatures, not on gas: over two weekdays the gas meter's night hours (the
water heater alone) hardly vary between runs, and the point-wise
standardisation of so short a design turns the meter noise there into huge
standardised residuals (the measurement precision lambda* collapses to 1e-6 and
the calibration learns nothing). The full-size study, 27 training days with
weekends and night set-back, calibrates on all four outputs.

Checked: the screening ranks what matters above what does not (the furnaces'
burner efficiency has no effect on electricity or on the temperatures, the
plug loads and the heating setpoint do), ``--apply`` marks exactly the proposal,
``run`` calibrates exactly those parameters on a design that starts with the
screening's runs and stays within its cap, ``auto`` records the route it took,
the calibrated model fits the zone temperatures better than the nominal one
(training days and the held-out day) and the Guideline 14 columns are there, the
monthly ones undefined for a window inside one month.
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
    "screening": 'method = "sobol"\nruns = 20\nthreshold = 0.04\nmax_parameters = 4\n',
    "design": "reuse_screening = true\nruns = 6\nsequential = true\nbatch = 4\nmax_runs = 30\n",
    "emulator": "pca_variance = 0.99\nburn = 20\nsamples = 20\n",
    "calibration": "chains = 4\nburn = 200\nsamples = 300\nmax_samples = 300\n",
    "predict": 'method = "auto"\ncheck_runs = 3\ndraws = 20\n',
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
    assert screened.design.runs == 20
    st = {ix.output: dict(zip(ix.names, ix.st, strict=True)) for ix in screened.indices}
    assert set(st) == set(OUTPUTS)
    for output, total in st.items():
        # the furnaces burn gas only: no effect on these outputs, ranked below the loads
        assert total["burner_efficiency"] < 0.01 * max(total.values()), output
        assert max(total, key=total.__getitem__) in ("plug_loads", "heating_setpoint"), output
    assert max(st["electricity"], key=st["electricity"].__getitem__) == "plug_loads"
    for zone in ("temp_air_in_core", "temp_air_in_south"):
        assert max(st[zone], key=st[zone].__getitem__) == "heating_setpoint"
    proposed = set(screened.proposal.selected)
    assert {"plug_loads", "heating_setpoint"} <= proposed
    assert "burner_efficiency" not in proposed
    raw = tomllib.loads(path.read_text(encoding="utf-8"))["parameters"]
    assert {n for n, p in raw.items() if not p["screen"]} == proposed

    res = run(load_study(folder), until="report", options=options)
    assert res.posterior is not None
    assert set(res.posterior.names) - set(res.posterior.held_names) == proposed
    assert res.design is not None
    assert 20 + 6 <= res.design.runs <= 30  # the screening's runs first, within the cap
    assert res.predictions is not None
    assert res.predictions.dataset.attrs["route"] in ("emulator", "simulator")
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
