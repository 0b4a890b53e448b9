"""Known-truth calibrations of the virtual wall, scored for coverage (issue 15).

One *case* draws a truth inside the paper's priors, makes the virtual
experiment (white or AR(1) measurement noise; the measuring wall may have a
layer the calibrated model lacks), assembles it with one scale per output,
trains the emulator, calibrates with a chosen error model and predicts by
re-running the simulator at posterior draws (an in-likelihood discrepancy
conditioned on the training residuals, as ``bayescal run`` does). It returns
whether each 95 % parameter interval covers the truth and the coverage of the
95 % and 50 % prediction bands of the measurements on the training and test
windows.
"""

from __future__ import annotations

import hashlib
import pickle
from dataclasses import dataclass
from typing import Any

import numpy as np

from bayescal.calibration.modelerror import discrepancy_ratios
from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.emulator.assemble import Assembled, NoiseSpec, assemble
from bayescal.emulator.gp import Emulator
from bayescal.emulator.noise import ErrorModel, ObservationModel
from bayescal.emulator.training import train
from bayescal.periods import PeriodLayout
from bayescal.pipeline.predict import (
    conditioned_discrepancy,
    predict_band,
    simulator_band,
)
from bayescal.pipeline.simnoise import simulator_noise
from bayescal.simulators.base import Simulator
from bayescal.simulators.wall import MultilayerWall
from bayescal.simulators.wrappers import IntervalMeans
from nonlinear_wall import ConductivityWall
from virtual_wall import (
    NOISE_VARIANCE,
    PRIORS,
    VirtualExperiment,
    paper_wall,
    random_truth,
    simulate,
    virtual_experiment,
)

#: Settings of one case (reduced from the example's: the truth is sharp after ~2000 draws).
TRAIN_DAYS, TEST_DAYS = 20, 4
BAND_RUNS = 40
EMULATOR_DRAWS = 100  # draws propagated through the emulator for its band


#: Emulators trained in this process, by what training reads (see :func:`trained`).
_EMULATORS: dict[str, Emulator] = {}


def trained(a: Assembled, seed: int) -> Emulator:
    """``train(a, ...)`` with this module's settings, once per process for equal inputs.

    The experiments of one truth share the simulator runs (only the measurements, the
    error model or the measuring wall differ), and the emulator is made from the runs
    alone: every field :func:`train` reads or stores is in the key, so a cached emulator
    is the one training would return (``test_the_emulator_cache_is_exact``).
    """
    fields = (a.theta, a.x, a.w, a.y_std, a.basis, a.outputs, a.inputs, a.lam_prior)
    fields += (tuple(a.input_labels), tuple(a.parameter_names), a.theta_normaliser, seed)
    key = hashlib.sha256(pickle.dumps(fields)).hexdigest()
    if key not in _EMULATORS:
        _EMULATORS[key] = train(a, n_burn=300, n_draws=100, n_chains=1, seed=seed)
    return _EMULATORS[key]


@dataclass(frozen=True)
class CaseResult:
    """Coverage of one known-truth calibration."""

    truth: dict[str, float]
    covered: dict[str, bool]
    derived_covered: dict[str, bool]  # the wall's R_wall, U_value, areal heat capacity
    band95: dict[str, float]  # window -> share of measured samples inside the 95 % band
    band50: dict[str, float]
    posterior: Posterior
    samples: dict[str, int]  # window -> number of measured samples scored
    noise_covered: bool  # the noise SD's 95 % interval holds what it estimates (white errors)
    noise_interval: tuple[float, float]  # that interval [W/m²]
    emulator95: dict[str, float]  # the same shares for the band of [predict] method = "emulator"
    emulator50: dict[str, float]
    # the in-likelihood discrepancy's SD in noise SDs (2.5, 50, 97.5 %) and whether the
    # first screen says the model misses part of the measurements (None: no discrepancy)
    model_error: tuple[float, float, float] | None = None
    model_error_shown: bool | None = None


def windows(a: Assembled) -> dict[str, np.ndarray]:
    """Masks ``(n_total,)`` of the training periods and the test window."""
    layout = a.layout
    train = np.zeros(layout.n_total, dtype=bool)
    for start in layout.train_starts:
        train[start : start + layout.period] = True
    test = np.zeros(layout.n_total, dtype=bool)
    test[layout.test_begin :] = True
    return {"train": train, "test": test}


