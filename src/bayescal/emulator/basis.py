"""Standardisation and PCA bases of outputs and inputs (paper's eqs. 1, 6, 7, 13).

Layout: an output matrix ``Y`` is ``n x m`` -- one column per period, ``n``
samples within a period (several outputs are stacked along that axis with
:func:`stack_outputs`). Boundary-condition series for the inputs are given the
other way round, one row per period (``m* x n``), as in :func:`input_pca`.

Conventions
-----------
* Outputs are centred point-wise (the mean over the ``m`` simulated periods of
  each within-period sample) and scaled either point-wise (the paper: the
  population standard deviation, ``ddof = 0``, of each sample) or by one
  number per output (``scale="output"``: the root mean square of those
  standard deviations). With one scale per output a sensor's white noise of
  standard deviation ``sigma`` stays white in standardised units, with
  standard deviation ``sigma / s`` at every time of day; point-wise scaling
  turns it into noise whose size follows the design runs' spread.
* Several outputs get one basis each (:func:`block_basis`): ``K`` is block
  diagonal, so the weights of one output never carry another's noise.
* The output basis is scaled as in GPMSA, ``K = U_p S_p / sqrt(m)`` from the
  thin SVD ``Y = U S V^T``, so that the simulator weights ``W_hat = sqrt(m) V_p``
  have mean 0 and (population) variance 1 for every basis.
* Principal directions are signed so that the entry of largest magnitude of
  each is positive, which makes the basis reproducible across LAPACK builds.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy import linalg

from bayescal.emulator.kernel import FloatArray
from bayescal.errors import ConfigError, DataError

#: Singular values below this fraction of the largest count as zero.
RANK_TOL = 1e-12

Scale = Literal["pointwise", "output"]


def _finite_matrix(value: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 2:
        raise DataError(f"{name} must be a 2-D array, got ndim = {arr.ndim}")
    if arr.size == 0:
        raise DataError(f"{name} is empty (shape {arr.shape})")
    bad = ~np.isfinite(arr)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        raise DataError(
            f"{name} has {int(bad.sum())} NaN or infinite value(s), first at [{row}, {col}]",
            hint="drop failed runs and fill or exclude gappy periods before building the basis",
        )
    return arr


def _check_fraction(variance: float) -> None:
    if not 0.0 < variance <= 1.0:
        raise ConfigError(
            f"variance fraction must lie in (0, 1], got {variance!r}",
            hint="give the fraction of variance to keep, e.g. 0.90",
        )


def _sign_fix(directions: FloatArray) -> FloatArray:
    """Flip columns so that each one's largest-magnitude entry is positive."""
    pick = np.argmax(np.abs(directions), axis=0)
    signs = np.sign(directions[pick, np.arange(directions.shape[1])])
    signs[signs == 0] = 1.0
    return signs


@dataclass(frozen=True)
class Standardisation:
    """Point-wise centring and scaling of output periods.

    Parameters
    ----------
    mean
        Mean over the simulated periods of each within-period sample, ``(n,)``,
        in the output's units.
    sd
        Standard deviation (``ddof = 0``) over the same, ``(n,)``, same units.
    """

    mean: FloatArray
    sd: FloatArray

    def _check(self, y: FloatArray, name: str) -> None:
        if y.shape[0] != self.mean.size:
            raise DataError(
                f"{name} has {y.shape[0]} samples per period, the standardisation "
                f"was built for {self.mean.size}"
            )

    def apply(self, y: ArrayLike) -> FloatArray:
        """``(Y - mean) / sd`` row-wise; ``y`` is ``(n, m')``, e.g. ``Y*``."""
        arr = _finite_matrix(y, "Y")
        self._check(arr, "Y")
        return (arr - self.mean[:, None]) / self.sd[:, None]

    def invert(self, y_std: ArrayLike) -> FloatArray:
        """Back to the output's units: ``Y_std * sd + mean``."""
        arr = np.asarray(y_std, dtype=float)
        if arr.ndim == 1:
            arr = arr[:, None]
        self._check(arr, "Y_std")
        return arr * self.sd[:, None] + self.mean[:, None]


