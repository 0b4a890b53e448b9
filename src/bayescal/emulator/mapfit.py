"""The emulator's MAP by quasi-Newton search, and a Laplace approximation around it.

Why not only Metropolis-within-Gibbs
------------------------------------
The paper explores eq. 9 by Metropolis-within-Gibbs and keeps the MAP; the
emulator then uses the MAP only. At ``R = 500`` runs every move of a theta
correlation parameter costs an ``R x R`` eigen-decomposition, so thousands of
sweeps cost minutes. Here the MAP is found directly, on the log scale
``u = ln [beta, tau, lambda]`` the chains sample, with the exact gradient of
:class:`~bayescal.emulator.gradient.LogScalePosterior` and L-BFGS-B.

Several modes
-------------
Eq. 9 has local maxima: the variable conditions ``x`` are PCA weights of
boundary conditions that move together, so a basis weight may be explained by
one input or by another (on the virtual wall each basis has two to four modes,
tens to hundreds of log units apart, that differ in which ``x`` input gets a
large ``beta``). Given ``lambda`` the bases are independent, so the search runs
per basis at ``lambda`` fixed at its prior mode, from

* a neutral start (every ``beta = 1``, ``tau = 1``) and one start per input with
  that input's ``beta = e^3`` (the input "dominant"), then
* random starts (``ln beta ~ N(0, 1.5^2)``) until the best optimum has been
  reached by two starts (``confirmations``) or ``max_starts`` is reached.

Above ``explore_runs`` (64) design runs the starts run on a random subset of
that many runs (all periods: the modes are set by how the weights vary over
the periods' conditions; on the 500 x 200 virtual wall their order on 60 runs
was that on all 500 in both bases checked); the best ``candidates`` (3)
distinct optima are then polished on all runs and the best kept. A start there costs one
``64 x 64`` and one ``m* x m*`` eigen-decomposition per iteration instead of an
``R x R`` one.

The per-basis optima are joined and polished together with ``lambda``
(L-BFGS-B on all ``d`` coordinates). Each L-BFGS-B run stops by its own
criteria (relative decrease ``ftol``, projected gradient ``gtol``), so the
amount of work is set by convergence, not by a fixed number of sweeps.

Warm starts
-----------
Where the MAP of a similar problem is known (the sequential design's previous
step: the same inputs, a few more runs), ``find_map(..., warm=blocks)`` starts
basis ``j`` from ``blocks[j]`` and from the neutral start only, both on all
runs, and keeps the better; bases beyond ``blocks`` get the full search. Two
starts instead of up to ``2 (r + 1)`` plus the polish: a local search near a
known mode, not a search for the best mode.

Laplace approximation
---------------------
The hyperparameters' uncertainty is summarised by the Gaussian approximation
``N(u_map, H^-1)`` on the log scale, ``H`` the negative Hessian by central
differences of the exact gradient. ``H`` is block-diagonal over the bases
except for the ``lambda`` row, so a column costs one basis evaluation
(``2 d`` basis evaluations in all). A direction whose curvature is not
clearly positive gets unit curvature (:func:`laplace_covariance`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from bayescal.emulator.gradient import LogScalePosterior
from bayescal.emulator.kernel import FloatArray
from bayescal.errors import ConfigError

__all__ = [
    "BasisSearch",
    "MapResult",
    "MapSettings",
    "default_processes",
    "find_map",
    "laplace_covariance",
    "laplace_draws",
    "laplace_hessian",
    "search_basis",
    "structured_starts",
    "warm_basis",
]

#: Bounds of ``ln beta``, ``ln tau`` and ``ln lambda`` during the search: far
#: outside anything a standardised problem reaches (``beta = e^10``: correlation
#: ``e^-22000`` at 1 % of the input range).
LOG_BETA_BOUNDS = (-25.0, 10.0)
LOG_TAU_BOUNDS = (-20.0, 20.0)
LOG_LAMBDA_BOUNDS = (-30.0, 30.0)
DOMINANT = 3.0  # ln beta of the "dominant" input of a structured start


@dataclass(frozen=True)
class MapSettings:
    """Settings of the MAP search.

    Parameters
    ----------
    max_starts
        Most starts per basis (structured and random together); default
        ``2 (r + 1)``.
    confirmations
        Starts that must reach the best optimum (to ``tol``) before the
        random starts stop.
    tol
        Two optima are the same when their log densities differ by less than
        ``tol + 1e-9 |value|``.
    explore_runs
        Above this many design runs the starts are run on a random subset of
        that many runs (all periods) and the best ``candidates`` distinct
        optima are then polished on all runs.
    candidates
        Optima of the subset polished on all runs.
    ftol, gtol
        L-BFGS-B's relative-decrease and projected-gradient criteria.
    max_iter
        Iterations per L-BFGS-B run.
    """

    max_starts: int | None = None
    confirmations: int = 2
    tol: float = 0.01
    explore_runs: int = 64
    candidates: int = 3
    ftol: float = 1e-12
    gtol: float = 1e-4
    max_iter: int = 500

    def __post_init__(self) -> None:
        for name in ("confirmations", "explore_runs", "candidates", "max_iter"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.max_starts is not None and self.max_starts < 1:
            raise ConfigError(f"max_starts must be >= 1, got {self.max_starts}")

    def same(self, value: float, best: float) -> bool:
        """Whether ``value`` reaches ``best`` to the tolerance."""
        return value >= best - self.tol - 1e-9 * abs(best)


@dataclass(frozen=True)
class BasisSearch:
    """The multi-start search of one basis at fixed ``lambda``.

    Attributes
    ----------
    u
        Best ``ln [beta_j, tau_j]``, ``(r + 1,)``.
    value
        Its log-scale density (basis term at the fixed ``lambda``, all runs).
    optima
        Log density reached by each start (on the subset where one is used).
    polished
        Log density of each polished candidate on all runs (empty without a subset).
    evaluations
        Basis evaluations on the subset and on all runs.
    """

    u: FloatArray
    value: float
    optima: tuple[float, ...]
    polished: tuple[float, ...]
    evaluations: tuple[int, int]


@dataclass(frozen=True)
class MapResult:
    """The MAP of eq. 9 on the log scale.

    Attributes
    ----------
    u
        ``ln`` of the MAP vector ``(d,)``.
    value
        Log-scale log posterior at ``u``.
    u_start
        The joined per-basis optima before the joint polish ``(d,)``.
    value_start
        Its log-scale log posterior.
    searches
        One :class:`BasisSearch` per basis.
    joint_evaluations
        Evaluations of all bases in the joint polish.
    """

    u: FloatArray
    value: float
    u_start: FloatArray
    value_start: float
    searches: tuple[BasisSearch, ...]
    joint_evaluations: int


def _block_bounds(r: int) -> list[tuple[float, float]]:
    return [LOG_BETA_BOUNDS] * r + [LOG_TAU_BOUNDS]


def structured_starts(r: int) -> list[FloatArray]:
    """The neutral start and one start per input with that input dominant, ``(r + 1,)`` each."""
    neutral = np.zeros(r + 1)
    out = [neutral]
    for i in range(r):
        start = neutral.copy()
        start[i] = DOMINANT
        out.append(start)
    return out


@dataclass(frozen=True)
class _BasisObjective:
    """``-(basis term)`` and its gradient at fixed ``lambda``, for L-BFGS-B."""

    post: LogScalePosterior
    j: int
    lam: float

    def __call__(self, u_block: FloatArray) -> tuple[float, FloatArray]:
        term = self.post.basis(self.j, u_block, self.lam)
        if not math.isfinite(term.value):
            return 1e300, np.zeros_like(u_block)
        return -term.value, -term.grad


def _lbfgs(
    f: Callable[[FloatArray], tuple[float, FloatArray]],
    u0: FloatArray,
    bounds: Sequence[tuple[float, float]],
    settings: MapSettings,
) -> tuple[FloatArray, float]:
    res = optimize.minimize(
        f,
        np.clip(u0, [b[0] for b in bounds], [b[1] for b in bounds]),
        jac=True,
        method="L-BFGS-B",
        bounds=bounds,
        options={
            "maxiter": settings.max_iter,
            "maxfun": 2 * settings.max_iter,
            "ftol": settings.ftol,
            "gtol": settings.gtol,
        },
    )
    return np.asarray(res.x, dtype=float), -float(res.fun)


def _multistart(
    post: LogScalePosterior, j: int, lam: float, seed: int, settings: MapSettings
) -> list[tuple[float, FloatArray]]:
    """Every start's optimum ``(value, u)``, in order (module docstring)."""
    r = post.layout.r
    f = _BasisObjective(post, j, lam)
    bounds = _block_bounds(r)
    structured = structured_starts(r)
    max_starts = settings.max_starts if settings.max_starts is not None else 2 * (r + 1)
    rng = np.random.default_rng([seed, 7, j])
    found: list[tuple[float, FloatArray]] = []
    for k in range(max_starts):
        if k < len(structured):
            start = structured[k]
        else:
            best = max(v for v, _ in found)
            if sum(settings.same(v, best) for v, _ in found) >= settings.confirmations:
                break
            start = np.append(rng.normal(0.0, 1.5, r), rng.normal(0.0, 0.5))
        u, value = _lbfgs(f, start, bounds, settings)
        found.append((value, u))
    return found


