"""The discrepancy phase of the MCMC: eqs. 19–25 with theta* the only free quantity.

Everything here works in the **standardised** units of :mod:`bayescal.emulator.assemble`
(the units of ``Y*`` in eqs. 13 and 20–24); :mod:`bayescal.discrepancy.model` maps
the result back to physical units.

Empirical moments (eq. 25, sign ``Delta = observation - model``)
----------------------------------------------------------------
At the chain's current ``theta*`` the emulator gives, for every training period
``i``, the GP conditional of the weights given the training weights (eq. 17
conditioned on ``W``): mean ``mu_i`` and variance ``v_i`` per basis (the bases are
independent, so per-period marginals are all eq. 25 needs). ``b`` realisations
``w_ik = mu_i + sqrt(v_i) z`` give ``f_ik = K w_ik`` (eq. 1) and

    d_ik = y*_i - f_ik,   Delta_i = mean_k d_ik,   D_i = mean_k d_ik d_ik^T.

The paper's eq. 25 writes ``f - y*``; the outer product ``D_i`` is the same
either way, and ``Delta`` here has the sign of eq. 18
(``y* = f + Delta + eps``). ``D_i`` is the *non-centred* mean outer product, as
in eq. 25: it carries the bias ``Delta_i Delta_i^T`` as well as the model's
spread.

Every ``d_ik`` lies in the span of ``G_i = [y*_i, K]`` (``N x (p + 1)``):
``d_ik = G_i e_k`` with ``e_k = [1, -w_ik]``. Hence ``D_i = G_i S_i G_i^T`` with the
``(p + 1) x (p + 1)`` matrix ``S_i = mean_k e_k e_k^T`` and a factor
``U_i = G_i Q sqrt(L)`` from ``S_i = Q L Q^T``: ``D_i = U_i U_i^T`` of rank
``<= p + 1`` whatever ``b`` and ``N`` are.

Generalised least squares (eqs. 20–24)
--------------------------------------
``A_i = lambda*^-1 I + D_i`` (eq. 22) is handled by the Woodbury identity through
the ``r x r`` matrix ``M_i = c I + U_i^T U_i`` (``c = 1 / lambda*``)::

    K^T A^-1 K = (K^T K - K^T U M^-1 U^T K) / c,   log |A| = N log c + log |M / c|,

and likewise for ``K^T A^-1 y*`` and ``y*^T A^-1 y*``: ``O(N p^2)`` per period,
never an ``N x N`` factorisation. Then ``w*_i = H_i^-1 K^T A_i^-1 y*_i`` with
``H_i = K^T A_i^-1 K`` (eq. 20), the per-period observation nuggets
``B_j[i] = 1 / H_i[j, j]`` (eq. 21), and the extra log-likelihood term of
eqs. 23–24, ``sum_i -(log |A_i| + y*_i^T C_i y*_i) / 2`` with
``y^T C y = y^T A^-1 y - g^T H^-1 g`` (``g = K^T A^-1 y``). The paper prints
``exp{y^T C y}``; the minus one half of a Gaussian exponent is meant. With
``D_i = 0`` everything reduces to the calibration phase: ``w*`` the least-squares
weights of eq. 13 and ``B_j = (lambda* k_j^T k_j)^-1``.

Behaviour (measured, worth knowing)
-----------------------------------
``D_i`` is dominated by ``Delta_i Delta_i^T``, so ``A_i^-1`` discounts the
direction of the current residual and the GLS weights of eq. 20 come out close
to the model's own weights ``mu_i`` at the update's ``theta*`` rather than to the
least-squares weights of the data (virtual wall, first period:
``w*_OLS = [0.412, -0.087, 0.798]``, ``w*_GLS = [0.430, -0.051, 0.735]``,
``mu = [0.432, -0.053, 0.722]``). The data then inform ``theta*`` mostly through
its prior (the calibration posterior, :func:`bayescal.discrepancy.priors.default_priors`)
and the last update: the phase's posterior stays close to its prior and the
chains mix slowly across updates (bulk ESS of 20–90 in 1200 draws for the
well-identified wall parameters with ``update_interval = 50``). This is the
paper's warning that ``Delta`` "can cancel out information gained in the former
steps", and the reason it keeps the earlier posteriors as priors.

Sampling
--------
Between two updates the target of ``theta*`` is fixed: its prior plus the log
density of eq. 19 (:class:`bayescal.calibration.kron.KronCalibrationDensity` with
per-period nuggets ``B_j``) plus the constant of eq. 23.
:class:`EmpiricalDeltaSampler` runs Metropolis-within-Gibbs segments of
``update_interval`` sweeps and re-estimates ``Delta_i``, ``A_i``, ``w*`` and ``B``
at the start of each, from the current ``theta*`` and the chain's own generator
(so the draws depend on the seed only). Each segment is an exact Metropolis
chain for its target; across updates the target moves, which is the paper's
construction ("an additional step to the chain").
"""

