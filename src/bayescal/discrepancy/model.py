"""The difference process ``Delta(x)``: estimation (eqs. 18–25) and its predictive GP.

Sign convention
---------------
``Delta = observation - model``: ``y* = f(theta*, x) + Delta(x) + eps`` (eq. 18),
so a calibrated prediction is corrected by *adding* ``Delta``. The paper's
eq. 25 writes ``Delta_i = mean(f* - y*)``, the opposite sign; only the mean
changes sign, the covariance ``D_i`` of eq. 25 is the same.

What :func:`estimate_discrepancy` does
--------------------------------------
1. Fixes the hyperparameters at the emulator's MAP and ``lambda``, every
   output's ``lambda*`` and AR(1) coefficient and an in-likelihood discrepancy's
   variance at their calibration posterior means
   (:class:`~bayescal.discrepancy.phase.FixedPrecisions`); only ``theta*`` moves.
2. Runs ``n_chains`` chains in lockstep from calibration draws
   (:mod:`bayescal.discrepancy.sampler`): every ``update_interval`` sweeps each
   chain draws ``realisations`` model realisations at its current ``theta*``,
   re-estimates ``Delta_i``, ``A_i``, ``w*`` and ``B_j`` (eqs. 20–25) and samples
   ``theta*`` under eq. 19 plus the term of eq. 23, in whitened coordinates,
   for at least ``n_draws`` kept sweeps and until R-hat and ESS pass (at most
   ``max_draws``). Priors: :func:`default_priors` unless given.
3. Estimates ``Delta_i`` per training period as the observation minus the
   emulator's mean prediction averaged over (up to ``delta_draws``, thinned)
   theta* draws of this phase, in physical units: the posterior expectation
   that the in-chain estimates of eq. 25 approximate by Monte Carlo.
4. Fits the GP of :mod:`bayescal.discrepancy.delta_gp` to it, for ``Delta`` on
   new periods (``predict``).

Explained variance and MSE
--------------------------
The model here is the emulator's mean prediction at the phase's theta* draws
(the same as in step 3), so its training residual is ``Delta`` itself.
``mse`` gives per output the mean squared training error of the model and of
the model plus the GP's ``Delta`` at the training periods (the paper's
Table 7 rows); ``explained = 1 - MSE(model + Delta) / MSE(model)`` is the
fraction of the mean square of the training residual that the fitted
discrepancy accounts for (in-sample, about 0 when ``Delta`` is only noise,
negative if it makes things worse).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import ArrayLike

from bayescal.calibration.posterior import Posterior, check_priors
from bayescal.calibration.target import emulator_algebra
from bayescal.design import Prior
from bayescal.discrepancy.batched import BatchedDelta
from bayescal.discrepancy.delta_gp import MAX_COMPONENTS, DeltaGP, Trend, fit_delta_gp
from bayescal.discrepancy.moments import ErrorCovariance
from bayescal.discrepancy.phase import DeltaPhase, FixedPrecisions
from bayescal.discrepancy.priors import default_priors
from bayescal.discrepancy.sampler import DeltaSettings, Whitening, checkpoint_file, run_delta_chains
from bayescal.emulator.assemble import Assembled, OutputStack
from bayescal.emulator.gp import Emulator
from bayescal.emulator.kernel import FloatArray
from bayescal.emulator.noise import ObservationModel
from bayescal.errors import ConfigError, DataError

if TYPE_CHECKING:
    import pandas as pd

__all__ = ["Discrepancy", "estimate_discrepancy"]


@dataclass(frozen=True)
class Discrepancy:
    """The estimated difference process and its GP over ``x`` (immutable).

    Attributes
    ----------
    outputs
        Standardisation and stacking of the outputs (``N`` rows).
    x
        Normalised variable conditions of the training periods, ``(m*, s)``. [-]
    delta
        ``Delta = observation - model`` per training period, ``(N, m*)``, in the
        outputs' units (e.g. [W/m²] for ``heat_flux_in``).
    gp
        The GP of ``Delta`` over ``x`` (standardised).
    posterior
        theta* draws of the discrepancy phase; its ``aux`` holds the fixed
        precisions and error parameters (the calibration's layout, constant).
    fixed
        ``lambda``, the ``lambda*``, AR(1) coefficients and in-likelihood
        discrepancy variances held fixed in the phase. [-]
    realisations
        Model realisations per update (``b`` of eq. 25).
    update_interval
        Sweeps between two updates of ``Delta``.
    updates
        Updates of ``Delta`` per chain (burn-in included).
    converged
        Whether the phase's chains met R-hat <= 1.01 and bulk and tail ESS >= 400
        on every parameter (``None``: not recorded, e.g. an older file).
    """

    outputs: OutputStack
    x: FloatArray
    delta: FloatArray
    gp: DeltaGP
    posterior: Posterior
    fixed: FixedPrecisions
    realisations: int
    update_interval: int
    updates: int = 0
    converged: bool | None = None

    @property
    def lam(self) -> float:
        """The fixed ``lambda``. [-]"""
        return self.fixed.lam

    @property
    def lam_star(self) -> float:
        """The fixed ``lambda*`` of the first output. [-]"""
        return self.fixed.lam_star[0]

    def predict(self, x_new: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Predictive mean and variance of ``Delta`` at new periods, in physical units.

        Parameters
        ----------
        x_new
            Normalised variable conditions, ``(P, s)`` (``Assembled.x_test`` or
            ``inputs.transform(...)``). [-]

        Returns
        -------
        mean, variance
            ``(N, P)`` each, outputs stacked along the rows (``outputs.split``),
            mean in the outputs' units, variance in their squares.
        """
        mean, var = self.gp.predict_std(x_new)
        sd = self.outputs.sd[:, None]
        return mean * sd, var * sd * sd

    @property
    def fitted(self) -> FloatArray:
        """The GP's mean of ``Delta`` at the training periods, ``(N, m*)``, physical."""
        return self.predict(self.x)[0]

    def delta_by_output(self) -> dict[str, FloatArray]:
        """``delta`` split per output: name -> ``(n_q, m*)``."""
        return self.outputs.split(self.delta)

    @property
    def mse(self) -> dict[str, tuple[float, float]]:
        """Output -> training MSE of (model, model + Delta), in the output's unit squared."""
        resid = self.delta - self.fitted
        return {
            name: (float(np.mean(self.delta[sl] ** 2)), float(np.mean(resid[sl] ** 2)))
            for name, sl in self.outputs.slices.items()
        }

    @property
    def explained(self) -> dict[str, float]:
        """Output -> ``1 - MSE(model + Delta) / MSE(model)`` on the training periods. [-]"""
        out = {}
        for name, (model, corrected) in self.mse.items():
            out[name] = 1.0 - corrected / model if model > 0.0 else 0.0
        return out

    def correlation(
        self,
        boundary_periods: Mapping[str, ArrayLike],
        *,
        by: Literal["period", "sample"] = "period",
    ) -> pd.DataFrame:
        """Pearson correlation of ``delta`` with each boundary-condition series.

        Parameters
        ----------
        boundary_periods
            Series name -> values cut into the training periods, ``(n_b, m*)``
            (``PeriodLayout.cut``), or one value per period ``(m*,)``, in the
            series' unit.
        by
            ``"period"``: period means of ``delta`` against period means of the
            series; ``"sample"``: sample by sample (needs ``n_b`` equal to the
            output's samples per period).

        Returns
        -------
        pandas.DataFrame
            Rows: outputs; columns: series; NaN where a side has no variance.
        """
        import pandas as pd

        if by not in ("period", "sample"):
            raise ConfigError(f"by must be 'period' or 'sample', got {by!r}")
        m = self.delta.shape[1]
        table: dict[str, dict[str, float]] = {}
        for name, d in self.delta_by_output().items():
            row = {}
            for series, values in boundary_periods.items():
                arr = np.asarray(values, dtype=float)
                if arr.shape[-1] != m or arr.ndim not in (1, 2):
                    raise DataError(
                        f"boundary series {series!r} has shape {arr.shape}, expected "
                        f"(samples, {m}) or ({m},): cut into the training periods"
                    )
                row[series] = _pearson(*_paired(d, arr, by, series))
            table[name] = row
        return pd.DataFrame(table).T


def _paired(d: FloatArray, arr: FloatArray, by: str, series: str) -> tuple[FloatArray, FloatArray]:
    if by == "period":
        return d.mean(axis=0), arr if arr.ndim == 1 else arr.mean(axis=0)
    if arr.shape != d.shape:
        raise DataError(
            f"boundary series {series!r} has shape {arr.shape}; a sample-wise correlation "
            f"needs the output's shape {d.shape}",
            hint="use by='period' for series on another clock",
        )
    return d.ravel(), arr.ravel()


def _pearson(a: FloatArray, b: FloatArray) -> float:
    if not (np.std(a) > 0.0 and np.std(b) > 0.0):
        return math.nan
    return float(np.corrcoef(a, b)[0, 1])


def _positive_int(value: object, least: int, what: str, why: str) -> int:
    if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < least:
        raise ConfigError(f"{what} must be an integer >= {least} ({why}), got {value!r}")
    return int(value)


def _check_settings(
    realisations: int, update_interval: int, n_chains: int, n_burn: int, n_draws: int
) -> None:
    _positive_int(realisations, 2, "realisations", "eq. 25 averages over model realisations")
    _positive_int(update_interval, 1, "update_interval", "sweeps between updates of Delta")
    _positive_int(n_chains, 1, "n_chains", "independent chains")
    _positive_int(n_burn, 0, "n_burn", "burn-in sweeps per chain")
    _positive_int(n_draws, 4, "n_draws", "kept sweeps per chain; diagnostics need 4")


def _check_match(emulator: Emulator, assembled: Assembled, posterior: Posterior) -> None:
    """Raise :class:`ConfigError` unless the three come from the same study."""
    names = assembled.parameter_names
    hint = "pass the emulator trained on this assembled data and its calibration posterior"
    if tuple(emulator.parameter_names) != tuple(names):
        raise ConfigError(
            f"the emulator has parameters {list(emulator.parameter_names)}, the assembled "
            f"data {list(names)}",
            hint=hint,
        )
    if tuple(posterior.names) != tuple(names):
        raise ConfigError(
            f"the posterior has parameters {list(posterior.names)}, the assembled data "
            f"{list(names)}",
            hint=hint,
        )
    k_em, k_as = emulator.basis.k, assembled.basis.k
    if k_em.shape != k_as.shape or not np.allclose(k_em, k_as, rtol=1e-12, atol=1e-12):
        raise ConfigError(
            f"the emulator's basis K {k_em.shape} differs from the assembled data's {k_as.shape}",
            hint=hint,
        )
    if emulator.x.shape != assembled.x.shape or not np.allclose(emulator.x, assembled.x):
        raise ConfigError(
            f"the emulator was trained on {emulator.x.shape[0]} periods x "
            f"{emulator.x.shape[1]} inputs, the assembled data has {assembled.x.shape}",
            hint=hint,
        )


def _starts(posterior: Posterior, n_chains: int, rng: np.random.Generator) -> FloatArray:
    """``n_chains`` calibration draws spread over all chains (normalised theta*)."""
    flat = posterior.unit_draws.reshape(-1, len(posterior.names))
    picks = rng.choice(flat.shape[0], size=n_chains, replace=n_chains > flat.shape[0])
    return np.clip(flat[picks], 1e-9, 1.0 - 1e-9)


def _thinned(posterior: Posterior, n: int) -> FloatArray:
    flat = posterior.unit_draws.reshape(-1, len(posterior.names))
    return flat[np.unique(np.linspace(0, flat.shape[0] - 1, min(n, flat.shape[0])).astype(int))]


def _delta_std(emulator: Emulator, y_star: FloatArray, theta_unit: FloatArray) -> FloatArray:
    """``y* - mean_s K mu(theta_s, x_i)``, standardised, ``(N, m*)``."""
    n_per = emulator.x.shape[0]
    model = np.zeros_like(y_star)
    for th in theta_unit:
        mean, _ = emulator.predict_std(np.broadcast_to(th, (n_per, th.size)), emulator.x)
        model += mean
    return y_star - model / theta_unit.shape[0]


def _delta_variances(
    emulator: Emulator, observations: ObservationModel, fixed: FixedPrecisions
) -> FloatArray | None:
    """Per-basis variance ``r_o tau_j^-1`` of an in-likelihood discrepancy, or ``None``."""
    if not observations.delta_outputs:
        return None
    variances = np.array([k.variance for k in emulator.kernels])
    over_conditions, independent = observations.discrepancy_variances(fixed.delta_rel, variances)
    if independent is not None:
        raise ConfigError(
            "the difference-process phase ([discrepancy] enabled) takes an in-likelihood "
            "discrepancy over the conditions only; set discrepancy = true, or turn the phase off"
        )
    return over_conditions


def estimate_discrepancy(
    emulator: Emulator,
    assembled: Assembled,
    posterior: Posterior,
    *,
    priors: Mapping[str, Prior] | None = None,
    realisations: int = 50,
    update_interval: int = 100,
    n_chains: int = 4,
    n_burn: int = 1000,
    n_draws: int = 1000,
    max_draws: int | None = None,
    seed: int = 0,
    callback: Callable[[int], None] | None = None,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_seconds: float = 30.0,
    max_components: int = MAX_COMPONENTS,
    trend: Trend = "constant",
    delta_draws: int = 200,
) -> Discrepancy:
    """Estimate ``Delta(x)`` inside an MCMC over theta* and fit its GP (eqs. 18–25).

    Parameters
    ----------
    emulator
        The trained emulator (hyperparameters fixed at its MAP).
    assembled
        The assembled data it was trained on (``Y*``, ``x``, the outputs' error models).
    posterior
        The calibration posterior (starting points, the fixed precisions and
        error parameters, the default priors).
    priors
        Parameter name -> prior on the design's bounds; default
        :func:`bayescal.discrepancy.priors.default_priors`.
    realisations
        ``b``, model realisations per update (eq. 25), >= 2.
    update_interval
        Sweeps between two updates of ``Delta``, ``A``, ``w*`` and ``B``.
    n_chains, n_burn, n_draws
        Chains (run in lockstep), burn-in sweeps (discarded) and kept sweeps
        per chain before the first convergence check.
    max_draws
        Most kept sweeps per chain: the chains are extended until R-hat <= 1.01
        and bulk and tail ESS >= 400 or this length (default ``n_draws``: no
        extension).
    seed
        Root seed; chain ``k`` uses ``SeedSequence(seed).spawn(n_chains)[k]``.
    callback
        Progress: called with the sweeps completed over all chains.
    checkpoint_dir, checkpoint_seconds
        Folder of the phase's snapshot (``delta.npz``) and the least wall time
        between two snapshots [s]; a killed phase resumes from it with the
        draws of an uninterrupted run.
    max_components
        Most principal components of ``Delta`` given a GP.
    trend
        Mean of each component's GP over ``x``: ``"constant"`` or ``"linear"``
        (:mod:`bayescal.discrepancy.delta_gp`).
    delta_draws
        theta* draws (thinned evenly over all chains) averaged for ``Delta``.

    Returns
    -------
    Discrepancy
    """
    _check_settings(realisations, update_interval, n_chains, n_burn, n_draws)
    settings = DeltaSettings(
        n_burn=n_burn,
        n_draws=n_draws,
        max_draws=n_draws if max_draws is None else max_draws,
        update_interval=update_interval,
    )
    _check_match(emulator, assembled, posterior)
    prior_map = default_priors(posterior) if priors is None else check_priors(assembled, priors)
    observations = assembled.observations
    fixed = FixedPrecisions.from_posterior(posterior, observations)
    noise = ErrorCovariance.of(observations, fixed.lam_star, fixed.phi)
    delta = _delta_variances(emulator, observations, fixed)
    alg = emulator_algebra(emulator, assembled.w_star, "kronecker")
    phase = DeltaPhase(
        emulator,
        assembled.y_star_std,
        alg,
        list(prior_map.values()),
        fixed.lam,
        noise,
        realisations,
        delta,
    )
    grid = alg.stacked_grid()
    assert grid is not None  # the Kronecker back end always has one
    likelihood = BatchedDelta(grid, phase.a, delta)
    rng = np.random.default_rng([seed, 4])
    chains = run_delta_chains(
        phase,
        likelihood,
        _starts(posterior, n_chains, rng),
        Whitening.of(posterior.unit_draws),
        settings,
        seed,
        names=assembled.parameter_names,
        callback=callback,
        checkpoint=None
        if checkpoint_dir is None
        else checkpoint_file(checkpoint_dir, checkpoint_seconds),
    )
    shape = chains.unit_draws.shape[:2]
    values = fixed.values()
    post = Posterior.build(
        names=assembled.parameter_names,
        priors=prior_map,
        unit_draws=chains.unit_draws,
        log_density=chains.log_density,
        acceptance=np.hstack([chains.acceptance, np.full((shape[0], values.size), np.nan)]),
        seed=int(seed),
        algebra="kronecker",
        aux=np.broadcast_to(values, (*shape, values.size)).copy(),
        aux_names=posterior.aux_names,
        noise=posterior.noise,
    )
    delta_std = _delta_std(emulator, assembled.y_star_std, _thinned(post, delta_draws))
    gp = fit_delta_gp(delta_std, emulator.x, max_components=max_components, trend=trend)
    return Discrepancy(
        outputs=emulator.outputs,
        x=np.array(emulator.x, dtype=float),
        delta=delta_std * emulator.outputs.sd[:, None],
        gp=gp,
        posterior=post,
        fixed=fixed,
        realisations=int(realisations),
        update_interval=int(update_interval),
        updates=chains.updates,
        converged=chains.converged,
    )
