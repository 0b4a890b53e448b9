"""Several chains of one sampler, serially, in worker processes, or vectorised.

Chain ``k`` gets its own generator ``numpy.random.default_rng(child_k)`` with
``child_k = numpy.random.SeedSequence(seed).spawn(n_chains)[k]``, so the draws
depend on the seed only, not on whether the chains ran in parallel or in
which order they finished. In processes (``concurrent.futures``), the
log-density, the sampler and the starting points are pickled: use module-level
functions or instances of module-level classes.

Backend ``"vectorised"`` (Metropolis-within-Gibbs only) runs all chains in
this process in lockstep, one batched log-density call per coordinate update
(:mod:`bayescal.mcmc.samplers.lockstep`); each chain consumes its
generator as the serial sampler does, so its draws equal the serial ones
(bit for bit when the batched log-density equals the scalar one row by row).
Its checkpoint is one snapshot of all chains (``lockstep.npz``).

Backend ``"vectorised-processes"`` splits the chains into one lockstep group
per worker process (each group at least 2 chains, its own snapshot
``lockstep-<g>.npz``): both the batching and the cores. Draws are those of
the other backends (each chain keeps its generator).

Backend ``"auto"`` picks one for the target at hand (:func:`choose_backend`):
lockstep where the target says its batched form is worth it
(``lockstep_preferred(n_chains, workers)``; the calibration posterior of
eq. 16 does where its batched likelihood exists), in groups over the workers
where there are several; else worker processes, or one chain here.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from multiprocessing import Manager
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from bayescal.errors import ConfigError
from bayescal.mcmc.checkpoint import ChainCheckpoint
from bayescal.mcmc.samplers.base import Callback, LogDensity, Sampler, SamplerResult
from bayescal.mcmc.samplers.lockstep import as_lockstep, run_lockstep
from bayescal.mcmc.samplers.mwg import MetropolisWithinGibbs

StartFunction = Callable[[np.random.Generator], ArrayLike]
"""Draws a starting point (d,) with the chain's own generator."""

ChainBackend = Literal["processes", "serial", "vectorised", "vectorised-processes", "auto"]
BACKENDS: tuple[str, ...] = get_args(ChainBackend)


@dataclass(frozen=True)
class Chains:
    """The results of several chains of one sampler on one target.

    Attributes
    ----------
    results
        One :class:`SamplerResult` per chain.
    names
        Parameter names, one per coordinate.
    seed
        Entropy of the root ``SeedSequence`` the chains were spawned from.
    """

    results: tuple[SamplerResult, ...]
    names: tuple[str, ...]
    seed: int

    @property
    def draws(self) -> NDArray[np.float64]:
        """Draws, ``(n_chains, n_draws, d)``."""
        return np.stack([r.draws for r in self.results])

    @property
    def log_density(self) -> NDArray[np.float64]:
        """Log-density at the draws, ``(n_chains, n_draws)``."""
        return np.stack([r.log_density for r in self.results])

    @property
    def acceptance(self) -> NDArray[np.float64]:
        """Acceptance rate after burn-in, ``(n_chains, d)`` (NaN for fixed coordinates)."""
        return np.stack([r.acceptance for r in self.results])

    @property
    def n_chains(self) -> int:
        """Number of chains."""
        return len(self.results)


