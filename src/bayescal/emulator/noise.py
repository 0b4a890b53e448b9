"""Observation error models of the calibrated outputs: the observation block of eq. 16.

Each calibrated output ``o`` (rows ``r_o`` of the stacked standardised outputs,
``n_o`` samples per period, basis vectors ``B_o`` of the block-diagonal ``K``)
is measured with an error that is independent between periods and outputs:

    y*_{o,i} = K_o w*(theta*, x_i) + e_{o,i},   e_{o,i} ~ N(0, R_o(phi_o) / lambda*_o),

``R = I`` for white noise (the paper) or the AR(1) correlation ``R_ab =
phi^|a - b|`` within a period (residuals of a dynamic model drift slowly: the
Twin House's have a lag-1 autocorrelation of 0.83). ``lambda*_o`` is a
precision in standardised units: the noise's standard deviation in the
output's unit is ``s_o / sqrt(lambda*_o)`` with ``s_o`` the output's scale
(:func:`bayescal.emulator.basis.standardise`, ``scale="output"``).

For any ``R`` the Gaussian density of a period factorises exactly into a part
that sees theta* only through the weights and a remainder (method.md, "Noise
and correlated residuals"): with ``H0 = K_o^T R^-1 K_o`` and the generalised
least-squares weights ``w_hat = H0^-1 K_o^T R^-1 y``,

    log N(y; K w, R / lambda*) = log N(w_hat; w, H0^-1 / lambda*)
        - 1/2 [(n - p) log 2 pi - (n - p) log lambda* + log |R| + log |H0|
               + lambda* y^T C0 y],    C0 = R^-1 - R^-1 K H0^-1 K^T R^-1.

With white noise ``H0 = diag(k_j^T k_j)`` (the GPMSA basis is orthogonal), the
first factor is the per-basis observation nugget of eq. 14 and the remainder
is eq. 7 applied to ``Y*``: the Gamma prior of ``lambda*`` updated with shape
``m* (n - p) / 2`` and rate ``RSS* / 2``. With AR(1) noise ``H0`` is full: the
observed block couples an output's ``p_o`` weights within a period
(:meth:`bayescal.calibration.kron.KronCalibrationDensity.pieces_grouped`), the
weights ``w_hat`` move with ``phi`` and the remainder is evaluated explicitly.
AR(1) products go through the prewhitening map ``z_1 = y_1``, ``z_t = (y_t -
phi y_{t-1}) / sqrt(1 - phi^2)`` (``y^T R^-1 y = z^T z``, ``log |R| = (n - 1)
log(1 - phi^2)``): ``O(n p)`` per period.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg

from bayescal.emulator.kernel import LOG_2PI, FloatArray
from bayescal.errors import ConfigError, DataError

__all__ = [
    "DEFAULT_NOISE_PRIOR",
    "DISCREPANCY_PARTS",
    "RELATIVE_UNIT",
    "ErrorModel",
    "GlsPieces",
    "LogLevel",
    "ObservationModel",
    "OutputNoise",
    "ar1_whiten",
    "noise_prior_from_sd",
]

ErrorModel = Literal["white", "ar1"]

#: Gamma(shape, rate) of ``lambda*`` (standardised units) when the study states
#: no sensor accuracy: with the scale of "output" standardisation, its density of
#: ``log sigma`` is flat (within 1 %) from ``sigma = 1e-3 s`` up: the data decide.
DEFAULT_NOISE_PRIOR = (0.5, 1e-6)

#: Largest ``|phi|`` of an AR(1) error (the correlation matrix must stay invertible).
PHI_MAX = 0.999
#: Range of the relative variance ``r`` of a model discrepancy (log-uniform prior):
#: from negligible to as large as the emulator's prior variance of a weight.
#: "Negligible" is judged against the observed weights' noise, ``1 / (lambda* k^T k)``,
#: about 1e-6 of a weight's variance with a few hundred samples a period: a floor of
#: 1e-4 (until 2026-11-27) was not, and held a part the data did not want (the
#: free-float box's discrepancy of each day's own piled up there, its left-out bands
#: covering 0.999 / 0.661).
DELTA_RANGE = (1e-8, 1.0)

DeltaCoordinate = Literal["delta_rel", "delta_ind"]
DiscrepancyKind = Literal["conditions", "independent", "both", "orthogonal"]

#: The variance coordinates of each kind of in-likelihood discrepancy:
#: ``delta_rel`` scales the GP over the periods' conditions, ``delta_ind`` the
#: part independent from period to period. ``"orthogonal"`` is the GP over the
#: conditions constrained orthogonal to the model's sensitivities (Plumlee 2017,
#: :mod:`bayescal.calibration.orthogonal`).
DISCREPANCY_PARTS: dict[str, tuple[DeltaCoordinate, ...]] = {
    "conditions": ("delta_rel",),
    "independent": ("delta_ind",),
    "both": ("delta_rel", "delta_ind"),
    "orthogonal": ("delta_rel",),
}


#: The unit of an output with relative errors: its noise SD is a fraction of the level.
RELATIVE_UNIT = "relative"


@dataclass(frozen=True)
class LogLevel:
    """Errors proportional to the level: an output calibrated on ``z = log(y + floor)``.

    A meter accurate to 3 % has an error SD of 3 % of what it reads; on
    ``z`` that error is additive with SD ~0.03 whatever the level, which is
    what the error models of this module assume. ``floor`` (> 0, the output's
    unit) keeps zero readings finite and is the level below which the error
    stops shrinking. Bands computed on ``z`` map back exactly (quantiles
    commute with a monotone map); a Gaussian on ``z`` has the mean
    ``exp(mu + v/2) - floor`` on ``y``. Densities of ``y`` are those of ``z``
    plus the log-Jacobian ``-sum log(y + floor)`` (:meth:`log_jacobian`), so
    that variants with and without relative errors compare in the
    measurements' own units.
    """

    floor: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.floor) and self.floor > 0.0):
            raise ConfigError(f"the floor of relative errors must be > 0, got {self.floor!r}")

    def forward(self, y: ArrayLike, what: str = "values") -> FloatArray:
        """``log(y + floor)``; NaN stays NaN.

        Raises
        ------
        DataError
            Where ``y + floor <= 0`` (relative errors need a non-negative level).
        """
        arr = np.asarray(y, dtype=float)
        shifted = arr + self.floor
        bad = np.isfinite(shifted) & ~(shifted > 0.0)
        if bad.any():
            low = float(arr[bad].min())
            raise DataError(
                f"{what}: relative errors need values above -floor ({-self.floor:.6g}), "
                f"found {low:.6g}",
                hint="relative errors suit non-negative outputs (meters); use absolute "
                "errors here, or raise [outputs.errors.NAME] floor",
            )
        with np.errstate(invalid="ignore"):
            out: FloatArray = np.log(shifted)
        return out

    def inverse(self, z: ArrayLike) -> FloatArray:
        """``exp(z) - floor``."""
        out: FloatArray = np.exp(np.asarray(z, dtype=float)) - self.floor
        return out

    def mean(self, mu: ArrayLike, var: ArrayLike) -> FloatArray:
        """Mean on ``y`` of a Gaussian ``N(mu, var)`` on ``z``."""
        m = np.asarray(mu, dtype=float)
        out: FloatArray = np.exp(m + 0.5 * np.asarray(var, dtype=float)) - self.floor
        return out

    def log_jacobian(self, y: ArrayLike) -> FloatArray:
        """``log |dz/dy| = -log(y + floor)`` per value (added to a density of ``z``)."""
        out: FloatArray = -np.log(np.asarray(y, dtype=float) + self.floor)
        return out


def ar1_whiten(y: FloatArray, phi: float) -> FloatArray:
    """The prewhitening map of AR(1) noise along axis 0 (``y^T R^-1 y = z^T z``).

    Parameters
    ----------
    y
        Series within a period along axis 0, ``(n, ...)``. [-]
    phi
        AR(1) coefficient, ``|phi| < 1``. [-]
    """
    z = np.array(y, dtype=float, copy=True)
    if phi != 0.0:
        z[1:] = (y[1:] - phi * y[:-1]) / math.sqrt(1.0 - phi * phi)
    return z


@dataclass(frozen=True)
class OutputNoise:
    """The observation error model of one calibrated output.

    Parameters
    ----------
    name
        Output name (glossary).
    rows
        ``(start, stop)`` of its rows in the stacked standardised outputs.
    bases
        Its basis vectors (columns of ``K``).
    model
        ``"white"`` or ``"ar1"``.
    prior
        Gamma ``(shape, rate)`` of ``lambda*`` before the data. [-]
    scale
        Physical units per standardised unit (the output's scale ``s_o``). [unit]
    unit
        The output's unit, for reports.
    discrepancy
        Whether the observed weights of this output also carry a model
        discrepancy (Kennedy and O'Hagan's ``delta(x)`` inside the likelihood;
        the paper's difference process is separate), and which: ``"conditions"``
        (or ``True``) a GP ``GP(0, r tau_j^-1 c_x)`` over the periods'
        conditions, ``"independent"`` one independent from period to period
        (covariance ``r_0 tau_j^-1`` within a period, none between periods),
        ``"both"`` their sum, each relative variance sampled (coordinates
        ``delta_rel`` and ``delta_ind``), ``"orthogonal"`` the GP over the
        conditions constrained orthogonal to the model's sensitivities in theta*
        (Plumlee 2017; coordinate ``delta_rel``); ``False``: none.
    """

    name: str
    rows: tuple[int, int]
    bases: tuple[int, ...]
    model: ErrorModel = "white"
    prior: tuple[float, float] = DEFAULT_NOISE_PRIOR
    scale: float = 1.0
    unit: str = ""
    discrepancy: bool | DiscrepancyKind = False

    def __post_init__(self) -> None:
        if self.model not in ("white", "ar1"):
            raise ConfigError(f"error model must be 'white' or 'ar1', got {self.model!r}")
        if self.discrepancy is True:
            object.__setattr__(self, "discrepancy", "conditions")
        elif self.discrepancy not in (False, *DISCREPANCY_PARTS):
            raise ConfigError(
                f"discrepancy must be true, false or one of {', '.join(DISCREPANCY_PARTS)}, "
                f"got {self.discrepancy!r}"
            )
        shape, rate = self.prior
        if not (math.isfinite(shape) and shape > 0.0 and math.isfinite(rate) and rate > 0.0):
            raise ConfigError(
                f"the noise prior of {self.name!r} needs a finite shape and rate > 0, "
                f"got {self.prior!r}"
            )
        if not self.bases:
            raise DataError(f"output {self.name!r} has no basis vector")

    @property
    def n(self) -> int:
        """Samples per period ``n_o``."""
        return self.rows[1] - self.rows[0]

    @property
    def p(self) -> int:
        """Basis vectors ``p_o``."""
        return len(self.bases)

    @property
    def delta_parts(self) -> tuple[DeltaCoordinate, ...]:
        """The discrepancy's variance coordinates: ``delta_rel`` (over the conditions)
        and/or ``delta_ind`` (independent between periods), in that order."""
        return DISCREPANCY_PARTS.get(str(self.discrepancy), ()) if self.discrepancy else ()


@dataclass(frozen=True)
class GlsPieces:
    """The observed weights and remainder terms of one output at one ``phi``.

    Attributes
    ----------
    w_hat
        Generalised least-squares weights ``(m*, p_o)``. [-]
    h0_inv
        ``(K_o^T R^-1 K_o)^-1`` ``(p_o, p_o)``: times ``1 / lambda*`` the noise
        block of a period's weights. [-]
    logdet_r, logdet_h0
        ``log |R|`` and ``log |H0|`` (per period).
    quad0
        ``sum_i y_i^T C0 y_i`` over the periods.
    """

    w_hat: FloatArray
    h0_inv: FloatArray
    logdet_r: float
    logdet_h0: float
    quad0: float


@dataclass(frozen=True)
class _Lags:
    """``A_z^T B_z`` of two prewhitened series as a function of ``phi``.

    With ``z_1 = a_1`` and ``z_t = (a_t - phi a_{t-1}) / sqrt(1 - phi^2)``,
    ``A_z^T B_z = F + (S_0 - phi S_1 + phi^2 S_2) / (1 - phi^2)`` where ``F`` is
    the first samples' product and ``S_0, S_1, S_2`` the lag-0, symmetric lag-1
    and shifted lag-0 sums over samples 2..n.
    """

    first: FloatArray
    s0: FloatArray
    s1: FloatArray
    s2: FloatArray

    @classmethod
    def of(cls, a: FloatArray, b: FloatArray) -> _Lags:
        """From series ``a`` ``(n, .)`` and ``b`` ``(n, .)`` along axis 0."""
        return cls(
            np.outer(a[0], b[0]),
            a[1:].T @ b[1:],
            a[1:].T @ b[:-1] + a[:-1].T @ b[1:],
            a[:-1].T @ b[:-1],
        )

    def at(self, phi: float) -> FloatArray:
        """``A_z^T B_z`` at ``phi``."""
        out: FloatArray = self.first + (self.s0 - phi * self.s1 + phi * phi * self.s2) / (
            1.0 - phi * phi
        )
        return out


@dataclass(frozen=True)
class _LagSums:
    """What the GLS of one output needs at any ``phi`` (:meth:`ObservationModel.gls`)."""

    kk: _Lags  # K^T R^-1 K (p_o, p_o)
    ky: _Lags  # K^T R^-1 Y (p_o, m*)
    yy: _Lags  # sum over the periods of y^T R^-1 y (1, 1)
    n: int

    @classmethod
    def of(cls, ko: FloatArray, yo: FloatArray) -> _LagSums:
        """From the output's basis ``(n_o, p_o)`` and periods ``(n_o, m*)``."""
        y = yo.reshape(yo.shape[0], -1)
        yy = _Lags(
            np.array([[np.sum(y[0] * y[0])]]),
            np.array([[np.sum(y[1:] * y[1:])]]),
            np.array([[2.0 * np.sum(y[1:] * y[:-1])]]),
            np.array([[np.sum(y[:-1] * y[:-1])]]),
        )
        return cls(_Lags.of(ko, ko), _Lags.of(ko, y), yy, ko.shape[0])


@dataclass(frozen=True)
class ObservationModel:
    """Every calibrated output's error model with the measured periods it applies to.

    Parameters
    ----------
    outputs
        One :class:`OutputNoise` per output, in stacking order.
    k
        The basis ``K`` ``(N, p)`` (block diagonal over the outputs). [-]
    y_star
        Standardised measured periods ``(N, m*)``. [-]
    """

    outputs: tuple[OutputNoise, ...]
    k: FloatArray
    y_star: FloatArray
    _ktk: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "outputs", tuple(self.outputs))
        n, p = self.k.shape
        if self.y_star.shape[0] != n:
            raise DataError(f"Y* has {self.y_star.shape[0]} rows, K has {n}")
        covered = sorted(j for o in self.outputs for j in o.bases)
        if covered != list(range(p)):
            raise DataError(f"the outputs' bases {covered} do not cover the {p} basis vectors")
        for o in self.outputs:
            outside = np.delete(self.k[:, list(o.bases)], np.s_[o.rows[0] : o.rows[1]], axis=0)
            if np.any(outside != 0.0):
                raise DataError(f"basis vectors of {o.name!r} reach rows of another output")
        object.__setattr__(self, "_ktk", np.einsum("ij,ij->j", self.k, self.k))

    # ------------------------------------------------------------ layout

    @property
    def n_outputs(self) -> int:
        """Number of outputs ``O`` (and of ``lambda*`` coordinates)."""
        return len(self.outputs)

    @cached_property
    def ar_outputs(self) -> tuple[int, ...]:
        """Indices of the outputs with AR(1) errors (one ``phi`` coordinate each)."""
        return tuple(q for q, o in enumerate(self.outputs) if o.model == "ar1")

    @cached_property
    def delta_outputs(self) -> tuple[int, ...]:
        """Indices of the outputs with a model discrepancy (one or two ``r`` coordinates)."""
        return tuple(q for q, o in enumerate(self.outputs) if o.discrepancy)

    @cached_property
    def orthogonal_outputs(self) -> tuple[int, ...]:
        """Indices of the outputs whose discrepancy is orthogonal (Plumlee 2017)."""
        return tuple(q for q, o in enumerate(self.outputs) if o.discrepancy == "orthogonal")

    @property
    def delta_over_conditions(self) -> bool:
        """Whether some output's discrepancy has a part over the periods' conditions."""
        return any(kind == "delta_rel" for kind, _ in self.delta_coordinates)

    @cached_property
    def delta_coordinates(self) -> tuple[tuple[DeltaCoordinate, int], ...]:
        """``(kind, output)`` of every discrepancy variance coordinate, in order."""
        return tuple((kind, q) for q in self.delta_outputs for kind in self.outputs[q].delta_parts)

    @cached_property
    def _lag_sums(self) -> dict[int, _LagSums]:
        """The lag sums of each output :meth:`gls` has seen (filled on first use)."""
        return {}

    @property
    def coupled(self) -> bool:
        """Whether some output's observed weights are coupled (AR(1) errors)."""
        return bool(self.ar_outputs)

    @cached_property
    def group_of_basis(self) -> tuple[int, ...]:
        """The output of every basis vector ``(p,)``."""
        out = [0] * self.k.shape[1]
        for q, o in enumerate(self.outputs):
            for j in o.bases:
                out[j] = q
        return tuple(out)

    def names(self) -> tuple[str, ...]:
        """Coordinate names of the precisions, AR coefficients and discrepancy variances."""
        lam = [self.coordinate("lambda_star", q) for q in range(self.n_outputs)]
        phi = [self.coordinate("phi", q) for q in self.ar_outputs]
        rel = [self.coordinate(kind, q) for kind, q in self.delta_coordinates]
        return (*lam, *phi, *rel)

    def coordinate(
        self, kind: Literal["lambda_star", "phi", "delta_rel", "delta_ind"], q: int
    ) -> str:
        """Name of output ``q``'s ``lambda*``, AR(1) ``phi`` or discrepancy ``r`` coordinate."""
        if kind == "phi" and q not in self.ar_outputs:
            raise ValueError(f"output {self.outputs[q].name!r} has no AR(1) errors")
        if kind in ("delta_rel", "delta_ind") and kind not in self.outputs[q].delta_parts:
            raise ValueError(f"output {self.outputs[q].name!r} has no {kind} discrepancy part")
        return kind if self.n_outputs == 1 else f"{kind}_{self.outputs[q].name}"

    def discrepancy_variances(
        self, rel: ArrayLike, variances: ArrayLike
    ) -> tuple[FloatArray | None, FloatArray | None]:
        """Per-basis discrepancy variances ``r tau_j^-1`` ``(p,)`` of the two parts.

        Parameters
        ----------
        rel
            The discrepancy coordinates, in the order of :attr:`delta_coordinates`. [-]
        variances
            ``1 / tau_j`` of every basis ``(p,)``. [-]

        Returns
        -------
        over_conditions, independent
            The part over the periods' conditions (``delta_rel``) and the part
            independent between periods (``delta_ind``); ``None`` where no output
            has that part.
        """
        values = np.asarray(rel, dtype=float).reshape(-1)
        var = np.asarray(variances, dtype=float)
        if values.size != len(self.delta_coordinates):
            raise ValueError(
                f"expected {len(self.delta_coordinates)} discrepancy coordinates, got {values.size}"
            )
        parts: dict[str, FloatArray] = {}
        for (kind, q), r in zip(self.delta_coordinates, values, strict=True):
            bases = list(self.outputs[q].bases)
            out = parts.setdefault(kind, np.zeros(var.size))
            out[bases] = r * var[bases]
        return parts.get("delta_rel"), parts.get("delta_ind")

    # ------------------------------------------------------------ white outputs

    def block(self, q: int) -> tuple[FloatArray, FloatArray]:
        """``K_o`` ``(n_o, p_o)`` and ``Y*_o`` ``(n_o, m*)`` of output ``q``."""
        o = self.outputs[q]
        rows = slice(*o.rows)
        return self.k[rows][:, list(o.bases)], self.y_star[rows]

    def white_prior(self, q: int) -> tuple[float, float]:
        """Gamma of ``lambda*`` of white output ``q`` after eq. 7 (its prior and the RSS)."""
        o = self.outputs[q]
        ko, yo = self.block(q)
        w = linalg.solve(ko.T @ ko, ko.T @ yo, assume_a="pos")
        resid = yo - ko @ w
        m = yo.shape[1]
        return (
            o.prior[0] + 0.5 * m * (o.n - o.p),
            o.prior[1] + 0.5 * float(np.sum(resid * resid)),
        )

    def ls_weights(self) -> FloatArray:
        """Least-squares weights of every period ``(m*, p)`` (eq. 13)."""
        gram = self.k.T @ self.k
        return np.asarray(linalg.solve(gram, self.k.T @ self.y_star, assume_a="pos").T)

    def white_nuggets(self, lam_star: ArrayLike) -> FloatArray:
        """Per-basis observation nuggets ``1 / (lambda*_o k_j^T k_j)`` ``(p,)``."""
        lam = np.asarray(lam_star, dtype=float)[list(self.group_of_basis)]
        out: FloatArray = 1.0 / (self._ktk * lam)
        return out

    # ------------------------------------------------------------ AR(1) outputs

    def gls(self, q: int, phi: float) -> GlsPieces:
        """Generalised least squares of output ``q`` under AR(1) errors with ``phi``.

        From the lag sums of ``K_o`` and ``Y*_o`` (:class:`_LagSums`, computed once):
        ``K_o^T R^-1 K_o``, ``K_o^T R^-1 Y*_o`` and the periods' ``y^T R^-1 y`` at any
        ``phi`` in ``O(p_o^2 + p_o m*)``, the same as prewhitening (:func:`ar1_whiten`)
        up to rounding; an AR(1) coefficient's move then costs no pass over the samples.
        """
        if not abs(phi) < 1.0:
            raise ValueError(f"AR(1) coefficient must satisfy |phi| < 1, got {phi}")
        sums = self._lag_sums.get(q)
        if sums is None:
            sums = self._lag_sums[q] = _LagSums.of(*self.block(q))
        h0 = sums.kk.at(phi)
        kty = sums.ky.at(phi)  # (p_o, m*)
        chol = linalg.cho_factor(h0, lower=True, check_finite=False)
        w_hat = linalg.cho_solve(chol, kty, check_finite=False)  # (p_o, m*)
        # y^T R^-1 y - (K^T R^-1 y)^T w: the whitened residuals' sum of squares
        quad0 = sums.yy.at(phi).item() - float(np.vdot(kty, w_hat))
        return GlsPieces(
            w_hat=np.ascontiguousarray(w_hat.T),
            h0_inv=linalg.cho_solve(chol, np.eye(h0.shape[0]), check_finite=False),
            logdet_r=(sums.n - 1) * math.log1p(-phi * phi),
            logdet_h0=2.0 * float(np.sum(np.log(np.diag(chol[0])))),
            quad0=max(quad0, 0.0),
        )

    def weights_of(self, q: int, y: FloatArray, phi: float = 0.0) -> FloatArray:
        """The observed-weight estimate of output ``q`` applied to other periods ``y``.

        ``(m', p_o)`` from standardised periods ``y`` ``(n_o, m')``: least squares
        for white errors, generalised least squares with ``phi`` for AR(1) ones (the
        same linear map that gives ``w_hat`` of the measurements, so the difference
        of two such weights is the weights of the difference).
        """
        kz = self._whitened_basis(q, phi)
        yz = ar1_whiten(y, phi) if self.outputs[q].model == "ar1" else np.asarray(y, dtype=float)
        w = linalg.solve(kz.T @ kz, kz.T @ yz, assume_a="pos")
        return np.ascontiguousarray(np.asarray(w, dtype=float).T)

    def precision_given(self, q: int, resid: FloatArray) -> tuple[float, float]:
        """Gamma ``(shape, rate)`` of ``lambda*`` of output ``q`` given known residuals.

        ``resid`` ``(n_o, m')`` are standardised residuals of whole periods (the
        measurement minus a model known exactly there, e.g. the simulator re-run
        at a posterior draw); a period with a missing value is left out. The
        output's prior is updated with shape ``n_o m' / 2`` and rate
        ``resid^T resid / 2``, whatever the error model: the mean square is an
        unbiased estimate of the marginal variance ``1/lambda*`` (``R`` has a
        unit diagonal) whatever the residuals' correlation.
        """
        o = self.outputs[q]
        r = np.asarray(resid, dtype=float)
        r = r[:, np.all(np.isfinite(r), axis=0)]
        return o.prior[0] + 0.5 * r.size, o.prior[1] + 0.5 * float(np.sum(r * r))

    def precision_out_of_basis(
        self, q: int, resid: FloatArray, phi: float = 0.0
    ) -> tuple[float, float]:
        """Gamma ``(shape, rate)`` of ``lambda*`` of output ``q`` from what its basis leaves
        of known residuals.

        ``resid`` ``(n_o, m')`` as in :meth:`precision_given`. An output with an
        in-likelihood discrepancy holds it on its basis weights, so the part of a
        residual outside the basis (after prewhitening with ``phi`` for AR(1)
        errors) is noise alone: ``(I - P) z`` with ``z`` the whitened residual and
        ``P`` the projection on the whitened basis has covariance
        ``(I - P) / lambda*``, which updates the prior with shape
        ``m' (n_o - p_o) / 2`` and rate ``|(I - P) z|^2 / 2``, whatever the
        discrepancy (the calibration's remainder term, :meth:`remainder`).
        """
        o = self.outputs[q]
        r = np.asarray(resid, dtype=float)
        r = r[:, np.all(np.isfinite(r), axis=0)]
        kz = self._whitened_basis(q, phi)
        z = ar1_whiten(r, phi) if o.model == "ar1" else r
        w = linalg.lstsq(kz, z)[0]
        e = z - kz @ w
        return o.prior[0] + 0.5 * r.shape[1] * (o.n - o.p), o.prior[1] + 0.5 * float(np.sum(e * e))

    def noise_block(self, q: int, lam_star: float, phi: float = 0.0) -> FloatArray:
        """Covariance ``(p_o, p_o)`` of one period's observed-weight errors of output ``q``.

        ``(K_o^T R^-1 K_o)^-1 / lambda*`` (``R = I`` for white errors).
        """
        kz = self._whitened_basis(q, phi)
        out: FloatArray = np.asarray(np.linalg.inv(kz.T @ kz), dtype=float) / lam_star
        return out

    def _whitened_basis(self, q: int, phi: float) -> FloatArray:
        """``K_o`` of output ``q``, prewhitened with ``phi`` for AR(1) errors."""
        ko = self.block(q)[0]
        return ar1_whiten(ko, phi) if self.outputs[q].model == "ar1" else ko

    def remainder(self, q: int, pieces: GlsPieces, lam_star: float) -> float:
        """The remainder of output ``q``'s density summed over the periods (module docstring)."""
        o = self.outputs[q]
        m = self.y_star.shape[1]
        dof = m * (o.n - o.p)
        return -0.5 * (
            dof * (LOG_2PI - math.log(lam_star))
            + m * (pieces.logdet_r + pieces.logdet_h0)
            + lam_star * pieces.quad0
        )

    def noise_sd(self, lam_star: ArrayLike) -> FloatArray:
        """Noise standard deviation of every output in its unit, ``(..., O)``."""
        scale = np.array([o.scale for o in self.outputs])
        out: FloatArray = scale / np.sqrt(np.asarray(lam_star, dtype=float))
        return out


def noise_prior_from_sd(
    sd: float | Sequence[float], scale: float, name: str = "output"
) -> tuple[float, float]:
    """The Gamma prior of ``lambda*`` (standardised) from a sensor accuracy in physical units.

    Parameters
    ----------
    sd
        One standard deviation (the prior is centred on it, shape 2: the noise
        SD lies within about [0.6, 2.9] x ``sd`` with 95 % probability) or a range
        ``[low, high]`` taken as the central 95 % interval of the noise SD. [unit]
    scale
        The output's scale ``s_o``. [unit]
    name
        The output, for messages.
    """
    from scipy import optimize, stats

    values = [float(sd)] if isinstance(sd, int | float) else [float(v) for v in sd]
    if not all(math.isfinite(v) and v > 0.0 for v in values) or len(values) not in (1, 2):
        raise ConfigError(
            f"noise sd of {name!r} must be one positive value or a range [low, high], got {sd!r}"
        )
    if len(values) == 1:
        lam = (scale / values[0]) ** 2
        return 2.0, 2.0 / lam
    low, high = values
    if not low < high:
        raise ConfigError(f"noise sd range of {name!r} must have low < high, got {values}")
    # sigma = lam^-1/2: sigma's 2.5 % / 97.5 % quantiles are lam's 97.5 % / 2.5 % ones.
    ratio = (high / low) ** 2

    def spread(log_a: float) -> float:
        g = stats.gamma(math.exp(log_a))
        return float(np.log(g.ppf(0.975)) - np.log(g.ppf(0.025)) - math.log(ratio))

    bracket = (math.log(0.1), math.log(1e6))
    if not spread(bracket[0]) > 0.0 > spread(bracket[1]):
        raise ConfigError(
            f"noise sd range of {name!r} spans a factor {high / low:.3g}; give a range "
            "between about 1.001 and 1e4 times its low end"
        )
    a = math.exp(optimize.brentq(spread, *bracket))
    rate = float(stats.gamma(a).ppf(0.975)) * (low / scale) ** 2
    return a, rate