def distinct_best(
    found: Sequence[tuple[float, FloatArray]], k: int, settings: MapSettings
) -> list[tuple[float, FloatArray]]:
    """The ``k`` best optima whose values differ by more than the tolerance."""
    out: list[tuple[float, FloatArray]] = []
    for value, u in sorted(found, key=lambda item: -item[0]):
        if all(not settings.same(value, v) for v, _ in out):
            out.append((value, u))
        if len(out) == k:
            break
    return out


def search_basis(
    post: LogScalePosterior,
    explore: LogScalePosterior | None,
    j: int,
    lam: float,
    seed: int,
    settings: MapSettings,
) -> BasisSearch:
    """Multi-start L-BFGS-B of basis ``j`` at fixed ``lambda`` (module docstring).

    Parameters
    ----------
    post
        The posterior on all runs.
    explore
        The same on a subset of runs, where the starts run; ``None``: on ``post``.
    j
        Basis index.
    lam
        The fixed ``lambda``. [-]
    seed
        Seed of the random starts.
    settings
        Search settings.
    """
    where = post if explore is None else explore
    before_sub, before_all = where.evaluations, post.evaluations
    found = _multistart(where, j, lam, seed, settings)
    polished: list[float] = []
    if explore is None:
        value, u = max(found, key=lambda item: item[0])
        spent = (0, post.evaluations - before_all)
    else:
        f = _BasisObjective(post, j, lam)
        bounds = _block_bounds(post.layout.r)
        value, u = -math.inf, found[0][1]
        for _, start in distinct_best(found, settings.candidates, settings):
            u_k, value_k = _lbfgs(f, start, bounds, settings)
            polished.append(value_k)
            if value_k > value:
                value, u = value_k, u_k
        spent = (explore.evaluations - before_sub, post.evaluations - before_all)
    return BasisSearch(u, value, tuple(v for v, _ in found), tuple(polished), spent)


