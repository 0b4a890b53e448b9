"""Calibration parameters, their priors and the Latin-hypercube design of simulator runs.

Two scales are used for every calibration parameter ``theta`` with bounds
``[lower, upper]``:

* the *physical* scale, in the parameter's own unit, on which the simulator
  is run;
* the *normalised* scale ``u = (theta - lower) / (upper - lower)`` in
  ``[0, 1]``, on which the emulator and the calibration work (Higdon et al.
  2008; the paper's section 2).

The map between them is linear for every prior, so a design that is a Latin
hypercube in ``[0, 1]^t`` is a Latin hypercube over the box of the priors'
bounds. **The design covers the bounds, not the prior density**: a Beta prior
concentrates belief in part of the interval but the simulator runs are spread
evenly over all of it, as the emulator must be accurate wherever the posterior
may go. The prior density enters only the calibration, through
:meth:`Prior.logpdf_unit`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special
from scipy.stats import qmc

from bayescal.errors import ConfigError

__all__ = [
    "BetaPrior",
    "Design",
    "LogitNormal",
    "PosteriorPrior",
    "Prior",
    "UniformPrior",
    "fit_logit_normal",
    "latin_hypercube",
    "log_gamma",
    "log_gamma_array",
    "log_gamma_of_log",
    "prior_from_spec",
]

FloatArray = NDArray[np.float64]
Optimization = Literal["random-cd", "lloyd"]
OPTIMIZATIONS: tuple[str, ...] = ("random-cd", "lloyd")


def _finite(value: float, what: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise ConfigError(f"{what} must be finite, got {value!r}")
    return number


def log_gamma(value: float, shape: float, rate: float) -> float:
    """Log Gamma(shape, rate) density of a precision, up to its constant; ``-inf`` if <= 0.

    The priors of the precisions ``lambda``, ``lambda*`` and ``tau`` of the
    paper's eqs. 7 and 9: ``(shape - 1) log value - rate value``. The numpy
    Gamma log-density lives here only, in three forms: this one (one value),
    :func:`log_gamma_array` (elementwise) and :func:`log_gamma_of_log` (given
    the log of the value, for samplers on the log scale).
    """
    if not value > 0.0:
        return -math.inf
    return (shape - 1.0) * math.log(value) - rate * value


def log_gamma_array(value: ArrayLike, shape: ArrayLike, rate: ArrayLike) -> FloatArray:
    """:func:`log_gamma` elementwise: ``(shape - 1) log x - rate x``, ``-inf`` where ``x <= 0``.

    ``shape`` and ``rate`` broadcast against ``value`` (one pair per column of a
    ``(B, q)`` array, say). Equal, value for value, to :func:`log_gamma`.
    """
    x = np.asarray(value, dtype=float)
    shape_m1 = np.asarray(shape, dtype=float) - 1.0
    rate_arr = np.asarray(rate, dtype=float)
    if x.size and x.min() > 0.0:  # the common case, without the masking
        out: FloatArray = shape_m1 * np.log(x) - rate_arr * x
        return out
    positive = x > 0.0
    safe = np.where(positive, x, 1.0)
    masked: FloatArray = np.where(positive, shape_m1 * np.log(safe) - rate_arr * safe, -math.inf)
    return masked


def log_gamma_of_log(log_value: float, shape: float, rate: float) -> float:
    """:func:`log_gamma` at ``exp(log_value)``, given ``log_value`` (no logarithm taken).

    ``(shape - 1) log_value - rate exp(log_value)``; the Jacobian of the log
    scale (``+ log_value``) is the caller's.
    """
    return (shape - 1.0) * log_value - rate * math.exp(log_value)


@dataclass(frozen=True)
class Prior:
    """Base class of priors on a bounded interval ``[lower, upper]``.

    Parameters
    ----------
    lower
        Lower bound, in the parameter's unit.
    upper
        Upper bound, in the parameter's unit; must exceed ``lower``.
    unit
        The parameter's unit as the study file writes it (``"W/(m·K)"``), for
        artefacts, tables and reports; ``""`` where unknown. Keyword only.
    description
        What the parameter is, in words (``"conductivity of the blocks"``).
        Keyword only.
    """

    lower: float
    upper: float
    unit: str = field(default="", kw_only=True)
    description: str = field(default="", kw_only=True)
    distribution: ClassVar[str] = "base"

    def __post_init__(self) -> None:
        lower = _finite(self.lower, "prior lower bound")
        upper = _finite(self.upper, "prior upper bound")
        if not lower < upper:
            raise ConfigError(
                f"prior bounds must satisfy lower < upper, got lower={lower!r}, upper={upper!r}",
                hint="swap or widen the bounds",
            )
        object.__setattr__(self, "lower", lower)
        object.__setattr__(self, "upper", upper)

    @property
    def width(self) -> float:
        """``upper - lower``, in the parameter's unit."""
        return self.upper - self.lower

    def to_unit(self, value: Any) -> np.ndarray:
        """Map physical values to the normalised scale ``(value - lower) / width``."""
        return (np.asarray(value, dtype=float) - self.lower) / self.width

    def from_unit(self, u: Any) -> np.ndarray:
        """Map normalised values back to the physical scale ``lower + u * width``."""
        return self.lower + np.asarray(u, dtype=float) * self.width

    def logpdf_unit(self, u: Any) -> np.ndarray:
        """Log density on the normalised scale; ``-inf`` outside ``[0, 1]``."""
        raise NotImplementedError

    def logpdf(self, value: Any) -> np.ndarray:
        """Log density on the physical scale; ``-inf`` outside ``[lower, upper]``.

        Equals ``logpdf_unit(to_unit(value)) - log(width)`` (change of variables).
        """
        return self.logpdf_unit(self.to_unit(value)) - math.log(self.width)

    def sample_unit(self, rng: np.random.Generator, size: int | tuple[int, ...]) -> np.ndarray:
        """Draw from the prior on the normalised scale."""
        raise NotImplementedError

    def spec(self) -> dict[str, Any]:
        """The prior as a plain dictionary (the study file's ``{distribution, ...}``).

        ``unit`` and ``description`` are included where set;
        :func:`prior_from_spec` reads the dictionary back.
        """
        out: dict[str, Any] = {
            "distribution": self.distribution,
            "lower": self.lower,
            "upper": self.upper,
        }
        if self.unit:
            out["unit"] = self.unit
        if self.description:
            out["description"] = self.description
        return out


