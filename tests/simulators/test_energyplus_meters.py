"""EnergyPlus meters and interval outputs on the DOE reference small office.

The reference for sums and means is EnergyPlus's own hourly reporting: the
adapter's hourly totals of the time-step meter values must equal the
``Hourly`` meter EnergyPlus writes, and its hourly means of the zone
temperature the ``Hourly`` average. Each run of the office over three days
takes about 1.5 s.
"""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from bayescal.errors import SimulatorError
from bayescal.simulators.base import Forcing
from bayescal.simulators.energyplus import EnergyPlusSimulator
from bayescal.simulators.energyplus_output import (
    OutputSpec,
    interval_series,
    parse_output,
)
from bayescal.simulators.energyplus_run import check_errors, run_energyplus

pyenergyplus = pytest.importorskip("pyenergyplus", reason="needs pyenergyplus-lbnl")
DATA = Path(pyenergyplus.__file__).parent / "data"
OFFICE = DATA / "model" / "RefBldgSmallOfficeNew2004_Chicago.idf"
WEATHER = DATA / "weather" / "USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw"
HOURS = 48
# 15 January 2013 00:00 local standard time (UTC-6); samples end each hour from 01:00.
START = np.datetime64("2013-01-15T07:00")


def _office(**options: object) -> EnergyPlusSimulator:
    return EnergyPlusSimulator(
        OFFICE,
        parameters={
            "lpd": {"object": "Lights", "name": "Core_ZN_Lights", "field": "Watts per Floor Area"}
        },
        outputs={
            "electricity": {"meter": "Electricity:Facility", "aggregate": "sum"},
            "temp_air_in_core": {
                "variable": "Zone Mean Air Temperature",
                "key": "Core_ZN",
                "aggregate": "mean",
            },
        },
        weather=WEATHER,
        **({"warmup_days": 1} | options),  # type: ignore[arg-type]
    )


def _hourly_reference(model_file: Path, folder: Path) -> dict[str, np.ndarray]:
    """EnergyPlus's own hourly meter and hourly mean temperature, by hour end [s of year]."""
    model = json.loads(model_file.read_text(encoding="utf-8"))
    model["Output:Meter"] = {
        "ref": {"key_name": "Electricity:Facility", "reporting_frequency": "Hourly"}
    }
    model["Output:Variable"] = {
        "ref": {
            "key_value": "Core_ZN",
            "variable_name": "Zone Mean Air Temperature",
            "reporting_frequency": "Hourly",
        }
    }
    path = folder / "reference.epJSON"
    path.write_text(json.dumps(model), encoding="utf-8")
    out = folder / "reference"
    run_energyplus(["-w", str(WEATHER), "-d", str(out), str(path)], 300.0, folder)
    check_errors(out / "eplusout.err")
    query = (
        "SELECT d.Name, t.Month, t.Day, t.Hour, r.Value FROM ReportData r JOIN "
        "ReportDataDictionary d USING (ReportDataDictionaryIndex) JOIN Time t USING (TimeIndex) "
        "WHERE d.ReportingFrequency = 'Hourly' AND (t.WarmupFlag IS NULL OR t.WarmupFlag = 0) "
        "ORDER BY t.TimeIndex"
    )
    with sqlite3.connect(out / "eplusout.sql") as db:
        rows = db.execute(query).fetchall()
    found: dict[str, dict[float, float]] = {}
    for name, month, day, hour, value in rows:
        assert month == 1
        found.setdefault(name, {})[((day - 1) * 24 + hour) * 3600.0] = value
    return {name: np.array(sorted(v.items())) for name, v in found.items()}


def test_hourly_totals_and_means_match_energyplus_reports(tmp_path: Path) -> None:
    sim = _office(workdir=tmp_path, keep_outputs=True)
    forcing = Forcing(3600.0, {"temp_air_out": np.zeros(HOURS)}, start=START)
    out = sim.simulate({}, forcing)
    (run,) = tmp_path.glob("bayescal-eplus-*")
    assert json.loads((run / "parameters.json").read_text()) == {"lpd": 10.76}
    reference = _hourly_reference(run / "model.epJSON", tmp_path)
    ends = (14 * 24 + 1 + np.arange(HOURS)) * 3600.0  # 15 Jan 01:00 ... 17 Jan 00:00
    for name, ours in (
        ("Electricity:Facility", "electricity"),
        ("Zone Mean Air Temperature", "temp_air_in_core"),
    ):
        table = reference[name]
        expected = np.interp(ends, table[:, 0], table[:, 1])
        assert set(ends) <= set(table[:, 0])
        # the same time-step values added up by EnergyPlus and by the adapter
        np.testing.assert_allclose(out[ours], expected, rtol=1e-6, atol=1e-6)
    assert out["electricity"].min() > 1e6  # J per hour: the office never uses under 0.3 kWh


