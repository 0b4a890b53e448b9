"""Leave-one-period-out cross-validation of a calibration, in physical units.

To choose a parameter set, priors, an error model or the in-likelihood
discrepancy without looking at the test window, every training period ``i`` is
left out in turn and predicted from the calibration on the others:

    elpd_i = log p(y*_i | y*_-i) = log E_{v ~ p(v | y*_-i)} [ p(y*_i | v; simulations) ],

``v = [theta*, lambda, lambda*.., phi.., r..]`` a posterior draw and ``p(y*_i
| v; simulations)`` the density of the period's measured samples given the
draw and the simulator runs (:func:`bayescal.calibration.loo.period_log_densities`):
the left-out period is predicted the way bayescal predicts the test window,
from the calibrated parameters and the emulator, and, for an output with a
discrepancy over the periods' conditions, that discrepancy kriged from the
other training periods' residuals (the predictions condition it on the
training residuals in the same way).

**Physical units.** The densities of :mod:`~bayescal.calibration.loo` are
those of the *standardised* samples ``(y - mean) / sd``. A variant with another
standardisation, basis or parameter set standardises differently, so each
period's value gets the log-Jacobian ``-sum log sd`` over its samples
(:func:`log_jacobian`): the density of the measurements in their own units
(W/m², °C ...), comparable across variants.

**PSIS.** The posterior without period ``i`` is reached by importance sampling
of the full posterior's draws (Vehtari, Gelman and Gabry 2017), the weights
Pareto-smoothed by ArviZ (``psislw``). The raw ratio of a draw is
``p(v | y*_-i) / p(v | y*) ∝ 1 / p(y*_i | y*_-i, v)``: in bayescal's likelihood
(eq. 16) the periods are *not* independent given ``v`` (the emulator's
uncertainty and a discrepancy are Gaussian processes over the periods'
conditions ``x``), so the ratio is not ``1 / p(y*_i | v)`` as in ArviZ's
``loo``, but the difference of two calibration log posteriors, with and
without the period's measurements (:func:`held_out_target`), evaluated at the
draw. The Pareto ``k`` of each period's weights says whether the estimate can
be trusted (above :data:`PARETO_K_MAX` it cannot).

**Exact refits.** For such a period :func:`refit_period` samples the
calibration again with the period's measurements removed (the emulator stays:
it is trained on simulations, not on the field data) and averages the
period's density over the new draws.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import logsumexp

from bayescal.calibration.heldout import HeldOutAlgebra
from bayescal.calibration.kron import (
    CalibrationAlgebra,
    Kind,
    KronCalibrationDensity,
    make_algebra,
)
from bayescal.calibration.loo import PARETO_K_MAX, loo_pit, pointwise_scores
from bayescal.calibration.posterior import Posterior
from bayescal.calibration.target import BatchedPosterior, CalibrationPosterior, Moves, sample
from bayescal.design import Prior
from bayescal.emulator.gp import Emulator
from bayescal.emulator.noise import ObservationModel
from bayescal.mcmc.chains import ChainBackend
from bayescal.mcmc.diagnostics import import_arviz

__all__ = [
    "BAND_CHECK_Z",
    "CONFIDENTLY_WRONG",
    "PARETO_K_MAX",
    "PeriodScores",
    "held_out_target",
    "leave_period_out",
    "log_jacobian",
    "paired_difference",
    "refit_period",
    "scored_outputs",
    "scored_rows",
    "thinned",
    "without_period",
]

FloatArray = NDArray[np.float64]
Tick = Callable[[int], None]

#: A left-out band "misses its rate" when its coverage is more than this many
#: standard errors (the period as the unit) from the band's level.
BAND_CHECK_Z = 2.0
#: A left-out period whose 95 % band holds less than this share of its samples is
#: predicted confidently wrong.
CONFIDENTLY_WRONG = 0.5


def log_jacobian(sd: ArrayLike) -> float:
    """``-sum log sd``: standardised log density of a period + this = physical log density.

    Parameters
    ----------
    sd
        The standardisation's scale of every sample of a period (stacked over
        the outputs), ``(N,)``, in the outputs' units. [unit]
    """
    arr = np.asarray(sd, dtype=float)
    if arr.ndim != 1 or not np.all(np.isfinite(arr) & (arr > 0.0)):
        raise ValueError("standardisation scales must be a 1-d array of positive numbers")
    return -float(np.sum(np.log(arr)))


def scored_outputs(
    observations: ObservationModel, names: Sequence[str] | None
) -> tuple[int, ...] | None:
    """The indices of the outputs ``names`` among ``observations.outputs`` (``None``
    where they are all of them, or ``names`` is ``None``: every output scored).

    Raises
    ------
    ValueError
        No name, or a name that is not a calibrated output.
    """
    if names is None:
        return None
    known = [o.name for o in observations.outputs]
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise ValueError(
            f"cannot score {unknown or 'no output'}: the calibrated outputs are {known}"
        )
    picked = tuple(sorted({known.index(n) for n in names}))
    return None if len(picked) == len(known) else picked


def scored_rows(observations: ObservationModel, scored: Sequence[int] | None) -> NDArray[np.intp]:
    """The rows of the stacked samples that belong to the outputs ``scored`` (all: ``None``)."""
    if scored is None:
        return np.arange(observations.y_star.shape[0])
    return np.concatenate([np.arange(*observations.outputs[q].rows) for q in scored])


def without_period(observations: ObservationModel, period: int) -> ObservationModel:
    """The same error models with the measured period ``period`` removed."""
    m = observations.y_star.shape[1]
    if not 0 <= period < m:
        raise IndexError(f"period {period} is not one of the {m} training periods")
    keep = np.delete(np.arange(m), period)
    return ObservationModel(observations.outputs, observations.k, observations.y_star[:, keep])


def held_out_target(
    emulator: Emulator,
    observations: ObservationModel,
    priors: Sequence[Prior],
    period: int | None = None,
    algebra: Kind = "kronecker",
    shortcut: bool = True,
) -> CalibrationPosterior:
    """The calibration log posterior (eq. 16) without the measurements of ``period``.

    The simulator block keeps every period (the emulator is trained on the
    simulations of all of them); the observed weights are those of the other
    periods only (``obs_index``), and the precisions' priors are updated with
    their data alone. ``period=None`` gives the target with every period.
    For one white output without discrepancy on the Kronecker algebra the
    likelihood goes the full grid's fast route minus the period's conditional
    density (:class:`~bayescal.calibration.heldout.HeldOutAlgebra`), else the
    general Schur route on the other periods.

    Parameters
    ----------
    emulator
        The trained emulator.
    observations
        The error models and all measured training periods.
    priors
        The theta* priors, in the emulator's parameter order.
    period
        The period left out (``None``: none).
    algebra
        ``"kronecker"`` or ``"dense"``.
    shortcut
        Use :class:`~bayescal.calibration.heldout.HeldOutAlgebra` where it applies
        (``False``: always the general route; the two agree to rounding).
    """
    m = observations.y_star.shape[1]
    if period is None:
        obs, keep = observations, np.arange(m)
    else:
        obs, keep = without_period(observations, period), np.delete(np.arange(m), period)
    plain = observations.n_outputs == 1 and not (
        observations.ar_outputs or observations.delta_outputs
    )
    if shortcut and plain and period is not None and algebra == "kronecker":
        full = KronCalibrationDensity(
            emulator.theta,
            emulator.x,
            emulator.kernels,
            emulator.basis.ktk,
            emulator.w,
            observations.ls_weights(),
        )
        alg: CalibrationAlgebra = HeldOutAlgebra(full, period)
    else:
        alg = make_algebra(
            algebra,
            emulator.theta,
            emulator.x,
            emulator.kernels,
            emulator.basis.ktk,
            emulator.w,
            obs.ls_weights(),
            keep,
        )
    return CalibrationPosterior(alg, priors, emulator.lam_prior, None, obs)


def thinned(posterior: Posterior, draws_per_chain: int) -> Posterior:
    """The posterior with ``draws_per_chain`` draws per chain, evenly spaced."""
    n = posterior.unit_draws.shape[1]
    pick = np.unique(np.linspace(0, n - 1, max(1, min(draws_per_chain, n))).astype(int))
    return dataclasses.replace(
        posterior,
        unit_draws=posterior.unit_draws[:, pick],
        aux=posterior.aux[:, pick],
        log_density=posterior.log_density[:, pick] if posterior.log_density.size else np.zeros(0),
        derived={},
    )


@dataclass(frozen=True)
class PeriodScores:
    """Leave-one-period-out log predictive densities of one calibration (physical units).

    Attributes
    ----------
    psis
        PSIS estimate of ``elpd_i`` per training period ``(m*,)``. [log density]
    pareto_k
        Pareto ``k`` of each period's importance weights ``(m*,)`` (NaN-free;
        ``inf`` where the ratios were not finite).
    lppd
        In-sample ``log E_{v ~ p(v | y*)} p(y*_i | v)`` per period ``(m*,)``.
    refit
        ``elpd_i`` from an exact refit, NaN where none was done ``(m*,)``.
    log_jacobian
        ``-sum log sd`` of a period's samples, already added to every value.
    draws
        Posterior draws the PSIS estimates used.
    refit_warnings
        Convergence warnings of the refits' chains.
    pit
        Probability integral transform of every measured sample of every training
        period under the calibration without that period ``(n, m*)``
        (:func:`~bayescal.calibration.loo.loo_pit`; a refit's draws where the
        period was refitted); empty where not computed.
    """

    psis: FloatArray
    pareto_k: FloatArray
    lppd: FloatArray
    refit: FloatArray
    log_jacobian: float
    draws: int
    refit_warnings: tuple[str, ...] = ()
    pit: FloatArray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def n_periods(self) -> int:
        """``m*``."""
        return int(self.psis.size)

    def shifted(self, per_period: ArrayLike) -> PeriodScores:
        """The scores with a log-Jacobian per period ``(m*,)`` added (relative errors:
        densities of ``log(y + floor)`` made densities of ``y``)."""
        add = np.asarray(per_period, dtype=float)
        return dataclasses.replace(
            self, psis=self.psis + add, lppd=self.lppd + add, refit=self.refit + add
        )

    @property
    def pointwise(self) -> FloatArray:
        """``elpd_i``: the refit where there is one, else the PSIS estimate ``(m*,)``."""
        out: FloatArray = np.where(np.isfinite(self.refit), self.refit, self.psis)
        return out

    @property
    def elpd(self) -> float:
        """Sum of :attr:`pointwise` over the training periods."""
        return float(np.sum(self.pointwise))

    @property
    def se(self) -> float:
        """Standard error of :attr:`elpd`: ``sqrt(m* var(elpd_i))``."""
        return math.sqrt(self.n_periods * float(np.var(self.pointwise)))

    @property
    def p_loo(self) -> float:
        """Effective number of parameters: ``sum lppd_i - elpd``."""
        return float(np.sum(self.lppd)) - self.elpd

    @property
    def high_k(self) -> NDArray[np.bool_]:
        """Periods whose Pareto ``k`` exceeds :data:`PARETO_K_MAX` ``(m*,)``."""
        out: NDArray[np.bool_] = ~(self.pareto_k <= PARETO_K_MAX)
        return out

    @property
    def refitted(self) -> NDArray[np.bool_]:
        """Periods scored by an exact refit ``(m*,)``."""
        out: NDArray[np.bool_] = np.isfinite(self.refit)
        return out

    @property
    def psis_only(self) -> NDArray[np.bool_]:
        """Periods with a high ``k`` and no refit: their estimate is unreliable ``(m*,)``."""
        out: NDArray[np.bool_] = self.high_k & ~self.refitted
        return out

    def refit_order(self) -> list[int]:
        """Periods that need a refit (high ``k``, none yet), worst ``k`` first."""
        need = np.flatnonzero(self.psis_only)
        return [int(i) for i in need[np.argsort(-self.pareto_k[need], kind="stable")]]

    def with_refits(
        self,
        values: dict[int, float],
        notes: Sequence[str] = (),
        pits: dict[int, FloatArray] | None = None,
    ) -> PeriodScores:
        """The same scores with exact refit values (physical units) for some periods,
        and the PIT of their samples under the refits (``pits``: period -> ``(n,)``)."""
        refit = self.refit.copy()
        for i, value in values.items():
            refit[i] = value
        pit = self.pit.copy()
        for i, column in (pits or {}).items():
            if pit.size:
                pit[:, i] = column
        return dataclasses.replace(
            self, refit=refit, refit_warnings=(*self.refit_warnings, *notes), pit=pit
        )

    def band_coverage(self, level: float) -> float:
        """Share of the training samples inside the central ``level`` band of their
        period's leave-one-out prediction (NaN without PIT values).

        The band of a period the calibration did not see: measured on the training
        periods alone, it says before the test window is read whether the bands of
        new periods hold their rate (what a sample inside means: ``|PIT - 1/2| <
        level / 2``)."""
        if not self.pit.size:
            return math.nan
        return float(np.mean(np.abs(self.pit - 0.5) < 0.5 * level))

    def band_shares(self, level: float) -> FloatArray:
        """Share of each training period's samples inside the central ``level`` band of
        its leave-one-out prediction ``(m*,)`` (empty without PIT values); their mean is
        :meth:`band_coverage`."""
        if not self.pit.size:
            return np.zeros(0)
        out: FloatArray = np.mean(np.abs(self.pit - 0.5) < 0.5 * level, axis=0)
        return out

    def band_coverage_se(self, level: float) -> float:
        """Standard error of :meth:`band_coverage` with the period as the unit,
        ``sqrt(var(share_i) / m*)`` (NaN without PIT values or with one period).

        The samples of a period fall inside or outside together (their errors are
        correlated in time), so the binomial SE of independent samples,
        ``sqrt(level (1 - level) / n)``, would be too small; the periods are the
        exchangeable units, as for the ELPD's :attr:`se`."""
        shares = self.band_shares(level)
        if shares.size < 2:
            return math.nan
        return math.sqrt(float(np.var(shares, ddof=1)) / shares.size)

    def band_check(self, level: float, *, z: float = BAND_CHECK_Z) -> str:
        """``"holds"``, ``"too wide"`` or ``"too narrow"``: whether the left-out band's
        coverage lies within ``z`` standard errors (:meth:`band_coverage_se`) of
        ``level`` (``""`` without PIT values)."""
        coverage, se = self.band_coverage(level), self.band_coverage_se(level)
        if not math.isfinite(coverage):
            return ""
        margin = z * se if math.isfinite(se) else 0.0
        if coverage > level + margin:
            return "too wide"
        if coverage < level - margin:
            return "too narrow"
        return "holds"


