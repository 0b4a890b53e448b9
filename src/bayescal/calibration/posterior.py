"""Calibration posterior of theta*, lambda and lambda* (the paper's eq. 16).

With the emulator's hyperparameters fixed at their MAP, the stacked weights
``v_j = [w_j; w*_j]`` are ``N(0, Omega_j)`` (eqs. 12, 14, 17). The sampled
vector is ``[u_1 .. u_t, lambda, lambda*]`` where ``u`` is ``theta*`` on the
normalised scale [0, 1] of the prior bounds; the log posterior adds

* the study priors of ``theta*`` on that scale (uniform, or Beta(a, b) on the
  bounds: :meth:`bayescal.design.Prior.logpdf_unit`);
* ``lambda ~ Gamma`` after eq. 7 (the training data outside the basis);
* ``lambda* ~ Gamma(a + m* (n - p) / 2, b + RSS* / 2)``, eq. 7 applied to the
  measured periods ``Y*``.

The likelihood goes through :class:`bayescal.emulator.kron.KronCalibrationDensity`
(default) or the dense reference. :func:`calibrate` runs ``n_chains`` (>= 4)
adaptive Metropolis-within-Gibbs chains (or, with the optional extra
``bayescal[hmc]``, NUTS chains: :mod:`bayescal.calibration.hmc`) from
dispersed starts and returns a
:class:`Posterior` with draws in physical units, ArviZ ``InferenceData`` and
diagnostics: every R-hat above 1.01, ESS below 400 or stuck chain is listed in
``Posterior.warnings`` (nothing is printed or logged here; the pipeline reports
them).
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from bayescal.calibration.chains import BACKENDS, ChainBackend, run_chains
from bayescal.calibration.diagnostics import Diagnostics, _arviz, diagnose
from bayescal.calibration.hmc import check_installed, sample_nuts_isolated
from bayescal.calibration.samplers.mwg import MetropolisWithinGibbs
from bayescal.calibration.samplers.rwm import AdaptiveMetropolis
from bayescal.config import NUTS_MIN_WARMUP
from bayescal.design import Prior, UniformPrior
from bayescal.emulator.assemble import Assembled
from bayescal.emulator.gp import Emulator
from bayescal.emulator.kernel import FloatArray
from bayescal.emulator.kron import CalibrationAlgebra, Kind, make_algebra
from bayescal.errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd
    from arviz import InferenceData

__all__ = ["CalibrationPosterior", "Posterior", "calibrate"]

Backend = ChainBackend
SamplerKind = Literal["mwg", "block", "nuts"]
LAMBDA_NAMES = ("lambda", "lambda_star")


def _log_gamma(value: float, shape: float, rate: float) -> float:
    if not value > 0.0:
        return -math.inf
    return (shape - 1.0) * math.log(value) - rate * value


class CalibrationPosterior:
    """Log posterior of eq. 16 at ``[u_1 .. u_t, lambda, lambda*]``, up to a constant.

    Picklable (for chains in worker processes). Non-positive-definite
    covariances count as zero density.

    Parameters
    ----------
    algebra
        Likelihood back end (Kronecker or dense) built with the MAP kernels.
    priors
        One prior per parameter, in the order of ``u``.
    lam_prior, lam_star_prior
        ``(shape, rate)`` of the Gamma priors of ``lambda`` and ``lambda*``.
    """

    def __init__(
        self,
        algebra: CalibrationAlgebra,
        priors: Sequence[Prior],
        lam_prior: tuple[float, float],
        lam_star_prior: tuple[float, float],
    ) -> None:
        self.algebra = algebra
        self.priors = tuple(priors)
        self.t = len(self.priors)
        self.lam_prior = (float(lam_prior[0]), float(lam_prior[1]))
        self.lam_star_prior = (float(lam_star_prior[0]), float(lam_star_prior[1]))

    def log_prior(self, v: ArrayLike) -> float:
        """Log prior density of ``[u, lambda, lambda*]`` (up to a constant)."""
        arr = np.asarray(v, dtype=float)
        total = _log_gamma(float(arr[self.t]), *self.lam_prior)
        total += _log_gamma(float(arr[self.t + 1]), *self.lam_star_prior)
        for k, prior in enumerate(self.priors):
            if total == -math.inf:
                break
            if type(prior) is UniformPrior:  # the common case, without numpy's overhead
                total += 0.0 if 0.0 <= float(arr[k]) <= 1.0 else -math.inf
            else:
                total += float(prior.logpdf_unit(arr[k]))
        return total

    def __call__(self, v: ArrayLike) -> float:
        """Log posterior (eq. 16) at ``v = [u_1 .. u_t, lambda, lambda*]``."""
        arr = np.asarray(v, dtype=float)
        prior = self.log_prior(arr)
        if prior == -math.inf:
            return prior
        try:
            lik = self.algebra.logpdf(arr[: self.t], float(arr[self.t]), float(arr[self.t + 1]))
        except np.linalg.LinAlgError:
            return -math.inf
        return prior + lik


@dataclass(frozen=True)
class Posterior:
    """Draws of theta* (physical units), lambda and lambda*, with diagnostics.

    Attributes
    ----------
    names
        Calibration parameter names ``(t,)``.
    priors
        Parameter name -> prior used in the calibration.
    unit_draws
        theta* on the normalised scale, ``(chains, draws, t)``. [-]
    lam, lam_star
        Precision draws ``(chains, draws)``. [-]
    log_density
        Log posterior (up to a constant) at the draws ``(chains, draws)``.
    acceptance
        Acceptance rate per chain and coordinate ``(chains, t + 2)``.
    seed
        Root seed of the chains.
    algebra
        ``"kronecker"`` or ``"dense"``.
    diagnostics
        R-hat, ESS, MCSE and the list of warnings (over theta*, lambda, lambda*).
    """

    names: tuple[str, ...]
    priors: Mapping[str, Prior]
    unit_draws: FloatArray
    lam: FloatArray
    lam_star: FloatArray
    log_density: FloatArray
    acceptance: FloatArray
    seed: int
    algebra: str
    diagnostics: Diagnostics

    @classmethod
    def build(
        cls,
        names: Sequence[str],
        priors: Mapping[str, Prior],
        unit_draws: ArrayLike,
        lam: ArrayLike,
        lam_star: ArrayLike,
        log_density: ArrayLike,
        acceptance: ArrayLike,
        seed: int,
        algebra: str,
        sampler_warnings: Sequence[str] = (),
    ) -> Posterior:
        """Assemble the posterior and compute its diagnostics (physical units).

        ``sampler_warnings`` (e.g. NUTS divergences) are appended to the
        diagnostics' warnings.
        """
        unit = np.asarray(unit_draws, dtype=float)
        lam_arr, lam_s = np.asarray(lam, dtype=float), np.asarray(lam_star, dtype=float)
        phys = np.stack([p.from_unit(unit[..., k]) for k, p in enumerate(priors.values())], axis=-1)
        everything = np.concatenate([phys, lam_arr[..., None], lam_s[..., None]], axis=-1)
        acc = np.asarray(acceptance, dtype=float)
        diag = diagnose(everything, (*names, *LAMBDA_NAMES), acc)
        if sampler_warnings:
            diag = dataclasses.replace(diag, warnings=(*diag.warnings, *sampler_warnings))
        return cls(
            tuple(names),
            dict(priors),
            unit,
            lam_arr,
            lam_s,
            np.asarray(log_density, dtype=float),
            acc,
            int(seed),
            str(algebra),
            diag,
        )

    @property
    def draws(self) -> FloatArray:
        """theta* in physical units, ``(chains, draws, t)``."""
        cols = [p.from_unit(self.unit_draws[..., k]) for k, p in enumerate(self.priors.values())]
        return np.stack(cols, axis=-1)

    @property
    def warnings(self) -> tuple[str, ...]:
        """Every diagnostic problem found (empty when all checks pass)."""
        return self.diagnostics.warnings

    @property
    def all_names(self) -> tuple[str, ...]:
        """``names`` then ``lambda`` and ``lambda_star``."""
        return (*self.names, *LAMBDA_NAMES)

    def all_draws(self) -> FloatArray:
        """``[theta* (physical), lambda, lambda*]``, ``(chains, draws, t + 2)``."""
        return np.concatenate([self.draws, self.lam[..., None], self.lam_star[..., None]], axis=-1)

    def interval(self, level: float = 0.95) -> tuple[FloatArray, FloatArray]:
        """Central credible interval of theta* per parameter (physical units), ``(t,)`` each."""
        flat = self.draws.reshape(-1, len(self.names))
        tail = 50.0 * (1.0 - level)
        return np.percentile(flat, tail, axis=0), np.percentile(flat, 100.0 - tail, axis=0)

    def summary(self, level: float = 0.95) -> pd.DataFrame:
        """Mean, SD, credible interval, R-hat and ESS per parameter (physical units)."""
        import pandas as pd

        flat = self.all_draws().reshape(-1, len(self.all_names))
        tail = 50.0 * (1.0 - level)
        table = self.diagnostics.table()
        table["lower"] = np.percentile(flat, tail, axis=0)
        table["upper"] = np.percentile(flat, 100.0 - tail, axis=0)
        return pd.DataFrame(table)

    def inference_data(self) -> InferenceData:
        """ArviZ ``InferenceData``: posterior (physical theta*, lambda, lambda*), lp, seed."""
        az = _arviz()
        draws = self.all_draws()
        posterior = {n: draws[..., k] for k, n in enumerate(self.all_names)}
        return az.from_dict(
            posterior=posterior,
            sample_stats={"lp": self.log_density},
            attrs={"seed": self.seed, "algebra": self.algebra},
        )


def _check_priors(assembled: Assembled, priors: Mapping[str, Prior] | None) -> dict[str, Prior]:
    if priors is None:
        return dict(assembled.priors)
    if tuple(priors) != assembled.parameter_names:
        raise ConfigError(
            f"calibration priors are given for {list(priors)}, the design has "
            f"{list(assembled.parameter_names)} (same names, same order)"
        )
    for name, prior in priors.items():
        ref = assembled.priors[name]
        if (prior.lower, prior.upper) != (ref.lower, ref.upper):
            raise ConfigError(
                f"prior of {name!r} has bounds [{prior.lower}, {prior.upper}], the design "
                f"was drawn on [{ref.lower}, {ref.upper}]",
                hint="keep the design's bounds; change only the shape (uniform or beta)",
            )
    return dict(priors)


def _starts(target: CalibrationPosterior, n_chains: int, rng: np.random.Generator) -> FloatArray:
    """Dispersed starts: theta* by strata in [0.05, 0.95], precisions from their priors."""
    t = target.t
    strata = (
        np.argsort(rng.random((t, n_chains)), axis=1).T + rng.random((n_chains, t))
    ) / n_chains
    lam = rng.gamma(target.lam_prior[0], 1.0 / target.lam_prior[1], n_chains)
    lam_star = rng.gamma(target.lam_star_prior[0], 1.0 / target.lam_star_prior[1], n_chains)
    return np.column_stack([0.05 + 0.9 * strata, lam, lam_star])


def _sampler(kind: SamplerKind, target: CalibrationPosterior, n_burn: int) -> Any:
    t = target.t
    lower = [0.0] * (t + 2)
    upper = [1.0] * t + [math.inf, math.inf]
    # Logit-scale widths for theta*, ~2.4 prior log-sd for the sharply known precisions.
    scales = [0.5] * t + [
        2.4 / math.sqrt(target.lam_prior[0]),
        2.4 / math.sqrt(target.lam_star_prior[0]),
    ]
    if kind == "mwg":
        # Short batches and a generous cap: the widths of sharply identified
        # parameters must shrink by ~e^3 within a burn-in of a few hundred sweeps.
        return MetropolisWithinGibbs(
            n_burn=n_burn, lower=lower, upper=upper, scales=scales, batch_size=25, max_adapt=0.25
        )
    if kind == "block":
        return AdaptiveMetropolis(n_burn=n_burn, lower=lower, upper=upper, scales=scales)
    raise ConfigError(f"sampler must be 'mwg', 'block' or 'nuts', got {kind!r}")


def calibrate(
    emulator: Emulator,
    assembled: Assembled,
    priors: Mapping[str, Prior] | None = None,
    *,
    n_chains: int = 4,
    n_burn: int = 1000,
    n_draws: int = 1000,
    seed: int = 0,
    backend: Backend = "processes",
    algebra: Kind = "kronecker",
    sampler: SamplerKind = "mwg",
    callback: Callable[[int], None] | None = None,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_seconds: float = 30.0,
) -> Posterior:
    """Sample theta*, lambda and lambda* (eq. 16) with the hyperparameters at the MAP.

    Parameters
    ----------
    emulator
        The trained emulator (its kernels, weights and ``lambda`` prior).
    assembled
        The assembled data (measured weights ``W*`` and the ``lambda*`` prior).
    priors
        Parameter name -> prior on the design's bounds (default: the design's).
    n_chains
        Number of chains; diagnostics warn below 4.
    n_burn, n_draws
        Burn-in (adapted, discarded) and kept iterations per chain.
    seed
        Root seed; chain ``k`` uses ``SeedSequence(seed).spawn(n_chains)[k]``.
    backend
        ``"processes"`` (chains in worker processes), ``"serial"``, or
        ``"vectorised"`` (all chains in lockstep in this process, one batched
        likelihood call per coordinate update; ``sampler="mwg"`` only, no
        checkpoints; draws equal the serial ones; 1.4-6x faster than serial
        4-16 chains, see ``docs/benchmarks.md``).
    algebra
        ``"kronecker"`` (fast, default) or ``"dense"`` (reference).
    sampler
        ``"mwg"`` (Metropolis-within-Gibbs), ``"block"`` (adaptive block
        Metropolis) or ``"nuts"`` (No-U-Turn sampler with window adaptation,
        :func:`bayescal.calibration.hmc.sample_nuts`; needs the extra
        ``bayescal[hmc]`` and ``algebra="kronecker"``). With ``"nuts"``
        ``n_burn`` is the warm-up length, the chains run one after another in
        one spawned process whatever ``backend`` says (JAX never starts in
        this one, so later process pools may fork safely), the acceptance columns all
        hold each chain's mean NUTS acceptance probability, divergent
        transitions are added to the warnings, and ``checkpoint_dir`` is
        ignored (a killed NUTS run starts again from the beginning).
    callback
        Progress: called with the iterations completed over all chains.
    checkpoint_dir
        Folder for per-chain snapshots; a killed run resumes from them with
        identical draws (see :func:`bayescal.calibration.chains.run_chains`).
        Not supported by ``"nuts"`` (ignored).
    checkpoint_seconds
        Minimum wall time between two snapshots of a chain. [s]

    Returns
    -------
    Posterior
    """
    if backend not in BACKENDS:
        raise ConfigError(f"backend must be one of {list(BACKENDS)}, got {backend!r}")
    if sampler == "nuts":
        check_installed()
        if n_burn < NUTS_MIN_WARMUP:
            raise ConfigError(
                f"sampler 'nuts' adapts its step size during the burn-in: got {n_burn} "
                f"iterations, expected at least {NUTS_MIN_WARMUP}",
                hint="set [calibration] burn = 500",
            )
        if algebra != "kronecker":
            raise ConfigError(
                f"sampler 'nuts' evaluates eq. 16 by the Kronecker route in JAX, got "
                f"algebra {algebra!r}",
                hint="set [emulator] algebra = 'kronecker' or use sampler 'mwg'",
            )
    prior_map = _check_priors(assembled, priors)
    alg = make_algebra(
        algebra,
        emulator.theta,
        emulator.x,
        emulator.kernels,
        emulator.basis.ktk,
        emulator.w,
        assembled.w_star,
    )
    target = CalibrationPosterior(
        alg, list(prior_map.values()), emulator.lam_prior, assembled.lam_star_prior
    )
    starts = _starts(target, n_chains, np.random.default_rng([seed, 2]))
    if sampler == "nuts":
        return _calibrate_nuts(
            target, starts, prior_map, assembled.parameter_names, n_burn, n_draws, seed, callback
        )
    names = (*assembled.parameter_names, *LAMBDA_NAMES)
    chains = run_chains(
        _sampler(sampler, target, n_burn),
        target,
        starts,
        n_draws,
        seed=seed,
        names=names,
        backend=backend,
        callback=callback,
        checkpoint_dir=checkpoint_dir,
        checkpoint_seconds=checkpoint_seconds,
    )
    draws = chains.draws
    t = target.t
    return Posterior.build(
        names=assembled.parameter_names,
        priors=prior_map,
        unit_draws=draws[..., :t],
        lam=draws[..., t],
        lam_star=draws[..., t + 1],
        log_density=chains.log_density,
        acceptance=chains.acceptance,
        seed=int(seed),
        algebra=algebra,
    )


def _calibrate_nuts(
    target: CalibrationPosterior,
    starts: FloatArray,
    prior_map: dict[str, Prior],
    names: Sequence[str],
    n_burn: int,
    n_draws: int,
    seed: int,
    callback: Callable[[int], None] | None,
) -> Posterior:
    """The ``sampler="nuts"`` branch of :func:`calibrate`."""
    result = sample_nuts_isolated(target, starts, n_burn, n_draws, seed, callback=callback)
    t = target.t
    acceptance = np.repeat(result.chains.acceptance[:, None], t + 2, axis=1)
    divergences = [
        f"chain {c} had {n} divergent NUTS transitions after warm-up; the posterior may be "
        "biased: lengthen the warm-up ([calibration] burn) or use sampler 'mwg'"
        for c, n in enumerate(result.chains.divergent)
        if n > 0
    ]
    return Posterior.build(
        names=names,
        priors=prior_map,
        unit_draws=result.draws[..., :t],
        lam=result.draws[..., t],
        lam_star=result.draws[..., t + 1],
        log_density=result.log_density,
        acceptance=acceptance,
        seed=int(seed),
        algebra="kronecker",
        sampler_warnings=divergences,
    )
