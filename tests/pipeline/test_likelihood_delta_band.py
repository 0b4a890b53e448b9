"""The band of an output with an in-likelihood discrepancy includes the discrepancy.

``[outputs.errors.X] discrepancy = true`` adds ``GP(0, r tau_j^-1 c_x)`` to each
of the output's basis weights in the likelihood; a new measurement then differs
from the model by ``K delta`` besides the noise. The variance that the band adds
is checked against draws of ``K delta`` (Monte Carlo, tolerance from its
standard error), and the band with it is wider than without.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from bayescal.calibration.posterior import calibrate
from bayescal.emulator.assemble import NoiseSpec, assemble
from bayescal.pipeline.predict import likelihood_delta_variance, simulator_band


@pytest.fixture(scope="module")
def with_delta(small_wall: tuple[Any, Any, Any]) -> tuple[Any, Any, Any]:
    ve, _, em = small_wall
    a = assemble(
        ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=2,
        noise={"heat_flux_in": NoiseSpec("white", None, discrepancy=True)},
    )  # fmt: skip
    post = calibrate(em, a, n_chains=2, n_burn=100, n_draws=50, seed=3, backend="serial",
                     observations=a.observations)  # fmt: skip
    return a, em, post


def test_added_variance_is_that_of_the_discrepancys_draws(with_delta: tuple[Any, Any, Any]) -> None:
    a, em, post = with_delta
    var = likelihood_delta_variance(em, a, post)["heat_flux_in"]
    draws = post.draws.shape[0] * post.draws.shape[1]
    assert var.shape == (draws, a.layout.n_total)
    # One draw: delta_j ~ N(0, r / tau_j) per basis, y = sd * (K delta), per sample.
    r = float(post.aux.reshape(draws, -1)[0, post.aux_names.index("delta_rel")])
    rng = np.random.default_rng(0)
    n = 40_000
    tau_inv = np.array([k.variance for k in em.kernels])
    delta = rng.normal(size=(n, tau_inv.size)) * np.sqrt(r * tau_inv)
    sl = a.outputs.slices["heat_flux_in"]
    y = (delta @ np.asarray(em.basis.k)[sl].T) * a.outputs.sd[sl]
    empirical = y.var(axis=0)
    start = int(a.layout.train_starts[0])
    want = var[0, start : start + a.layout.period]
    # The variance of a sample variance of n Gaussian draws is 2 sigma^4 / (n - 1).
    np.testing.assert_allclose(empirical, want, rtol=5 * np.sqrt(2 / (n - 1)))
    assert np.all(want > 0)


def test_band_is_wider_with_the_discrepancy(with_delta: tuple[Any, Any, Any]) -> None:
    a, em, post = with_delta
    s = 20
    sims = np.tile(np.asarray(a.layout.n_total * [0.0]), (s, 1))
    lam = post.lam_stars.reshape(-1)[:s]
    extra = likelihood_delta_variance(em, a, post)["heat_flux_in"][:s]
    plain = simulator_band(a, {"heat_flux_in": sims}, lam)
    wide = simulator_band(a, {"heat_flux_in": sims}, lam, model_error={"heat_flux_in": extra})
    ok = np.isfinite(plain.upper["heat_flux_in"])
    assert np.all(wide.upper["heat_flux_in"][ok] > plain.upper["heat_flux_in"][ok])
    assert np.all(wide.lower["heat_flux_in"][ok] < plain.lower["heat_flux_in"][ok])
