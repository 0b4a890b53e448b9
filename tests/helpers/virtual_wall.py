"""A virtual wall experiment with known truth (the paper's wall, section "Wall").

The built-in multilayer wall (glass-fibre board 27 mm | aerated concrete 150 mm |
glass-fibre board 27 mm) is driven by synthetic but realistic surface
temperatures: outside a daily cycle of a few kelvin whose mean and amplitude
change from day to day (a seeded AR(1) "weather"), a few degrees above zero;
inside about 21 °C with a slow drift. The "measured" inside heat flux is the
simulator's output at chosen true parameters plus Gaussian noise of variance
0.007 (W/m²)² (the paper's training MSE, Table 4). A Latin hypercube of 30
runs over the paper's priors (Table 2) supplies the simulations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bayescal.design import Design, UniformPrior, latin_hypercube
from bayescal.periods import PeriodLayout, layout_periods
from bayescal.simulators.base import Forcing, Simulator
from bayescal.simulators.fvm import Layer
from bayescal.simulators.wall import MultilayerWall

STEP = 1800.0  # half-hourly clock [s]
PER_DAY = 48  # samples per day
NOISE_VARIANCE = 0.007  # measurement noise of the inside heat flux [(W/m²)²]

#: The paper's priors (Table 2).
PRIORS = {
    "k_cb": UniformPrior(0.08, 0.16),
    "cp_cb": UniformPrior(640.0, 960.0),
    "cp_fb": UniformPrior(672.0, 1008.0),
}
#: The values the paper estimated (Table 3), used as the default truth.
PAPER_TRUTH = {"k_cb": 0.124, "cp_cb": 845.41, "cp_fb": 799.71}


def paper_wall(outputs: tuple[str, ...] = ("heat_flux_in",)) -> MultilayerWall:
    """The paper's wall with k_cb, cp_cb and cp_fb (both boards) as parameters, giving
    ``outputs``."""
    layers = [
        Layer("fb_out", 0.027, 0.0316, 116.6, 840.0),
        Layer("concrete", 0.150, 0.12, 552.0, 800.0),
        Layer("fb_in", 0.027, 0.0316, 116.6, 840.0),
    ]
    targets = {
        "k_cb": ["concrete.conductivity"],
        "cp_cb": ["concrete.specific_heat"],
        "cp_fb": ["fb_out.specific_heat", "fb_in.specific_heat"],
    }
    return MultilayerWall(layers, parameters=targets, boundary="surface", outputs=outputs)


def plastered_wall() -> MultilayerWall:
    """The paper's wall with a 15 mm gypsum plaster inside: what the 3-layer model lacks."""
    layers = [
        Layer("fb_out", 0.027, 0.0316, 116.6, 840.0),
        Layer("concrete", 0.150, 0.12, 552.0, 800.0),
        Layer("fb_in", 0.027, 0.0316, 116.6, 840.0),
        Layer("plaster", 0.015, 0.4, 1000.0, 1000.0),
    ]
    targets = {
        "k_cb": ["concrete.conductivity"],
        "cp_cb": ["concrete.specific_heat"],
        "cp_fb": ["fb_out.specific_heat", "fb_in.specific_heat"],
    }
    return MultilayerWall(layers, parameters=targets, boundary="surface")


def interval_means(wall: MultilayerWall, truth: dict[str, float], bc: dict[str, np.ndarray],
                   fine: int = 6) -> np.ndarray:  # fmt: skip
    """Inside heat flux as a logger records it: the mean over each clock interval.

    The wall is run on a clock ``fine`` times finer (the surface temperatures
    interpolated linearly, as the simulator itself does between samples) and
    the flux averaged over ``(t - STEP, t]`` by the trapezoidal rule; sample 0
    keeps the instantaneous value. The calibrated model returns instantaneous
    values: a model-form error of the observation, as in most monitoring
    campaigns, that leaves every parameter its physical meaning. [W/m²]
    """
    n = next(iter(bc.values())).size
    t_fine = np.arange((n - 1) * fine + 1) / fine
    series = {name: np.interp(t_fine, np.arange(n), v) for name, v in bc.items()}
    flux = wall.simulate(truth, Forcing(STEP / fine, series))["heat_flux_in"]
    out = np.empty(n)
    out[0] = flux[0]
    windows = flux[: (n - 1) * fine + 1]
    for i in range(1, n):
        seg = windows[(i - 1) * fine : i * fine + 1]
        out[i] = (seg.sum() - 0.5 * (seg[0] + seg[-1])) / fine
    return out


def _ar1(rng: np.random.Generator, n: int, phi: float, sd: float) -> np.ndarray:
    """Stationary AR(1) series with coefficient ``phi`` and marginal sd ``sd``."""
    out = np.empty(n)
    out[0] = rng.normal(0.0, sd)
    innovation = sd * np.sqrt(1.0 - phi * phi)
    for i in range(1, n):
        out[i] = phi * out[i - 1] + rng.normal(0.0, innovation)
    return out


def _daily_to_samples(daily: np.ndarray, n: int) -> np.ndarray:
    """Interpolate day-centred values linearly onto the half-hourly clock."""
    t_day = np.arange(n) / PER_DAY
    centres = np.arange(daily.size) + 0.5
    return np.interp(t_day, centres, daily)