from __future__ import annotations

import copy
import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from bayescal.calibration.kron import CalibrationAlgebra
from bayescal.calibration.priors import ThetaPriors
from bayescal.design import Prior
from bayescal.emulator.gp import Emulator
from bayescal.emulator.kernel import FloatArray
from bayescal.errors import ConfigError
from bayescal.mcmc.chains import Offset
from bayescal.mcmc.samplers.base import Callback, LogDensity, SamplerResult
from bayescal.mcmc.samplers.mwg import MetropolisWithinGibbs

__all__ = [
    "DeltaPhase",
    "DeltaTarget",
    "EmpiricalDeltaSampler",
    "GlsObservations",
    "PeriodMoments",
    "empirical_moments",
    "gls_observations",
]


@dataclass(frozen=True)
class PeriodMoments:
    """Empirical moments of ``y* - f`` per training period (eq. 25), standardised.

    Attributes
    ----------
    delta
        ``Delta_i`` as columns, ``(N, m*)``. [-]
    factor
        ``U_i`` with ``D_i = U_i U_i^T``, ``(m*, N, r)``, ``r <= p + 1``. [-]
    """

    delta: FloatArray
    factor: FloatArray


def empirical_moments(
    k: FloatArray,
    y_star: FloatArray,
    mean_w: FloatArray,
    var_w: FloatArray,
    realisations: int,
    rng: np.random.Generator,
) -> PeriodMoments:
    """``Delta_i`` and a factor of ``D_i`` from ``b`` realisations of the model (eq. 25).

    Parameters
    ----------
    k
        Basis ``K``, ``(N, p)``. [-]
    y_star
        Standardised observed periods ``Y*``, ``(N, m*)``. [-]
    mean_w, var_w
        Conditional mean and variance of the weights at ``[theta*, x_i]``, ``(m*, p)``. [-]
    realisations
        ``b``, the number of realisations per period.
    rng
        Generator of the realisations.
    """
    n_per, p = mean_w.shape
    z = rng.standard_normal((realisations, n_per, p))
    w = mean_w[None] + np.sqrt(np.maximum(var_w, 0.0))[None] * z  # (b, m*, p)
    e = np.concatenate([np.ones((realisations, n_per, 1)), -w], axis=2)  # (b, m*, p+1)
    s = np.einsum("kia,kib->iab", e, e) / realisations  # (m*, p+1, p+1)
    values, vectors = np.linalg.eigh(s)
    root = vectors * np.sqrt(np.maximum(values, 0.0))[:, None, :]  # S_i = root root^T
    g = np.concatenate([y_star.T[:, :, None], np.broadcast_to(k, (n_per, *k.shape))], axis=2)
    factor = g @ root  # (m*, N, p+1)
    delta = y_star - k @ w.mean(axis=0).T
    return PeriodMoments(delta, factor)


@dataclass(frozen=True)
class GlsObservations:
    """Observed weights and nuggets under ``A_i`` (eqs. 20–24), standardised.

    Attributes
    ----------
    w_star
        GLS weights ``w*_i`` (eq. 20), ``(m*, p)``. [-]
    nuggets
        ``B_j[i] = (k_j^T A_i^-1 k_j)^-1`` (eq. 21), ``(p, m*)``. [-]
    extra
        ``sum_i -(log |A_i| + y*_i^T C_i y*_i) / 2`` (eqs. 23–24).
    """

    w_star: FloatArray
    nuggets: FloatArray
    extra: float