def _relative_efficiency(posterior: Posterior) -> float:
    """ArviZ's ``reff``: mean bulk ESS (``method="mean"``) over the coordinates / draws."""
    chains, draws = posterior.unit_draws.shape[:2]
    if chains < 2 or draws < 4:
        return 1.0
    az = import_arviz()
    values = np.concatenate([posterior.unit_draws, posterior.aux], axis=-1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ess = [float(az.ess(values[..., k], method="mean")) for k in range(values.shape[-1])]
    finite = [e for e in ess if math.isfinite(e)]
    if not finite:
        return 1.0
    return float(np.clip(np.mean(finite) / (chains * draws), 1e-3, 1.0))


def _log_posterior(target: CalibrationPosterior, points: FloatArray) -> FloatArray:
    """The target at every row of ``points``: batched for one white output, else row by row."""
    if target.plain:
        out: FloatArray = BatchedPosterior(target.algebra, target.prior_terms)(points)
        return out
    return np.array([target(v) for v in points])


def leave_period_out(
    emulator: Emulator,
    observations: ObservationModel,
    posterior: Posterior,
    *,
    algebra: Kind = "kronecker",
    draws_per_chain: int = 250,
    callback: Tick | None = None,
    outputs: Sequence[str] | None = None,
) -> PeriodScores:
    """PSIS leave-one-period-out ``elpd_i`` of a calibration, in physical units.

    Parameters
    ----------
    emulator
        The trained emulator (its ``outputs.sd`` gives the log-Jacobian).
    observations
        The error models and the measured training periods.
    posterior
        The calibration's posterior.
    algebra
        The calibration's likelihood back end.
    draws_per_chain
        Draws per chain used (thinned evenly).
    callback
        Progress: called with the number of periods done.
    outputs
        The calibrated outputs whose samples are scored (``None``: all). Every
        output of the period is left out (the importance weights are those of the
        calibration without the whole period); the score and the PIT are those of
        these outputs' samples alone: how variants that calibrate different sets
        of outputs compare on the outputs they share.
    """
    scored = scored_outputs(observations, outputs)
    rows = scored_rows(observations, scored)
    post = thinned(posterior, draws_per_chain)
    loglik, mu, sd = pointwise_scores(
        emulator, observations, post, post.unit_draws.shape[1], scored
    )
    chains, draws, m = loglik.shape
    flat = loglik.reshape(-1, m)  # (S, m*)
    points = np.concatenate([post.unit_draws, post.aux], axis=-1).reshape(chains * draws, -1)
    priors = list(post.priors.values())
    full = _log_posterior(held_out_target(emulator, observations, priors, None, algebra), points)
    log_ratio = np.empty((m, flat.shape[0]))  # -log p(y*_i | y*_-i, v) + const
    for i in range(m):
        target = held_out_target(emulator, observations, priors, i, algebra)
        log_ratio[i] = _log_posterior(target, points) - full
        if callback is not None:
            callback(i + 1)
    az = import_arviz()
    bad = ~np.all(np.isfinite(log_ratio), axis=1)
    safe = np.where(np.isfinite(log_ratio), log_ratio, 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ArviZ warns about high k; we report it per period
        log_w, k = az.psislw(safe, _relative_efficiency(post))
    k = np.where(bad | ~np.isfinite(k), np.inf, np.asarray(k, dtype=float))
    jac = log_jacobian(emulator.outputs.sd[rows])
    psis = logsumexp(np.asarray(log_w) + flat.T, axis=1) + jac
    lppd = logsumexp(flat, axis=0) - math.log(flat.shape[0]) + jac
    n = observations.y_star.shape[0]
    pit = loo_pit(
        observations.y_star[rows],
        mu.reshape(-1, n, m)[:, rows],
        sd.reshape(-1, n, m)[:, rows],
        np.asarray(log_w).reshape(m, -1),
    )
    return PeriodScores(
        psis=np.asarray(psis, dtype=float),
        pareto_k=k,
        lppd=np.asarray(lppd, dtype=float),
        refit=np.full(m, np.nan),
        log_jacobian=jac,
        draws=int(flat.shape[0]),
        pit=pit,
    )


def refit_period(
    emulator: Emulator,
    observations: ObservationModel,
    priors: dict[str, Prior],
    period: int,
    *,
    n_chains: int = 4,
    n_burn: int = 1000,
    n_draws: int = 1000,
    seed: int = 0,
    backend: ChainBackend = "processes",
    algebra: Kind = "kronecker",
    draws_per_chain: int = 250,
    callback: Tick | None = None,
    moves: Moves = "gibbs",
    held: ArrayLike | None = None,
    outputs: Sequence[str] | None = None,
) -> tuple[float, Posterior, FloatArray]:
    """``elpd_i`` of ``period`` by an exact refit without its measurements (physical units).

    Metropolis-within-Gibbs chains (:func:`bayescal.calibration.target.sample`)
    sample :func:`held_out_target`; the period's density is averaged over
    their draws (thinned to ``draws_per_chain``). Returns the value, the
    refit's posterior (its ``warnings`` say whether the chains converged) and
    the PIT of the period's samples under it ``(n,)``.

    Parameters
    ----------
    emulator, observations
        As :func:`leave_period_out` (all periods; the left-out one is scored).
    priors
        Parameter name -> the calibration's prior.
    period
        The period left out.
    n_chains, n_burn, n_draws, seed, backend
        The chains (as :func:`bayescal.calibration.posterior.calibrate`).
    algebra
        The likelihood back end.
    draws_per_chain
        Draws per chain the score averages over.
    callback
        Progress of the chains (iterations over all chains).
    moves
        How the sweeps move the coordinates, as the calibration's.
    held
        theta* on the normalised scale ``(t,)`` held fixed, as the posterior's
        (:func:`bayescal.calibration.target.hold_theta`: the catalogue model);
        ``None``: sampled.
    outputs
        The calibrated outputs whose samples are scored (``None``: all), as
        :func:`leave_period_out`.
    """
    scored = scored_outputs(observations, outputs)
    rows = scored_rows(observations, scored)
    target = held_out_target(emulator, observations, list(priors.values()), period, algebra)
    names = tuple(priors)
    chains = sample(
        target,
        n_draws,
        n_burn=n_burn,
        n_chains=n_chains,
        seed=seed,
        backend=backend,
        names=(*names, *target.aux_names),
        callback=callback,
        moves=moves,
        held=held,
    )
    draws = chains.draws
    t = target.t
    refit = Posterior.build(
        names=names,
        priors=priors,
        unit_draws=draws[..., :t],
        log_density=chains.log_density,
        acceptance=chains.acceptance,
        seed=seed,
        algebra=algebra,
        aux=draws[..., t:],
        aux_names=target.aux_names,
        noise=observations.outputs,
    )
    post = thinned(refit, draws_per_chain)
    loglik, mu, sd = pointwise_scores(
        emulator, observations, post, post.unit_draws.shape[1], scored
    )
    column = loglik[..., period].reshape(-1)
    value = float(logsumexp(column)) - math.log(column.size)
    n, m = observations.y_star.shape
    pit = loo_pit(
        observations.y_star[rows], mu.reshape(-1, n, m)[:, rows], sd.reshape(-1, n, m)[:, rows]
    )[:, period]
    return value + log_jacobian(emulator.outputs.sd[rows]), refit, pit


def paired_difference(best: ArrayLike, other: ArrayLike) -> tuple[float, float]:
    """``elpd(best) - elpd(other)`` and its standard error from the paired periods.

    ``se = sqrt(m* var(best_i - other_i))`` (as ArviZ's ``compare``): the
    periods that both variants find hard cancel, so the difference is known
    better than either ELPD.
    """
    a, b = np.asarray(best, dtype=float), np.asarray(other, dtype=float)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"pointwise values of different shapes {a.shape} and {b.shape}")
    diff = a - b
    return float(np.sum(diff)), math.sqrt(diff.size * float(np.var(diff)))
