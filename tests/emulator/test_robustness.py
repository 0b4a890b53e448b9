"""Numerical robustness: near-duplicate design points and rho -> 1 give finite densities."""

from __future__ import annotations

import numpy as np

from bayescal.calibration.posterior import calibrate
from bayescal.design import Design
from bayescal.emulator.assemble import assemble
from bayescal.emulator.training import TrainingPosterior, train
from virtual_wall import virtual_experiment


def test_near_duplicate_runs_and_rho_near_one_stay_finite() -> None:
    ve = virtual_experiment(seed=1, runs=8, periods=6, warmup_days=2, test_days=0)
    unit = np.array(ve.design.unit)
    unit[1] = unit[0] + 1e-12  # two runs at (almost) the same point: a singular S_theta
    design = Design(ve.design.priors, unit)
    runs = {"heat_flux_in": ve.runs["heat_flux_in"].copy()}
    runs["heat_flux_in"][1] = runs["heat_flux_in"][0]
    a = assemble(design, runs, ve.measured, ve.boundary, ve.layout, components=2)
    target = TrainingPosterior(a.theta, a.x, a.w, a.basis.ktk, a.lam_prior)
    layout = target.layout
    # beta = -4 ln(rho): beta -> 0 is rho -> 1, where every kernel matrix tends to all ones.
    # The model's nugget 1/(lambda k^T k) keeps each eigenvalue of the covariance >= it.
    for beta in (1e-12, 1e-6, 1.0):
        v = layout.pack(np.full((layout.p, layout.r), beta), np.ones(layout.p), 10.0)
        assert np.isfinite(target(v)), beta
    em = train(a, n_burn=50, n_draws=20, n_chains=1, seed=0)
    post = calibrate(em, a, n_chains=4, n_burn=50, n_draws=50, backend="serial")
    assert np.all(np.isfinite(post.draws))
    assert np.all(np.isfinite(post.log_density))
    # Chains this short are not converged, and the diagnostics must say so.
    assert post.warnings
