"""Assembly of runs and measurements: layout, standardisation, basis, weights, inputs."""

from __future__ import annotations

import numpy as np
import pytest

from bayescal.emulator.assemble import NoiseSpec, assemble, runs_to_columns
from bayescal.emulator.noise import DEFAULT_NOISE_PRIOR
from bayescal.errors import DataError
from virtual_wall import PER_DAY, VirtualExperiment, virtual_experiment


@pytest.fixture(scope="module")
def small() -> VirtualExperiment:
    return virtual_experiment(seed=3, runs=8, periods=6, warmup_days=2, test_days=2)


def test_columns_are_run_major(small: VirtualExperiment) -> None:
    runs = small.runs["heat_flux_in"]
    a = assemble(small.design, small.runs, small.measured, small.boundary, small.layout)
    m_star = small.layout.m_star
    y = a.outputs.invert(a.y_std)
    for k in (0, 3, 7):
        for i in (0, 5):
            start = small.layout.train_starts[i]
            # Standardise-then-invert is exact up to rounding.
            np.testing.assert_allclose(
                y[:, k * m_star + i], runs[k, start : start + PER_DAY], rtol=1e-12
            )


def test_runs_to_columns_order() -> None:
    cut = np.arange(2 * 3 * 4, dtype=float).reshape(2, 3, 4)  # (R, n, m*)
    cols = runs_to_columns(cut)
    assert cols.shape == (3, 8)
    np.testing.assert_array_equal(cols[:, 1 * 4 + 2], cut[1, :, 2])


def test_standardisation_comes_from_the_simulations(small: VirtualExperiment) -> None:
    a = assemble(small.design, small.runs, small.measured, small.boundary, small.layout)
    # Mean 0 and SD 1 over the simulated periods, by construction: rounding only.
    np.testing.assert_allclose(a.y_std.mean(axis=1), 0.0, atol=1e-12)
    np.testing.assert_allclose(a.y_std.std(axis=1), 1.0, rtol=1e-12)
    sims = runs_to_columns(small.layout.cut(small.runs["heat_flux_in"]))
    meas = small.layout.cut(small.measured["heat_flux_in"])
    expected = (meas - sims.mean(axis=1)[:, None]) / sims.std(axis=1)[:, None]
    np.testing.assert_allclose(a.y_star_std, expected, rtol=1e-12, atol=1e-12)


def test_weights_and_lambda_priors_match_least_squares(small: VirtualExperiment) -> None:
    a = assemble(
        small.design, small.runs, small.measured, small.boundary, small.layout, components=2
    )
    assert a.basis.p == 2
    k = a.basis.k
    # lambda: the paper's Gamma(5, 5) updated by eq. 7; lambda*: the weak default
    # (a sensor accuracy the study does not state must not dominate the data).
    cases = (
        (a.y_std, a.w, a.lam_prior, (5.0, 5.0)),
        (a.y_star_std, a.w_star, a.lam_star_prior, DEFAULT_NOISE_PRIOR),
    )
    for y, w, prior, (shape, rate) in cases:
        ref, *_ = np.linalg.lstsq(k, y, rcond=None)
        # Two independent least-squares solvers on a well-conditioned 2-column K.
        np.testing.assert_allclose(w, ref.T, rtol=1e-9, atol=1e-11)
        resid = y - k @ ref
        n, m = y.shape
        assert prior[0] == pytest.approx(shape + 0.5 * m * (n - 2), rel=1e-15)
        assert prior[1] == pytest.approx(rate + 0.5 * float(np.sum(resid**2)), rel=1e-9)


def test_variance_fraction_picks_the_fewest_components(small: VirtualExperiment) -> None:
    a = assemble(
        small.design, small.runs, small.measured, small.boundary, small.layout, variance=0.99
    )
    cumulative = np.cumsum(a.basis.explained)
    assert cumulative[a.basis.p - 1] >= 0.99
    assert a.basis.p == 1 or cumulative[a.basis.p - 2] < 0.99