def band_coverage(
    a: Assembled, post: Posterior, measured: dict[str, np.ndarray], runs: dict[str, np.ndarray],
    pick: np.ndarray, emulator: Emulator | None = None,
) -> dict[str, dict[str, tuple[float, float]]]:  # fmt: skip
    """Per output and window, the shares of measured samples inside the 95 % and
    50 % bands built from simulator ``runs`` at the posterior draws ``pick``: the
    band ``bayescal run`` prints with ``[predict] method = "simulator"`` (the noise
    estimated again from the runs' training residuals; with an in-likelihood
    discrepancy, its conditional given the runs, and the discrepancy conditioned on
    the training residuals with it, which needs the ``emulator``)."""
    lam = simulator_noise(a, runs, post, pick, emulator=emulator)
    error = (
        {}
        if emulator is None
        else conditioned_discrepancy(emulator, a, post, pick, runs, lam_stars=lam)
    )
    band = simulator_band(a, runs, lam, measured=measured, model_error=error)
    out: dict[str, dict[str, tuple[float, float]]] = {}
    for name, y_all in measured.items():
        out[name] = {}
        for window, mask in windows(a).items():
            y = y_all[mask]
            inside95 = (y >= band.lower[name][mask]) & (y <= band.upper[name][mask])
            inside50 = (y >= band.lower50[name][mask]) & (y <= band.upper50[name][mask])
            out[name][window] = (float(np.mean(inside95)), float(np.mean(inside50)))
    return out


def draw_picks(post: Posterior, n: int = BAND_RUNS) -> np.ndarray:
    """``n`` evenly spaced indices into the flattened posterior draws."""
    total = post.draws.shape[0] * post.draws.shape[1]
    return np.unique(np.linspace(0, total - 1, n).astype(int))


def _band_coverage(
    a: Assembled, em: Emulator, post: Posterior, measured: np.ndarray,
    boundary: dict[str, np.ndarray], model: Simulator | None = None,
) -> tuple[dict[str, float], dict[str, float]]:  # fmt: skip
    theta = post.draws.reshape(-1, len(post.names))
    pick = draw_picks(post)
    runs = np.array(
        [simulate(boundary, dict(zip(post.names, row, strict=True)), model) for row in theta[pick]]
    )
    cover = band_coverage(
        a, post, {"heat_flux_in": measured}, {"heat_flux_in": runs}, pick, emulator=em
    )
    flux = cover["heat_flux_in"]
    return {w: v[0] for w, v in flux.items()}, {w: v[1] for w, v in flux.items()}


def case_data(
    seed: int,
    *,
    error_model: ErrorModel = "white",
    noise_phi: float = 0.0,
    true_wall: MultilayerWall | ConductivityWall | None = None,
    means: bool = False,
    described: bool = False,
    discrepancy: bool | str = False,
) -> tuple[dict[str, float], VirtualExperiment, Assembled, IntervalMeans | None]:
    """The truth, virtual experiment, assembled data and calibrated model of one case."""
    rng = np.random.default_rng([seed, 15])
    truth = random_truth(rng)
    model = IntervalMeans(paper_wall(), ("heat_flux_in",)) if described else None
    ve = virtual_experiment(
        seed=seed,
        truth=truth,
        periods=TRAIN_DAYS,
        test_days=TEST_DAYS,
        noise_phi=noise_phi,
        true_wall=true_wall,
        means=means,
        logger_substeps=12 if described else 6,
        model=model,
    )
    a = assemble(
        ve.design,
        ve.runs,
        ve.measured,
        ve.boundary,
        ve.layout,
        variance=0.999,
        history=1,
        scale="output",
        noise={"heat_flux_in": NoiseSpec(error_model, discrepancy=discrepancy)},
    )
    return truth, ve, a, model