def surface_temperatures(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    """Synthetic winter surface temperatures [°C] on a half-hourly clock of ``n`` samples."""
    days = n // PER_DAY + 2
    mean_out = 4.0 + _ar1(rng, days, 0.7, 3.0)  # daily mean a few °C above zero
    amplitude = np.clip(3.0 + _ar1(rng, days, 0.5, 1.5), 0.5, None)  # several K
    phase = rng.uniform(-1.5, 1.5, days)  # [h] shift of the daily maximum
    hours = np.arange(n) / 2.0
    cycle = np.cos(2.0 * np.pi * (hours - 14.0 - _daily_to_samples(phase, n)) / 24.0)
    temp_out = (
        _daily_to_samples(mean_out, n)
        + _daily_to_samples(amplitude, n) * cycle
        + _ar1(rng, n, 0.9, 0.4)
    )
    slow = 0.6 * np.sin(2.0 * np.pi * hours / (24.0 * rng.uniform(4.0, 7.0)) + rng.uniform(0, 6))
    temp_in = 21.0 + slow + 0.3 * np.cos(2.0 * np.pi * (hours - 18.0) / 24.0)
    temp_in += _ar1(rng, n, 0.95, 0.15)
    return {"temp_surf_out": temp_out, "temp_surf_in": temp_in}


@dataclass(frozen=True)
class VirtualExperiment:
    """Everything a calibration of the virtual wall needs.

    Attributes
    ----------
    design
        The Latin-hypercube design (30 runs by default).
    runs
        ``{"heat_flux_in": (R, n_total)}`` simulated inside heat flux. [W/m²]
    measured
        ``{"heat_flux_in": (n_total,)}`` truth plus noise. [W/m²]
    clean
        The truth run without noise, ``(n_total,)``. [W/m²]
    boundary
        Surface temperatures ``{"temp_surf_out", "temp_surf_in"}``, ``(n_total,)``. [°C]
    layout
        Warm-up, periods and test window.
    truth
        True parameter values in physical units.
    """

    design: Design
    runs: dict[str, np.ndarray]
    measured: dict[str, np.ndarray]
    clean: np.ndarray
    boundary: dict[str, np.ndarray]
    layout: PeriodLayout
    truth: dict[str, float]


def virtual_experiment(
    seed: int = 0,
    truth: dict[str, float] | None = None,
    runs: int = 30,
    periods: int = 25,
    warmup_days: int = 4,
    test_days: int = 2,
    noise_variance: float = NOISE_VARIANCE,
    noise_phi: float = 0.0,
    true_wall: Simulator | None = None,
    means: bool = False,
    logger_substeps: int = 6,
    model: Simulator | None = None,
) -> VirtualExperiment:
    """Simulate the virtual experiment.

    Parameters
    ----------
    seed
        Seeds the weather, the design and the noise.
    truth
        True parameters (default :data:`PAPER_TRUTH`).
    runs
        Latin-hypercube runs ``R``.
    periods
        Daily training periods ``m*``.
    warmup_days, test_days
        Days of warm-up before and of test window after the training periods.
    noise_variance
        Variance of the measurement noise on the inside heat flux. [(W/m²)²]
    noise_phi
        Lag-1 autocorrelation of the noise from sample to sample (AR(1), 0: white). [-]
    true_wall
        The wall that makes the "measurements" (default: the calibrated model
        itself; another wall gives a model-form error the calibration cannot remove).
    means
        Record interval means instead of instantaneous values (:func:`interval_means`).
    logger_substeps
        Fine steps per interval of that record.
    model
        The calibrated model that makes the design runs (default: :func:`paper_wall`,
        instantaneous values; an ``IntervalMeans`` of it describes an averaging logger).
    """
    rng = np.random.default_rng(seed)
    truth = dict(PAPER_TRUTH if truth is None else truth)
    n_total = PER_DAY * (warmup_days + periods + test_days)
    bc = surface_temperatures(rng, n_total)
    forcing = Forcing(STEP, bc)
    wall = paper_wall()
    design = latin_hypercube(PRIORS, runs, seed=int(rng.integers(2**31)))
    calibrated = wall if model is None else model
    sims = np.array(
        [calibrated.simulate(design.row(k), forcing)["heat_flux_in"] for k in range(runs)]
    )
    measuring = wall if true_wall is None else true_wall
    if means:
        clean = interval_means(measuring, truth, bc, fine=logger_substeps)
    else:
        clean = measuring.simulate(truth, forcing)["heat_flux_in"]
    if noise_phi:
        noisy = clean + _ar1(rng, n_total, noise_phi, np.sqrt(noise_variance))
    else:
        noisy = clean + rng.normal(0.0, np.sqrt(noise_variance), n_total)
    layout = layout_periods(n_total, PER_DAY, PER_DAY * warmup_days, PER_DAY * test_days)
    return VirtualExperiment(
        design=design,
        runs={"heat_flux_in": sims},
        measured={"heat_flux_in": noisy},
        clean=clean,
        boundary=bc,
        layout=layout,
        truth=truth,
    )


def random_truth(rng: np.random.Generator, margin: float = 0.1) -> dict[str, float]:
    """A truth drawn uniformly from the inner ``1 - 2 margin`` of each prior interval."""
    return {
        name: float(prior.from_unit(rng.uniform(margin, 1.0 - margin)))
        for name, prior in PRIORS.items()
    }


def simulate(
    boundary: dict[str, np.ndarray], parameters: dict[str, float], model: Simulator | None = None
) -> np.ndarray:
    """Inside heat flux of the paper wall (or ``model``) for ``parameters`` under
    ``boundary``. [W/m²]"""
    wall = paper_wall() if model is None else model
    return wall.simulate(parameters, Forcing(STEP, boundary))["heat_flux_in"]
