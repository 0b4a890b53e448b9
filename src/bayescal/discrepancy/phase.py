"""The discrepancy phase of the MCMC: eqs. 19–25 with theta* the only free quantity.

Everything here works in the **standardised** units of :mod:`bayescal.emulator.assemble`;
:mod:`bayescal.discrepancy.model` maps the result back to physical units. The
algebra of eqs. 20–25 is in :mod:`bayescal.discrepancy.moments`.

What stays fixed, what moves
----------------------------
The paper keeps the emulator's hyperparameters and the precisions at their
estimates and lets only ``theta*`` move. Here that means ``lambda``, every
output's ``lambda*`` and AR(1) coefficient ``phi`` (the measurement error
``Sigma_0`` of :class:`~bayescal.discrepancy.moments.ErrorCovariance`) and the
relative variance ``r`` of an in-likelihood discrepancy
(:mod:`bayescal.emulator.noise`) are fixed at their calibration posterior means
(:class:`FixedPrecisions`).

Every ``update_interval`` sweeps :meth:`DeltaPhase.update` draws ``b`` model
realisations at a chain's current ``theta*`` (eq. 25), re-estimates
``Delta_i``, ``A_i = Sigma_0 + D_i`` (eq. 22), the GLS weights ``w*`` (eq. 20), the
per-period nuggets ``B`` (eq. 21) and the constant of eq. 23; until the next
update the chain's target is its prior plus the log density of eq. 19
(simulator nuggets ``a``, observation nuggets ``B``, an in-likelihood
discrepancy if the calibration had one) plus that constant.
:class:`DeltaTarget` is this target for one chain through the scalar
likelihood (the reference); :class:`bayescal.discrepancy.batched.BatchedDelta`
evaluates it for all chains at once (what the sampler uses,
:mod:`bayescal.discrepancy.sampler`).

Behaviour (measured, worth knowing)
-----------------------------------
``D_i`` is dominated by ``Delta_i Delta_i^T``, so ``A_i^-1`` discounts the
direction of the current residual and the GLS weights of eq. 20 come out close
to the model's own weights ``mu_i`` at the update's ``theta*`` rather than to the
least-squares weights of the data (virtual wall, first period:
``w*_OLS = [0.412, -0.087, 0.798]``, ``w*_GLS = [0.430, -0.051, 0.735]``,
``mu = [0.432, -0.053, 0.722]``). The target after an update therefore leans
towards the ``theta*`` it was estimated at, and a chain's draws stay correlated
across updates: the number of updates, not of sweeps, sets the effective
sample size (:mod:`bayescal.discrepancy.sampler`). This is the paper's warning
that ``Delta`` "can cancel out information gained in the former steps", and the
reason it keeps the earlier posteriors as priors.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from bayescal.calibration.kron import CalibrationAlgebra
from bayescal.calibration.posterior import Posterior
from bayescal.calibration.priors import ThetaPriors
from bayescal.design import Prior
from bayescal.discrepancy.moments import (
    ErrorCovariance,
    GlsObservations,
    empirical_moments,
    gls_observations,
)
from bayescal.emulator.gp import Emulator
from bayescal.emulator.kernel import FloatArray
from bayescal.emulator.noise import ObservationModel
from bayescal.errors import ConfigError

__all__ = ["DeltaPhase", "DeltaTarget", "FixedPrecisions"]


@dataclass(frozen=True)
class FixedPrecisions:
    """The calibration's precisions and error parameters, fixed for the discrepancy phase.

    Attributes
    ----------
    lam
        ``lambda``. [-]
    lam_star
        ``lambda*`` per output. [-]
    phi
        AR(1) coefficient per output with AR(1) errors, in their order. [-]
    delta_rel
        Relative variance ``r`` per output with an in-likelihood discrepancy. [-]
    """

    lam: float
    lam_star: tuple[float, ...]
    phi: tuple[float, ...] = ()
    delta_rel: tuple[float, ...] = ()

    @classmethod
    def from_posterior(
        cls, posterior: Posterior, observations: ObservationModel
    ) -> FixedPrecisions:
        """Posterior means, after checking the posterior's layout against the error models."""
        n_out = observations.n_outputs
        n_phi, n_rel = len(observations.ar_outputs), len(observations.delta_coordinates)
        expected = 1 + n_out + n_phi + n_rel
        names = posterior.aux_names
        if len(names) != expected or posterior.aux.shape[-1] != expected:
            raise ConfigError(
                f"the calibration posterior has the coordinates {list(names)} besides theta*; "
                f"the outputs' error models need {expected}: lambda, {n_out} lambda*, "
                f"{n_phi} AR(1) coefficient(s) and {n_rel} discrepancy variance(s)",
                hint="calibrate again with the same [outputs] and [outputs.errors]",
            )
        # Column by column, as np.mean(posterior.lam) would (same summation, same bits).
        means = [float(np.mean(posterior.aux[..., k])) for k in range(expected)]
        return cls(
            lam=float(means[0]),
            lam_star=tuple(float(v) for v in means[1 : 1 + n_out]),
            phi=tuple(float(v) for v in means[1 + n_out : 1 + n_out + n_phi]),
            delta_rel=tuple(float(v) for v in means[1 + n_out + n_phi :]),
        )

    def values(self) -> FloatArray:
        """``[lambda, lambda*.., phi.., r..]`` (the calibration posterior's ``aux`` layout)."""
        return np.array([self.lam, *self.lam_star, *self.phi, *self.delta_rel], dtype=float)


