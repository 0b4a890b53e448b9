"""The prior terms of the calibration posterior (eq. 16), in one place.

The sampled vector is ``v = [u_1 .. u_t, lambda, lambda*]``: ``u`` is theta*
on the normalised scale [0, 1] of the prior bounds, with the study's priors
(uniform, or Beta(a, b) on the bounds: :meth:`bayescal.design.Prior.logpdf_unit`);
``lambda`` and ``lambda*`` have Gamma priors built after eq. 7. Up to a
constant the log prior is

    sum_k log p_k(u_k) + (a - 1) log lambda - b lambda + (a* - 1) log lambda* - b* lambda*.

:class:`CalibrationPriors` evaluates it in the three forms the samplers need:
one point (:meth:`~CalibrationPriors.scalar`, with a fast path for uniform
priors), ``B`` points or one coordinate of ``B`` points for chains in lockstep
(:meth:`~CalibrationPriors.batch`, :meth:`~CalibrationPriors.term`), and the
coefficients of the JAX log posterior (:meth:`~CalibrationPriors.beta_coefficients`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

from bayescal.design import (
    BetaPrior,
    LogitNormal,
    PosteriorPrior,
    Prior,
    UniformPrior,
    log_gamma,
    log_gamma_array,
)
from bayescal.emulator.noise import DELTA_RANGE, PHI_MAX
from bayescal.errors import ConfigError

__all__ = ["CalibrationPriors", "ThetaPriors"]

FloatArray = NDArray[np.float64]
_INF = math.inf


@dataclass(frozen=True)
class ThetaPriors:
    """Priors of ``u = theta*`` on the normalised scale, one per parameter.

    Parameters
    ----------
    priors
        One prior per calibration parameter, in the order of ``u``.
    """

    priors: tuple[Prior, ...]
    is_uniform: tuple[bool, ...] = field(init=False, repr=False, compare=False)
    joints: tuple[tuple[LogitNormal, tuple[int, ...]], ...] = field(
        init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        object.__setattr__(self, "priors", tuple(self.priors))
        # a PosteriorPrior's coordinate is checked against its bounds here, and the
        # joint density of its group is added once (joint_term)
        object.__setattr__(
            self,
            "is_uniform",
            tuple(type(p) in (UniformPrior, PosteriorPrior) for p in self.priors),
        )
        groups: dict[LogitNormal, dict[int, int]] = {}
        for k, p in enumerate(self.priors):
            if isinstance(p, PosteriorPrior):
                groups.setdefault(p.joint, {})[p.index] = k
        joints = []
        for joint, places in groups.items():
            if sorted(places) != list(range(len(joint.names))):
                raise ConfigError(
                    f"the prior from {joint.source or 'a previous posterior'} covers "
                    f"{', '.join(joint.names)}: every one of them needs its share"
                )
            joints.append((joint, tuple(places[i] for i in range(len(joint.names)))))
        object.__setattr__(self, "joints", tuple(joints))

    def joint_term(self, u: ArrayLike) -> FloatArray:
        """The joint densities of previous posteriors at the rows of ``u`` ``(B, >= t)``."""
        arr = np.atleast_2d(np.asarray(u, dtype=float))
        total = np.zeros(arr.shape[0])
        for joint, columns in self.joints:
            total += joint.logpdf_unit(arr[:, list(columns)])
        return total

    def scalar(self, u: ArrayLike, start: float = 0.0) -> float:
        """``start + sum_k log p_k(u_k)`` at one point (``-inf`` outside the support)."""
        arr = np.asarray(u, dtype=float)
        total = start
        for k, (prior, uniform) in enumerate(zip(self.priors, self.is_uniform, strict=True)):
            if total == -_INF:
                break
            if uniform:  # the common case, without numpy's overhead
                total += 0.0 if 0.0 <= float(arr[k]) <= 1.0 else -_INF
            else:
                total += float(prior.logpdf_unit(arr[k]))
        if self.joints and total > -_INF:
            total += float(self.joint_term(arr[None, : len(self.priors)])[0])
        return total

    def batch(self, u: FloatArray) -> FloatArray:
        """``sum_k log p_k(u_k)`` per row of ``u`` ``(B, t)`` (``-inf`` outside the support)."""
        total = np.zeros(u.shape[0])
        for k, (prior, uniform) in enumerate(zip(self.priors, self.is_uniform, strict=True)):
            if uniform:
                total += np.where((u[:, k] >= 0.0) & (u[:, k] <= 1.0), 0.0, -_INF)
            else:
                total += np.asarray(prior.logpdf_unit(u[:, k]), dtype=float)
        if self.joints:
            total += self.joint_term(u)
        return total


@dataclass(frozen=True)
class CalibrationPriors:
    """Priors of ``[u_1 .. u_t, lambda, lambda*_1 .. lambda*_O, phi_1 .. phi_A]``.

    ``O`` is the number of calibrated outputs (one observation precision each),
    ``A`` the number with AR(1) errors (one coefficient each, uniform on
    ``(-PHI_MAX, PHI_MAX)``; :mod:`bayescal.emulator.noise`). One white output
    gives the paper's ``[u, lambda, lambda*]``.

    Parameters
    ----------
    theta
        One prior per calibration parameter, in the order of ``u``.
    lam
        ``(shape, rate)`` of the Gamma prior of ``lambda``.
    lam_star
        ``(shape, rate)`` of the Gamma prior of ``lambda*``, or one such pair per output.
    n_phi
        Number of AR(1) coefficients ``A``.
    n_delta
        Number of model-discrepancy relative variances ``D`` (after the ``phi``;
        log-uniform on :data:`~bayescal.emulator.noise.DELTA_RANGE`).
    """

    theta: tuple[Prior, ...]
    lam: tuple[float, float]
    lam_star: Any
    n_phi: int = 0
    n_delta: int = 0
    lam_stars: tuple[tuple[float, float], ...] = field(init=False, repr=False, compare=False)
    theta_priors: ThetaPriors = field(init=False, repr=False, compare=False)
    uniform: tuple[int, ...] = field(init=False, repr=False, compare=False)
    is_uniform: tuple[bool, ...] = field(init=False, repr=False, compare=False)
    shape: FloatArray = field(init=False, repr=False, compare=False)
    rate: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "theta", tuple(self.theta))
        lam = (float(self.lam[0]), float(self.lam[1]))
        pairs = self.lam_star
        if len(pairs) == 2 and np.ndim(pairs[0]) == 0:
            pairs = (pairs,)
        stars = tuple((float(a), float(b)) for a, b in pairs)
        object.__setattr__(self, "lam", lam)
        object.__setattr__(self, "lam_stars", stars)
        object.__setattr__(self, "lam_star", stars[0])
        theta = ThetaPriors(self.theta)
        object.__setattr__(self, "theta_priors", theta)
        is_uniform = theta.is_uniform
        object.__setattr__(self, "is_uniform", is_uniform)
        object.__setattr__(self, "uniform", tuple(k for k, u in enumerate(is_uniform) if u))
        gammas = (lam, *stars)
        object.__setattr__(self, "shape", np.array([g[0] for g in gammas]))
        object.__setattr__(self, "rate", np.array([g[1] for g in gammas]))

    @property
    def t(self) -> int:
        """Number of calibration parameters."""
        return len(self.theta)

    @property
    def n_outputs(self) -> int:
        """Number of observation precisions ``O``."""
        return len(self.lam_stars)

    @property
    def d(self) -> int:
        """Length of the sampled vector ``t + 1 + O + A + D``."""
        return self.t + 1 + self.n_outputs + self.n_phi + self.n_delta

    # ------------------------------------------------------------ one point

    def scalar(self, v: ArrayLike) -> float:
        """Log prior of ``v = [u, lambda, lambda*.., phi..]`` (up to a constant)."""
        arr = np.asarray(v, dtype=float)
        t = self.t
        total = log_gamma(float(arr[t]), *self.lam)
        for q, pair in enumerate(self.lam_stars):
            total += log_gamma(float(arr[t + 1 + q]), *pair)
        start = t + 1 + self.n_outputs
        if self.n_phi:
            phi = arr[start : start + self.n_phi]
            if not np.all(np.abs(phi) < PHI_MAX):
                return -_INF
        if self.n_delta:
            rel = arr[start + self.n_phi :]
            if not np.all((rel >= DELTA_RANGE[0]) & (rel <= DELTA_RANGE[1])):
                return -_INF
            total -= float(np.sum(np.log(rel)))
        return self.theta_priors.scalar(arr, total)

    # ------------------------------------------------------------ B points

    def term(self, column: FloatArray, k: int) -> FloatArray:
        """Log prior of coordinate ``k`` at the values ``column`` ``(B,)`` (a coordinate
        of a previous posterior's joint density: its bounds; :meth:`joint_term` the rest)."""
        t = self.t
        if k >= t + 1 + self.n_outputs + self.n_phi:
            inside = (column >= DELTA_RANGE[0]) & (column <= DELTA_RANGE[1])
            return np.where(inside, -np.log(np.where(inside, column, 1.0)), -_INF)
        if k >= t + 1 + self.n_outputs:
            return np.where(np.abs(column) < PHI_MAX, 0.0, -_INF)
        if k >= t:
            return log_gamma_array(column, float(self.shape[k - t]), float(self.rate[k - t]))
        if self.is_uniform[k]:
            if column.min() >= 0.0 and column.max() <= 1.0:
                return np.zeros(column.shape)
            return np.where((column >= 0.0) & (column <= 1.0), 0.0, -_INF)
        return np.asarray(self.theta[k].logpdf_unit(column), dtype=float)

    def batch(self, points: FloatArray) -> FloatArray:
        """Log prior density per row of ``points`` ``(B, d)`` (up to a constant)."""
        t = self.t
        n_prec = 1 + self.n_outputs
        prec = points[:, t : t + n_prec]
        if prec.min() > 0.0:  # one call; the other branch sums the columns in order
            total = log_gamma_array(prec, self.shape, self.rate).sum(axis=1)
        else:
            total = log_gamma_array(prec[:, 0], float(self.shape[0]), float(self.rate[0]))
            for q in range(1, n_prec):
                total += log_gamma_array(prec[:, q], float(self.shape[q]), float(self.rate[q]))
        if self.n_phi:
            phi = points[:, t + n_prec : t + n_prec + self.n_phi]
            total = np.where((np.abs(phi) < PHI_MAX).all(axis=1), total, -_INF)
        for k in range(t + n_prec + self.n_phi, self.d):
            total = total + self.term(points[:, k], k)
        if self.uniform:
            u = points[:, list(self.uniform)]
            inside = ((u >= 0.0) & (u <= 1.0)).all(axis=1)
            if not inside.all():
                total[~inside] = -_INF
        for k, prior in enumerate(self.theta):
            if not self.is_uniform[k]:
                total += np.asarray(prior.logpdf_unit(points[:, k]), dtype=float)
        if self.theta_priors.joints:
            total = total + self.theta_priors.joint_term(points[:, : self.t])
        out: FloatArray = total
        return out

    def joint_term(self, points: FloatArray) -> FloatArray:
        """The part of the log prior that :meth:`term` leaves out: the joint densities
        of previous posteriors (:class:`~bayescal.design.PosteriorPrior`), ``(B,)``."""
        if not self.theta_priors.joints:
            return np.zeros(points.shape[0])
        return self.theta_priors.joint_term(points[:, : self.t])

    # ------------------------------------------------------------ JAX

    def beta_coefficients(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The theta priors as ``a1 log u + b1 log(1 - u) + const`` per parameter.

        Uniform priors give ``(0, 0, 0)``, Beta(a, b) ``(a - 1, b - 1, -log B(a, b))``.

        Raises
        ------
        ConfigError
            For another prior family (the JAX log posterior knows only these two).
        """
        n = self.t
        a1, b1, const = np.zeros(n), np.zeros(n), np.zeros(n)
        for k, prior in enumerate(self.theta):
            if isinstance(prior, BetaPrior):
                a1[k], b1[k] = prior.a - 1.0, prior.b - 1.0
                const[k] = -float(special.betaln(prior.a, prior.b))
            elif not isinstance(prior, UniformPrior):
                raise ConfigError(
                    f"sampler 'nuts' supports uniform and beta priors, got {type(prior).__name__}",
                    hint="use sampler 'mwg' for other priors",
                )
        return a1, b1, const