def standardise(y: ArrayLike, scale: Scale = "pointwise") -> Standardisation:
    """Point-wise mean, and the scale, over the simulated periods.

    Parameters
    ----------
    y
        Simulated output, ``n x m`` (column ``i`` is period ``i``), in the
        output's units.
    scale
        ``"pointwise"`` (each sample's standard deviation, the paper) or
        ``"output"`` (one number: the root mean square of those, so that the
        standardised output keeps its shape over the period and a sensor's
        noise keeps one size; see the module docstring).

    Raises
    ------
    bayescal.errors.DataError
        If a within-period sample is the same in every simulated period: it
        carries no information and cannot be scaled to unit variance.
    """
    arr = _finite_matrix(y, "Y")
    mean = arr.mean(axis=1)
    sd = arr.std(axis=1)
    magnitude = np.maximum(np.abs(mean), np.max(np.abs(arr), axis=1))
    constant = np.flatnonzero(sd <= RANK_TOL * np.maximum(magnitude, np.finfo(float).tiny))
    if constant.size:
        raise DataError(
            f"within-period sample(s) {constant[:10].tolist()} of Y are the same in all "
            f"{arr.shape[1]} simulated periods (sd = 0), so they cannot be standardised",
            hint="check that the design varies the parameters and that the output "
            "is not clamped; drop such samples or shorten the periods",
        )
    if scale == "output":
        return Standardisation(mean, np.full_like(sd, np.sqrt(np.mean(sd * sd))))
    if scale != "pointwise":
        raise ConfigError(f"scale must be 'pointwise' or 'output', got {scale!r}")
    return Standardisation(mean, sd)


def stack_outputs(blocks: Sequence[ArrayLike]) -> FloatArray:
    """Stack several standardised outputs along the within-period axis.

    Parameters
    ----------
    blocks
        Standardised outputs ``(n_q, m)``, all with the same ``m``.

    Returns
    -------
    numpy.ndarray
        ``(sum n_q, m)``; split back with ``numpy.split`` at the cumulative
        ``n_q``.
    """
    arrays = [_finite_matrix(b, f"output {q}") for q, b in enumerate(blocks)]
    if not arrays:
        raise DataError("no outputs to stack")
    widths = [a.shape[1] for a in arrays]
    if len(set(widths)) != 1:
        raise DataError(f"outputs have different numbers of periods {widths}; expected equal")
    return np.vstack(arrays)


@dataclass(frozen=True)
class Basis:
    """PCA basis of standardised outputs with the GPMSA scaling.

    Parameters
    ----------
    k
        Basis vectors ``K``, shape ``(n, p)``, ``K = U_p S_p / sqrt(m)``.
    explained
        Fraction of the variance explained by every component of the SVD,
        shape ``(min(n, m),)``, non-increasing; the first ``p`` are kept.
    n_periods
        ``m``, the number of simulated periods the basis was built from.
    groups
        Output of every basis vector ``(p,)`` (an index into the outputs in
        stacking order); all 0 for one output. With several outputs each has
        its own basis (:func:`block_basis`) and ``explained`` is that of the
        first output.
    """

    k: FloatArray
    explained: FloatArray
    n_periods: int
    groups: tuple[int, ...] = field(default=())

    def __post_init__(self) -> None:
        if not self.groups:
            object.__setattr__(self, "groups", (0,) * int(self.k.shape[1]))
        if len(self.groups) != self.k.shape[1]:
            raise DataError(
                f"basis has {self.k.shape[1]} vectors but {len(self.groups)} output indices"
            )

    @property
    def p(self) -> int:
        """Number of basis vectors kept."""
        return int(self.k.shape[1])

    @property
    def explained_kept(self) -> FloatArray:
        """Variance fraction of each kept component, ``(p,)``."""
        return self.explained[: self.p]

    @property
    def ktk(self) -> FloatArray:
        """``k_j^T k_j`` for every basis vector, ``(p,)``."""
        return np.einsum("ij,ij->j", self.k, self.k)

    def weights(self, y_std: ArrayLike) -> FloatArray:
        """Least-squares weights ``[(K^T K)^-1 K^T Y]^T`` (eqs. 6 and 13).

        Parameters
        ----------
        y_std
            Standardised periods, ``(n, m')``, e.g. ``Y`` or ``Y*``.

        Returns
        -------
        numpy.ndarray
            ``(m', p)``; row ``i`` is ``w_i``.
        """
        arr = _finite_matrix(y_std, "Y_std")
        if arr.shape[0] != self.k.shape[0]:
            raise DataError(f"Y_std has {arr.shape[0]} samples per period, K has {self.k.shape[0]}")
        gram = self.k.T @ self.k
        return linalg.solve(gram, self.k.T @ arr, assume_a="pos").T

    def reconstruct(self, w: ArrayLike) -> FloatArray:
        """``K w_i`` for every row of ``w`` (eq. 1): ``(n, m')`` from ``(m', p)``."""
        return self.k @ np.atleast_2d(np.asarray(w, dtype=float)).T

    def residual(self, y_std: ArrayLike) -> FloatArray:
        """``(I - K (K^T K)^-1 K^T) y_i`` for every column: what the basis leaves out."""
        arr = np.asarray(y_std, dtype=float)
        out: FloatArray = arr - self.reconstruct(self.weights(arr))
        return out

    def residual_sum_of_squares(self, y_std: ArrayLike) -> float:
        """``sum_i y_i^T (I - K (K^T K)^-1 K^T) y_i``: what the basis leaves out."""
        resid = self.residual(y_std)
        return float(np.sum(resid * resid))

    def lambda_posterior(
        self, y_std: ArrayLike, shape: float = 5.0, rate: float = 5.0
    ) -> tuple[float, float]:
        """Gamma prior of the precision updated with the out-of-basis part (eq. 7).

        Parameters
        ----------
        y_std
            Standardised periods ``(n, m')``: ``Y`` for ``lambda``, ``Y*`` for
            ``lambda*``.
        shape, rate
            Gamma prior of the precision (paper: 5 and 5). [-]

        Returns
        -------
        tuple of float
            ``(shape + m' (n - p) / 2, rate + RSS / 2)``.
        """
        arr = _finite_matrix(y_std, "Y_std")
        n, m = arr.shape
        return shape + 0.5 * m * (n - self.p), rate + 0.5 * self.residual_sum_of_squares(arr)