@dataclass(frozen=True)
class UniformPrior(Prior):
    """Uniform prior on ``[lower, upper]``."""

    distribution: ClassVar[str] = "uniform"

    def logpdf_unit(self, u: Any) -> np.ndarray:
        """Log density on the normalised scale: 0 on ``[0, 1]``, ``-inf`` outside."""
        u = np.asarray(u, dtype=float)
        return np.where((u >= 0.0) & (u <= 1.0), 0.0, -np.inf)

    def sample_unit(self, rng: np.random.Generator, size: int | tuple[int, ...]) -> np.ndarray:
        """Draw uniformly from ``[0, 1)``."""
        return rng.random(size)


@dataclass(frozen=True)
class BetaPrior(Prior):
    """Beta(a, b) prior scaled to ``[lower, upper]``.

    Parameters
    ----------
    lower
        Lower bound, in the parameter's unit.
    upper
        Upper bound, in the parameter's unit.
    a
        First shape parameter, > 0. [-]
    b
        Second shape parameter, > 0. [-]
    """

    a: float
    b: float
    distribution: ClassVar[str] = "beta"

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("a", "b"):
            value = _finite(getattr(self, name), f"beta prior shape {name}")
            if value <= 0:
                raise ConfigError(
                    f"beta prior shape {name} must be > 0, got {value!r}",
                    hint="a = b = 1 is the uniform prior; a, b > 1 favour the middle",
                )
            object.__setattr__(self, name, value)

    def logpdf_unit(self, u: Any) -> np.ndarray:
        """Log Beta(a, b) density on the normalised scale; ``-inf`` outside ``[0, 1]``."""
        u = np.asarray(u, dtype=float)
        inside = (u >= 0.0) & (u <= 1.0)
        clipped = np.clip(u, 0.0, 1.0)
        with np.errstate(divide="ignore"):
            value = (
                special.xlogy(self.a - 1.0, clipped)
                + special.xlog1py(self.b - 1.0, -clipped)
                - special.betaln(self.a, self.b)
            )
        return np.where(inside, value, -np.inf)

    def sample_unit(self, rng: np.random.Generator, size: int | tuple[int, ...]) -> np.ndarray:
        """Draw from Beta(a, b)."""
        return rng.beta(self.a, self.b, size)

    def spec(self) -> dict[str, Any]:
        """The prior as a plain dictionary, with its shapes."""
        return {**super().spec(), "a": self.a, "b": self.b}


