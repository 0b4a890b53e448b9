"""Meters and interval values: energy units, labelled names, totals and means on the clock,
and Guideline 14's monthly criteria."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from bayescal.config import build_simulator, study_from_dict
from bayescal.data.measured import load_measured
from bayescal.data.meters import interval_values
from bayescal.errors import ConfigError, DataError
from bayescal.glossary import GLOSSARY, glossary_quantity
from bayescal.metrics import fit_metrics, meets_guideline14, monthly_metrics
from bayescal.runner import simulator_fingerprint
from bayescal.simulators.wrappers import IntervalMeans
from bayescal.units import dimension_of, to_internal

HOUR = pd.Timedelta("1h")


def test_energy_units_convert_to_joules() -> None:
    assert to_internal([1.0], "kWh")[0] == 3.6e6
    assert to_internal([2.0], "Wh")[0] == 7200.0
    assert to_internal([1.0], "MJ")[0] == 1e6
    # 1 therm = 100 000 international-table Btu = 105.506 MJ
    assert to_internal([1.0], "therm")[0] == pytest.approx(105.505585e6, rel=1e-8)
    assert dimension_of("kBtu") == "energy"


def test_labelled_names_keep_their_quantity() -> None:
    core = glossary_quantity("temp_air_in_core")
    assert core is not None
    assert core.dimension == "temperature"
    assert "(core)" in core.description
    assert GLOSSARY["electricity_lights"].unit == "J"
    assert "gas_boiler_2" in GLOSSARY
    assert glossary_quantity("temp_air_out_core") is None  # only zone and meter names take labels
    assert glossary_quantity("temp_interface_2") is not None
    assert "temp_air_in_core" not in list(GLOSSARY)  # iteration lists the entries only


def test_interval_totals_of_finer_meter_readings() -> None:
    # 15-minute readings of 1 kWh (in J) stamped at the end of their quarter hour.
    times = pd.date_range("2013-01-01 00:15", periods=16, freq="15min", tz="UTC")
    readings = pd.Series(np.full(16, 3.6e6), index=times, name="electricity")
    readings.iloc[9] = np.nan  # the third hour lacks a reading
    clock = pd.date_range("2013-01-01 01:00", periods=4, freq="1h", tz="UTC")
    total = interval_values(readings, clock, HOUR, "sum")
    np.testing.assert_array_equal(total[[0, 1, 3]], 4 * 3.6e6)
    assert np.isnan(total[2])  # a partial total would be wrong by the missing share
    mean = interval_values(readings, clock, HOUR, "mean")
    np.testing.assert_array_equal(mean, 3.6e6)  # three of four readings are enough for a mean


def test_readings_that_do_not_nest_in_the_clock_are_refused() -> None:
    times = pd.date_range("2013-01-01 00:20", periods=12, freq="30min", tz="UTC")
    readings = pd.Series(np.ones(12), index=times, name="gas")
    clock = pd.date_range("2013-01-01 01:00", periods=5, freq="1h", tz="UTC")
    with pytest.raises(DataError, match="does not nest in the clock's intervals"):
        interval_values(readings, clock, HOUR, "sum")
    with pytest.raises(DataError, match="do not add up to the study step"):
        interval_values(readings, clock, pd.Timedelta("45min"), "sum")


def _meter_study(root: Path, **column: Any) -> dict[str, Any]:
    return {
        "study": {"name": "meters"},
        "data": {
            "file": "meters.csv",
            "time_column": "time",
            "step": "1h",
            "columns": {
                "temp_air_out": {"source": "T_out", "unit": "degC"},
                "electricity": {"source": "E", "unit": "kWh", "aggregate": "sum"} | column,
            },
        },
        "simulator": {
            "type": "energyplus",
            "model": "model.epJSON",
            "weather": "weather.epw",
            "outputs": {"electricity": {"meter": "Electricity:Facility"}},
        },
        "parameters": {
            "lpd": {
                "unit": "W/m2",
                "nominal": 10.0,
                "prior": {"distribution": "uniform", "lower": 5.0, "upper": 15.0},
                "targets": ["Lights:Core_ZN_Lights:Watts per Floor Area"],
            }
        },
        "outputs": {"calibrate": ["electricity"]},
        "periods": {"length": "1D", "warmup": "0min", "test_samples": 24},
    }


def test_study_reads_quarter_hour_kwh_as_hourly_joules(tmp_path: Path) -> None:
    # four days: a test day and the two whole training days a study needs
    times = pd.date_range("2013-01-01 00:15", periods=4 * 24 * 4, freq="15min")
    energy = np.round(1.0 + 0.5 * np.sin(np.arange(times.size) / 7.0), 3)  # [kWh]
    pd.DataFrame({"time": times, "T_out": 1.0, "E": energy}).to_csv(
        tmp_path / "meters.csv", index=False
    )
    study = study_from_dict(_meter_study(tmp_path), root=tmp_path)
    measured = load_measured(study)
    hourly = pd.Series(energy, index=times).groupby(lambda t: t.ceil("1h")).sum()
    clock = pd.DatetimeIndex(measured.times).tz_localize(None)
    expected = hourly.reindex(clock).to_numpy() * 3.6e6
    got = measured.outputs["electricity"]
    ok = np.isfinite(got)
    assert ok.sum() >= 4 * 24 - 2  # the first clock instant may lack its first readings
    np.testing.assert_allclose(got[ok], expected[ok], rtol=1e-12)


@pytest.mark.parametrize(
    ("column", "match"),
    [
        ({"aggregate": "point"}, "is an energy over each clock interval"),
        ({"aggregate": "mean"}, "set aggregate = 'sum'"),
    ],
)
def test_meter_columns_must_be_totals(tmp_path: Path, column: dict[str, str], match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        study_from_dict(_meter_study(tmp_path, **column), root=tmp_path)


def test_held_out_meter_must_be_a_total(tmp_path: Path) -> None:
    raw = _meter_study(tmp_path)
    raw["data"]["columns"]["gas"] = {"source": "G", "unit": "kWh", "aggregate": "mean"}
    raw["simulator"]["outputs"]["gas"] = {"meter": "NaturalGas:Facility"}
    raw["outputs"] |= {"held_out": ["gas"], "errors": {"gas": {"sd": "1 kWh"}}}
    with pytest.raises(ConfigError, match="set aggregate = 'sum', got 'mean'"):
        study_from_dict(raw, root=tmp_path)


def test_sum_of_a_temperature_is_refused(tmp_path: Path) -> None:
    raw = _meter_study(tmp_path)
    raw["data"]["columns"]["temp_air_out"]["aggregate"] = "sum"
    with pytest.raises(ConfigError, match="'sum' adds up energies"):
        study_from_dict(raw, root=tmp_path)


def _wall_meter_study(tmp_path: Path, aggregate: str) -> dict[str, Any]:
    raw = _meter_study(tmp_path)
    raw["data"]["columns"] = {
        "temp_surf_out": {"source": "a", "unit": "degC"},
        "temp_surf_in": {"source": "b", "unit": "degC"},
        "heat_flux_in": {"source": "q", "unit": "W/m2", "aggregate": aggregate},
    }
    raw["simulator"] = {
        "type": "wall",
        "layers": [
            {
                "name": "c",
                "thickness": 0.1,
                "conductivity": 1.0,
                "density": 1000.0,
                "specific_heat": 1000.0,
            }
        ],
        "substeps": 4,
    }
    raw["parameters"]["lpd"]["targets"] = ["c.conductivity"]
    raw["parameters"]["lpd"]["unit"] = "W/(m·K)"
    raw["outputs"]["calibrate"] = ["heat_flux_in"]
    return raw


def test_wall_gives_interval_means_not_totals(tmp_path: Path) -> None:
    # A logger's interval means: the built-in wall is wrapped to average its output.
    study = study_from_dict(_wall_meter_study(tmp_path, "mean"), root=tmp_path)
    simulator = build_simulator(study)
    assert isinstance(simulator, IntervalMeans)
    assert simulator.means == ("heat_flux_in",)
    assert simulator.substeps == 4
    point = study_from_dict(_wall_meter_study(tmp_path, "point"), root=tmp_path)
    assert not isinstance(build_simulator(point), IntervalMeans)
    # A held-out sensor logged as means is averaged too (names sorted: the order of
    # the outputs does not change the simulator, nor its stored runs).
    raw = _wall_meter_study(tmp_path, "mean")
    raw["simulator"]["outputs"] = ["heat_flux_in", "heat_flux_out"]
    raw["data"]["columns"]["heat_flux_out"] = {"source": "p", "unit": "W/m2", "aggregate": "mean"}
    raw["outputs"] |= {"held_out": ["heat_flux_out"], "errors": {"heat_flux_out": {"sd": 0.1}}}
    both = build_simulator(study_from_dict(raw, root=tmp_path))
    assert isinstance(both, IntervalMeans)
    assert both.means == ("heat_flux_in", "heat_flux_out")
    # The number of fine steps is part of the simulator's fingerprint (stored runs redone).
    raw["simulator"]["substeps"] = 8
    finer = build_simulator(study_from_dict(raw, root=tmp_path))
    assert simulator_fingerprint(finer) != simulator_fingerprint(both)
    # A total over the interval is an energy, which a flux is not.
    with pytest.raises(ConfigError, match="'sum' adds up energies"):
        study_from_dict(_wall_meter_study(tmp_path, "sum"), root=tmp_path)


# --------------------------------------------------------------------------- Guideline 14


def test_monthly_criteria_use_monthly_totals_and_n_minus_one() -> None:
    times = np.arange("2013-01-01", "2013-04-01", dtype="datetime64[h]")
    obs = np.ones(times.size)
    sim = obs.copy()
    months = times.astype("datetime64[M]")
    sim[months == np.datetime64("2013-02")] *= 1.06  # February 6 % high, others exact
    got = monthly_metrics(times, sim, obs)
    totals_obs = np.array([744.0, 672.0, 744.0])
    totals_sim = totals_obs * np.array([1.0, 1.06, 1.0])
    e = totals_sim - totals_obs
    # Guideline 14: CV(RMSE) = sqrt(sum e² / (n - 1)) / mean; NMBE = sum(-e) / ((n - 1) mean)
    assert got["n_months"] == 3
    assert got["cv_rmse_monthly"] == pytest.approx(
        100 * np.sqrt(np.sum(e**2) / 2) / totals_obs.mean(), rel=1e-12
    )
    assert got["nmbe_monthly"] == pytest.approx(-100 * e.sum() / (2 * totals_obs.mean()))
    assert got["guideline14_monthly"] is True  # CV 3.9 % <= 15, |NMBE| 2.7 % <= 5
    assert meets_guideline14(16.0, 1.0, "monthly") is False
    assert meets_guideline14(16.0, 1.0) is True  # the hourly criteria are looser


def test_monthly_criteria_need_two_months() -> None:
    times = np.arange("2013-01-01", "2013-01-20", dtype="datetime64[h]")
    got = monthly_metrics(times, np.ones(times.size), np.ones(times.size))
    assert got["n_months"] == 1
    assert np.isnan(got["cv_rmse_monthly"])
    assert np.isnan(got["guideline14_monthly"])


def test_monthly_means_for_levels() -> None:
    times = np.arange("2013-01-01", "2013-03-01", dtype="datetime64[h]")
    obs = np.full(times.size, 20.0)
    got = monthly_metrics(times, obs + 0.5, obs, how="mean")
    hourly = fit_metrics(obs + 0.5, obs)
    # a constant offset: monthly NMBE = -0.5 * 2 / (1 * 20) by n - 1 = 1 month
    assert got["nmbe_monthly"] == pytest.approx(-100 * 2 * 0.5 / 20.0)
    assert hourly.nmbe == pytest.approx(-100 * 0.5 * times.size / ((times.size - 1) * 20.0))