def gls_observations(
    k: FloatArray, y_star: FloatArray, factor: FloatArray, noise: float
) -> GlsObservations:
    """Eqs. 20–24 for ``A_i = noise I + U_i U_i^T`` by the Woodbury identity.

    Parameters
    ----------
    k
        Basis ``K``, ``(N, p)``. [-]
    y_star
        Standardised observed periods, ``(N, m*)``. [-]
    factor
        ``U_i``, ``(m*, N, r)`` (:attr:`PeriodMoments.factor`); zeros give the
        calibration phase back. [-]
    noise
        ``c = 1 / lambda*``, the observation noise variance. [-]
    """
    n = y_star.shape[0]
    r = factor.shape[2]
    c = float(noise)
    ut = np.swapaxes(factor, 1, 2)  # (m*, r, N)
    m = ut @ factor + c * np.eye(r)  # (m*, r, r)
    ku = k.T[None] @ factor  # (m*, p, r)
    uy = (ut @ y_star.T[:, :, None])[..., 0]  # (m*, r)
    rhs = np.concatenate([np.swapaxes(ku, 1, 2), uy[:, :, None]], axis=2)  # (m*, r, p+1)
    sol = np.linalg.solve(m, rhs)
    h = (k.T @ k)[None] - ku @ sol[:, :, :-1]
    g = (k.T @ y_star).T - (ku @ sol[:, :, -1:])[..., 0]
    yy = np.einsum("ni,ni->i", y_star, y_star) - np.einsum("ir,ir->i", uy, sol[:, :, -1])
    h, g, yy = h / c, g / c, yy / c
    w_star = np.asarray(np.linalg.solve(h, g[:, :, None])[..., 0], dtype=float)  # (m*, p)
    _, logdet_m = np.linalg.slogdet(m / c)
    logdet_a = n * math.log(c) + logdet_m
    quad = yy - np.einsum("ip,ip->i", g, w_star)
    nuggets = 1.0 / np.diagonal(h, axis1=1, axis2=2).T  # (p, m*)
    extra = -0.5 * float(np.sum(logdet_a + quad))
    return GlsObservations(w_star, np.ascontiguousarray(nuggets), extra)


class DeltaTarget:
    """Log density of ``u = theta*`` (normalised) between two updates; picklable.

    ``log p(u) + sum_j log N(v_j; 0, Omega_j)`` with ``Omega_j`` of eq. 19
    (simulator nuggets ``a_j``, observation nuggets ``B_j``) plus the constant of
    eq. 23. Non-positive-definite covariances count as zero density.

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
    """

    def __init__(
        self,
        algebra: CalibrationAlgebra,
        priors: Sequence[Prior],
        a: FloatArray,
        gls: GlsObservations,
    ) -> None:
        self.algebra = algebra
        self.priors = ThetaPriors(tuple(priors))
        self.a = a
        self.nuggets = gls.nuggets
        self.extra = gls.extra

    def __call__(self, u: ArrayLike) -> float:
        """Log density at ``u`` (``(t,)``, normalised theta*)."""
        arr = np.asarray(u, dtype=float)
        prior = self.priors.scalar(arr)
        if prior == -math.inf:
            return prior
        try:
            lik = self.algebra.pieces_nuggets(arr, self.a, self.nuggets).logpdf
        except np.linalg.LinAlgError:
            return -math.inf
        return prior + lik + self.extra


class DeltaPhase:
    """What stays fixed in the discrepancy phase; builds a :class:`DeltaTarget` per update.

    Calling the object gives the log prior of ``u`` (the part of the target that
    does not depend on the empirical moments); :class:`EmpiricalDeltaSampler`
    uses :meth:`update` for the rest. Picklable, for chains in worker processes.

    Parameters
    ----------
    emulator
        The trained emulator (hyperparameters at the MAP).
    y_star
        Standardised observed periods ``Y*``, ``(N, m*)``. [-]
    algebra
        Calibration likelihood back end built with the emulator's kernels.
    priors
        One prior per parameter, in the order of ``u``.
    lam, lam_star
        Fixed precisions ``lambda`` and ``lambda*``. [-]
    realisations
        ``b`` realisations per update (eq. 25).
    """

    def __init__(
        self,
        emulator: Emulator,
        y_star: FloatArray,
        algebra: CalibrationAlgebra,
        priors: Sequence[Prior],
        lam: float,
        lam_star: float,
        realisations: int,
    ) -> None:
        self.emulator = emulator
        self.y_star = np.asarray(y_star, dtype=float)
        self.algebra = algebra
        self.priors = tuple(priors)
        self.theta_priors = ThetaPriors(self.priors)
        self.a = 1.0 / (float(lam) * emulator.basis.ktk)
        self.noise = 1.0 / float(lam_star)
        self.realisations = int(realisations)

    def __call__(self, u: ArrayLike) -> float:
        """Log prior of ``u``."""
        return self.theta_priors.scalar(np.asarray(u, dtype=float))

    def moments(self, u: ArrayLike, rng: np.random.Generator) -> PeriodMoments:
        """Empirical ``Delta_i`` and ``D_i`` (eq. 25) at normalised ``theta* = u``."""
        em = self.emulator
        th = np.broadcast_to(np.asarray(u, dtype=float), (em.x.shape[0], len(self.priors)))
        mean_w, var_w = em.predict_weights(th, em.x)
        return empirical_moments(em.basis.k, self.y_star, mean_w, var_w, self.realisations, rng)

    def update(self, u: ArrayLike, rng: np.random.Generator) -> DeltaTarget:
        """The target after re-estimating ``Delta``, ``A``, ``w*`` and ``B`` at ``u``."""
        mom = self.moments(u, rng)
        gls = gls_observations(self.emulator.basis.k, self.y_star, mom.factor, self.noise)
        return DeltaTarget(self.algebra.with_observations(gls.w_star), self.priors, self.a, gls)