def warm_basis(
    post: LogScalePosterior, j: int, lam: float, start: FloatArray, settings: MapSettings
) -> BasisSearch:
    """L-BFGS-B of basis ``j`` at fixed ``lambda`` from ``start`` and from the neutral
    start, on all runs; the better optimum (module docstring, "Warm starts")."""
    f = _BasisObjective(post, j, lam)
    bounds = _block_bounds(post.layout.r)
    before = post.evaluations
    found = [_lbfgs(f, u0, bounds, settings) for u0 in (start, structured_starts(post.layout.r)[0])]
    u, value = max(found, key=lambda item: item[1])
    return BasisSearch(u, value, tuple(v for _, v in found), (), (0, post.evaluations - before))


@dataclass(frozen=True)
class _SearchTask:
    """One basis's search, sent to a worker process."""

    post: LogScalePosterior
    explore: LogScalePosterior | None
    lam: float
    seed: int
    settings: MapSettings
    warm: tuple[FloatArray, ...] = ()

    def __call__(self, j: int) -> BasisSearch:
        if j < len(self.warm):
            return warm_basis(self.post, j, self.lam, self.warm[j], self.settings)
        return search_basis(self.post, self.explore, j, self.lam, self.seed, self.settings)


@dataclass(frozen=True)
class _JointObjective:
    """``-(log-scale log posterior)`` and its gradient in scaled coordinates ``z = u * scale``.

    ``lambda``'s eq. 7 prior is very sharp (shape ``~ m (n - p) / 2``): its
    curvature on the log scale is about its shape, orders of magnitude above
    the others', which stalls L-BFGS-B's first line search. Scaling its
    coordinate by the square root of the shape evens the curvatures out.
    """

    post: LogScalePosterior
    scale: FloatArray

    def __call__(self, z: FloatArray) -> tuple[float, FloatArray]:
        value, grad = self.post.value_and_grad(z / self.scale)
        if not math.isfinite(value):
            return 1e300, np.zeros_like(z)
        return -value, -grad / self.scale


