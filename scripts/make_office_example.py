"""Generate the office example: its EnergyPlus model and its "metered" data (a virtual experiment).

The DOE reference small office (``RefBldgSmallOfficeNew2004_Chicago.idf``,
shipped with EnergyPlus in the package ``pyenergyplus-lbnl``) in Chicago
(O'Hare TMY3 weather, shipped beside it), 9 March - 13 April: the end of the
heating season and the shoulder season.

* Model (``office/office.epJSON``): the reference IDF converted by EnergyPlus,
  with its reports and utility tariffs removed (the adapter asks for its own
  series) and its heating setpoint schedule rewritten from ``Schedule:Compact``
  into ``Schedule:Day:Hourly`` day schedules, whose hours are numeric fields a
  parameter can set (``Schedule:Day:Hourly:HTGSETP_WD:Hour 7``). Nothing else
  changes: geometry, constructions, internal gains, five packaged single-zone
  units with gas furnaces and DX cooling, autosized on the design days.
* Boundary conditions (``data/office.csv``): outdoor air temperature and
  global horizontal irradiance from the weather file, and the HVAC operating
  schedule the building manager knows (``hvac_operation``: the share of each
  hour the fans run by schedule, on daylight-saving clock time from 10 March,
  as the model applies it). The emulator needs the schedule to tell a Sunday
  from a Monday of the same weather.
* "Metered" outputs, hourly, stamped at the end of their hour (local standard
  time, UTC-6): facility electricity and natural gas [kWh], and the mean air
  temperatures of the core zone and of the south perimeter zone [°C], from
  EnergyPlus at the hidden true parameters (:data:`TRUTH`, six of the
  study's 21 candidates) plus noise: 2 % (electricity) and 3 % (gas)
  multiplicative Gaussian noise, the meters' resolution (0.01 kWh, 0.1 kWh),
  and 0.15 K Gaussian sensor noise on the temperatures, read to 0.1 K.

The study (``office/study.toml``) is written by hand; this script reads it,
builds its simulator and runs it at the truth, so that the data and the
study's targets cannot disagree.

Usage::

    python scripts/make_office_example.py [--out-dir PATH]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

#: The hidden truth: six of the candidates, none at its nominal value.
TRUTH = {
    "infiltration": 0.00050,  # [m³/(s·m²) of facade]    nominal 0.000302
    "lighting": 8.5,  # [W/m²]                            nominal 10.76
    "plug_loads": 12.5,  # [W/m²]                         nominal 10.76
    "floor_area_per_person": 14.0,  # [m²]                 nominal 18.58
    "heating_setpoint": 22.0,  # [°C] occupied hours        nominal 21.0
    "ground_temperature": 16.0,  # [°C] under the slab      nominal 19.5
}
#: Noise of the meters and sensors.
RELATIVE_NOISE = {"electricity": 0.02, "gas": 0.03}  # [-], standard deviation
RESOLUTION_KWH = {"electricity": 0.01, "gas": 0.1}  # [kWh]
TEMPERATURE_NOISE = 0.15  # [K]
TEMPERATURE_RESOLUTION = 0.1  # [K]
SEED = 20130309
START = pd.Timestamp("2013-03-09 01:00")  # local standard time, end of the first hour
DAYS = 36
DST_START = pd.Timestamp("2013-03-10 02:00")  # second Sunday of March, local standard time
MODEL_NAME = "RefBldgSmallOfficeNew2004_Chicago.idf"
EPW_NAME = "USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw"
COLUMNS = {  # glossary name -> column of data/office.csv
    "temp_air_out": "T_out",
    "ghi": "GHI",
    "hvac_operation": "HVAC_on",
    "electricity": "E_kWh",
    "gas": "Gas_kWh",
    "temp_air_in_core": "T_core",
    "temp_air_in_south": "T_south",
}
#: Report objects of the reference model that the example drops (the adapter asks for
#: its own series; tariffs and environmental factors only feed tables).
DROPPED = (
    "UtilityCost:Charge:Block",
    "UtilityCost:Charge:Simple",
    "UtilityCost:Qualify",
    "UtilityCost:Tariff",
    "UtilityCost:Variable",
    "EnvironmentalImpactFactors",
    "FuelFactors",
    "RunPeriod",
)
#: HVACOperationSchd of the reference model: hours on (clock time) by day type.
OPERATION_HOURS = {"weekday": (6, 22), "saturday": (6, 18), "sunday": (0, 0)}


def _data_folder() -> Path:
    import pyenergyplus

    return Path(pyenergyplus.__file__).parent / "data"


def _hourly(name: str, values: list[float]) -> dict[str, Any]:
    assert len(values) == 24, name
    return {"schedule_type_limits_name": "Temperature"} | {
        f"hour_{h + 1}": v for h, v in enumerate(values)
    }


def heating_schedules() -> dict[str, dict[str, Any]]:
    """HTGSETP_SCH of the reference model as Schedule:Year/Week:Daily/Day:Hourly objects.

    Same values: 21 °C from 06:00 to 22:00 on weekdays and to 18:00 on
    Saturdays, 15.6 °C otherwise (Sundays, holidays, summer design day),
    21 °C all day on the winter design day.
    """
    occupied, setback = 21.0, 15.6
    weekday = [setback] * 6 + [occupied] * 16 + [setback] * 2
    saturday = [setback] * 6 + [occupied] * 12 + [setback] * 6
    days = {
        "HTGSETP_WD": _hourly("HTGSETP_WD", weekday),
        "HTGSETP_SAT": _hourly("HTGSETP_SAT", saturday),
        "HTGSETP_OFF": _hourly("HTGSETP_OFF", [setback] * 24),
        "HTGSETP_DESIGN": _hourly("HTGSETP_DESIGN", [occupied] * 24),
    }
    week = {
        f"{day}_schedule_day_name": "HTGSETP_WD"
        for day in ("monday", "tuesday", "wednesday", "thursday", "friday")
    }
    week |= {
        "saturday_schedule_day_name": "HTGSETP_SAT",
        "sunday_schedule_day_name": "HTGSETP_OFF",
        "holiday_schedule_day_name": "HTGSETP_OFF",
        "summerdesignday_schedule_day_name": "HTGSETP_OFF",
        "winterdesignday_schedule_day_name": "HTGSETP_DESIGN",
        "customday1_schedule_day_name": "HTGSETP_OFF",
        "customday2_schedule_day_name": "HTGSETP_OFF",
    }
    year = {
        "schedule_type_limits_name": "Temperature",
        "schedule_weeks": [
            {
                "schedule_week_name": "HTGSETP_WEEK",
                "start_month": 1,
                "start_day": 1,
                "end_month": 12,
                "end_day": 31,
            }
        ],
    }
    return {
        "Schedule:Day:Hourly": days,
        "Schedule:Week:Daily": {"HTGSETP_WEEK": week},
        "Schedule:Year": {"HTGSETP_SCH": year},
    }


def prepare_model() -> dict[str, Any]:
    """The reference small office as the example ships it (see the module notes)."""
    from bayescal.simulators.energyplus_model import load_model
    from bayescal.simulators.energyplus_output import MODEL_REPORT_OBJECTS

    model = load_model(_data_folder() / "model" / MODEL_NAME)
    for key in (*MODEL_REPORT_OBJECTS, *DROPPED):
        model.pop(key, None)
    del model["Schedule:Compact"]["HTGSETP_SCH"]
    ground = model["Site:GroundTemperature:BuildingSurface"]  # a name without colons
    model["Site:GroundTemperature:BuildingSurface"] = {"Ground Temperatures": ground.popitem()[1]}
    for kind, objects in heating_schedules().items():
        model.setdefault(kind, {}).update(objects)
    return model


def operation(times: pd.DatetimeIndex) -> np.ndarray:
    """Share of each hour ending at ``times`` (local standard time) the HVAC runs by schedule."""
    clock = times - pd.Timedelta(hours=1) + pd.to_timedelta((times > DST_START).astype(int), "h")
    day = np.where(
        clock.day_of_week < 5, "weekday", np.where(clock.day_of_week == 5, "saturday", "sunday")
    )
    first = np.array([OPERATION_HOURS[d][0] for d in day])
    last = np.array([OPERATION_HOURS[d][1] for d in day])
    return ((clock.hour >= first) & (clock.hour < last)).astype(float)


def boundary_conditions(times: pd.DatetimeIndex) -> pd.DataFrame:
    """Weather from the EPW (its hour-ending values) and the HVAC schedule on the clock."""
    from bayescal.data.readers import read_epw

    weather = read_epw(_data_folder() / "weather" / EPW_NAME, year=2013)
    utc = (times + pd.Timedelta(hours=6)).tz_localize("UTC")
    frame = weather.reindex(utc)[["temp_air_out", "ghi"]]
    frame.index = times
    frame["hvac_operation"] = operation(times)
    return frame


def truth(study_dir: Path, frame: pd.DataFrame) -> dict[str, np.ndarray]:
    """EnergyPlus at :data:`TRUTH` (the other parameters at their nominal values)."""
    from bayescal.config import build_simulator, load_study
    from bayescal.simulators.base import Forcing

    study = load_study(study_dir)
    simulator = build_simulator(study, screening=True)
    values = {name: p.nominal for name, p in study.parameters.items()} | TRUTH
    start = np.datetime64(frame.index[0] + pd.Timedelta(hours=6), "s")
    series = {name: frame[name].to_numpy(float) for name in study.boundary_conditions}
    out = simulator.simulate(values, Forcing(3600.0, series, start=start))
    return {name: np.asarray(v) for name, v in out.items()}


def measured(simulated: dict[str, np.ndarray], rng: np.random.Generator) -> dict[str, np.ndarray]:
    """The meters' and sensors' readings of the true series (see the module notes)."""
    out = {}
    for name, joules in simulated.items():
        if name in RELATIVE_NOISE:
            kwh = joules / 3.6e6 * (1.0 + rng.normal(0.0, RELATIVE_NOISE[name], joules.size))
            out[name] = np.round(np.maximum(kwh, 0.0) / RESOLUTION_KWH[name]) * RESOLUTION_KWH[name]
        else:
            noisy = joules + rng.normal(0.0, TEMPERATURE_NOISE, joules.size)
            out[name] = np.round(noisy / TEMPERATURE_RESOLUTION) * TEMPERATURE_RESOLUTION
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    examples = Path(__file__).resolve().parents[1] / "src/bayescal/examples"
    parser.add_argument("--out-dir", type=Path, default=examples / "office")
    args = parser.parse_args()
    folder: Path = args.out_dir
    model = prepare_model()
    (folder / "office.epJSON").write_text(
        json.dumps(model, separators=(",", ":"), sort_keys=True) + "\n", encoding="utf-8"
    )
    times = pd.date_range(START, periods=DAYS * 24, freq="1h")
    frame = boundary_conditions(times)
    rng = np.random.default_rng(SEED)
    readings = measured(truth(folder, frame), rng)
    table = pd.DataFrame({"time": times.strftime("%Y-%m-%d %H:%M")})
    for name, column in COLUMNS.items():
        values = frame[name] if name in frame else readings[name]
        table[column] = np.asarray(values, dtype=float)
    path = folder / "data" / "office.csv"
    path.parent.mkdir(parents=True, exist_ok=True)
    table.to_csv(path, index=False, float_format="%.6g")
    print(f"wrote {folder / 'office.epJSON'} and {path} ({len(table)} rows), truth {TRUTH}")


if __name__ == "__main__":
    main()
