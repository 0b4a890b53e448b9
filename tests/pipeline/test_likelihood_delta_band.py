"""The band of an output with an in-likelihood discrepancy: conditioned on the training residuals.

``[outputs.errors.X] discrepancy = true`` adds ``GP(0, r tau_j^-1 c_x)`` to each
of the output's basis weights in the likelihood. Predictions condition it on the
measured training periods at every posterior draw
(:func:`bayescal.pipeline.predict.conditioned_discrepancy`; the Gaussian algebra
is checked against dense conditioning in ``tests/calibration/test_conditional.py``).
Here: that the series are placed on the right samples in physical units, for the
simulator and the emulator routes, by a limit with a known answer (a discrepancy
as large as the prior allows and almost no noise reproduces the measured weights),
and that the band uses it.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

from bayescal.calibration.orthogonal import Sensitivity
from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.emulator.assemble import NoiseSpec, assemble
from bayescal.pipeline.predict import (
    conditioned_discrepancy,
    emulator_with_test_window,
    predict_band,
    simulator_band,
)
from virtual_wall import simulate


def _calibrated(wall: tuple[Any, Any, Any], **basis: Any) -> tuple[Any, Any, Any, Any]:
    """The wall's emulator, its data assembled with a discrepancy, and a short posterior."""
    ve, _, em = wall
    a = assemble(
        ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, **basis,
        noise={"heat_flux_in": NoiseSpec("white", None, discrepancy=True)},
    )  # fmt: skip
    post = calibrate(em, a, n_chains=2, n_burn=100, n_draws=50, seed=3, backend="serial",
                     observations=a.observations)  # fmt: skip
    return ve, a, em, post


@pytest.fixture(scope="module")
def with_delta(small_wall: tuple[Any, Any, Any]) -> tuple[Any, Any, Any, Any]:
    return _calibrated(small_wall, components=2)


def _sharp(post: Posterior) -> Posterior:
    """The same draws with r = 1 and lambda* = 1e10: the discrepancy takes up every residual."""
    aux = np.array(post.aux, dtype=float, copy=True)
    aux[..., post.aux_names.index("delta_rel")] = 1.0
    aux[..., post.aux_names.index("lambda_star")] = 1e10
    return dataclasses.replace(post, aux=aux)


def _train_mask(a: Any) -> np.ndarray:
    mask = np.zeros(a.layout.n_total, dtype=bool)
    for start in a.layout.train_starts:
        mask[start : start + a.layout.period] = True
    return mask


def test_simulator_route_reproduces_the_measured_weights_in_the_limit(
    with_delta: tuple[Any, Any, Any, Any],
) -> None:
    ve, a, em, post = with_delta
    sharp = _sharp(post)
    pick = np.arange(0, 100, 25)
    theta = post.draws.reshape(-1, len(post.names))[pick]
    runs = np.array(
        [simulate(ve.boundary, dict(zip(post.names, row, strict=True))) for row in theta]
    )
    out = conditioned_discrepancy(em, a, sharp, pick, {"heat_flux_in": runs})
    mean, var = out["heat_flux_in"]
    mask = _train_mask(a)
    assert mean.shape == var.shape == (pick.size, a.layout.n_total)
    assert np.all(np.isnan(mean[:, ~mask]))
    assert np.all(np.isfinite(mean[:, mask]))
    # expected: the runs' weights replaced by the measured ones, in physical units
    obs = a.observations
    ko = obs.block(0)[0]
    sd = a.outputs.sd[:, None]
    measured_w = obs.weights_of(0, obs.y_star)
    for s in range(pick.size):
        y_sim = (a.layout.cut(runs[s]) - a.outputs.mean[:, None]) / sd
        want = sd * (ko @ (measured_w - obs.weights_of(0, y_sim)).T)  # (n, m*)
        got = a.layout.cut(mean[s])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * np.abs(want).max())
        assert np.all(a.layout.cut(var[s]) < 1e-6 * np.abs(want).max() ** 2)
    # with the calibration's own r and lambda* the shift is smaller and the variance not 0
    mean0, var0 = conditioned_discrepancy(em, a, post, pick, {"heat_flux_in": runs})["heat_flux_in"]
    assert np.all(var0[:, mask] > 0.0)
    band = simulator_band(a, {"heat_flux_in": runs}, post.lam_stars.reshape(-1)[pick],
                          model_error={"heat_flux_in": (mean0, var0)})  # fmt: skip
    plain = simulator_band(a, {"heat_flux_in": runs}, post.lam_stars.reshape(-1)[pick])
    np.testing.assert_allclose(
        band.mean["heat_flux_in"][mask], (runs + mean0).mean(axis=0)[mask], rtol=1e-12
    )
    # in-sample the conditioned discrepancy pulls the prediction towards the measurement
    y = ve.measured["heat_flux_in"][mask]
    rmse = np.sqrt(np.mean((band.mean["heat_flux_in"][mask] - y) ** 2))
    assert rmse < np.sqrt(np.mean((plain.mean["heat_flux_in"][mask] - y) ** 2))