@dataclass(frozen=True)
class LogitNormal:
    """A joint density of several parameters on their normalised scales, from draws.

    ``z = logit(u)`` is Gaussian with ``mean`` and ``cov``; the density of ``u``
    on ``(0, 1)^m`` is that Gaussian's times the Jacobian ``prod 1 / (u (1 - u))``.
    It is how another study's posterior becomes this one's prior
    (:func:`fit_logit_normal`): correlations between the parameters are kept.

    Parameters
    ----------
    names
        The parameters, in the order of ``mean``.
    mean
        Mean of ``z``, ``(m,)``. [-]
    cov
        Covariance of ``z``, ``(m, m)``, positive definite. [-]
    source
        Where the draws came from (a study's output folder), for messages.
    """

    names: tuple[str, ...]
    mean: tuple[float, ...]
    cov: tuple[tuple[float, ...], ...]
    source: str = ""

    def logpdf_unit(self, u: Any) -> np.ndarray:
        """Log density at the rows of ``u`` ``(B, m)``; ``-inf`` outside ``(0, 1)^m``."""
        arr = np.atleast_2d(np.asarray(u, dtype=float))
        inside = np.all((arr > 0.0) & (arr < 1.0), axis=1)
        clipped = np.clip(arr, 1e-300, 1.0 - 1e-16)
        z = special.logit(clipped) - np.asarray(self.mean)
        cov = np.asarray(self.cov, dtype=float)
        chol = np.linalg.cholesky(cov)
        white = np.linalg.solve(chol, z.T)
        m = len(self.names)
        log_norm = -0.5 * m * math.log(2.0 * math.pi) - float(np.sum(np.log(np.diag(chol))))
        jacobian = -np.sum(np.log(clipped) + np.log1p(-clipped), axis=1)
        value = log_norm - 0.5 * np.sum(white * white, axis=0) + jacobian
        return np.where(inside, value, -np.inf)


def fit_logit_normal(names: tuple[str, ...], unit_draws: Any, source: str = "") -> LogitNormal:
    """The :class:`LogitNormal` fitted (by moments of ``logit(u)``) to draws ``(S, m)``.

    Draws on or outside the bounds are refused: the previous posterior must lie
    inside this study's prior bounds.
    """
    arr = np.asarray(unit_draws, dtype=float)
    if not np.all((arr > 0.0) & (arr < 1.0)):
        raise ConfigError(
            "the draws of the previous posterior reach or cross this study's prior bounds",
            hint="widen the bounds of the shared parameters to hold the previous posterior",
        )
    z = special.logit(arr)
    cov = np.atleast_2d(np.cov(z, rowvar=False))
    return LogitNormal(
        tuple(names),
        tuple(float(v) for v in z.mean(axis=0)),
        tuple(tuple(float(v) for v in row) for row in cov),
        source,
    )