def run_case(
    seed: int, *, n_burn: int = 1000, n_draws: int = 1000, **experiment: Any
) -> CaseResult:
    """One known-truth calibration (see the module docstring); ``experiment``: the
    keywords of :func:`case_data`.

    ``described``: the calibrated model gives interval means as the logger records
    them (``aggregate = "mean"``: :class:`IntervalMeans` with its default sub-steps),
    the logger itself averaging over a finer clock (12 steps an interval).
    """
    truth, ve, a, model = case_data(seed, **experiment)
    true_wall = experiment.get("true_wall")
    em = trained(a, seed)
    post = calibrate(
        em,
        a,
        n_chains=4,
        n_burn=n_burn,
        n_draws=n_draws,
        seed=seed,
        backend="processes",
        observations=a.observations,
    )
    lower, upper = post.interval(0.95)
    covered = {
        n: bool(lo <= truth[n] <= hi) for n, lo, hi in zip(post.names, lower, upper, strict=True)
    }
    band95, band50 = _band_coverage(a, em, post, ve.measured["heat_flux_in"], ve.boundary, model)
    samples = {w: int(m.sum()) for w, m in windows(a).items()}
    sd_lo, sd_hi = np.quantile(post.noise_sd()["heat_flux_in"], [0.025, 0.975])
    noise_sd = effective_noise_sd(a, ve.clean, float(np.mean(post.phi)) if post.phi.size else 0.0)
    emulator = predict_band(em, a, post, draws=EMULATOR_DRAWS)
    em95, em50 = {}, {}
    y = ve.measured["heat_flux_in"]
    for window, mask in windows(a).items():
        lo, hi = emulator.lower["heat_flux_in"][mask], emulator.upper["heat_flux_in"][mask]
        em95[window] = float(np.mean((y[mask] >= lo) & (y[mask] <= hi)))
        lo, hi = emulator.lower50["heat_flux_in"][mask], emulator.upper50["heat_flux_in"][mask]
        em50[window] = float(np.mean((y[mask] >= lo) & (y[mask] <= hi)))
    sizes = discrepancy_ratios(em, post)
    size = sizes[0] if sizes else None
    actual = _derived_truth(truth, true_wall, ve.boundary, ve.layout)
    return CaseResult(
        truth, covered, _derived_covered(post, actual),
        band95, band50, post, samples,
        bool(sd_lo <= noise_sd <= sd_hi), (float(sd_lo), float(sd_hi)), em95, em50,
        None if size is None else tuple(np.quantile(size.ratio, [0.025, 0.5, 0.975])),
        None if size is None else size.shown,
    )  # fmt: skip


def effective_noise_sd(a: Assembled, clean: np.ndarray, phi: float = 0.0) -> float:
    """What the calibration's noise SD estimates with white errors: the injected noise and
    the part of the noise-free measurement the output basis cannot represent.

    lambda* is learnt from the measured periods' residual outside the basis (the
    remainder of :mod:`bayescal.emulator.noise`, ``m* (n - p)`` degrees of freedom):
    the sensor's noise there, plus the noise-free signal's own out-of-basis part,
    which the model at theta* lacks too. (With AR(1) errors the in-basis block and
    phi share the residual too; there the tests check only that the SD is an upper
    estimate of the sensor's.)
    """
    obs = a.observations
    clean_std = a.outputs.apply({"heat_flux_in": a.layout.cut(clean)})
    model = ObservationModel(obs.outputs, obs.k, clean_std)
    o = obs.outputs[0]
    quad = model.gls(0, phi).quad0 if o.model == "ar1" else model.gls(0, 0.0).quad0
    dof = clean_std.shape[1] * (o.n - o.p)
    return float(np.sqrt(NOISE_VARIANCE + o.scale**2 * quad / dof))


def _derived_truth(
    truth: dict[str, float],
    true_wall: MultilayerWall | ConductivityWall | None,
    boundary: dict[str, np.ndarray],
    layout: PeriodLayout,
) -> dict[str, float]:
    """R, U and areal heat capacity of the wall that made the measurements; a wall whose
    conductivities depend on temperature gives its steady ones at the mean surface
    temperatures of the training periods (warm-up and test days left out)."""
    if isinstance(true_wall, ConductivityWall):
        idx = (layout.train_starts[:, None] + np.arange(layout.period)).ravel()
        t_out, t_in = (float(np.mean(boundary[k][idx])) for k in ("temp_surf_out", "temp_surf_in"))
        return true_wall.derived_at(truth, t_out, t_in)
    return (true_wall or paper_wall()).derived(truth)


def _derived_covered(post: Posterior, actual: dict[str, float]) -> dict[str, bool]:
    """Whether the 95 % intervals of the calibrated wall's R, U and heat capacity
    cover those of the wall that made the measurements (``actual``)."""
    wall = paper_wall()
    flat = post.draws.reshape(-1, len(post.names))
    rows = [wall.derived(dict(zip(post.names, map(float, r), strict=True))) for r in flat]
    out = {}
    for name, value in actual.items():
        column = np.array([r[name] for r in rows])
        lo, hi = np.quantile(column, [0.025, 0.975])
        out[name] = bool(lo <= value <= hi)
    return out


def summary(results: list[CaseResult]) -> dict[str, float]:
    """Parameter coverage (share of intervals covering) and mean band coverages."""
    hits = [c for r in results for c in r.covered.values()]
    out = {"parameters": float(np.mean(hits)), "intervals": float(len(hits))}
    for name in results[0].derived_covered:
        out[name] = float(np.mean([r.derived_covered[name] for r in results]))
    for window in ("train", "test"):
        out[f"band95_{window}"] = float(np.mean([r.band95[window] for r in results]))
        out[f"band50_{window}"] = float(np.mean([r.band50[window] for r in results]))
    return out


__all__ = ["PRIORS", "CaseResult", "band_coverage", "draw_picks", "run_case", "summary", "windows"]
