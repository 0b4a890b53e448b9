"""The noise of the simulator route's bands, estimated from the re-run simulator's residuals.

With ``[predict] method = "simulator"`` the model part of a band is the
simulator itself, which does not make the emulator's error that the
calibration's lambda* also holds; the band's noise is estimated again at every
draw from the run's training residuals
(:func:`bayescal.pipeline.simnoise.simulator_noise`). Checked here: the Gamma
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
from bayescal.emulator.training import train
from bayescal.pipeline.predict import predictions_dataset, simulator_band
from bayescal.pipeline.simnoise import simulator_noise
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


def _discrepancy_experiment(
    model: ErrorModel, phi: float
) -> tuple[Assembled, np.ndarray, np.ndarray, dict]:
    ve = virtual_experiment(seed=11, runs=8, periods=8, warmup_days=2, test_days=4, noise_phi=phi)
    a = assemble(
        ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=2, scale="output",
        noise={"heat_flux_in": NoiseSpec(model, None, discrepancy=True)},
    )  # fmt: skip
    return a, ve.measured["heat_flux_in"], simulate(ve.boundary, ve.truth), ve.truth


@pytest.mark.parametrize(("model", "phi"), [("white", 0.0), ("ar1", 0.7)])
def test_the_out_of_basis_update_against_a_dense_projection(model: ErrorModel, phi: float) -> None:
    a, *_ = _discrepancy_experiment(model, 0.0)
    obs = a.observations
    resid = np.random.default_rng(6).normal(size=obs.y_star.shape)
    resid[5, 1] = np.nan  # this period is left out
    shape, rate = obs.precision_out_of_basis(0, resid, phi)
    kept = np.delete(resid, 1, axis=1)
    n, p = obs.block(0)[0].shape
    # the whitening map as a matrix: W^T W = R^-1 of unit-diagonal AR(1)
    w = np.eye(n)
    if model == "ar1":
        w[1:] = (np.eye(n)[1:] - phi * np.eye(n)[:-1]) / np.sqrt(1.0 - phi * phi)
        lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
        np.testing.assert_allclose(w.T @ w, np.linalg.inv(phi**lags), atol=1e-10)
    kz = w @ obs.block(0)[0]
    leave = np.eye(n) - kz @ np.linalg.solve(kz.T @ kz, kz.T)
    quad = float(np.sum((leave @ w @ kept) ** 2))
    prior = obs.outputs[0].prior
    assert shape == pytest.approx(prior[0] + 0.5 * kept.shape[1] * (n - p), rel=1e-12)
    assert rate == pytest.approx(prior[1] + 0.5 * quad, rel=1e-10)


@pytest.mark.parametrize(("model", "noise_phi"), [("white", 0.0), ("ar1", 0.6)])
def test_with_noise_basis_an_output_with_a_discrepancy_gets_the_noise_its_basis_leaves(
    model: ErrorModel, noise_phi: float
) -> None:
    """The discrepancy lies on the basis: adding any in-basis term to the residuals leaves
    the estimate unchanged, and on the truth's run it is the injected noise."""
    a, _, truth_run, truth = _discrepancy_experiment(model, noise_phi)
    post = _posterior_at_truth(a, truth, noise_phi)
    runs = {"heat_flux_in": np.tile(truth_run, (DRAWS, 1))}
    # by default (noise = "simulator") such an output keeps the calibration's lambda*
    np.testing.assert_array_equal(
        simulator_noise(a, runs, post, np.arange(DRAWS))[:, 0], post.lam_stars.reshape(-1)
    )
    lam = simulator_noise(a, runs, post, np.arange(DRAWS), noise="basis")
    sd = a.observations.outputs[0].scale / np.sqrt(lam[:, 0])
    obs = a.observations
    n, p = obs.block(0)[0].shape
    dof = obs.y_star.shape[1] * (n - p)
    tolerance = 4.0 * np.sqrt((1 + noise_phi**2) / (1 - noise_phi**2) / (2.0 * dof))
    assert np.all(np.abs(sd / np.sqrt(NOISE_VARIANCE) - 1.0) < tolerance)
    calibration = obs.outputs[0].scale / np.sqrt(post.lam_stars.reshape(-1))
    assert np.all(calibration > 2.0 * sd)  # the inflated lambda* was replaced
    # a large discrepancy on the basis weights, period by period: the estimate is unchanged
    st = a.outputs.standardisations[0]
    shift = obs.block(0)[0] @ np.random.default_rng(2).normal(0.0, 5.0, (p, obs.y_star.shape[1]))
    moved = a.layout.cut(truth_run) - (st.sd[:, None] * shift)
    flat = np.asarray(truth_run, dtype=float).copy()
    for j, start in enumerate(a.layout.train_starts):
        flat[start : start + n] = moved[:, j]
    moved_runs = {"heat_flux_in": np.tile(flat, (DRAWS, 1))}
    lam_moved = simulator_noise(a, moved_runs, post, np.arange(DRAWS), noise="basis")
    np.testing.assert_allclose(lam_moved, lam, rtol=1e-9)


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


def test_with_the_emulator_a_discrepancy_output_gets_its_conditional_noise() -> None:
    """noise = "simulator" with the emulator: the noise given the run, the draw's phi and
    r (:meth:`OutputDiscrepancy.noise_given`). At a negligible r the residuals' weights
    are noise too, so it is the white update of the whole residual (precision_given);
    and the truth's run leaves the injected noise."""
    a, _, truth_run, truth = _discrepancy_experiment("white", 0.0)
    post = _posterior_at_truth(a, truth, 0.0)
    names = list(post.aux_names)
    aux = np.array(post.aux, dtype=float)
    aux[..., names.index("delta_rel")] = 1e-12
    post = Posterior.build(
        list(PRIORS), PRIORS, post.unit_draws, acceptance=post.acceptance, aux=aux,
        aux_names=names, noise=a.observations.outputs,
    )  # fmt: skip
    emulator = train(a, n_burn=60, n_draws=10, n_chains=1, seed=0)
    runs = {"heat_flux_in": np.tile(truth_run, (DRAWS, 1))}
    lam = simulator_noise(a, runs, post, np.arange(DRAWS), emulator=emulator)
    obs = a.observations
    st = a.outputs.standardisations[0]
    resid = obs.block(0)[1] - (a.layout.cut(truth_run) - st.mean[:, None]) / st.sd[:, None]
    shape, rate = obs.precision_given(0, resid)
    np.testing.assert_allclose(lam[:, 0], (shape - 1.0) / rate, rtol=1e-6)
    sd = obs.outputs[0].scale / np.sqrt(lam[:, 0])
    tolerance = 4.0 / np.sqrt(2.0 * obs.y_star.size)
    assert np.all(np.abs(sd / np.sqrt(NOISE_VARIANCE) - 1.0) < tolerance)