def _segments(n_burn: int, total: int, interval: int) -> list[tuple[int, int]]:
    """``[start, end)`` pieces cut at every multiple of ``interval`` and at ``n_burn``."""
    cuts = sorted({0, n_burn, total, *range(0, total, interval)})
    return [(s, e) for s, e in itertools.pairwise(cuts) if e > s]


@dataclass(frozen=True)
class EmpiricalDeltaSampler:
    """Metropolis-within-Gibbs on ``theta*`` with the paper's periodic update of Delta.

    Segments are cut at every multiple of ``update_interval`` and at ``n_burn``;
    each is one run of :class:`MetropolisWithinGibbs` (logit scale on [0, 1])
    started where the previous one stopped, with the proposal widths it left.
    During burn-in the widths adapt (batches of ``batch_size``; the last sweep
    of a burn-in segment is not adapted); afterwards they are frozen.

    Parameters
    ----------
    n_burn
        Burn-in sweeps (proposal widths adapted, draws discarded).
    update_interval
        Sweeps between two re-estimations of ``Delta``, ``A``, ``w*``, ``B``.
    scales
        Initial proposal widths on the logit scale, one per parameter.
    batch_size
        Sweeps per adaptation batch during burn-in.
    max_adapt
        Cap of the per-batch change of a log proposal width.
    thin
        Always 1 (kept for the progress count of :func:`run_chains`).
    """

    n_burn: int
    update_interval: int
    scales: tuple[float, ...]
    batch_size: int = 25
    max_adapt: float = 0.25
    thin: int = 1

    def run(
        self,
        log_density: LogDensity,
        x0: ArrayLike,
        n_draws: int,
        rng: np.random.Generator,
        callback: Callback | None = None,
    ) -> SamplerResult:
        """Run one chain; ``log_density`` must be a :class:`DeltaPhase`."""
        if not isinstance(log_density, DeltaPhase):
            raise ConfigError(
                f"EmpiricalDeltaSampler needs a DeltaPhase target, got {type(log_density).__name__}"
            )
        rng_state = copy.deepcopy(rng.bit_generator.state)
        x = np.array(x0, dtype=float).reshape(-1)
        scales = np.asarray(self.scales, dtype=float)
        total = self.n_burn + int(n_draws)
        draws: list[FloatArray] = []
        lps: list[FloatArray] = []
        accepted = np.zeros(x.size)
        target: Callable[[FloatArray], float] | None = None
        for start, end in _segments(self.n_burn, total, self.update_interval):
            if target is None or start % self.update_interval == 0:
                target = log_density.update(x, rng)
            burn = start < self.n_burn
            size = end - start
            inner = MetropolisWithinGibbs(
                n_burn=size - 1 if burn else 0,
                lower=[0.0] * x.size,
                upper=[1.0] * x.size,
                scales=scales.tolist(),
                batch_size=self.batch_size,
                max_adapt=self.max_adapt,
            )
            shift = None if callback is None else Offset(callback, start)
            res = inner.run(target, x, 1 if burn else size, rng, callback=shift)
            x = res.draws[-1].copy()
            scales = res.scales
            if not burn:
                draws.append(res.draws)
                lps.append(res.log_density)
                accepted += res.acceptance * size
        return SamplerResult(
            draws=np.concatenate(draws),
            log_density=np.concatenate(lps),
            acceptance=accepted / int(n_draws),
            scales=scales,
            rng_state=rng_state,
            n_burn=self.n_burn,
            thin=1,
        )