def explore_posterior(
    post: LogScalePosterior, settings: MapSettings, seed: int
) -> LogScalePosterior | None:
    """The subset of runs the starts run on, or ``None`` for all runs."""
    n = post.n_runs
    if n <= settings.explore_runs:
        return None
    rng = np.random.default_rng([seed, 11])
    return post.subset(np.sort(rng.choice(n, settings.explore_runs, replace=False)))


def find_map(
    post: LogScalePosterior,
    *,
    seed: int = 0,
    settings: MapSettings | None = None,
    processes: int = 1,
    callback: Callable[[int], None] | None = None,
    warm: Sequence[FloatArray] = (),
) -> MapResult:
    """The MAP of eq. 9 on the log scale (module docstring).

    Parameters
    ----------
    post
        The log-scale posterior.
    seed
        Seed of the random starts and of the subset of runs.
    settings
        Search settings (defaults: :class:`MapSettings`).
    processes
        Worker processes for the per-basis searches (1: all here).
    callback
        Called with the number of bases searched so far (then ``p + 1`` after the polish).
    warm
        Starts ``ln [beta_j, tau_j]`` (``(r + 1,)`` each) of the first ``len(warm)``
        bases (module docstring, "Warm starts"); extra blocks are ignored.

    Raises
    ------
    ValueError
        A warm block is not of length ``r + 1``.
    """
    cfg = MapSettings() if settings is None else settings
    layout = post.layout
    blocks = tuple(np.asarray(b, dtype=float) for b in warm[: layout.p])
    if any(b.shape != (layout.r + 1,) for b in blocks):
        raise ValueError(f"warm starts must be blocks of length r + 1 = {layout.r + 1}")
    shape, rate = post.lam_prior
    lam0 = max(shape - 1.0, 1.0) / rate  # the prior mode (eq. 7: sharp)
    explore = explore_posterior(post, cfg, seed) if len(blocks) < layout.p else None
    task = _SearchTask(post, explore, lam0, int(seed), cfg, blocks)
    searches: list[BasisSearch] = []
    if processes > 1 and layout.p > 1:
        with ProcessPoolExecutor(max_workers=min(processes, layout.p)) as pool:
            for found in pool.map(task, range(layout.p)):
                searches.append(found)
                if callback is not None:
                    callback(len(searches))
    else:
        for j in range(layout.p):
            searches.append(task(j))
            if callback is not None:
                callback(j + 1)
    u0 = np.concatenate([*(s.u for s in searches), [math.log(lam0)]])
    before = post.evaluations
    value0 = post.value(u0)
    scale = np.ones(layout.d)
    scale[layout.lam_index] = math.sqrt(max(shape, 1.0))
    bounds = [
        (lo * k, hi * k)
        for (lo, hi), k in zip(
            _block_bounds(layout.r) * layout.p + [LOG_LAMBDA_BOUNDS], scale, strict=True
        )
    ]
    z, value = _lbfgs(_JointObjective(post, scale), u0 * scale, bounds, cfg)
    u = z / scale
    if not value >= value0:  # the polish never loses what the search found
        u, value = u0, value0
    if callback is not None:
        callback(layout.p + 1)
    joint = (post.evaluations - before) // layout.p
    return MapResult(u, value, u0, value0, tuple(searches), joint)