class DeltaTarget:
    """Log density of ``u = theta*`` (normalised) between two updates, scalar; picklable.

    ``log p(u) + sum_j log N(v_j; 0, Omega_j)`` with ``Omega_j`` of eq. 19
    (simulator nuggets ``a_j``, observation nuggets ``B_j``) plus the constant of
    eq. 23. Non-positive-definite covariances count as zero density. The
    reference of the batched evaluation.

    Parameters
    ----------
    algebra
        Likelihood back end holding the GLS weights ``w*`` (eq. 20).
    priors
        One prior per parameter, in the order of ``u``.
    a
        Simulator nuggets ``(lambda k_j^T k_j)^-1``, ``(p,)``. [-]
    gls
        The observation nuggets ``B`` and the eq. 23 constant.
    delta
        In-likelihood discrepancy variance per basis ``(p,)``, or ``None``. [-]
    """

    def __init__(
        self,
        algebra: CalibrationAlgebra,
        priors: Sequence[Prior],
        a: FloatArray,
        gls: GlsObservations,
        delta: FloatArray | None = None,
    ) -> None:
        self.algebra = algebra
        self.priors = ThetaPriors(tuple(priors))
        self.a = a
        self.nuggets = gls.nuggets
        self.extra = gls.extra
        self.delta = delta

    def __call__(self, u: ArrayLike) -> float:
        """Log density at ``u`` (``(t,)``, normalised theta*)."""
        arr = np.asarray(u, dtype=float)
        prior = self.priors.scalar(arr)
        if prior == -math.inf:
            return prior
        try:
            lik = self.algebra.pieces_nuggets(arr, self.a, self.nuggets, self.delta).logpdf
        except np.linalg.LinAlgError:
            return -math.inf
        return prior + lik + self.extra


class DeltaPhase:
    """What stays fixed in the discrepancy phase, and the update of eqs. 20–25.

    Parameters
    ----------
    emulator
        The trained emulator (hyperparameters at the MAP).
    y_star
        Standardised observed periods ``Y*``, ``(N, m*)``. [-]
    algebra
        Calibration likelihood back end built with the emulator's kernels (for
        :meth:`update`, the scalar reference).
    priors
        One prior per parameter, in the order of ``u``.
    lam
        The fixed precision ``lambda``. [-]
    noise
        The measurement error: ``1 / lambda*`` of one white output, or an
        :class:`~bayescal.discrepancy.moments.ErrorCovariance`. [-]
    realisations
        ``b`` realisations per update (eq. 25).
    delta
        In-likelihood discrepancy variance per basis ``(p,)`` (``r_o tau_j^-1``), or ``None``. [-]
    """

    def __init__(
        self,
        emulator: Emulator,
        y_star: FloatArray,
        algebra: CalibrationAlgebra,
        priors: Sequence[Prior],
        lam: float,
        noise: float | ErrorCovariance,
        realisations: int,
        delta: FloatArray | None = None,
    ) -> None:
        self.emulator = emulator
        self.y_star = np.asarray(y_star, dtype=float)
        self.algebra = algebra
        self.priors = tuple(priors)
        self.theta_priors = ThetaPriors(self.priors)
        self.a = 1.0 / (float(lam) * emulator.basis.ktk)
        n = self.y_star.shape[0]
        self.noise = (
            noise if isinstance(noise, ErrorCovariance) else ErrorCovariance.white(n, noise)
        )
        self.realisations = int(realisations)
        self.delta = delta

    def __call__(self, u: ArrayLike) -> float:
        """Log prior of ``u``."""
        return self.theta_priors.scalar(np.asarray(u, dtype=float))

    def observations(
        self, u: ArrayLike, rngs: Sequence[np.random.Generator]
    ) -> list[GlsObservations]:
        """Eqs. 20–25 at each row of ``u`` ``(B, t)``, row ``b`` with generator ``rngs[b]``.

        One emulator prediction for all rows; the realisations of row ``b`` come
        from its own generator, so a chain's updates do not depend on the others.
        """
        em = self.emulator
        th = np.atleast_2d(np.asarray(u, dtype=float))
        n_per = em.x.shape[0]
        pairs = np.repeat(th, n_per, axis=0)
        mean_w, var_w = em.predict_weights(pairs, np.tile(em.x, (th.shape[0], 1)))
        k = em.basis.k
        out = []
        for b, rng in enumerate(rngs):
            rows = slice(b * n_per, (b + 1) * n_per)
            mom = empirical_moments(
                k, self.y_star, mean_w[rows], var_w[rows], self.realisations, rng
            )
            out.append(gls_observations(k, self.y_star, mom.factor, self.noise))
        return out

    def update(self, u: ArrayLike, rng: np.random.Generator) -> DeltaTarget:
        """The scalar target after re-estimating ``Delta``, ``A``, ``w*`` and ``B`` at ``u``."""
        gls = self.observations(np.asarray(u, dtype=float)[None], [rng])[0]
        algebra = self.algebra.with_observations(gls.w_star)
        return DeltaTarget(algebra, self.priors, self.a, gls, self.delta)
