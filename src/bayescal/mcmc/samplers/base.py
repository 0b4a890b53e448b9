"""The sampler protocol, its result, and the handling of bounded coordinates.

A sampler draws from a target given as a log-density callable ``log_density(x)``
on a vector ``x`` of ``d`` coordinates, returning the log of an unnormalised
density (a Python ``float``; ``-inf`` outside the support). The log-density
knows nothing about the sampler. Samplers are small frozen dataclasses holding
their settings, with one method::

    result = sampler.run(log_density, x0, n_draws, rng, callback=None)

Contract for the log-density
----------------------------
* It is always called with ``x`` on the original (bounded) scale; a sampler
  that works on a transformed scale adds the Jacobian itself.
* The array passed in is reused and modified in place between calls: copy it
  if you keep it.
* ``-inf`` rejects the point. ``NaN`` and ``+inf`` are errors
  (:class:`LogDensityError`), never silently rejected.
* For :mod:`bayescal.mcmc.chains` with processes it must be picklable
  (a module-level function or an instance of a module-level class).

Bounded coordinates
-------------------
Coordinates may have a lower and/or an upper bound (``-inf``/``inf`` where
there is none). Two ways of keeping them inside are offered (``bounds=``):

``"transform"`` (default)
    Sample ``z`` on the real line: ``x = lo + (hi - lo) / (1 + exp(-z))``
    (logit) for two bounds, ``x = lo + exp(z)`` for a lower bound only,
    ``x = hi - exp(z)`` for an upper bound only, and add ``log |dx/dz|`` to the
    target. Proposal scales then refer to ``z``. This copes with densities
    piled against a bound (a Beta(1, 0.1) prior of a correlation parameter
    ``rho``). Float64 cannot resolve ``x`` closer than one ulp to a bound; the
    value passed to the log-density is clipped to the open interval, so a
    density with noticeable mass within ``1e-16`` of a bound (Beta(1, 0.1) has
    2.5 % of its mass within ``1.1e-16`` of 1) is slightly distorted there.
    Parametrise such a quantity so that its pile-up is at a bound of 0, where
    floats have relative precision: GPMSA's ``beta = -4 ln(rho)`` on
    ``[0, inf)``, with ``1 - rho = -expm1(-beta / 4)``.
``"reflect"``
    Random-walk proposals on the original scale folded back into the box
    (mirror images at the bounds). The folded Gaussian proposal is still
    symmetric, so no correction is needed and proposal scales refer to ``x``.
    Adequate for densities that stay finite at the bounds (Beta(2, 5)); it
    mixes badly when the density diverges at a bound.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.errors import BayescalError, ConfigError

LogDensity = Callable[[NDArray[np.float64]], float]
"""A log-density: vector ``x`` (d,) on the original scale -> ``float``."""

Callback = Callable[[int], None]
"""Called with the number of completed iterations (burn-in included)."""

BoundsMethod = Literal["transform", "reflect"]

ScalarMap = Callable[[float], tuple[float, float]]
"""Sampling value -> (original value, log |dx/dz|) of one coordinate."""

_INF = math.inf


class LogDensityError(BayescalError):
    """The log-density returned NaN or +inf, or could not be evaluated."""


@dataclass(frozen=True)
class SamplerResult:
    """Draws of one chain and what is needed to judge and reproduce them.

    Attributes
    ----------
    draws
        Draws after burn-in and thinning, ``(n_draws, d)``, original scale.
    log_density
        The log-density at each draw (without any Jacobian), ``(n_draws,)``.
    acceptance
        Acceptance rate after burn-in per coordinate, ``(d,)``; for a block
        sampler every free coordinate carries the block's rate; ``NaN`` for
        fixed coordinates.
    scales
        Final proposal standard deviation per coordinate on the sampling scale
        (``z`` for transformed coordinates), ``(d,)``; 0 for fixed ones.
    rng_state
        ``rng.bit_generator.state`` at the start of the run: restoring it into a
        generator of the same bit-generator type reproduces the run.
    n_burn
        Burn-in iterations run (and discarded) before the draws.
    thin
        Iterations per kept draw.
    proposal_cov
        Final proposal covariance of a block sampler on the sampling scale,
        ``(d, d)``, zero rows/columns for fixed coordinates; ``None`` otherwise.
    screened
        Share of the joint proposals after burn-in that the screen turned down
        without evaluating the log-density (delayed acceptance); ``None`` without
        a screen.
    """

    draws: NDArray[np.float64]
    log_density: NDArray[np.float64]
    acceptance: NDArray[np.float64]
    scales: NDArray[np.float64]
    rng_state: Mapping[str, Any]
    n_burn: int
    thin: int
    proposal_cov: NDArray[np.float64] | None = None
    screened: float | None = None

    @property
    def n_draws(self) -> int:
        """Number of kept draws."""
        return int(self.draws.shape[0])


class Sampler(Protocol):
    """What every sampler offers: one ``run`` method."""

    def run(
        self,
        log_density: LogDensity,
        x0: ArrayLike,
        n_draws: int,
        rng: np.random.Generator,
        callback: Callback | None = None,
    ) -> SamplerResult:
        """Draw ``n_draws`` states after burn-in, starting from ``x0`` (d,)."""
        ...


def check_log_density(value: float, x: NDArray[np.float64]) -> float:
    """Return ``value`` as a float, raising on ``NaN`` or ``+inf``."""
    value = float(value)
    if not value < _INF:
        raise LogDensityError(
            f"log-density returned {value} at x = {np.array2string(x, precision=6)}",
            hint="return -inf outside the support; NaN or +inf point to a bug in the model",
        )
    return value


def check_run_args(n_draws: int, n_burn: int, thin: int) -> None:
    """Raise :class:`ConfigError` for impossible run lengths."""
    for name, value, least in (("n_draws", n_draws, 1), ("n_burn", n_burn, 0), ("thin", thin, 1)):
        if int(value) != value or value < least:
            raise ConfigError(
                f"sampler setting {name} must be an integer >= {least}, got {value!r}"
            )


def fixed_mask(fixed: Sequence[bool] | Sequence[int] | None, d: int) -> NDArray[np.bool_]:
    """A boolean mask (d,) from a mask or a list of coordinate indices."""
    if fixed is None:
        return np.zeros(d, dtype=bool)
    arr = np.asarray(fixed)
    if arr.dtype == bool:
        if arr.shape != (d,):
            raise ConfigError(f"fixed mask must have shape ({d},), got {arr.shape}")
        return arr.copy()
    if arr.size and (arr.ndim != 1 or not np.issubdtype(arr.dtype, np.integer)):
        raise ConfigError(f"fixed must be a boolean mask or integer indices, got {fixed!r}")
    if arr.size and (arr.min() < -d or arr.max() >= d):
        raise ConfigError(f"fixed indices {arr.tolist()} out of range for d = {d}")
    mask = np.zeros(d, dtype=bool)
    mask[arr.astype(int)] = True
    return mask


def adaptation_step(batch: int, max_step: float) -> float:
    """Roberts & Rosenthal (2009) adaptation amount ``min(max_step, batch**-0.5)``."""
    return min(max_step, 1.0 / math.sqrt(batch))


def initial_scales(scales: float | Sequence[float] | None, box: Box) -> NDArray[np.float64]:
    """Initial proposal standard deviations (d,) on the sampling scale.

    ``scales`` (scalar or (d,)) if given; else 0.25 * (upper - lower) for a coordinate
    reflected in two bounds and 1 otherwise.
    """
    d = box.lower.size
    if scales is not None:
        given = np.asarray(scales, dtype=float)
        if given.size not in (1, d):
            raise ConfigError(f"proposal scales need 1 or {d} values, got {given.size}")
        s = np.broadcast_to(given.reshape(-1), (d,)).copy()
        if not np.all(np.isfinite(s) & (s > 0)):
            raise ConfigError(f"proposal scales must be positive and finite, got {s.tolist()}")
        return s
    s = np.ones(d)
    if not box.transforms:
        two = np.isfinite(box.lower) & np.isfinite(box.upper)
        s[two] = 0.25 * (box.upper[two] - box.lower[two])
    return s


# --- scalar maps: sampling value -> (x value, log |dx/dz|) -------------------------------
# Closures rather than functools.partial: they are three times faster to call, and
# MetropolisWithinGibbs calls one per coordinate update.


def _logit_map(lo: float, hi: float) -> ScalarMap:
    width, log_width = hi - lo, math.log(hi - lo)
    lo_in, hi_in = math.nextafter(lo, _INF), math.nextafter(hi, -_INF)
    exp, log1p = math.exp, math.log1p

    def logit_map(z: float) -> tuple[float, float]:
        a = z if z >= 0.0 else -z
        e = exp(-a)
        x = lo + width * (1.0 / (1.0 + e) if z >= 0.0 else e / (1.0 + e))
        x = lo_in if x < lo_in else (hi_in if x > hi_in else x)
        return x, log_width - a - 2.0 * log1p(e)

    return logit_map


def _lower_map(lo: float) -> ScalarMap:
    lo_in, exp = math.nextafter(lo, _INF), math.exp

    def lower_map(z: float) -> tuple[float, float]:
        x = lo + exp(z)
        return (x if x > lo_in else lo_in), z

    return lower_map


def _upper_map(hi: float) -> ScalarMap:
    hi_in, exp = math.nextafter(hi, -_INF), math.exp

    def upper_map(z: float) -> tuple[float, float]:
        x = hi - exp(z)
        return (x if x < hi_in else hi_in), z

    return upper_map


def _reflect_two(lo: float, hi: float) -> ScalarMap:
    width = hi - lo

    def reflect_two(x: float) -> tuple[float, float]:
        if lo <= x <= hi:
            return x, 0.0
        t = (x - lo) % (2.0 * width)
        return (lo + t if t <= width else lo + 2.0 * width - t), 0.0

    return reflect_two


def _reflect_lower(lo: float) -> ScalarMap:
    def reflect_lower(x: float) -> tuple[float, float]:
        return (x if x >= lo else 2.0 * lo - x), 0.0

    return reflect_lower


def _reflect_upper(hi: float) -> ScalarMap:
    def reflect_upper(x: float) -> tuple[float, float]:
        return (x if x <= hi else 2.0 * hi - x), 0.0

    return reflect_upper


@dataclass(frozen=True)
class Box:
    """Bounds of the d coordinates and how the sampler respects them.

    Parameters
    ----------
    lower, upper
        Bounds per coordinate, ``(d,)``; ``-inf``/``inf`` where there is none.
    method
        ``"transform"`` or ``"reflect"`` (see the module docstring).
    """

    lower: NDArray[np.float64]
    upper: NDArray[np.float64]
    method: BoundsMethod = "transform"
    _maps: tuple[ScalarMap | None, ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.method not in ("transform", "reflect"):
            raise ConfigError(
                f"bounds method must be 'transform' or 'reflect', got {self.method!r}"
            )
        lo, hi = self.lower, self.upper
        if lo.shape != hi.shape or lo.ndim != 1:
            raise ConfigError(
                f"lower and upper must be 1-D of equal length, got {lo.shape}, {hi.shape}"
            )
        bad = ~(lo < hi) | np.isnan(lo) | np.isnan(hi) | (lo == _INF) | (hi == -_INF)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ConfigError(
                f"coordinate {i}: bounds must satisfy lower < upper, got [{lo[i]}, {hi[i]}]"
            )
        object.__setattr__(self, "_maps", tuple(self._scalar_map(i) for i in range(lo.size)))

    @classmethod
    def build(
        cls, d: int, lower: ArrayLike | None, upper: ArrayLike | None, method: BoundsMethod
    ) -> Box:
        """Bounds for ``d`` coordinates; ``None`` means unbounded on that side."""
        lo = np.full(d, -_INF) if lower is None else np.array(lower, dtype=float).reshape(-1)
        hi = np.full(d, _INF) if upper is None else np.array(upper, dtype=float).reshape(-1)
        if lo.size != d or hi.size != d:
            raise ConfigError(
                f"bounds must have one value per coordinate (d = {d}), "
                f"got {lo.size} lower and {hi.size} upper"
            )
        return cls(lo, hi, method)

    @property
    def transforms(self) -> bool:
        """Whether the sampling scale differs from the original scale."""
        return self.method == "transform"

    def _scalar_map(self, i: int) -> ScalarMap | None:
        lo, hi = float(self.lower[i]), float(self.upper[i])
        has_lo, has_hi = lo > -_INF, hi < _INF
        if not (has_lo or has_hi):
            return None
        if self.method == "reflect":
            if has_lo and has_hi:
                return _reflect_two(lo, hi)
            return _reflect_lower(lo) if has_lo else _reflect_upper(hi)
        if has_lo and has_hi:
            return _logit_map(lo, hi)
        return _lower_map(lo) if has_lo else _upper_map(hi)

    def __reduce__(self) -> tuple[type[Box], tuple[Any, ...]]:
        # The scalar maps are closures; rebuild them instead of pickling them.
        return (type(self), (self.lower, self.upper, self.method))

    def scalar_map(self, i: int) -> ScalarMap | None:
        """Map of coordinate ``i`` from sampling to original scale, ``None`` if identity.

        The map returns ``(x_i, log |dx_i/dz_i|)``; it may raise ``OverflowError``
        for a sampling value too large to represent (treat as rejected).
        """
        return self._maps[i]

    def check_start(self, x0: NDArray[np.float64]) -> None:
        """Raise :class:`ConfigError` unless ``x0`` lies inside the box."""
        inside = (x0 > self.lower) & (x0 < self.upper)
        if self.method == "reflect":
            inside = (x0 >= self.lower) & (x0 <= self.upper)
        if not inside.all():
            i = int(np.flatnonzero(~inside)[0])
            where = "strictly inside" if self.transforms else "inside"
            raise ConfigError(
                f"starting point coordinate {i} = {x0[i]} is not {where} its bounds "
                f"[{self.lower[i]}, {self.upper[i]}]",
                hint="start the chain inside the prior support",
            )

    def to_sampling(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Original scale -> sampling scale, ``(d,)``."""
        if not self.transforms:
            return np.array(x, dtype=float)
        lo, hi = self.lower, self.upper
        z = np.array(x, dtype=float)
        both = np.isfinite(lo) & np.isfinite(hi)
        only_lo = np.isfinite(lo) & ~np.isfinite(hi)
        only_hi = ~np.isfinite(lo) & np.isfinite(hi)
        z[both] = np.log(x[both] - lo[both]) - np.log(hi[both] - x[both])
        z[only_lo] = np.log(x[only_lo] - lo[only_lo])
        z[only_hi] = np.log(hi[only_hi] - x[only_hi])
        return z

    def log_jacobians(self, z: NDArray[np.float64]) -> list[float]:
        """``log |dx_i/dz_i|`` of every coordinate at the sampling values ``z`` (0 if unmapped)."""
        out = [0.0] * z.size
        if self.transforms:
            for i, f in enumerate(self._maps):
                if f is not None:
                    out[i] = f(float(z[i]))[1]
        return out

    def to_original(self, z: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
        """Sampling scale -> original scale (reflected if need be) and ``log |dx/dz|``."""
        x = np.array(z, dtype=float)
        log_jac = 0.0
        for i, f in enumerate(self._maps):
            if f is not None:
                x[i], lj = f(float(z[i]))
                log_jac += lj
        return x, log_jac