def test_successful_runs_leave_nothing_and_outputs_do_not_change_the_key(tmp_path: Path) -> None:
    sim = _office(workdir=tmp_path)
    forcing = Forcing(3600.0, {"temp_air_out": np.zeros(24)}, start=START)
    sim.simulate({"lpd": 8.0}, forcing)
    assert list(tmp_path.iterdir()) == []  # the run's folder was deleted
    kept = _office(workdir=tmp_path / "elsewhere", keep_outputs=True, timeout=60.0)
    assert kept.fingerprint() == sim.fingerprint()
    assert _office(warmup_days=2).fingerprint() != sim.fingerprint()


def test_interval_series_splits_time_steps_in_proportion() -> None:
    times = np.arange(1, 13) * 600.0  # ten-minute steps over two hours
    values = np.arange(12.0)
    total = interval_series(times, values, np.array([3600.0, 7200.0]), 3600.0, "sum")
    np.testing.assert_array_equal(total, [values[:6].sum(), values[6:].sum()])
    mean = interval_series(times, values, np.array([3600.0, 5400.0]), 3600.0, "mean")
    np.testing.assert_allclose(mean, [values[:6].mean(), values[3:9].mean()])
    half = interval_series(times, values, np.array([3900.0]), 3600.0, "sum")
    # 01:05: half of the first step (300 of 600 s) and half of the seventh
    assert half[0] == pytest.approx(values[1:6].sum() + 0.5 * values[0] + 0.5 * values[6])
    with pytest.raises(SimulatorError, match="does not cover"):
        interval_series(times, values, np.array([1800.0]), 3600.0, "sum")


def test_output_specs_are_checked() -> None:
    assert parse_output("e", {"meter": "Gas:Facility", "aggregate": "sum"}) == OutputSpec(
        "Gas:Facility", "", 1.0, True, "sum"
    )
    with pytest.raises(SimulatorError, match="aggregate it with 'sum'"):
        parse_output("e", {"meter": "Gas:Facility"})
    with pytest.raises(SimulatorError, match="'variable' and 'key' or 'meter'"):
        parse_output("e", {"meter": "Gas:Facility", "variable": "x"})
    with pytest.raises(SimulatorError, match="aggregate must be one of"):
        parse_output("e", {"variable": "x", "key": "y", "aggregate": "max"})


def test_package_paths_name_the_files_that_ship_with_energyplus(tmp_path: Path) -> None:
    from bayescal.config.energyplus import EnergyPlusSection

    section = EnergyPlusSection.model_validate(
        {
            "type": "energyplus",
            "model": "pyenergyplus:model/RefBldgSmallOfficeNew2004_Chicago.idf",
            "weather": "pyenergyplus:weather/USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw",
            "outputs": {"electricity": {"meter": "Electricity:Facility"}},
        },
        context={"root": tmp_path},
    )
    assert section.model == OFFICE
    assert section.weather == WEATHER
    with pytest.raises(ValueError, match=r"pyenergyplus ships no 'weather/nowhere\.epw'"):
        EnergyPlusSection.model_validate(
            {
                "type": "energyplus",
                "model": "model.epJSON",
                "weather": "pyenergyplus:weather/nowhere.epw",
                "outputs": {"electricity": {"meter": "Electricity:Facility"}},
            },
            context={"root": tmp_path},
        )


@pytest.mark.parametrize(
    ("output", "match"),
    [
        ({"variable": "Zone Mean Air Temperature"}, "needs its key"),
        ({"meter": "Gas:Facility", "key": "x"}, "a meter has no key"),
        ({"meter": "Gas:Facility", "variable": "x", "key": "y"}, "either variable"),
        ({}, "either variable"),
    ],
)
def test_output_sections_are_variables_or_meters(tmp_path: Path, output: dict, match: str) -> None:
    from bayescal.config.energyplus import EnergyPlusSection

    with pytest.raises(ValueError, match=match):
        EnergyPlusSection.model_validate(
            {"type": "energyplus", "model": "m.epJSON", "outputs": {"gas": output}},
            context={"root": tmp_path},
        )