def pca_basis(y_std: ArrayLike, variance: float = 0.90, components: int | None = None) -> Basis:
    """PCA basis of standardised simulator output, GPMSA-scaled.

    Parameters
    ----------
    y_std
        Standardised simulator output ``Y``, ``(n, m)``.
    variance
        Keep the fewest components whose cumulative explained variance is at
        least this fraction (ignored when ``components`` is given). [-]
    components
        Keep exactly this many components.

    Raises
    ------
    bayescal.errors.DataError
        If ``Y`` has no variance at all.
    bayescal.errors.ConfigError
        If ``variance`` is not in (0, 1] or ``components`` exceeds the rank.
    """
    arr = _finite_matrix(y_std, "Y_std")
    _check_centred(arr)
    u, s, _ = linalg.svd(arr, full_matrices=False, check_finite=False)
    if s[0] <= RANK_TOL * np.sqrt(arr.size):
        raise DataError(
            "Y_std has no variance (all periods identical); no basis can be built",
            hint="check that the design varies parameters the output depends on",
        )
    explained = s * s / np.sum(s * s)
    rank = int(np.sum(s > RANK_TOL * s[0]))
    p = _n_components(explained, rank, variance, components)
    signs = _sign_fix(u[:, :p])
    k = u[:, :p] * (signs * s[:p] / np.sqrt(arr.shape[1]))
    return Basis(k=k, explained=explained, n_periods=arr.shape[1])


def block_basis(
    y_std: ArrayLike,
    sizes: Sequence[int],
    variance: float = 0.90,
    components: int | None = None,
) -> Basis:
    """One GPMSA-scaled PCA basis per output, stacked block-diagonally.

    Parameters
    ----------
    y_std
        Standardised simulator output of all outputs stacked, ``(sum n_q, m)``.
    sizes
        Samples per period of each output ``n_q``, in stacking order.
    variance, components
        As :func:`pca_basis`, for each output.

    Returns
    -------
    Basis
        ``K`` ``(sum n_q, sum p_q)`` with output ``q``'s vectors nonzero only in
        its rows; ``groups`` says which output each vector belongs to. With one
        output this is :func:`pca_basis`.
    """
    arr = _finite_matrix(y_std, "Y_std")
    if sum(sizes) != arr.shape[0]:
        raise DataError(f"outputs of {list(sizes)} samples do not stack to {arr.shape[0]} rows")
    if len(sizes) == 1:
        return pca_basis(arr, variance, components)
    bounds = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    parts = [
        pca_basis(arr[bounds[q] : bounds[q + 1]], variance, components) for q in range(len(sizes))
    ]
    k = np.zeros((arr.shape[0], sum(b.p for b in parts)))
    col, groups = 0, []
    for q, b in enumerate(parts):
        k[bounds[q] : bounds[q + 1], col : col + b.p] = b.k
        col += b.p
        groups += [q] * b.p
    return Basis(k=k, explained=parts[0].explained, n_periods=arr.shape[1], groups=tuple(groups))


