"""Interval means of a built-in simulator (``aggregate = "mean"``): IntervalMeans.

References: an output linear in time (its interval mean is the value at the
interval's midpoint), the virtual wall's own logger (tests/helpers: the same
rule, written as a loop over the intervals for the validation experiments), and
the box run on the fine clock and averaged by hand (scipy's trapezoid).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.integrate import trapezoid

from bayescal.errors import SimulatorError
from bayescal.simulators import solar
from bayescal.simulators.base import Forcing
from bayescal.simulators.box import TestBox
from bayescal.simulators.wrappers import IntervalMeans, interval_means
from virtual_wall import PAPER_TRUTH, STEP, paper_wall, surface_temperatures
from virtual_wall import interval_means as logger_means


@dataclass(frozen=True)
class Clock:
    """A toy simulator: its output is the time since the start (and a copy of its input)."""

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return ("a",)

    @property
    def input_names(self) -> tuple[str, ...]:
        return ("temp_air_out",)

    @property
    def output_names(self) -> tuple[str, ...]:
        return ("heat_flux_in", "temp_air_in")

    def simulate(self, parameters: Mapping[str, float], forcing: Forcing) -> dict[str, np.ndarray]:
        t = np.arange(forcing.n) * forcing.step
        return {
            "heat_flux_in": parameters["a"] * t,
            "temp_air_in": forcing["temp_air_out"].copy(),
        }


def test_the_mean_of_a_ramp_is_its_midpoint_value() -> None:
    n, step = 7, 600.0
    forcing = Forcing(step, {"temp_air_out": np.linspace(0.0, 6.0, n) ** 2})
    sim = IntervalMeans(Clock(), ("heat_flux_in",), substeps=5)
    out = sim.simulate({"a": 2.0}, forcing)
    t = np.arange(n) * step
    expected = 2.0 * (t - step / 2)
    expected[0] = 0.0  # no interval before the first sample: its instantaneous value
    np.testing.assert_allclose(out["heat_flux_in"], expected, rtol=0, atol=1e-9)
    # Outputs not averaged are the values at the instants; inputs interpolated
    # linearly pass through unchanged at the clock's samples.
    np.testing.assert_allclose(out["temp_air_in"], forcing["temp_air_out"], rtol=0, atol=1e-12)
    assert all(v.shape == (n,) for v in out.values())


def test_wall_means_equal_the_validation_logger() -> None:
    # tests/helpers/virtual_wall.interval_means: the same rule as a loop over the intervals.
    bc = surface_temperatures(np.random.default_rng(3), 48 * 3)
    wall = paper_wall()
    got = IntervalMeans(wall, ("heat_flux_in",), substeps=6).simulate(
        PAPER_TRUTH, Forcing(STEP, bc)
    )["heat_flux_in"]
    expected = logger_means(wall, PAPER_TRUTH, bc, fine=6)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    # The mean lags the instantaneous flux: the difference is what the wrapper is for.
    instant = wall.simulate(PAPER_TRUTH, Forcing(STEP, bc))["heat_flux_in"]
    assert np.sqrt(np.mean((got - instant) ** 2)) > 0.01


def test_means_converge_with_substeps() -> None:
    bc = surface_temperatures(np.random.default_rng(4), 48 * 2)
    wall, forcing = paper_wall(), Forcing(STEP, bc)
    runs = {
        k: IntervalMeans(wall, ("heat_flux_in",), k).simulate(PAPER_TRUTH, forcing)["heat_flux_in"]
        for k in (3, 6, 24)
    }
    coarse = np.max(np.abs(runs[3] - runs[24]))
    fine = np.max(np.abs(runs[6] - runs[24]))
    assert fine < coarse / 2  # measured 0.34: the wall's own steps refine with the clock
    # The default's error is small next to the lag it corrects.
    instant = wall.simulate(PAPER_TRUTH, forcing)["heat_flux_in"]
    assert fine < 0.1 * np.max(np.abs(runs[24] - instant))


def test_interval_means_helper_and_errors() -> None:
    np.testing.assert_allclose(interval_means(np.arange(7.0), 3), [0.0, 1.5, 4.5])
    with pytest.raises(SimulatorError, match="whole intervals"):
        interval_means(np.arange(6.0), 3)
    with pytest.raises(SimulatorError, match="substeps must be >= 1"):
        IntervalMeans(Clock(), ("heat_flux_in",), substeps=0)
    with pytest.raises(SimulatorError, match="does not produce"):
        IntervalMeans(Clock(), ("heating_power",))
    sim = IntervalMeans(Clock(), ("heat_flux_in",))
    assert sim.parameter_names == ("a",)
    assert sim.input_names == ("temp_air_out",)


def test_box_heating_power_means_follow_the_sun_on_the_fine_clock() -> None:
    # The box computes the sun's position from the forcing's start and step: the
    # fine clock must keep both, so each hourly mean is the trapezoid of the box run
    # by hand on the 10-minute clock over the hour that ends at the timestamp.
    n, step, lat, lon = 49, 3600.0, 50.8, 4.35
    start = np.datetime64("2013-03-10T00:00", "s")
    times = start + (np.arange(n) * step).astype("timedelta64[s]")
    ghi, dhi = solar.clear_sky(times, lat, lon)
    series = {
        "temp_air_out": 6.0 + 5.0 * np.sin(2 * np.pi * (np.arange(n) - 9.0) / 24.0),
        "ghi": ghi,
        "dhi": dhi,
        "wind_speed": np.full(n, 3.0),
        "temp_air_in": np.full(n, 25.0),
    }
    box = TestBox(mode="coheating", latitude=lat, longitude=lon)
    got = IntervalMeans(box, ("heating_power",), 6).simulate({}, Forcing(step, series, start))
    x = np.arange((n - 1) * 6 + 1) / 6
    fine = Forcing(600.0, {k: np.interp(x, np.arange(n), v) for k, v in series.items()}, start)
    power = box.simulate({}, fine)["heating_power"]
    by_hand = [power[0]] + [trapezoid(power[6 * (i - 1) : 6 * i + 1]) / 6 for i in range(1, n)]
    np.testing.assert_allclose(got["heating_power"], by_hand, rtol=0, atol=1e-9)
    # In the morning the power falls as the sun rises: the hour's mean lies above its end.
    instant = box.simulate({}, Forcing(step, series, start))["heating_power"]
    morning = slice(8, 12)
    assert np.all(got["heating_power"][morning] > instant[morning])
