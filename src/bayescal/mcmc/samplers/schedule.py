"""The batch schedule of adaptive Metropolis-within-Gibbs, shared by one chain and many.

:class:`~bayescal.mcmc.samplers.mwg.MetropolisWithinGibbs` runs its sweeps in
batches of ``batch_size``: burn-in batches, after each of which every proposal
width is adapted (Roberts & Rosenthal 2009), then the batches whose sweeps are
kept (every ``thin``-th). The same schedule drives a single chain
(:meth:`~bayescal.mcmc.samplers.mwg.MetropolisWithinGibbs.run`) and ``B``
chains in lockstep (:func:`~bayescal.mcmc.samplers.lockstep.run_lockstep`):
only the inner loop differs, behind the small :class:`ChainSet` protocol.

Between batches the schedule may write a snapshot (:class:`~bayescal.mcmc.
checkpoint.ChainCheckpoint`): the chain set's state (points, sampling-scale
values, proposal widths, acceptance counts), the draws kept so far and every
generator's state, so that a killed run resumes with the draws of an
uninterrupted one. A snapshot is resumed only if its fingerprint (settings,
starting points, the generators' initial states) matches and it has not run
past the requested length. The last batch always writes one, so a finished
run can be *extended*: the same call with more draws resumes it and keeps
sampling from the chains' state, widths frozen after burn-in as they were. When
the first run's kept sweeps fill whole batches, the result equals the draws of a
run that had asked for that many from the start; otherwise (a batch draws its
random numbers at once, so a short last batch shifts the stream) it is another,
equally valid continuation of the same chains, reproducible from the seed.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from bayescal.mcmc.checkpoint import ChainCheckpoint

FloatArray = NDArray[np.float64]
Kept = tuple[FloatArray, Any]
"""One kept sweep: the point(s) (a copy) and the log-density value(s)."""

__all__ = ["ChainSet", "Schedule", "batch_sizes", "fingerprint"]


def batch_sizes(total: int, batch: int) -> list[int]:
    """Split ``total`` iterations into batches of ``batch`` (the last may be shorter)."""
    sizes = [batch] * (total // batch)
    if total % batch:
        sizes.append(total % batch)
    return sizes


def fingerprint(settings: object, x0: FloatArray, rng_states: Any) -> str:
    """What a snapshot must match to be resumed: settings, start and seeds.

    Not the number of draws: a finished run's last snapshot is where a longer run
    with the same settings stands after as many sweeps, so it extends the run
    (:meth:`Schedule.run`).
    """
    text = json.dumps([repr(settings), x0.tolist(), rng_states], default=str)
    return hashlib.sha256(text.encode()).hexdigest()


class ChainSet(Protocol):
    """The part of the sampler that differs between one chain and many."""

    def block(self, size: int, n_done: int, keep_every: int, keep_start: int) -> list[Kept]:
        """Run ``size`` sweeps after ``n_done``; keep a copy every ``keep_every`` sweeps
        counted from ``keep_start`` (``keep_every = 0``: keep none)."""
        ...

    def reset_counts(self) -> None:
        """Start counting acceptances afresh."""
        ...

    def adapt(self, size: int, n_batch: int) -> None:
        """Adapt the proposal widths after burn-in batch ``n_batch`` of ``size`` sweeps."""
        ...

    def state(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """Arrays and JSON-able metadata of the current state (for a snapshot)."""
        ...

    def restore(self, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
        """Take over a state written by :meth:`state`."""
        ...


@dataclass(frozen=True)
class Schedule:
    """Burn-in and kept batches of one run.

    Parameters
    ----------
    n_burn
        Burn-in sweeps (adapted, discarded).
    n_draws
        Kept draws.
    thin
        Sweeps per kept draw.
    batch_size
        Sweeps per batch.
    """

    n_burn: int
    n_draws: int
    thin: int
    batch_size: int

    @property
    def burn(self) -> list[int]:
        """Sizes of the burn-in batches."""
        return batch_sizes(self.n_burn, self.batch_size)

    def run(
        self,
        chains: ChainSet,
        start: Callable[[], None],
        checkpoint: ChainCheckpoint | None,
        fingerprint: str,
        draw_shape: Sequence[int],
    ) -> tuple[FloatArray, FloatArray]:
        """Run the batches, resuming or extending a matching snapshot: draws, log-densities.

        Parameters
        ----------
        chains
            The chain set.
        start
            Puts the chain set in its starting state; called unless a snapshot is resumed.
        checkpoint
            Where snapshots go, or ``None``.
        fingerprint
            The run's :func:`fingerprint`.
        draw_shape
            Shape of one kept point: ``(d,)`` for one chain, ``(B, d)`` for ``B``.

        Returns
        -------
        draws, log_density
            ``(n_draws, *draw_shape)`` and ``(n_draws, *draw_shape[:-1])``.
        """
        burn, total = self.burn, self.n_burn + self.n_draws * self.thin
        kept: list[Kept] = []
        first, n_done = 0, 0
        resumed = None if checkpoint is None else checkpoint.load(fingerprint)
        if resumed is not None and int(resumed[1]["n_done"]) > total:
            resumed = None  # a longer run's snapshot: it cannot be cut back
        if resumed is None:
            start()
        else:
            arrays, meta = resumed
            chains.restore(arrays, meta)
            first, n_done = int(meta["next_batch"]), int(meta["n_done"])
            kept = list(zip(arrays["draws"], arrays["lps"].tolist(), strict=True))
        index = first
        for size in burn[first:] if n_done < self.n_burn else []:
            chains.reset_counts()
            chains.block(size, n_done, 0, 0)
            chains.adapt(size, index + 1)
            if index == len(burn) - 1:
                chains.reset_counts()
            n_done += size
            index += 1
            if checkpoint is not None and checkpoint.due():
                self._snapshot(chains, checkpoint, fingerprint, index, n_done, kept, draw_shape)
        rest = batch_sizes(total - n_done, self.batch_size)
        for j, size in enumerate(rest):
            if n_done == 0:
                chains.reset_counts()
            kept.extend(chains.block(size, n_done, self.thin, self.n_burn))
            n_done += size
            index += 1
            if checkpoint is not None and (checkpoint.due() or j == len(rest) - 1):
                self._snapshot(chains, checkpoint, fingerprint, index, n_done, kept, draw_shape)
        draws = np.array([k[0] for k in kept], dtype=float).reshape(self.n_draws, *draw_shape)
        lps = np.array([k[1] for k in kept], dtype=float).reshape(self.n_draws, *draw_shape[:-1])
        return draws, lps

    @staticmethod
    def _snapshot(
        chains: ChainSet,
        checkpoint: ChainCheckpoint,
        fingerprint: str,
        next_batch: int,
        n_done: int,
        kept: list[Kept],
        draw_shape: Sequence[int],
    ) -> None:
        arrays, meta = chains.state()
        arrays["draws"] = np.array([k[0] for k in kept], dtype=float).reshape(
            len(kept), *draw_shape
        )
        arrays["lps"] = np.array([k[1] for k in kept], dtype=float).reshape(
            len(kept), *draw_shape[:-1]
        )
        meta |= {"fingerprint": fingerprint, "next_batch": next_batch, "n_done": n_done}
        checkpoint.save(arrays, meta)
