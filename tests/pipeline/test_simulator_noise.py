"""The noise of the simulator route's bands, estimated from the re-run simulator's residuals.

With ``[predict] method = "simulator"`` the model part of a band is the
simulator itself, which does not make the emulator's error that the
calibration's lambda* also holds; the band's noise is estimated again at every
draw from the run's training residuals
(:func:`bayescal.pipeline.predict.simulator_noise`). Checked here: the Gamma
update (the prior plus the mean square), the estimate against the injected
noise on a known truth, and the bands' coverage on a known truth at their
stated rates (binomial bounds), where the calibration's inflated lambda* makes
them over-cover.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from bayescal.calibration.posterior import Posterior
from bayescal.emulator.assemble import Assembled, NoiseSpec, assemble
from bayescal.emulator.noise import ErrorModel
from bayescal.pipeline.predict import predictions_dataset, simulator_band, simulator_noise
from virtual_wall import NOISE_VARIANCE, PRIORS, simulate, virtual_experiment

DRAWS = 12
INFLATION = 3.0  # the calibration's noise SD, as a multiple of the injected one


def _experiment(model: ErrorModel, phi: float) -> tuple[Assembled, np.ndarray, np.ndarray, dict]:
    ve = virtual_experiment(seed=11, runs=8, periods=8, warmup_days=2, test_days=4, noise_phi=phi)
    a = assemble(
        ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=2, scale="output",
        noise={"heat_flux_in": NoiseSpec(model)},
    )  # fmt: skip
    truth_run = simulate(ve.boundary, ve.truth)
    return a, ve.measured["heat_flux_in"], truth_run, ve.truth


def _posterior_at_truth(a: Assembled, truth: dict[str, float], phi: float) -> Posterior:
    """Draws at the truth, with a calibration noise SD INFLATION times the injected one."""
    obs = a.observations
    scale = obs.outputs[0].scale
    lam_star = (scale / (INFLATION * np.sqrt(NOISE_VARIANCE))) ** 2
    unit = np.array([PRIORS[n].to_unit(truth[n]) for n in PRIORS])
    jitter = np.random.default_rng(0).normal(0.0, 1e-9, (2, DRAWS // 2, unit.size))
    names = ["lambda", *obs.names()]
    aux = np.zeros((2, DRAWS // 2, len(names)))
    aux[..., 0] = 1e4
    aux[..., 1] = lam_star
    if "phi" in names:
        aux[..., names.index("phi")] = phi
    acceptance = np.full((2, unit.size + len(names)), 0.3)
    return Posterior.build(
        list(PRIORS), PRIORS, unit + jitter, acceptance=acceptance, aux=aux, aux_names=names,
        noise=obs.outputs,
    )  # fmt: skip


@pytest.mark.parametrize("model", ["white", "ar1"])
def test_the_gamma_update_is_the_prior_plus_the_mean_square(model: ErrorModel) -> None:
    """Whatever the error model: a band needs the marginal variance (R has a unit diagonal)."""
    a, *_ = _experiment(model, 0.0)
    obs = a.observations
    resid = np.random.default_rng(5).normal(size=obs.y_star.shape)
    resid[3, 2] = np.nan  # this period is left out
    shape, rate = obs.precision_given(0, resid)
    kept = np.delete(resid, 2, axis=1)
    quad = float(np.einsum("im,im->", kept, kept))
    prior = obs.outputs[0].prior
    assert shape == pytest.approx(prior[0] + 0.5 * kept.size, rel=1e-12)
    assert rate == pytest.approx(prior[1] + 0.5 * quad, rel=1e-10)


@pytest.mark.parametrize(
    ("model", "noise_phi", "calibration_phi"),
    [("white", 0.0, 0.0), ("ar1", 0.8, 0.8), ("ar1", 0.0, 0.6)],
)
def test_the_estimate_is_the_injected_noise(
    model: ErrorModel, noise_phi: float, calibration_phi: float
) -> None:
    a, _, truth_run, truth = _experiment(model, noise_phi)
    post = _posterior_at_truth(a, truth, calibration_phi)
    runs = {"heat_flux_in": np.tile(truth_run, (DRAWS, 1))}
    lam = simulator_noise(a, runs, post, np.arange(DRAWS))
    sd = a.observations.outputs[0].scale / np.sqrt(lam[:, 0])
    n = a.observations.y_star.size
    # the truth's run leaves only the noise; the mean square's relative SE as an SD is
    # 1/sqrt(2N), times sqrt((1 + phi^2) / (1 - phi^2)) for AR(1) noise. The third case is
    # white noise under a calibration phi of 0.6: whitening with it would inflate the SD
    # by 46 %, well outside this bound (the marginal variance is what a band needs)
    tolerance = 4.0 * np.sqrt((1 + noise_phi**2) / (1 - noise_phi**2) / (2.0 * n))
    assert np.all(np.abs(sd / np.sqrt(NOISE_VARIANCE) - 1.0) < tolerance)
    calibration = a.observations.outputs[0].scale / np.sqrt(post.lam_stars.reshape(-1))
    assert np.all(calibration > 2.0 * sd)  # the inflated lambda* was replaced


def test_an_output_with_a_discrepancy_keeps_the_calibrations_noise() -> None:
    ve = virtual_experiment(seed=11, runs=8, periods=8, warmup_days=2, test_days=4)
    a = assemble(
        ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=2, scale="output",
        noise={"heat_flux_in": NoiseSpec("white", None, discrepancy=True)},
    )  # fmt: skip
    obs = a.observations
    names = ["lambda", *obs.names()]
    aux = np.ones((1, DRAWS, len(names)))
    aux[..., 1] = np.linspace(1.0, 2.0, DRAWS)
    unit = np.full((1, DRAWS, len(PRIORS)), 0.5)
    acceptance = np.full((1, len(PRIORS) + len(names)), 0.3)
    post = Posterior.build(
        list(PRIORS), PRIORS, unit, acceptance=acceptance, aux=aux, aux_names=names,
        noise=obs.outputs,
    )  # fmt: skip
    runs = {"heat_flux_in": np.tile(simulate(ve.boundary, ve.truth), (DRAWS, 1))}
    lam = simulator_noise(a, runs, post, np.arange(DRAWS))
    np.testing.assert_array_equal(lam[:, 0], aux[0, :, 1])


def _coverage(a: Assembled, measured: np.ndarray, runs: np.ndarray, lam: np.ndarray) -> dict:
    band = simulator_band(a, {"heat_flux_in": runs}, lam, measured={"heat_flux_in": measured})
    test = np.zeros(a.layout.n_total, dtype=bool)
    test[a.layout.test_begin :] = True
    y = measured[test]
    out = {}
    for level, lo, hi in ((0.95, band.lower, band.upper), (0.5, band.lower50, band.upper50)):
        inside = (y >= lo["heat_flux_in"][test]) & (y <= hi["heat_flux_in"][test])
        out[level] = (int(inside.sum()), int(inside.size))
    return out


def test_bands_cover_the_test_window_at_their_rates_on_a_known_truth() -> None:
    a, measured, truth_run, truth = _experiment("white", 0.0)
    post = _posterior_at_truth(a, truth, 0.0)
    runs = np.tile(truth_run, (DRAWS, 1))
    lam = simulator_noise(a, {"heat_flux_in": runs}, post, np.arange(DRAWS))
    honest = _coverage(a, measured, runs, lam)
    inflated = _coverage(a, measured, runs, post.lam_stars.reshape(DRAWS, -1))
    for level in (0.95, 0.5):
        k, n = honest[level]
        lo, hi = stats.binom.interval(0.998, n, level)
        assert lo <= k <= hi, (level, k, n)
    # the calibration's lambda* (emulator error included) over-covers: the failure fixed
    k, n = inflated[0.5]
    assert k > stats.binom.interval(0.998, n, 0.5)[1]


def test_the_bands_noise_is_stated_in_the_outputs_unit() -> None:
    a, measured, truth_run, truth = _experiment("white", 0.0)
    post = _posterior_at_truth(a, truth, 0.0)
    runs = {"heat_flux_in": np.tile(truth_run, (DRAWS, 1))}
    lam = simulator_noise(a, runs, post, np.arange(DRAWS))
    band = simulator_band(a, runs, lam, measured={"heat_flux_in": measured})
    want = float(np.median(a.observations.outputs[0].scale / np.sqrt(lam[:, 0])))
    assert band.noise_sd["heat_flux_in"] == pytest.approx(want, rel=1e-12)
    times = np.arange(a.layout.n_total).astype("datetime64[h]")
    ds = predictions_dataset(
        times, a.layout, {"heat_flux_in": measured}, {"heat_flux_in": truth_run}, band, {}
    )
    assert ds.attrs["heat_flux_in_calibrated_noise_sd"] == pytest.approx(want, rel=1e-12)
