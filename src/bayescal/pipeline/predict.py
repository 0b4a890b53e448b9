"""Calibrated predictions with bands, and fit metrics on the training and test windows.

**What a band includes.** For every sample the predictive distribution of a
*measurement* is the mixture over ``S`` posterior draws of Gaussians
(:mod:`bayescal.calibration.predictive`): for draw ``s`` the model's prediction at
theta*_s (the emulator's mean, or the simulator re-run at theta*_s), the
emulator's own interpolation variance (emulator predictions only: its
in-basis variance, and on the test window the out-of-basis variance beyond the
training periods', :meth:`Assembled.out_of_basis_excess`), the observation noise of the draw
(``sd^2 / lambda*_s`` with ``sd`` the output's standardisation scale: with
"output" standardisation this is the noise SD in the output's unit squared; on
the simulator route estimated again from the runs, see below), and,
for the corrected prediction, the difference process ``Delta(x)`` (its GP mean
and variance) with theta* from the discrepancy phase. An output with a
discrepancy in the likelihood adds that discrepancy conditioned on the training
residuals at the draw (:func:`conditioned_discrepancy`). So the band of a
measurement holds parameter uncertainty + emulator uncertainty + noise (+ Delta).
The prediction line is the mixture's mean.

The 95 % and 50 % bands (``[predict] level`` sets the outer one) are the
mixture's central quantiles, computed exactly by bisection on its CDF, not from
random realisations; their Monte Carlo error (from the finite ``S``) is
estimated and reported as a fraction of the band's width (``mc_error``). The
probability integral transform ``PIT = F(y_measured)`` of every measured sample
is stored for the report's PIT histogram (uniform when the bands mean what they
say).

With ``[predict] method = "simulator"`` the simulator itself is re-run at
``runs`` posterior draws (:func:`simulator_band`): exact physics at every draw,
no emulator error. Its noise is estimated again at every draw from the run's
residuals on the training periods (:func:`bayescal.pipeline.simnoise.simulator_noise`;
``[predict] noise = "calibration"`` keeps lambda*): lambda* also holds the
emulator's error, which the re-run simulator does not make.

With ``method = "emulator"`` the emulator is also conditioned on the design
runs over the test window (:func:`emulator_with_test_window`: they were simulated
under its known boundary conditions), so it interpolates there between runs as
on the training periods; and the band adds the out-of-basis variance by which
the test window's runs exceed the training periods' (:meth:`Assembled.out_of_basis_excess`).

With ``method = "auto"`` on the emulator route the held-out runs of its check
complete the centre with their part off the output basis
(:mod:`bayescal.pipeline.completed`, ``[predict] off_basis``).

Samples of the training periods get the training predictions; samples of the
test window get the predictions of the periods covering it. Everything else
(warm-up, dropped periods) is NaN.

Metrics (see :mod:`bayescal.metrics`) are computed on the samples of the
training periods (``window = "train"``) and of the test window (``"test"``)
where the measurement is finite; ``coverage95`` and ``coverage50`` are the
fractions of measured samples inside the 95 % and 50 % bands. ``guideline14``
says whether the ASHRAE Guideline 14 criteria for hourly data hold (CV(RMSE) <=
30 %, |NMBE| <= 10 %); they were written for whole-building energy use and are
shown for orientation only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal, Protocol

import numpy as np
import pandas as pd
import xarray as xr
from scipy.stats import norm

from bayescal.calibration.conditional import OutputDiscrepancy
from bayescal.calibration.posterior import Posterior
from bayescal.calibration.predictive import mixture_quantiles, quantile_error
from bayescal.calibration.predictive import pit as predictive_pit
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.emulator.noise import LogLevel
from bayescal.glossary import GLOSSARY
from bayescal.metrics import (
    KEY_COLUMNS,
    MODELS,
    coverage_n_effs,
    fit_metrics,
    meets_guideline14,
    metric_columns,
    monthly_metrics,
)
from bayescal.periods import PeriodLayout

__all__ = [
    "Band",
    "DiscrepancyModel",
    "conditioned_discrepancy",
    "emulator_with_test_window",
    "metrics_table",
    "predict_band",
    "predictions_dataset",
    "simulator_band",
]

PAIRS_PER_CHUNK = 20_000


class DiscrepancyModel(Protocol):
    """What predictions need of a fitted difference process."""

    def predict(self, x_new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of Delta, ``(N, q)`` each, physical units."""
        ...