def dispersed_starts(
    lower: ArrayLike,
    upper: ArrayLike,
    n_chains: int,
    rng: np.random.Generator,
    center: ArrayLike | None = None,
    spread: ArrayLike = 1.0,
) -> NDArray[np.float64]:
    """Starting points spread over the support, ``(n_chains, d)``.

    Coordinates bounded on both sides are drawn from a Latin hypercube over
    the middle 90 % of the interval (one stratum per chain); the others from
    ``center + spread * N(0, 1)``, folded to the bounded side if one bound exists.
    With every coordinate bounded on both sides only the strata are drawn
    (``2 d n_chains`` uniform numbers), so a caller may go on drawing other
    quantities from ``rng`` (the calibration's precisions).

    Parameters
    ----------
    lower, upper
        Bounds per coordinate, ``(d,)`` (``-inf``/``inf`` for none).
    n_chains
        Number of starting points.
    rng
        Random generator.
    center, spread
        Location and scale for coordinates not bounded on both sides; default
        center 0 (or 1 beyond a one-sided bound).
    """
    lo = np.asarray(lower, dtype=float).reshape(-1)
    hi = np.asarray(upper, dtype=float).reshape(-1)
    d = lo.size
    both = np.isfinite(lo) & np.isfinite(hi)
    strata = (
        np.argsort(rng.random((d, n_chains)), axis=1).T + rng.random((n_chains, d))
    ) / n_chains
    width = np.where(both, hi - lo, 0.0)
    starts = np.where(both, lo, 0.0) + width * (0.05 + 0.9 * strata)
    if both.all():  # nothing else to draw: the generator is left where the strata left it
        out_box: NDArray[np.float64] = starts
        return out_box
    c = np.zeros(d) if center is None else np.broadcast_to(np.asarray(center, float), (d,))
    c = np.where(np.isfinite(lo) & ~both & (c <= lo), lo + 1.0, c)
    c = np.where(np.isfinite(hi) & ~both & (c >= hi), hi - 1.0, c)
    free = c + np.asarray(spread, dtype=float) * rng.standard_normal((n_chains, d))
    free = np.where(np.isfinite(lo) & (free <= lo), 2 * lo - free, free)
    free = np.where(np.isfinite(hi) & (free >= hi), 2 * hi - free, free)
    out: NDArray[np.float64] = np.where(both, starts, free)
    return out


def run_chains(
    sampler: Sampler,
    log_density: LogDensity,
    starts: ArrayLike | StartFunction,
    n_draws: int,
    *,
    seed: int,
    n_chains: int | None = None,
    names: Sequence[str] | None = None,
    backend: ChainBackend = "processes",
    max_workers: int | None = None,
    callback: Callback | None = None,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_seconds: float = 30.0,
) -> Chains:
    """Run ``n_chains`` chains of ``sampler`` and collect them.

    Parameters
    ----------
    sampler
        Any :class:`~bayescal.mcmc.samplers.base.Sampler`.
    log_density
        The target (picklable for the ``"processes"`` backend).
    starts
        Starting points ``(n_chains, d)``, or a function drawing one from the
        chain's generator (see :func:`dispersed_starts`).
    n_draws
        Draws to keep per chain.
    seed
        Root seed; chain ``k`` uses ``SeedSequence(seed).spawn(n_chains)[k]``.
    n_chains
        Number of chains (the diagnostics expect at least 4); default: the
        number of rows of ``starts``, or 4 with a start function.
    names
        Parameter names; default ``x0, x1, ...``.
    backend
        ``"processes"`` (each chain in a worker process, ``ProcessPoolExecutor``;
        one chain runs here), ``"serial"`` (one after another here) or
        ``"vectorised"`` (all chains in lockstep here, batched log-density
        calls; Metropolis-within-Gibbs only); the log-density's batched form is
        chosen by :func:`~bayescal.mcmc.samplers.lockstep.as_lockstep` (the
        calibration posterior offers the batched Kronecker likelihood);
        ``"vectorised-processes"`` (lockstep groups of at least 2 chains, one
        per worker process); ``"auto"``: one of these by :func:`choose_backend`.
    max_workers
        Worker processes; default ``min(n_chains, os.cpu_count())``.
    callback
        Called in this process with the iterations completed over all chains
        (the total is ``n_chains * (n_burn + n_draws * thin)``); from worker
        processes the count arrives in steps of about 1 % per chain.
    checkpoint_dir
        Folder for one snapshot per chain (``chain-<k>.npz``; one
        ``lockstep.npz`` for all chains with ``"vectorised"``, one
        ``lockstep-<g>.npz`` per group with ``"vectorised-processes"``), written between
        batches at most every ``checkpoint_seconds``; matching snapshots found
        there are resumed, so a killed run continues with identical draws, and a
        finished run called again with more ``n_draws`` continues its chains
        (:mod:`bayescal.mcmc.samplers.schedule`). The sampler must accept
        ``checkpoint=`` (Metropolis-within-Gibbs does).
    checkpoint_seconds
        Minimum wall time between two snapshots of a chain. [s]

    Returns
    -------
    Chains
    """
    mode = _backend(backend, sampler)
    start_list = _start_list(starts, n_chains)
    n_chains = len(start_list)
    if mode == "auto":
        mode = choose_backend(sampler, log_density, n_chains, max_workers)
    children = np.random.SeedSequence(seed).spawn(n_chains)
    groups = lockstep_groups(n_chains, max_workers) if mode == "vectorised-processes" else 1
    if groups > 1:
        _check_picklable(log_density, sampler, starts)
        results = _run_groups(
            sampler,
            log_density,
            start_list,
            n_draws,
            children,
            groups,
            callback,
            None if checkpoint_dir is None else (Path(checkpoint_dir), checkpoint_seconds),
        )
        return _named(results, names, seed)
    if mode in ("vectorised", "vectorised-processes"):
        snapshot = None
        if checkpoint_dir is not None:
            snapshot = ChainCheckpoint(Path(checkpoint_dir) / "lockstep.npz", checkpoint_seconds)
        results = _run_vectorised(
            sampler, log_density, start_list, n_draws, children, callback, snapshot
        )
        return _named(results, names, seed)
    checkpoints: list[ChainCheckpoint | None] = [
        None
        if checkpoint_dir is None
        else ChainCheckpoint(Path(checkpoint_dir) / f"chain-{k}.npz", checkpoint_seconds)
        for k in range(n_chains)
    ]
    if mode == "processes" and n_chains > 1:
        _check_picklable(log_density, sampler, starts)
        results = _run_parallel(
            sampler, log_density, start_list, n_draws, children, max_workers, callback, checkpoints
        )
    else:
        results = []
        for k, child in enumerate(children):
            offset = k * _iterations(sampler, n_draws)
            report = None if callback is None else Offset(callback, offset)
            results.append(
                _run_one(
                    sampler, log_density, start_list[k], n_draws, child, report, checkpoints[k]
                )
            )
    return _named(results, names, seed)