@dataclass(frozen=True)
class PosteriorPrior(Prior):
    """One parameter's share of a joint prior from a previous posterior (:class:`LogitNormal`).

    Alone (plots, a report's prior curve, sampling starts) it is the joint's
    marginal, a logit-normal on ``[lower, upper]``; the calibration's log prior
    evaluates the joint once for all the parameters that share it
    (:class:`bayescal.calibration.priors.ThetaPriors`), so their correlation is kept.
    """

    joint: LogitNormal = field(kw_only=True)
    index: int = field(kw_only=True)
    distribution: ClassVar[str] = "posterior"

    def logpdf_unit(self, u: Any) -> np.ndarray:
        """The marginal's log density on the normalised scale; ``-inf`` outside ``(0, 1)``."""
        u = np.asarray(u, dtype=float)
        inside = (u > 0.0) & (u < 1.0)
        clipped = np.clip(u, 1e-300, 1.0 - 1e-16)
        mu = self.joint.mean[self.index]
        var = self.joint.cov[self.index][self.index]
        z = special.logit(clipped)
        value = (
            -0.5 * math.log(2.0 * math.pi * var)
            - 0.5 * (z - mu) ** 2 / var
            - np.log(clipped)
            - np.log1p(-clipped)
        )
        return np.where(inside, value, -np.inf)

    def sample_unit(self, rng: np.random.Generator, size: int | tuple[int, ...]) -> np.ndarray:
        """Draw from the marginal."""
        mu = self.joint.mean[self.index]
        sd = math.sqrt(self.joint.cov[self.index][self.index])
        return np.asarray(special.expit(rng.normal(mu, sd, size)))

    def spec(self) -> dict[str, Any]:
        """The prior as a plain dictionary, with the whole joint density and its index."""
        joint = {
            "names": list(self.joint.names),
            "mean": list(self.joint.mean),
            "cov": [list(row) for row in self.joint.cov],
            "source": self.joint.source,
        }
        return {**super().spec(), "index": self.index, "joint": joint}


def prior_from_spec(
    distribution: str,
    lower: float,
    upper: float,
    a: float | None = None,
    b: float | None = None,
    *,
    unit: str = "",
    description: str = "",
    index: int | None = None,
    joint: Mapping[str, Any] | None = None,
) -> Prior:
    """Build a prior from the study file's fields.

    Parameters
    ----------
    distribution
        ``"uniform"`` or ``"beta"``.
    lower, upper
        Bounds, in the parameter's unit.
    a, b
        Beta shape parameters (required for ``"beta"``, refused for ``"uniform"``). [-]
    unit, description
        The parameter's unit and description (see :class:`Prior`).
    index, joint
        ``"posterior"``: the parameter's place in the joint density and the
        density itself (names, mean, cov, source; :class:`PosteriorPrior`).

    Returns
    -------
    Prior
        A :class:`UniformPrior` or :class:`BetaPrior`.
    """
    if distribution == "uniform":
        if a is not None or b is not None:
            raise ConfigError(
                f"a uniform prior takes no shape parameters, got a={a!r}, b={b!r}",
                hint='remove a and b, or set distribution = "beta"',
            )
        return UniformPrior(lower, upper, unit=unit, description=description)
    if distribution == "beta":
        if a is None or b is None:
            raise ConfigError(
                f"a beta prior needs both shape parameters, got a={a!r}, b={b!r}",
                hint="set a and b (> 0); a = b = 1 is uniform",
            )
        return BetaPrior(lower, upper, a, b, unit=unit, description=description)
    if distribution == "posterior" and joint is not None and index is not None:
        density = LogitNormal(
            tuple(joint["names"]),
            tuple(float(v) for v in joint["mean"]),
            tuple(tuple(float(v) for v in row) for row in joint["cov"]),
            str(joint.get("source", "")),
        )
        return PosteriorPrior(
            lower, upper, unit=unit, description=description, joint=density, index=int(index)
        )
    raise ConfigError(f"unknown prior distribution {distribution!r}; expected 'uniform' or 'beta'")