@dataclass(frozen=True)
class Band:
    """A prediction over the record: output name -> series ``(n_total,)``.

    ``lower``/``upper`` bound the outer band (``level``, 95 % by default),
    ``lower50``/``upper50`` the 50 % band; ``pit`` is ``F(y_measured)`` (NaN
    where not measured or not predicted); ``mc_error`` the median Monte Carlo
    standard error of the outer band's edges as a fraction of its width;
    ``noise_sd`` the observation noise SD the band holds (median over draws
    and samples, in the output's unit; simulator route only).
    """

    mean: dict[str, np.ndarray]
    lower: dict[str, np.ndarray]
    upper: dict[str, np.ndarray]
    lower50: dict[str, np.ndarray] = field(default_factory=dict)
    upper50: dict[str, np.ndarray] = field(default_factory=dict)
    pit: dict[str, np.ndarray] = field(default_factory=dict)
    mc_error: dict[str, float] = field(default_factory=dict)
    level: float = 0.95
    noise_sd: dict[str, float] = field(default_factory=dict)


def _mixture_band(
    means: Mapping[str, np.ndarray],
    variances: Mapping[str, np.ndarray],
    measured: Mapping[str, np.ndarray],
    level: float,
    transforms: Mapping[str, LogLevel] | None = None,
) -> Band:
    """The band of the mixtures ``(S, n_total)`` per output (NaN where not predicted).

    An output in ``transforms`` (relative errors) has its mixture on the log
    scale: the edges map back exactly, the mean is the mixture's mean on the
    output's own scale, the PIT is unchanged and the Monte Carlo error is that
    of the edges on the log scale as a fraction of the band's width there.
    ``measured`` is on the output's own scale.
    """
    tail = 0.5 * (1.0 - level)
    band = Band({}, {}, {}, level=level)
    for name, mean in means.items():
        var = variances[name]
        level_map = (transforms or {}).get(name)
        ok = np.all(np.isfinite(mean), axis=0) & np.all(np.isfinite(var), axis=0)
        series = {k: np.full(mean.shape[1], np.nan) for k in ("m", "lo", "hi", "lo50", "hi50")}
        pit = np.full(mean.shape[1], np.nan)
        error = float("nan")
        if ok.any():
            mu, v = mean[:, ok], var[:, ok]
            q = mixture_quantiles(mu, v, [tail, 0.25, 0.75, 1.0 - tail])
            width = np.maximum(q[3] - q[0], np.finfo(float).tiny)
            edge = np.maximum(quantile_error(mu, v, q[0]), quantile_error(mu, v, q[3]))
            error = float(np.median(edge / width))
            if level_map is None:
                series["m"][ok] = mu.mean(axis=0)
            else:
                series["m"][ok] = level_map.mean(mu, v).mean(axis=0)
                q = level_map.inverse(q)
            for k, row in zip(("lo", "lo50", "hi50", "hi"), q, strict=True):
                series[k][ok] = row
            obs = np.asarray(measured[name], dtype=float) if name in measured else None
            if obs is not None:
                seen = obs[ok] if level_map is None else level_map.forward(obs[ok], name)
                pit[ok] = predictive_pit(mu, v, seen)
        band.mean[name], band.lower[name], band.upper[name] = (
            series["m"],
            series["lo"],
            series["hi"],
        )
        band.lower50[name], band.upper50[name] = series["lo50"], series["hi50"]
        band.pit[name] = pit
        band.mc_error[name] = error
    return band