def _check_centred(arr: FloatArray) -> None:
    """PCA needs the within-period samples centred over the periods."""
    offset = np.abs(arr.mean(axis=1))
    worst = int(np.argmax(offset))
    if offset[worst] > 1e-8 * max(float(np.max(np.abs(arr))), 1.0):
        raise DataError(
            f"Y_std is not centred: sample {worst} has mean {arr.mean(axis=1)[worst]:.3g} "
            "over the periods, expected 0",
            hint="apply standardise(Y).apply(Y) before pca_basis",
        )


def _n_components(explained: FloatArray, rank: int, variance: float, components: int | None) -> int:
    if components is not None:
        if not 1 <= components <= rank:
            raise ConfigError(
                f"asked for {components} components, the output has rank {rank}",
                hint=f"choose between 1 and {rank}",
            )
        return components
    _check_fraction(variance)
    cumulative = np.cumsum(explained)
    # A small slack so that 0.9 is not missed by one rounding error.
    p = int(np.searchsorted(cumulative, variance - 1e-12) + 1)
    return min(p, rank)


@dataclass(frozen=True)
class Normaliser:
    """Affine map of each column onto [0, 1]: ``(v - lower) / (upper - lower)``.

    Parameters
    ----------
    lower, upper
        Column bounds, ``(d,)``, in the columns' units; ``upper > lower``.
    """

    lower: FloatArray
    upper: FloatArray

    @classmethod
    def from_bounds(cls, lower: ArrayLike, upper: ArrayLike) -> Normaliser:
        """From prior bounds (theta)."""
        lo = np.asarray(lower, dtype=float).reshape(-1)
        hi = np.asarray(upper, dtype=float).reshape(-1)
        if lo.shape != hi.shape or not np.all(np.isfinite(lo) & np.isfinite(hi) & (hi > lo)):
            raise ConfigError(
                f"bounds must be finite with upper > lower, got lower={lo.tolist()} "
                f"upper={hi.tolist()}"
            )
        return cls(lo, hi)

    @classmethod
    def from_data(cls, values: ArrayLike) -> Normaliser:
        """From column minima and maxima of ``values`` ``(rows, d)``."""
        arr = _finite_matrix(values, "values")
        return cls.from_bounds(arr.min(axis=0), arr.max(axis=0))

    def apply(self, values: ArrayLike) -> FloatArray:
        """Scale to the unit cube (values outside the bounds map outside [0, 1])."""
        return (np.asarray(values, dtype=float) - self.lower) / (self.upper - self.lower)

    def invert(self, unit: ArrayLike) -> FloatArray:
        """Back to the columns' units."""
        return self.lower + np.asarray(unit, dtype=float) * (self.upper - self.lower)


@dataclass(frozen=True)
class SeriesPCA:
    """PCA of one boundary-condition series cut into periods.

    Parameters
    ----------
    name
        Glossary name of the series.
    mean
        Mean period, ``(n,)``, in the series' units.
    directions
        Kept principal directions as rows, ``(q, n)``, orthonormal; ``q = 0``
        for a series that is the same in every period.
    explained
        Variance fraction of each kept direction, ``(q,)``.
    """

    name: str
    mean: FloatArray
    directions: FloatArray
    explained: FloatArray

    def scores(self, periods: FloatArray) -> FloatArray:
        """Weights ``(periods - mean) @ directions^T``: ``(m', q)`` from ``(m', n)``."""
        return (periods - self.mean) @ self.directions.T


