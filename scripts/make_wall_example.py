"""Generate the measured data of the paper's wall example (a virtual experiment).

The original measurements of the paper's wall are not public, so the worked
example is a virtual experiment with stated truth and noise:

* Boundary temperatures come from real weather: the Chicago O'Hare TMY3 file
  that ships with EnergyPlus (package ``pyenergyplus-lbnl``), three days of
  warm-up from 12 January, then the 1500 half-hours of the paper. The outside
  surface temperature of a south-facing wall is the solution of its surface
  energy balance (convection with h = 4 + 4 v, absorbed solar with absorptance
  0.6 on the transposed irradiance from pvlib, long-wave exchange with the sky
  from the file's horizontal infrared and with the ground at air temperature).
  The inside face sits in a heated room whose surface temperature wanders
  slowly around 21 °C (a seeded random walk with 0.2 K steps per day, plus a
  heater cycle of 0.3 K amplitude and 3 h period).
* The "measured" inside heat flux is the simulator's output at the true
  parameters plus Gaussian noise with variance 0.007 (W/m²)², the training MSE
  of the paper's Table 4. ``--truth builtin`` uses bayescal's finite-volume wall,
  ``--truth energyplus`` (the default) the EnergyPlus model of the same wall
  (conduction transfer functions, which agree with the exact solution better than
  EnergyPlus's finite differences at this clock; ``paper_wall_simulator``).

Usage::

    python scripts/make_wall_example.py [--truth builtin|energyplus] [--out PATH]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
import pvlib
from scipy import constants, optimize

TRUTH = {"k_cb": 0.124, "cp_cb": 845.0, "cp_fb": 800.0}
NOISE_VARIANCE = 0.007  # (W/m²)², the paper's Table 4 training MSE
WARMUP = 144  # three days simulated before the paper's 1500 values
N_SAMPLES = WARMUP + 1500
SEED = 20130115
EPW_NAME = "USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw"


def _epw_path() -> Path:
    import pyenergyplus

    return Path(pyenergyplus.__file__).parent / "data" / "weather" / EPW_NAME


def outside_surface_temperature(weather: pd.DataFrame, lat: float, lon: float) -> np.ndarray:
    """Surface temperature of a south-facing wall from its steady surface energy balance. [°C]"""
    sigma = constants.Stefan_Boltzmann
    solpos = pvlib.solarposition.get_solarposition(weather.index, lat, lon)
    poa = (
        pvlib.irradiance.get_total_irradiance(
            90.0,
            180.0,
            solpos["apparent_zenith"],
            solpos["azimuth"],
            weather["dni"],
            weather["ghi"],
            weather["dhi"],
            albedo=0.2,
        )["poa_global"]
        .fillna(0.0)
        .to_numpy()
    )
    t_air = weather["temp_air"].to_numpy() + 273.15
    t_sky4 = weather["ghi_infrared"].to_numpy() / sigma
    h_c = 4.0 + 4.0 * weather["wind_speed"].to_numpy()
    eps, alpha = 0.9, 0.6

    def balance(ts: np.ndarray) -> np.ndarray:
        lw = eps * sigma * (0.5 * (t_sky4 - ts**4) + 0.5 * (t_air**4 - ts**4))
        return h_c * (t_air - ts) + alpha * poa + lw

    ts = optimize.newton(balance, t_air.copy(), maxiter=50)
    return np.asarray(ts) - 273.15


def make_boundary(rng: np.random.Generator) -> pd.DataFrame:
    """Half-hourly boundary temperatures, local standard time (UTC-6)."""
    weather, meta = pvlib.iotools.read_epw(_epw_path())
    weather.index = weather.index.map(lambda t: t.replace(year=2013))
    t_se_hourly = pd.Series(
        outside_surface_temperature(weather, meta["latitude"], meta["longitude"]),
        index=weather.index,
    )
    start = pd.Timestamp("2013-01-12 00:00", tz=weather.index.tz)
    times = pd.date_range(start, periods=N_SAMPLES, freq="30min")
    t_se = np.interp(times.asi8, t_se_hourly.index.asi8, t_se_hourly.to_numpy())
    days = np.arange(N_SAMPLES) / 48.0
    walk = np.cumsum(rng.normal(0.0, 0.2 / np.sqrt(48.0), N_SAMPLES))
    t_si = 21.0 + walk + 0.3 * np.sin(2 * np.pi * days * 8.0)
    return pd.DataFrame({"time": times.tz_localize(None), "T_se": t_se, "T_si": t_si})


def truth_flux(
    frame: pd.DataFrame, truth: str, values: dict[str, float] | None = None
) -> np.ndarray:
    """Inside heat flux at the true parameters ``values`` (default :data:`TRUTH`;
    positive wall -> room). [W/m²]"""
    values = TRUTH if values is None else values
    from bayescal.config import build_simulator, load_study
    from bayescal.examples import path
    from bayescal.simulators.base import Forcing

    study = load_study(path("wall"))
    start = pd.Timestamp(frame["time"].iloc[0]).tz_localize("Etc/GMT+6").tz_convert("UTC")
    forcing = Forcing(
        start=np.datetime64(start.tz_localize(None), "s"),
        step=1800.0,
        series={
            "temp_surf_out": frame["T_se"].to_numpy(),
            "temp_surf_in": frame["T_si"].to_numpy(),
        },
    )
    if truth == "builtin":
        sim = build_simulator(study)
    else:
        from bayescal.simulators.energyplus import paper_wall_simulator

        sim = paper_wall_simulator(algorithm="ConductionTransferFunction")
        # the boards' conductivity is fixed at the paper's average (Table 1) in both models
        return sim.simulate(values | {"k_fb": 0.03157}, forcing)["heat_flux_in"]
    return sim.simulate(values, forcing)["heat_flux_in"]


def make_data(
    rng: np.random.Generator, truth: str = "energyplus", values: dict[str, float] | None = None
) -> pd.DataFrame:
    """The example's table (time, T_se, T_si, q_si): boundary temperatures, then the
    inside flux of the ``truth`` model at ``values`` (default :data:`TRUTH`) plus noise;
    the inside surface's wander, then the noise, drawn from ``rng``."""
    frame = make_boundary(rng)
    flux = truth_flux(frame, truth, values)
    frame["q_si"] = flux + rng.normal(0.0, np.sqrt(NOISE_VARIANCE), flux.size)
    return frame


def write_data(frame: pd.DataFrame, out: Path) -> None:
    """Write the table as the example's CSV."""
    out.parent.mkdir(parents=True, exist_ok=True)
    frame.to_csv(out, index=False, float_format="%.4f", date_format="%Y-%m-%d %H:%M")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--truth", choices=["builtin", "energyplus"], default="energyplus")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path(__file__).resolve().parents[1] / "src/bayescal/examples/wall/data/wall.csv",
    )
    args = parser.parse_args()
    frame = make_data(np.random.default_rng(SEED), args.truth)
    write_data(frame, args.out)
    print(f"wrote {args.out} ({len(frame)} rows, truth from {args.truth}: {TRUTH})")


if __name__ == "__main__":
    main()