def laplace_hessian(post: LogScalePosterior, u: FloatArray, step: float = 1e-4) -> FloatArray:
    """Negative Hessian ``(d, d)`` of the log-scale log posterior at ``u``.

    Central differences of the exact gradient, one basis at a time: a
    coordinate of basis ``j`` moves basis ``j``'s gradient and the ``lambda``
    derivative only; ``lambda`` moves every basis. Symmetrised.

    Parameters
    ----------
    post
        The log-scale posterior.
    u
        The point (the MAP), ``(d,)``.
    step
        Central-difference step on the log scale.
    """
    layout = post.layout
    d, r, li = layout.d, layout.r, layout.lam_index
    lam = math.exp(float(u[li]))
    hess = np.zeros((d, d))
    for j in range(layout.p):
        block = layout.block(j)
        base = u[block].copy()
        for i in range(r + 1):
            up, down = base.copy(), base.copy()
            up[i] += step
            down[i] -= step
            t_up, t_down = post.basis(j, up, lam), post.basis(j, down, lam)
            col = block.start + i
            hess[block, col] = (t_up.grad - t_down.grad) / (2.0 * step)
            hess[li, col] = (t_up.grad_lam - t_down.grad_lam) / (2.0 * step)
    g_up = post.value_and_grad(np.where(np.arange(d) == li, u + step, u))[1]
    g_down = post.value_and_grad(np.where(np.arange(d) == li, u - step, u))[1]
    hess[:, li] = (g_up - g_down) / (2.0 * step)
    hess = -0.5 * (hess + hess.T)
    return hess


def laplace_covariance(hess: FloatArray) -> FloatArray:
    """Covariance ``H^-1`` of the Laplace approximation, ``(d, d)``.

    Directions whose curvature is not clearly positive (below ``1e-8`` of the
    largest: flat directions of inputs without influence, or a point that
    is not quite a maximum) get unit curvature, a standard deviation of 1 on
    the log scale (a factor ``e`` either way).
    """
    values, vectors = np.linalg.eigh(hess)
    floor = 1e-8 * max(float(values.max()), 1.0)
    values = np.where(values > floor, values, 1.0)
    cov: FloatArray = (vectors / values) @ vectors.T
    return 0.5 * (cov + cov.T)


def laplace_draws(u: FloatArray, cov: FloatArray, n: int, rng: np.random.Generator) -> FloatArray:
    """``n`` draws ``(n, d)`` of ``exp(N(u, cov))`` (original scale)."""
    values, vectors = np.linalg.eigh(cov)
    half = vectors * np.sqrt(np.maximum(values, 0.0))
    z = rng.standard_normal((n, u.size))
    with np.errstate(over="ignore"):
        out: FloatArray = np.exp(u + z @ half.T)
    return out


def default_processes(p: int) -> int:
    """Worker processes for ``p`` per-basis searches: at most the CPUs, at most ``p``."""
    return max(1, min(p, os.cpu_count() or 1))