def _named(results: Sequence[SamplerResult], names: Sequence[str] | None, seed: int) -> Chains:
    d = results[0].draws.shape[1]
    chain_names = tuple(names) if names is not None else tuple(f"x{i}" for i in range(d))
    if len(chain_names) != d:
        raise ConfigError(f"got {len(chain_names)} parameter names for {d} coordinates")
    return Chains(tuple(results), chain_names, int(seed))


def choose_backend(
    sampler: Sampler, log_density: Any, n_chains: int, max_workers: int | None = None
) -> str:
    """The backend ``"auto"`` runs: ``"vectorised"``, ``"processes"`` or ``"serial"``.

    Lockstep when the sampler is Metropolis-within-Gibbs and the target's
    ``lockstep_preferred(n_chains, workers)`` (if it has one) says its batched
    form is faster than ``workers`` processes; one chain runs here
    (``"serial"``); otherwise worker processes.

    Parameters
    ----------
    sampler
        The sampler.
    log_density
        The target.
    n_chains
        Number of chains.
    max_workers
        Worker processes the ``"processes"`` backend would use; default
        ``min(n_chains, os.cpu_count())``.
    """
    if n_chains <= 1:
        return "serial"
    workers = max_workers if max_workers is not None else min(n_chains, os.cpu_count() or 1)
    advice = getattr(log_density, "lockstep_preferred", None)
    if not (isinstance(sampler, MetropolisWithinGibbs) and callable(advice)):
        return "processes"
    if not advice(n_chains, max(1, min(workers, n_chains))):
        return "processes"
    return "vectorised-processes" if lockstep_groups(n_chains, workers) > 1 else "vectorised"