@dataclass(frozen=True, eq=False)  # no == : arrays have no single truth value
class Design:
    """A set of ``R`` parameter vectors at which to run the simulator.

    Parameters
    ----------
    priors
        Parameter name -> prior, in column order.
    unit
        Normalised design, shape ``(R, t)``, in ``[0, 1]``.
    seed
        Seed of the random generator that drew it (``None`` for a design given
        explicitly).
    optimization
        The Latin-hypercube optimisation used, if any.
    """

    priors: Mapping[str, Prior]
    unit: np.ndarray
    seed: int | None = None
    optimization: str | None = None

    def __post_init__(self) -> None:
        unit = np.array(self.unit, dtype=float)
        t = len(self.priors)
        if unit.ndim != 2 or unit.shape[1] != t:
            raise ConfigError(f"design must have shape (runs, {t}), got {unit.shape}")
        if not np.all((unit >= 0.0) & (unit <= 1.0)):
            raise ConfigError("normalised design values must lie in [0, 1]")
        unit.flags.writeable = False
        object.__setattr__(self, "unit", unit)
        object.__setattr__(self, "priors", dict(self.priors))

    @classmethod
    def from_values(
        cls, priors: Mapping[str, Prior], values: Any, seed: int | None = None
    ) -> Design:
        """A design from explicit physical values, shape ``(R, t)``, inside the bounds."""
        values = np.atleast_2d(np.asarray(values, dtype=float))
        if values.ndim != 2 or values.shape[1] != len(priors):
            raise ConfigError(f"design must have shape (runs, {len(priors)}), got {values.shape}")
        columns = [p.to_unit(values[:, j]) for j, p in enumerate(priors.values())]
        unit = np.column_stack(columns) if columns else values
        outside = [n for j, n in enumerate(priors) if np.any((unit[:, j] < 0) | (unit[:, j] > 1))]
        if outside:
            raise ConfigError(f"design values of {outside} lie outside their prior bounds")
        return cls(priors, unit, seed=seed)

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names, in column order."""
        return tuple(self.priors)

    @property
    def runs(self) -> int:
        """Number of runs ``R``."""
        return int(self.unit.shape[0])

    @property
    def values(self) -> np.ndarray:
        """Physical design, shape ``(R, t)``, each column in its parameter's unit."""
        if not self.priors:
            return np.empty((self.runs, 0))
        return np.column_stack(
            [p.from_unit(self.unit[:, j]) for j, p in enumerate(self.priors.values())]
        )

    def row(self, index: int) -> dict[str, float]:
        """Physical parameter values of run ``index`` as ``{name: value}``."""
        values = self.values[index]
        return {name: float(v) for name, v in zip(self.names, values, strict=True)}

    def to_frame(self) -> Any:
        """The physical design as a ``pandas.DataFrame`` (one row per run, index ``run``)."""
        import pandas as pd

        frame = pd.DataFrame(self.values, columns=list(self.names))
        frame.index.name = "run"
        return frame


def latin_hypercube(
    priors: Mapping[str, Prior],
    runs: int,
    seed: int,
    optimization: Optimization | None = None,
) -> Design:
    """Draw a Latin-hypercube design over the priors' bounds.

    Parameters
    ----------
    priors
        Parameter name -> prior; the column order follows this mapping.
    runs
        Number of simulator runs ``R``; at least ``t + 2`` for ``t`` parameters
        (the emulator needs more runs than parameters; the paper uses 20–50).
    seed
        Seed of the generator (``numpy.random.default_rng(seed)``); recorded
        in the design, so the same seed gives the same design bit for bit.
    optimization
        ``None`` (plain scrambled LHS), ``"random-cd"`` (column permutations
        that lower the centred discrepancy; keeps the Latin-hypercube
        property) or ``"lloyd"`` (Lloyd-Max relaxation towards even spacing;
        may break the one-point-per-stratum property; needs ``t >= 2``).

    Returns
    -------
    Design
        The normalised design is the LHS in ``[0, 1]^t``; the physical design
        is ``lower + u * (upper - lower)`` per column, i.e. uniform over the
        bounds whatever the prior's shape (see the module docstring).
    """
    if not priors:
        raise ConfigError("a design needs at least one calibration parameter, got none")
    t = len(priors)
    if isinstance(runs, bool) or not isinstance(runs, int | np.integer) or runs < t + 2:
        raise ConfigError(
            f"a design for {t} parameter(s) needs at least {t + 2} runs, got runs={runs!r}",
            hint="the paper uses 20 to 50 runs",
        )
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ConfigError(f"design seed must be a non-negative integer, got {seed!r}")
    if optimization is not None and optimization not in OPTIMIZATIONS:
        raise ConfigError(
            f"unknown design optimization {optimization!r}; expected None, "
            + " or ".join(repr(o) for o in OPTIMIZATIONS)
        )
    if optimization == "lloyd" and t < 2:
        raise ConfigError("optimization 'lloyd' needs at least 2 parameters; use 'random-cd'")
    sampler = qmc.LatinHypercube(d=t, optimization=optimization, rng=np.random.default_rng(seed))
    unit = sampler.random(int(runs))
    return Design(priors, unit, seed=int(seed), optimization=optimization)