def _series_pca(name: str, periods: FloatArray, variance: float) -> SeriesPCA:
    mean = periods.mean(axis=0)
    centred = periods - mean
    _, s, vt = linalg.svd(centred, full_matrices=False, check_finite=False)
    scale = max(float(np.max(np.abs(periods))), np.finfo(float).tiny)
    if s[0] <= RANK_TOL * scale * np.sqrt(periods.size):
        return SeriesPCA(name, mean, np.zeros((0, periods.shape[1])), np.zeros(0))
    explained = s * s / np.sum(s * s)
    rank = int(np.sum(s > RANK_TOL * s[0]))
    q = _n_components(explained, rank, variance, None)
    directions = vt[:q] * _sign_fix(vt[:q].T)[:, None]
    return SeriesPCA(name, mean, directions, explained[:q])


@dataclass(frozen=True)
class InputPCA:
    """Variable conditions ``x`` of the periods from boundary-condition series.

    Parameters
    ----------
    series
        One :class:`SeriesPCA` per series, in input order.
    normaliser
        Min/max of the raw weights over the training periods.
    x
        Normalised ``x`` of the training periods, ``(m*, s)``, in [0, 1].
    """

    series: tuple[SeriesPCA, ...]
    normaliser: Normaliser
    x: FloatArray

    @property
    def labels(self) -> list[str]:
        """A label per column of ``x``: ``"<series>:pc<k>"``."""
        return [f"{sp.name}:pc{k + 1}" for sp in self.series for k in range(sp.explained.size)]

    def transform(self, series_periods: Mapping[str, ArrayLike]) -> FloatArray:
        """``x`` of new periods (e.g. the test window), same transform as training.

        Parameters
        ----------
        series_periods
            Glossary name -> ``(m', n)`` array of periods, in the series' units.

        Returns
        -------
        numpy.ndarray
            ``(m', s)``; may fall outside [0, 1] for conditions not seen in
            training.
        """
        missing = [sp.name for sp in self.series if sp.name not in series_periods]
        if missing:
            raise DataError(f"series {missing} missing; expected {[s.name for s in self.series]}")
        raw = [sp.scores(_periods(series_periods[sp.name], sp)) for sp in self.series]
        return self.normaliser.apply(np.hstack(raw))


def _periods(value: ArrayLike, sp: SeriesPCA) -> FloatArray:
    arr = _finite_matrix(value, f"series {sp.name!r}")
    if arr.shape[1] != sp.mean.size:
        raise DataError(
            f"series {sp.name!r} has periods of {arr.shape[1]} samples, expected {sp.mean.size}"
        )
    return arr


def input_pca(series_periods: Mapping[str, ArrayLike], variance: float = 0.90) -> InputPCA:
    """PCA of each boundary-condition series over the periods -> normalised ``x``.

    Each series is centred over the periods (not scaled: its samples share one
    unit, and scaling would blow up samples with no spread such as night-time
    solar radiation), reduced to its leading principal-component weights
    explaining at least ``variance``, and the weights of all series are
    concatenated and scaled to [0, 1] by their min and max over the periods.
    A series that is the same in every period contributes no column.

    Parameters
    ----------
    series_periods
        Glossary name -> ``(m*, n)`` array, one row per period, in the
        series' units.
    variance
        Fraction of each series' variance to keep. [-]

    Raises
    ------
    bayescal.errors.DataError
        If no series varies between periods or the shapes disagree.
    """
    _check_fraction(variance)
    if not series_periods:
        raise DataError("no boundary-condition series given for the input PCA")
    pcas = []
    n_rows: set[int] = set()
    for name, value in series_periods.items():
        arr = _finite_matrix(value, f"series {name!r}")
        n_rows.add(arr.shape[0])
        pcas.append(_series_pca(name, arr, variance))
    if len(n_rows) != 1:
        raise DataError(f"series have different numbers of periods {sorted(n_rows)}")
    raw = np.hstack([sp.scores(np.asarray(series_periods[sp.name], float)) for sp in pcas])
    if raw.shape[1] == 0:
        raise DataError(
            f"none of the series {list(series_periods)} varies between periods",
            hint="the variable conditions x need at least one boundary condition that changes",
        )
    normaliser = Normaliser.from_data(raw)
    return InputPCA(tuple(pcas), normaliser, normaliser.apply(raw))