def lockstep_groups(n_chains: int, max_workers: int | None = None) -> int:
    """Lockstep groups of ``"vectorised-processes"``: one per worker, each >= 2 chains."""
    workers = max_workers if max_workers is not None else min(n_chains, os.cpu_count() or 1)
    return max(1, min(workers, n_chains // 2))


def _backend(backend: str, sampler: Sampler) -> str:
    if backend not in BACKENDS:
        raise ConfigError(f"chain backend must be one of {list(BACKENDS)}, got {backend!r}")
    lockstep = backend in ("vectorised", "vectorised-processes")
    if lockstep and not isinstance(sampler, MetropolisWithinGibbs):
        raise ConfigError(
            f"backend {backend!r} needs a MetropolisWithinGibbs sampler, "
            f"got {type(sampler).__name__}",
            hint="use backend 'serial' or 'processes' for this sampler",
        )
    return backend


def _run_vectorised(
    sampler: Sampler,
    log_density: LogDensity,
    starts: list[Any],
    n_draws: int,
    children: list[np.random.SeedSequence],
    callback: Callback | None,
    checkpoint: ChainCheckpoint | None,
) -> list[SamplerResult]:
    """All chains in lockstep; chain ``k`` draws its start from its own generator first."""
    assert isinstance(sampler, MetropolisWithinGibbs)  # checked by _backend
    rngs = [np.random.default_rng(child) for child in children]
    x0 = np.array(
        [
            np.asarray(s(rng) if callable(s) else s, dtype=float).reshape(-1)
            for s, rng in zip(starts, rngs, strict=True)
        ]
    )
    return run_lockstep(sampler, as_lockstep(log_density), x0, n_draws, rngs, callback, checkpoint)


@dataclass(frozen=True)
class _Group:
    """One lockstep group of ``"vectorised-processes"``, run in a worker process."""

    sampler: Sampler
    log_density: LogDensity
    n_draws: int
    snapshots: tuple[Path, float] | None

    def __call__(
        self,
        index: int,
        starts: list[Any],
        children: list[np.random.SeedSequence],
        callback: Callback | None,
    ) -> list[SamplerResult]:
        snapshot = None
        if self.snapshots is not None:
            folder, seconds = self.snapshots
            snapshot = ChainCheckpoint(folder / f"lockstep-{index}.npz", seconds)
        return _run_vectorised(
            self.sampler, self.log_density, starts, self.n_draws, children, callback, snapshot
        )


def _run_groups(
    sampler: Sampler,
    log_density: LogDensity,
    starts: list[Any],
    n_draws: int,
    children: list[np.random.SeedSequence],
    n_groups: int,
    callback: Callback | None,
    snapshots: tuple[Path, float] | None,
) -> list[SamplerResult]:
    """The chains in ``n_groups`` contiguous lockstep groups, one per worker process."""
    members = [g.tolist() for g in np.array_split(np.arange(len(starts)), n_groups)]
    group = _Group(sampler, log_density, n_draws, snapshots)
    total = _iterations(sampler, n_draws)
    with ProcessPoolExecutor(max_workers=n_groups) as pool:

        def submit(g: int, report: Callback | None) -> Future[list[SamplerResult]]:
            chains = members[g]
            return pool.submit(
                group, g, [starts[k] for k in chains], [children[k] for k in chains], report
            )

        if callback is None:
            futures = [submit(g, None) for g in range(n_groups)]
        else:
            with Manager() as manager:
                queue = manager.Queue()
                futures = []
                for g, chains in enumerate(members):
                    size = len(chains) * total
                    reporter = _QueueReporter(queue, g, max(1, size // 100), size)
                    futures.append(submit(g, reporter))
                _relay_progress(futures, queue, callback, n_groups)
        return [result for f in futures for result in f.result()]


def _start_list(starts: ArrayLike | StartFunction, n_chains: int | None) -> list[Any]:
    if n_chains is not None and (int(n_chains) != n_chains or n_chains < 1):
        raise ConfigError(f"n_chains must be a positive integer, got {n_chains!r}")
    if callable(starts):
        return [starts] * (4 if n_chains is None else n_chains)
    arr = np.asarray(starts, dtype=float)
    rows = arr.shape[0] if arr.ndim == 2 and n_chains is None else n_chains
    if arr.ndim != 2 or arr.shape[0] != rows or rows < 1:
        raise ConfigError(
            f"starts must have shape (n_chains, d) = ({rows}, d), got {arr.shape}",
            hint="give one starting point per chain, e.g. from dispersed_starts()",
        )
    return list(arr)


def _check_picklable(*objects: object) -> None:
    for obj in objects:
        try:
            pickle.dumps(obj)
        except (pickle.PicklingError, AttributeError, TypeError) as exc:
            raise ConfigError(
                f"cannot send {type(obj).__name__} {obj!r:.60} to worker processes: {exc}",
                hint="define it at module level (no lambdas or local functions), "
                "or run the chains with backend='serial'",
            ) from exc


def _iterations(sampler: Sampler, n_draws: int) -> int:
    return int(getattr(sampler, "n_burn", 0)) + n_draws * int(getattr(sampler, "thin", 1))


def _run_one(
    sampler: Sampler,
    log_density: LogDensity,
    start: Any,
    n_draws: int,
    seed: np.random.SeedSequence,
    callback: Callback | None,
    checkpoint: ChainCheckpoint | None = None,
) -> SamplerResult:
    rng = np.random.default_rng(seed)
    x0 = start(rng) if callable(start) else start
    if checkpoint is None:
        return sampler.run(log_density, x0, n_draws, rng, callback=callback)
    run: Any = sampler.run  # samplers with checkpoints accept the keyword
    result: SamplerResult = run(
        log_density, x0, n_draws, rng, callback=callback, checkpoint=checkpoint
    )
    return result


@dataclass(frozen=True)
class Offset:
    """Progress of one part reported as progress of the whole: adds ``offset``."""

    callback: Callback
    offset: int

    def __call__(self, iteration: int) -> None:
        self.callback(self.offset + iteration)


@dataclass(frozen=True)
class _QueueReporter:
    """Worker-side progress: put ``(chain, iteration)`` on a queue about every 1 %."""

    queue: Any
    chain: int
    every: int
    total: int

    def __call__(self, iteration: int) -> None:
        if iteration % self.every == 0 or iteration == self.total:
            self.queue.put((self.chain, iteration))


def _run_parallel(
    sampler: Sampler,
    log_density: LogDensity,
    starts: list[Any],
    n_draws: int,
    children: list[np.random.SeedSequence],
    max_workers: int | None,
    callback: Callback | None,
    checkpoints: list[ChainCheckpoint | None],
) -> list[SamplerResult]:
    n = len(children)
    total = _iterations(sampler, n_draws)
    workers = max_workers if max_workers is not None else n
    with ProcessPoolExecutor(max_workers=min(workers, n)) as pool:
        if callback is None:
            futures = [
                pool.submit(
                    _run_one,
                    sampler,
                    log_density,
                    starts[k],
                    n_draws,
                    children[k],
                    None,
                    checkpoints[k],
                )
                for k in range(n)
            ]
            return [f.result() for f in futures]
        with Manager() as manager:
            queue = manager.Queue()
            every = max(1, total // 100)
            futures = [
                pool.submit(
                    _run_one,
                    sampler,
                    log_density,
                    starts[k],
                    n_draws,
                    children[k],
                    _QueueReporter(queue, k, every, total),
                    checkpoints[k],
                )
                for k in range(n)
            ]
            _relay_progress(futures, queue, callback, n)
            return [f.result() for f in futures]


def _relay_progress(futures: list[Future[Any]], queue: Any, callback: Callback, n: int) -> None:
    """Call ``callback`` with the summed progress until every future is done."""
    progress = [0] * n
    pending = set(futures)
    while True:
        while not queue.empty():
            chain, iteration = queue.get()
            progress[chain] = iteration
            callback(sum(progress))
        if not pending:
            break
        _, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