def test_emulator_route_reproduces_the_measured_weights_in_the_limit(
    with_delta: tuple[Any, Any, Any, Any],
) -> None:
    _, a, em, post = with_delta
    pick = np.arange(0, 100, 33)
    mean, var = conditioned_discrepancy(em, a, _sharp(post), pick)["heat_flux_in"]
    obs = a.observations
    want = a.outputs.invert(obs.block(0)[0] @ obs.weights_of(0, obs.y_star).T)
    for s in range(pick.size):
        got = a.layout.cut(mean[s])
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * np.abs(want).max())
        # nothing is left: the noise (here ~0) carries the out-of-basis part on the
        # training periods, and the emulator's 1 / lambda is not added again
        scale = float(np.max(a.outputs.sd**2 / em.lam))
        assert np.all(np.abs(a.layout.cut(var[s])) <= 1e-4 * scale)
    band = predict_band(em, a, post, draws=20)
    assert np.all(np.isfinite(band.mean["heat_flux_in"][_train_mask(a)]))


def test_a_posterior_without_r_has_nothing_to_condition(
    with_delta: tuple[Any, Any, Any, Any],
) -> None:
    _, a, em, post = with_delta
    names = tuple(n for n in post.aux_names if n != "delta_rel")
    keep = [post.aux_names.index(n) for n in names]
    plain = dataclasses.replace(post, aux=post.aux[..., keep], aux_names=names)
    assert conditioned_discrepancy(em, a, plain, np.arange(3)) == {}


def test_emulator_route_with_a_test_window_conditions_on_its_runs(
    paper_wall: tuple[Any, Any, Any],
) -> None:
    # The emulator extended to the test window's runs (method.md section 6) keeps the
    # discrepancy conditioned on the training periods alone, and the test window's
    # variance holds the out-of-basis excess there.
    ve, a, em, post = _calibrated(paper_wall, variance=0.99)
    ext = emulator_with_test_window(em, a)
    assert ext.x.shape[0] == a.n_periods + a.x_test.shape[0]
    pick = np.arange(0, 100, 33)
    mean, var = conditioned_discrepancy(ext, a, post, pick)["heat_flux_in"]
    test = np.zeros(a.layout.n_total, dtype=bool)
    test[a.layout.test_begin :] = True
    assert np.all(np.isfinite(mean[:, test]))
    excess = a.out_of_basis_excess()
    assert excess.max() > 0.0
    floor = (a.outputs.sd**2 * excess)[:, None]  # (samples per period, 1)
    assert np.all(a.layout.cut(var, "test") >= floor[None] * (1.0 - 1e-12))
    band = predict_band(
        em, a, post, draws=20, measured={"heat_flux_in": ve.measured["heat_flux_in"]}
    )
    assert np.all(np.isfinite(band.lower["heat_flux_in"][test]))


def test_the_orthogonal_discrepancy_predicted_on_the_training_days_is_orthogonal(
    small_wall: tuple[Any, Any, Any],
) -> None:
    # Both routes krige the discrepancy with the constrained covariance at each draw's
    # theta* and lambda: on the training periods its weights meet the constraint
    # F^T delta = 0 (calibration/orthogonal.py) at that draw.
    ve, _, em = small_wall
    a = assemble(
        ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=2,
        noise={"heat_flux_in": NoiseSpec("white", None, discrepancy="orthogonal")},
    )  # fmt: skip
    post = calibrate(em, a, n_chains=2, n_burn=100, n_draws=50, seed=3, backend="serial",
                     observations=a.observations)  # fmt: skip
    pick = np.arange(0, 100, 33)
    theta = post.draws.reshape(-1, len(post.names))[pick]
    runs = np.array(
        [simulate(ve.boundary, dict(zip(post.names, row, strict=True))) for row in theta]
    )
    obs = a.observations
    ko = obs.block(0)[0]
    sensitivity = Sensitivity(em, a.n_periods, [obs.outputs[0].bases])
    unit = post.unit_draws.reshape(-1, len(post.names))[pick]
    lam = np.asarray(post.aux).reshape(-1, len(post.aux_names))[pick, 0]
    assert post.aux_names[0] == "lambda"
    # r = 1: the discrepancy takes up what the constraint and the noise let it (the limit
    # of no noise is ill-conditioned along F, where the constrained covariance is singular)
    aux = np.array(post.aux, dtype=float, copy=True)
    aux[..., post.aux_names.index("delta_rel")] = 1.0
    sharp = dataclasses.replace(post, aux=aux)
    runs_in = {"heat_flux_in": runs}
    mean, var = conditioned_discrepancy(em, a, sharp, pick, runs_in)["heat_flux_in"]
    assert np.all(np.isfinite(mean[:, _train_mask(a)]))
    for s in range(pick.size):
        delta = np.linalg.lstsq(ko, a.layout.cut(mean[s]) / a.outputs.sd[:, None], rcond=None)[0]
        f = sensitivity(unit[s], float(lam[s]))  # (p, m*, t)
        inner = np.einsum("jik,ji->k", f, delta)
        assert np.all(np.abs(inner) < 1e-8 * np.abs(delta).max()), inner
        assert np.abs(delta).max() > 1e-3  # not zero
    # with the calibration's own r and lambda*, both routes: finite, positive variances
    for route in (runs_in, None):
        mean, var = conditioned_discrepancy(em, a, post, pick, route)["heat_flux_in"]
        assert np.all(np.isfinite(mean[:, _train_mask(a)]))
        assert np.all(var[:, _train_mask(a)] > 0)