def thin_draws(posterior: Posterior, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` draws spread evenly over all chains: theta* ``(n, t)``, lambda* ``(n, O)``
    and the draws' indices in the flattened draws."""
    theta = posterior.draws.reshape(-1, len(posterior.names))
    lam_stars = posterior.lam_stars.reshape(theta.shape[0], -1)
    pick = np.unique(np.linspace(0, theta.shape[0] - 1, min(n, theta.shape[0])).astype(int))
    return theta[pick], lam_stars[pick], pick


def period_moments(
    emulator: Emulator,
    theta: np.ndarray,
    lam_stars: np.ndarray,
    x: np.ndarray,
    discrepancy: DiscrepancyModel | None,
    excess: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Means and variances ``(S, N, P)`` of a measurement at ``P`` periods, per draw.

    The variance is the emulator's in-basis variance, the draw's noise and
    ``excess`` ``(N,)``, the out-of-basis variance beyond the training periods'
    (standardised; :meth:`Assembled.out_of_basis_excess`).
    """
    s, p = theta.shape[0], x.shape[0]
    th = np.repeat(theta, p, axis=0)
    xx = np.tile(x, (s, 1))
    # Chunks of whole draws keep the (pairs x runs) work arrays to ~100 MB.
    per = max(1, PAIRS_PER_CHUNK // p) * p
    parts = [
        emulator.predict(th[i : i + per], xx[i : i + per], out_of_basis=False)
        for i in range(0, s * p, per)
    ]
    mean = np.concatenate([m for m, _ in parts], axis=1)  # (N, S P)
    var = np.concatenate([v for _, v in parts], axis=1)
    n = mean.shape[0]
    mean = mean.reshape(n, s, p).transpose(1, 0, 2)
    var = var.reshape(n, s, p).transpose(1, 0, 2)
    sd = emulator.outputs.sd
    var += (sd * sd * excess)[None, :, None]
    for q, sl in enumerate(emulator.outputs.slices.values()):
        var[:, sl] += (sd[sl] * sd[sl])[None, :, None] / lam_stars[:, q, None, None]
    if discrepancy is not None:
        d_mean, d_var = discrepancy.predict(x)
        mean = mean + d_mean[None]
        var = var + d_var[None]
    return mean, var


def place_periods(
    layout: PeriodLayout, starts: np.ndarray, values: np.ndarray, out: np.ndarray, begin: int
) -> None:
    """Write period columns ``values`` ``(..., n, P)`` into ``out`` ``(..., n_total)`` at
    samples >= ``begin``."""
    for i, start in enumerate(starts):
        idx = start + np.arange(layout.period)
        keep = idx >= begin
        out[..., idx[keep]] = values[..., keep, i]


def predict_band(
    emulator: Emulator,
    assembled: Assembled,
    posterior: Posterior,
    *,
    draws: int = 300,
    level: float = 0.95,
    discrepancy: DiscrepancyModel | None = None,
    measured: Mapping[str, np.ndarray] | None = None,
    transforms: Mapping[str, LogLevel] | None = None,
) -> Band:
    """Calibrated prediction of every output over the record, with its bands.

    Parameters
    ----------
    emulator, assembled
        The trained emulator and the assembled data (periods, ``x``, ``x_test``,
        and the design runs over the test window, ``y_test_sim_std``, on which
        the emulator is conditioned too: :func:`emulator_with_test_window`).
    posterior
        theta* and lambda* draws.
    draws
        Posterior draws propagated (thinned evenly over the chains).
    level
        Probability of the outer band. [-]
    discrepancy
        A fitted difference process to add (``None``: the model alone).
    measured
        Output name -> measured series ``(n_total,)`` for the PIT (optional).
    transforms
        Outputs with relative errors -> their log map (the emulator's values
        are on that scale; the band is returned on the output's own).

    Returns
    -------
    Band
        NaN outside the training periods and the test window.
    """
    theta, lam_stars, pick = thin_draws(posterior, draws)
    layout = assembled.layout
    emulator = emulator_with_test_window(emulator, assembled)
    parts = predicted_parts(assembled)
    slices = emulator.outputs.slices
    s = theta.shape[0]
    means = {n: np.full((s, layout.n_total), np.nan) for n in slices}
    variances = {n: np.full((s, layout.n_total), np.nan) for n in slices}
    excess = assembled.out_of_basis_excess()
    for i, (x, starts, begin) in enumerate(parts):
        if not len(starts):
            continue
        extra = excess if i else np.zeros_like(excess)  # parts: training periods, test window
        mean, var = period_moments(emulator, theta, lam_stars, x, discrepancy, extra)
        for name, sl in slices.items():
            place_periods(layout, starts, mean[:, sl], means[name], begin)
            place_periods(layout, starts, var[:, sl], variances[name], begin)
    order = list(slices)
    for name, (mean, var) in conditioned_discrepancy(emulator, assembled, posterior, pick).items():
        noise = _phase_sd(assembled, name) ** 2 / lam_stars[:, order.index(name), None]
        means[name], variances[name] = mean, var + noise
    return _mixture_band(means, variances, measured or {}, level, transforms)


def emulator_with_test_window(emulator: Emulator, assembled: Assembled) -> Emulator:
    """The emulator conditioned also on the design runs over the test window.

    The design runs are simulated over the whole record, the test window
    included (the simulator is driven by the known boundary conditions, not by
    measurements there), so the emulator need not extrapolate to the test
    periods' conditions: conditioned on those runs too (hyperparameters kept,
    :meth:`~bayescal.emulator.gp.Emulator.extended`) it interpolates between
    runs made under them, as on the training periods. Unchanged when there is
    no test window or the runs are not finite on it.
    """
    y_new = assembled.y_test_sim_std
    if y_new is None or not assembled.x_test.shape[0]:
        return emulator
    if emulator.x.shape[0] != assembled.n_periods:  # extended already
        return emulator
    return emulator.extended(assembled.x_test, y_new)


def _phase_sd(assembled: Assembled, name: str) -> np.ndarray:
    """Standardisation SD of output ``name`` at every sample, by its position in the period."""
    layout = assembled.layout
    sl = assembled.outputs.slices[name]
    sd = assembled.outputs.sd[sl]
    anchor = int(layout.test_starts[0]) if layout.test_starts.size else int(layout.train_starts[0])
    return np.asarray(sd[(np.arange(layout.n_total) - anchor) % layout.period])


def conditioned_discrepancy(
    emulator: Emulator,
    assembled: Assembled,
    posterior: Posterior,
    pick: np.ndarray,
    runs: Mapping[str, np.ndarray] | None = None,
    at: Assembled | None = None,
    lam_stars: np.ndarray | None = None,
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The in-likelihood discrepancy conditioned on the training residuals, per draw and sample.

    An output declared with ``[outputs.errors.NAME] discrepancy = true`` carries a
    discrepancy ``GP(0, r tau_j^-1 c_x)`` on each of its basis weights. At every
    posterior draw it is conditioned on that output's measured training periods
    (:mod:`bayescal.calibration.conditional`: Gaussian conditioning, exact at the
    draw) and predicted at the training periods and the test window.

    Parameters
    ----------
    emulator, assembled
        The trained emulator and the assembled data.
    posterior
        The calibration posterior (its draws carry ``r``); a posterior without
        them (the difference-process phase) gives an empty result.
    pick
        Indices of the draws used, in the flattened draws ``(S,)``.
    runs
        Output name -> the simulator at those draws ``(S, n_total)``
        (``method = "simulator"``: the model is known at theta*, only the
        discrepancy is kriged); ``None``: the emulator is the model, and eta and
        the discrepancy are conditioned together.
    at
        Another record to predict on: ``assembled`` with the layout and
        ``x_test`` of new conditions (:mod:`bayescal.pipeline.newdata`); the
        training residuals stay the study's. Default: the study's own record.
    lam_stars
        With ``runs``: the noise precisions ``(S, O)`` the residuals are kriged
        with (:func:`bayescal.pipeline.simnoise.simulator_noise`: the re-run
        simulator's noise, which holds no emulator error); default the draws'
        ``lambda*``.

    Returns
    -------
    dict
        Output name -> ``(mean, variance)``, ``(S, n_total)`` each, NaN outside
        the training periods and the test window, physical units. With
        ``runs``: the discrepancy's conditioned mean and variance, to add to the
        runs. Without: the whole model + discrepancy part, the mean of the
        output and its variance without the observation noise (with the test
        window's out-of-basis excess, :meth:`Assembled.out_of_basis_excess`).
    """
    obs = assembled.observations
    if not obs.delta_outputs or not set(obs.names()) <= set(posterior.aux_names):
        return {}
    target = assembled if at is None else at
    layout = target.layout
    t = len(posterior.names)
    unit = posterior.unit_draws.reshape(-1, t)[pick]
    aux = np.asarray(posterior.aux, dtype=float).reshape(-1, len(posterior.aux_names))[pick]
    parts = predicted_parts(target)
    x_new = np.vstack([x for x, _, _ in parts])
    m = assembled.n_periods
    x_all = np.vstack([assembled.x, x_new])
    beyond = target.out_of_basis_excess()
    out = {}
    for q in obs.delta_outputs:
        noise = obs.outputs[q]
        name, bases = noise.name, list(noise.bases)
        st = assembled.outputs.standardisations[q]
        ko = obs.block(q)[0]
        field = OutputDiscrepancy.build(emulator, obs, q, x_new)
        # the test window's out-of-basis excess (emulator route), by column
        excess = np.zeros((ko.shape[0], x_new.shape[0]))
        excess[:, m:] = beyond[assembled.outputs.slices[name]][:, None]
        mean = np.full((pick.size, layout.n_total), np.nan)
        var = np.full((pick.size, layout.n_total), np.nan)
        for s in range(pick.size):
            values = dict(zip(posterior.aux_names, aux[s], strict=True))
            phi = float(values[obs.coordinate("phi", q)]) if q in obs.ar_outputs else 0.0
            if runs is not None and lam_stars is not None:
                values[obs.coordinate("lambda_star", q)] = float(lam_stars[s, q])
            if runs is not None:
                y_sim = assembled.layout.cut(np.asarray(runs[name][s], float))
                y_sim = (y_sim - st.mean[:, None]) / st.sd[:, None]
                shift, cov = field.condition(values, obs.weights_of(q, y_sim, phi), None, unit[s])
                w_new, extra = shift, np.zeros_like(excess)
                offset = np.zeros(ko.shape[0])
            else:
                theta = np.broadcast_to(unit[s], (x_all.shape[0], t))
                w_all = emulator.predict_weights(theta, x_all)[0][:, bases]
                eta = emulator.weight_covariance(unit[s], x_all, bases)
                shift, cov = field.condition(values, w_all[:m], eta, unit[s])
                w_new, extra = w_all[m:] + shift, excess
                offset = st.mean
            mu = offset[:, None] + st.sd[:, None] * (ko @ w_new.T)  # (n_o, P)
            v = st.sd[:, None] ** 2 * (np.einsum("nj,ajk,nk->na", ko, cov, ko) + extra)
            col = 0  # a part's rows of x (the training periods of another record: none placed)
            for x, starts, begin in parts:
                cols = slice(col, col + len(starts))
                place_periods(layout, starts, mu[:, cols], mean[s], begin)
                place_periods(layout, starts, v[:, cols], var[s], begin)
                col += x.shape[0]
        out[name] = (mean, var)
    return out


def simulator_band(
    assembled: Assembled,
    runs: Mapping[str, np.ndarray],
    lam_stars: np.ndarray,
    *,
    level: float = 0.95,
    discrepancy: DiscrepancyModel | None = None,
    measured: Mapping[str, np.ndarray] | None = None,
    model_error: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
    transforms: Mapping[str, LogLevel] | None = None,
) -> Band:
    """Calibrated prediction from simulator runs at posterior draws, with its bands.

    Parameters
    ----------
    assembled
        The assembled data (layout, standardisation; ``x`` for a discrepancy).
    runs
        Output name -> simulated series at ``S`` posterior draws ``(S, n_total)``.
    lam_stars
        lambda* of the same draws, ``(S,)`` or ``(S, O)`` (one per output); the
        noise variance is ``sd^2 / lambda*``.
    level
        Probability of the outer band. [-]
    discrepancy
        A fitted difference process to add (its mean and variance).
    measured
        Output name -> measured series ``(n_total,)`` for the PIT (optional).
    model_error
        Output name -> mean and variance ``(S, n_total)`` of an in-likelihood
        discrepancy at the same draws, conditioned on the training residuals
        (:func:`conditioned_discrepancy` with ``runs``), added to the runs.
    transforms
        Outputs with relative errors -> their log map: their ``runs`` are on
        that scale, and the band is returned on the output's own.

    Returns
    -------
    Band
        NaN outside the training periods and the test window.
    """
    layout = assembled.layout
    covered = np.zeros(layout.n_total, dtype=bool)
    for start in layout.train_starts:
        covered[start : start + layout.period] = True
    covered[layout.test_begin :] = True
    delta_mean = delta_var = None
    if discrepancy is not None:
        names = list(assembled.outputs.names)
        delta_mean = delta_series(assembled, discrepancy, names)
        delta_var = delta_series(assembled, discrepancy, names, variance=True)
    lam = np.asarray(lam_stars, dtype=float)
    lam = lam[:, None] if lam.ndim == 1 else lam
    order = list(assembled.outputs.names)
    means, variances, noise_sd = {}, {}, {}
    for name, sims in runs.items():
        column = lam[:, order.index(name) if lam.shape[1] > 1 else 0]
        var = _phase_sd(assembled, name) ** 2 / column[:, None]
        noise_sd[name] = float(np.median(np.sqrt(var[:, covered])))
        mean = np.asarray(sims, dtype=float)
        if model_error and name in model_error:
            mean = mean + model_error[name][0]
            var = var + model_error[name][1]
        if delta_mean is not None and delta_var is not None:
            mean = mean + delta_mean[name][None]
            var = var + delta_var[name][None]
        means[name] = np.where(covered, mean, np.nan)
        variances[name] = np.where(covered, var, np.nan)
    band = _mixture_band(means, variances, measured or {}, level, transforms)
    return replace(band, noise_sd=noise_sd)


def held_out_band(
    layout: PeriodLayout,
    runs: Mapping[str, np.ndarray],
    noise_sd: Mapping[str, float],
    measured: Mapping[str, np.ndarray],
    level: float = 0.95,
) -> Band:
    """Bands of held-out sensors: the simulator at posterior draws plus the sensor's noise.

    Parameters
    ----------
    layout
        The study's periods (bands on the training periods and the test window).
    runs
        Output name -> simulated series at ``S`` posterior draws ``(S, n_total)``.
    noise_sd
        Output name -> the sensor's stated accuracy (one standard deviation). [unit]
    measured
        Output name -> measured series ``(n_total,)``, for the PIT.
    level
        Probability of the outer band. [-]
    """
    covered = np.zeros(layout.n_total, dtype=bool)
    for start in layout.train_starts:
        covered[start : start + layout.period] = True
    covered[layout.test_begin :] = True
    means, variances = {}, {}
    for name, sims in runs.items():
        mean = np.asarray(sims, dtype=float)
        means[name] = np.where(covered, mean, np.nan)
        variances[name] = np.where(covered, float(noise_sd[name]) ** 2, np.nan) + 0.0 * mean
    return _mixture_band(means, variances, measured, level)


def merge_bands(first: Band, second: Band) -> Band:
    """One band holding the outputs of both (same level)."""
    return Band(
        first.mean | second.mean,
        first.lower | second.lower,
        first.upper | second.upper,
        first.lower50 | second.lower50,
        first.upper50 | second.upper50,
        first.pit | second.pit,
        first.mc_error | second.mc_error,
        first.level,
        first.noise_sd | second.noise_sd,
    )


def delta_series(
    assembled: Assembled,
    discrepancy: DiscrepancyModel,
    names: Sequence[str],
    *,
    variance: bool = False,
) -> dict[str, np.ndarray]:
    """The discrepancy's mean (or variance) over the training periods and the test window."""
    layout = assembled.layout
    out = {n: np.full(layout.n_total, np.nan) for n in names}
    slices = dict(zip(names, _slices(assembled), strict=True))
    parts = predicted_parts(assembled)
    for x, starts, begin in parts:
        if len(starts):
            mean, var = discrepancy.predict(x)
            values = var if variance else mean
            for name, sl in slices.items():
                place_periods(layout, starts, values[sl], out[name], begin)
    return out


def predicted_parts(assembled: Assembled) -> list[tuple[np.ndarray, np.ndarray, int]]:
    """``(x, period starts, first sample)`` of the training periods and of the test window."""
    layout = assembled.layout
    parts = [(assembled.x, layout.train_starts, 0)]
    if layout.test_starts.size:
        parts.append((assembled.x_test, layout.test_starts, layout.test_begin))
    return parts


def _slices(assembled: Assembled) -> list[slice]:
    return list(assembled.outputs.slices.values())


def windows(layout: PeriodLayout) -> np.ndarray:
    """Label of every sample: ``warmup``, ``train``, ``test`` or ``unused``."""
    label = np.full(layout.n_total, "unused", dtype=object)
    first = int(layout.train_starts.min()) if layout.m_star else layout.warmup
    label[:first] = "warmup"
    for start in layout.train_starts:
        label[start : start + layout.period] = "train"
    label[layout.test_begin :] = "test"
    return label.astype(str)


_SERIES = {
    "measured": "measured {what}",
    "nominal": "{what} simulated at the nominal parameters",
    "calibrated": "calibrated prediction of {what}: mean of the predictive distribution",
    "calibrated_lower": "lower edge of the outer (level) band of a measurement of {what}",
    "calibrated_upper": "upper edge of the outer (level) band of a measurement of {what}",
    "calibrated_lower50": "lower edge of the 50 % band of a measurement of {what}",
    "calibrated_upper50": "upper edge of the 50 % band of a measurement of {what}",
    "calibrated_pit": "PIT of the measured {what}: predictive CDF at the measurement",
    "delta": "discrepancy Delta = observation - model of {what} (mean)",
    "corrected": "calibrated prediction of {what} corrected by Delta",
    "corrected_lower": "lower edge of the outer band of the corrected prediction of {what}",
    "corrected_upper": "upper edge of the outer band of the corrected prediction of {what}",
    "corrected_lower50": "lower edge of the 50 % band of the corrected prediction of {what}",
    "corrected_upper50": "upper edge of the 50 % band of the corrected prediction of {what}",
    "corrected_pit": "PIT of the measured {what} under the corrected prediction",
}
_WINDOW = "part of the record: warmup, train (training periods), test (test window) or unused"


def predictions_dataset(
    times: np.ndarray,
    layout: PeriodLayout,
    measured: Mapping[str, np.ndarray],
    nominal: Mapping[str, np.ndarray],
    calibrated: Band,
    boundary: Mapping[str, np.ndarray],
    corrected: Band | None = None,
    delta: Mapping[str, np.ndarray] | None = None,
    attrs: Mapping[str, Any] | None = None,
) -> xr.Dataset:
    """Measured, nominal, calibrated (and corrected) series on the study clock.

    Variables ``{o}_measured``, ``{o}_nominal``, ``{o}_calibrated``,
    ``{o}_calibrated_lower``/``_upper`` and, with a discrepancy, ``{o}_delta``,
    ``{o}_corrected``, ``{o}_corrected_lower``/``_upper``; boundary conditions
    as ``bc_{name}``. Coordinates ``time`` (UTC) and ``window``. Held-out
    outputs (``attrs["held_out"]``) have no corrected series.
    """
    data: dict[str, Any] = {}
    for o in measured:
        unit = GLOSSARY[o].unit if o in GLOSSARY else ""
        what = f"{o} ({GLOSSARY[o].description})" if o in GLOSSARY else o
        series = {"measured": measured[o], "nominal": nominal[o]}
        series |= _band_series("calibrated", calibrated, o)
        if corrected is not None and delta is not None and o in delta:
            series |= {"delta": delta[o], **_band_series("corrected", corrected, o)}
        for kind, values in series.items():
            text = _SERIES[kind].format(what=what)
            var = {"units": unit, "long_name": f"{o} {kind}", "description": text}
            data[f"{o}_{kind}"] = ("time", np.asarray(values, dtype=float), var)
    for b, values in boundary.items():
        unit = GLOSSARY[b].unit if b in GLOSSARY else ""
        text = f"boundary condition {b}" + (f": {GLOSSARY[b].description}" if b in GLOSSARY else "")
        var = {"units": unit, "long_name": b, "description": text}
        data[f"bc_{b}"] = ("time", np.asarray(values, dtype=float), var)
    coords = {
        "time": ("time", np.asarray(times).astype("datetime64[ns]"), {"description": "UTC"}),
        "window": ("time", windows(layout), {"description": _WINDOW}),
    }
    meta: dict[str, Any] = {"outputs": ",".join(measured), "boundary": ",".join(boundary)}
    for name, band in (("calibrated", calibrated), ("corrected", corrected)):
        if band is not None:
            for o, error in band.mc_error.items():
                meta[f"{o}_{name}_mc_error"] = error
            for o, sd in band.noise_sd.items():
                meta[f"{o}_{name}_noise_sd"] = sd
    return xr.Dataset(data, coords=coords, attrs=meta | dict(attrs or {}))


def _band_series(kind: str, band: Band, output: str) -> dict[str, np.ndarray]:
    """The series a band contributes to the dataset (those it has)."""
    out = {kind: band.mean[output], f"{kind}_lower": band.lower[output]}
    out[f"{kind}_upper"] = band.upper[output]
    for suffix, values in (("lower50", band.lower50), ("upper50", band.upper50), ("pit", band.pit)):
        if output in values:
            out[f"{kind}_{suffix}"] = values[output]
    return out


def _band_scores(
    ds: xr.Dataset, prefix: str, obs: np.ndarray, mask: np.ndarray, rmse: float
) -> dict[str, float]:
    """Coverage of the bands, the outer band's spread over ``rmse`` (the prediction's,
    :func:`~bayescal.metrics.fit_metrics` on the same samples) and the PIT's distance
    from uniform on the masked samples."""
    ok = mask & np.isfinite(obs)
    out: dict[str, float] = {}
    if not ok.any():
        return out
    for name, lower, upper in (
        ("coverage95", "lower", "upper"),
        ("coverage50", "lower50", "upper50"),
    ):
        if f"{prefix}_{lower}" in ds:
            lo, hi = ds[f"{prefix}_{lower}"].values[ok], ds[f"{prefix}_{upper}"].values[ok]
            out[name] = float(np.mean((obs[ok] >= lo) & (obs[ok] <= hi)))
    if f"{prefix}_lower" in ds:
        level = float(ds.attrs.get("level", 0.95))
        width = (ds[f"{prefix}_upper"] - ds[f"{prefix}_lower"]).values[ok]
        with np.errstate(divide="ignore", invalid="ignore"):  # a zero-width band: left out
            z = (ds[prefix].values[ok] - obs[ok]) / width
        names = ("n_eff95", "n_eff50") if "coverage50" in out else ("n_eff95",)
        levels = (level, 0.5)[: len(names)]
        out |= dict(zip(names, coverage_n_effs(z, np.flatnonzero(ok), levels=levels), strict=True))
        half = 0.5 * (ds[f"{prefix}_upper"].values[ok] - ds[f"{prefix}_lower"].values[ok])
        spread = float(np.median(half)) / float(norm.ppf(0.5 + 0.5 * level))
        out["band_scale"] = spread / rmse if rmse > 0 else float("nan")
    if f"{prefix}_pit" in ds:
        values = np.sort(ds[f"{prefix}_pit"].values[ok])
        values = values[np.isfinite(values)]
        if values.size:
            n = values.size
            steps = np.arange(1, n + 1) / n
            out["pit_ks"] = float(max(np.max(steps - values), np.max(values - (steps - 1.0 / n))))
    return out


def _window_mask(ds: xr.Dataset, window: str) -> np.ndarray:
    return np.asarray(ds["window"].values == window)


def _monthly_how(output: str) -> Literal["sum", "mean"]:
    """Monthly totals for energies (meters), monthly means for anything else."""
    quantity = GLOSSARY.get(output)
    return "sum" if quantity is not None and quantity.dimension == "energy" else "mean"


def metrics_table(ds: xr.Dataset) -> pd.DataFrame:
    """Fit metrics per output, model and window (see the module docstring)."""
    rows = []
    for o in ds.attrs["outputs"].split(","):
        obs = ds[f"{o}_measured"].values
        for model in MODELS:
            key = {"nominal": "nominal", "calibrated": "calibrated"}.get(model, "corrected")
            if f"{o}_{key}" not in ds:
                continue
            sim = ds[f"{o}_{key}"].values
            for window in ("train", "test"):
                mask = _window_mask(ds, window) & np.isfinite(sim)
                if not mask.any():
                    continue
                m = fit_metrics(sim[mask], obs[mask]).as_dict()
                m |= dict.fromkeys(("coverage95", "coverage50", "pit_ks", "band_scale"), np.nan)
                if model != "nominal":
                    m |= _band_scores(ds, f"{o}_{key}", obs, mask, m["rmse"])
                m["guideline14"] = meets_guideline14(m["cv_rmse"], m["nmbe"])
                times = ds["time"].values[mask]
                m |= monthly_metrics(times, sim[mask], obs[mask], how=_monthly_how(o))
                rows.append({"output": o, "model": model, "window": window} | m)
    columns = [*KEY_COLUMNS, *(c.name for c in metric_columns("csv"))]
    return pd.DataFrame(rows, columns=columns)