def test_inputs_theta_and_test_window(small: VirtualExperiment) -> None:
    a = assemble(small.design, small.runs, small.measured, small.boundary, small.layout)
    np.testing.assert_allclose(a.x.min(axis=0), 0.0, atol=1e-15)  # min/max scaling: rounding
    np.testing.assert_allclose(a.x.max(axis=0), 1.0, rtol=1e-14)
    assert a.x.shape[0] == small.layout.m_star
    lower = np.array([p.lower for p in small.design.priors.values()])
    upper = np.array([p.upper for p in small.design.priors.values()])
    np.testing.assert_allclose(a.theta, (small.design.values - lower) / (upper - lower), atol=1e-14)
    # The test window goes through the same transform as the training periods.
    train = {n: small.layout.cut(v).T for n, v in small.boundary.items()}
    np.testing.assert_allclose(a.inputs.transform(train), a.x, atol=1e-13)
    test = {n: small.layout.cut(v, "test").T for n, v in small.boundary.items()}
    np.testing.assert_allclose(a.x_test, a.inputs.transform(test), atol=0.0)
    assert a.x_test.shape == (small.layout.test_starts.size, a.x.shape[1])
    assert a.y_star_test_std.shape == (PER_DAY, small.layout.test_starts.size)
    assert a.input_labels[:3] == ["k_cb", "cp_cb", "cp_fb"]


def test_two_outputs_are_standardised_separately_and_stacked(small: VirtualExperiment) -> None:
    runs = dict(small.runs)
    runs["heat_flux_out"] = 10.0 * small.runs["heat_flux_in"] + 3.0  # another unit scale
    measured = dict(small.measured)
    measured["heat_flux_out"] = 10.0 * small.measured["heat_flux_in"] + 3.0
    a = assemble(small.design, runs, measured, small.boundary, small.layout)
    assert a.outputs.names == ("heat_flux_in", "heat_flux_out")
    assert a.y_std.shape[0] == 2 * PER_DAY
    parts = a.outputs.split(a.y_std)
    # An affine copy of an output standardises to the same values: rounding only.
    np.testing.assert_allclose(parts["heat_flux_in"], parts["heat_flux_out"], atol=1e-11)
    sd = a.outputs.split(a.outputs.sd)
    np.testing.assert_allclose(sd["heat_flux_out"], 10.0 * sd["heat_flux_in"], rtol=1e-12)


def test_wrong_run_shape_is_named(small: VirtualExperiment) -> None:
    runs = {"heat_flux_in": small.runs["heat_flux_in"][:5]}
    with pytest.raises(DataError, match=r"shape \(5, \d+\), expected \(8 runs"):
        assemble(small.design, runs, small.measured, small.boundary, small.layout)


def test_missing_measurement_in_a_training_period_is_refused(small: VirtualExperiment) -> None:
    measured = {"heat_flux_in": small.measured["heat_flux_in"].copy()}
    measured["heat_flux_in"][small.layout.train_starts[2] + 4] = np.nan
    with pytest.raises(DataError, match="missing values inside the training periods"):
        assemble(small.design, small.runs, measured, small.boundary, small.layout)


def test_history_adds_the_previous_periods_conditions(small: VirtualExperiment) -> None:
    ve = small
    base = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=2)
    lagged = assemble(
        ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=2, history=1
    )
    names = [sp.name for sp in lagged.inputs.series]
    assert names == [*ve.boundary, *(f"{n}_lag1" for n in ve.boundary)]
    assert lagged.x.shape[1] > base.x.shape[1]
    assert lagged.x_test.shape[1] == lagged.x.shape[1]
    # The lag series' PCA is centred on the mean day *before* each training period.
    layout = ve.layout
    out = ve.boundary["temp_surf_out"]
    before = np.stack([out[s - PER_DAY : s] for s in layout.train_starts], axis=1)
    lag = next(sp for sp in lagged.inputs.series if sp.name == "temp_surf_out_lag1")
    np.testing.assert_allclose(lag.mean, before.mean(axis=1), rtol=1e-12)
    # The basis and the weights do not depend on x.
    np.testing.assert_array_equal(lagged.w, base.w)


def test_noise_specs_reach_the_observation_model(small: VirtualExperiment) -> None:
    # [outputs.errors] discrepancy = true must switch the in-likelihood discrepancy on.
    noise = {"heat_flux_in": NoiseSpec("ar1", None, discrepancy=True)}
    a = assemble(
        small.design, small.runs, small.measured, small.boundary, small.layout, noise=noise
    )
    (out,) = a.observations.outputs
    assert (out.model, out.discrepancy) == ("ar1", "conditions")
    assert a.observations.names() == ("lambda_star", "phi", "delta_rel")
    plain = assemble(small.design, small.runs, small.measured, small.boundary, small.layout)
    assert not plain.observations.outputs[0].discrepancy
