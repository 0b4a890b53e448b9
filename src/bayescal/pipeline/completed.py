"""The emulator route's bands with its centre completed off the output basis.

The emulator predicts an output's basis weights, so its centre at a draw holds
only the part of the simulator's output on the output basis (the PCA basis of
the design runs). The rest, the run's part *off* the basis, is left to the
band's noise (lambda*), so the centre can miss the simulator by as much as
the noise: on the office example the hourly gas CV(RMSE) on the held-out week
was 18 % on the emulator route against 6 % on the simulator route at the same
posterior.

``[predict] method = "auto"`` has already run the simulator at ``check_runs``
posterior draws (:mod:`bayescal.pipeline.route`). Their part off the basis,
``o_j = y_j - B(y_j)`` (``B`` the projection on the basis, in the output's
standardised scale, mapped back), is measured on every sample of the training
periods and the test window. With ``[predict] off_basis = "check_runs"`` the
emulator route treats, at every one of its ``draws`` posterior draws ``s``,

    y_s = eta(theta_s) + mean_j o_j

as the run at the draw, with the variance of the emulator's mean (in-basis)
plus the spread of ``o`` over the held-out runs as the variance of one more
run's part (sample variance times ``1 + 1/n``), and then makes the band as the
simulator route does (:func:`bayescal.pipeline.predict.simulator_band`): the
noise estimated again from the completed centre's residuals on the training
periods (:func:`bayescal.pipeline.simnoise.simulator_noise`; those residuals
also hold the emulator's in-basis error and the draw's departure of its part off
the basis from the mean, which the two variances above add once more:
conservative, and small where ``auto`` takes this route) and an in-likelihood
discrepancy kriged from those residuals. No simulator run is made beyond the
held-out ones. The corrected prediction (the difference process) is not made
here: Delta was estimated against the emulator's centre on the basis, so what of
the part off it Delta's own basis holds is in Delta already
(:func:`bayescal.pipeline.stages.predict_stage`; not measured with the completion).

The part off the basis varies with theta; over the posterior's narrow region
it varies little, which the route check measures: each held-out run against
the centre completed with the *other* runs' mean part
(:attr:`bayescal.pipeline.route.RouteCheck.completed`), and a warning where
that exceeds ``check_tolerance`` noise SDs.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from bayescal.calibration.posterior import Posterior
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.emulator.noise import LogLevel
from bayescal.pipeline.predict import (
    Band,
    DiscrepancyModel,
    conditioned_discrepancy,
    emulator_with_test_window,
    period_moments,
    place_periods,
    predicted_parts,
    simulator_band,
    thin_draws,
)
from bayescal.pipeline.simnoise import NoiseChoice, simulator_noise

__all__ = ["completed_band", "emulator_runs"]


def emulator_runs(
    emulator: Emulator, assembled: Assembled, theta: np.ndarray
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """The emulator's mean and in-basis variance of every output at ``theta``, on the record.

    The emulator is conditioned on the design runs over the test window too
    (:func:`bayescal.pipeline.predict.emulator_with_test_window`), as the emulator
    route's is; no noise, no out-of-basis variance.

    Returns
    -------
    tuple of dict
        Output name -> mean and variance ``(S, n_total)``, on the calibration's level
        scale, NaN outside the training periods and the test window's periods.
    """
    layout = assembled.layout
    extended = emulator_with_test_window(emulator, assembled)
    slices = extended.outputs.slices
    s = theta.shape[0]
    silent = np.full((s, len(slices)), np.inf)  # lambda* = inf: no noise
    no_excess = np.zeros(extended.outputs.sd.shape)
    means = {n: np.full((s, layout.n_total), np.nan) for n in slices}
    variances = {n: np.full((s, layout.n_total), np.nan) for n in slices}
    for x, starts, begin in predicted_parts(assembled):
        if not len(starts):
            continue
        mean, var = period_moments(extended, theta, silent, x, None, no_excess)
        for name, sl in slices.items():
            place_periods(layout, starts, mean[:, sl], means[name], begin)
            place_periods(layout, starts, var[:, sl], variances[name], begin)
    return means, variances


def completed_band(
    emulator: Emulator,
    assembled: Assembled,
    posterior: Posterior,
    off_basis: Mapping[str, tuple[np.ndarray, np.ndarray]],
    *,
    draws: int = 300,
    level: float = 0.95,
    noise: NoiseChoice = "simulator",
    discrepancy: DiscrepancyModel | None = None,
    measured: Mapping[str, np.ndarray] | None = None,
    transforms: Mapping[str, LogLevel] | None = None,
) -> Band:
    """The emulator route's band with its centre completed off the basis (module docstring).

    Parameters
    ----------
    emulator, assembled
        The trained emulator and the assembled data.
    posterior
        theta* and lambda* draws of the calibration.
    off_basis
        Output name -> the held-out runs' mean part off the output basis and the
        variance of one more run's part, ``(n_total,)`` each, on the level scale
        (:attr:`bayescal.pipeline.route.RouteCheck.off_basis`). Every calibrated
        output must have one.
    draws
        Posterior draws propagated (thinned evenly over the chains).
    level
        Probability of the outer band. [-]
    noise
        ``[predict] noise`` (:func:`bayescal.pipeline.simnoise.simulator_noise`).
    discrepancy
        A fitted difference process to add (``None``, as the pipeline calls it: the
        model alone; the corrected prediction is not completed).
    measured
        Output name -> measured series ``(n_total,)`` for the PIT (optional).
    transforms
        Outputs with relative errors -> their log map.

    Raises
    ------
    ValueError
        An output has no part off the basis in ``off_basis``.
    """
    names = list(emulator.outputs.slices)
    if missing := [o for o in names if o not in off_basis]:
        raise ValueError(f"completed_band: no part off the basis for {', '.join(missing)}")
    theta, lam_stars, pick = thin_draws(posterior, draws)
    means, variances = emulator_runs(emulator, assembled, theta)
    runs = {o: means[o] + off_basis[o][0][None] for o in names}
    spread = {o: variances[o] + off_basis[o][1][None] for o in names}
    if discrepancy is None:
        lam_stars = simulator_noise(assembled, runs, posterior, pick, noise, emulator)
    model_error = conditioned_discrepancy(
        emulator, assembled, posterior, pick, runs, lam_stars=lam_stars
    )
    for o in names:
        mean, var = model_error.get(o, (np.zeros_like(runs[o]), np.zeros_like(runs[o])))
        model_error[o] = (mean, var + spread[o])
    return simulator_band(
        assembled,
        runs,
        lam_stars,
        level=level,
        discrepancy=discrepancy,
        measured=measured,
        model_error=model_error,
        transforms=transforms,
    )
