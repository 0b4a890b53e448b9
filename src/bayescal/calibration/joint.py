"""Several records calibrated together: one posterior from the product of their likelihoods.

Two experiments on the same construction (the test box's co-heating and
free-float phases, two walls of one house) each have their own boundary
conditions, simulator runs, PCA basis, emulator and error model. Calibrated
together, the shared parameters ``theta`` get one posterior

    p(theta, e_1 .. e_R | y_1 .. y_R)  ∝  p(theta) prod_r p(e_r) L_r(theta, e_r)

where ``L_r`` is record ``r``'s likelihood of eq. 16 (its emulator at the MAP,
its measured weights) and ``e_r`` its error parameters (``lambda``, the
``lambda*``, AR(1) ``phi``, discrepancy ``r``). The records' errors are taken
as independent of each other; a parameter one record does not calibrate is
held there at that study's value (its nominal, or the value its emulator was
built for). The prior of a shared parameter counts once, so every record must
state the same one.

:class:`JointPosterior` is that log density on the vector ``[u_1 .. u_t,
e_1, .., e_R]`` (``u``: the union of the calibrated parameters on the normalised
scale of their bounds); :func:`joint_sampler` and :func:`joint_starts` configure
Metropolis-within-Gibbs for it as :func:`~bayescal.calibration.target.default_sampler`
does for one record, and :func:`calibrate_joint` samples it to convergence.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from bayescal.calibration.posterior import Callback, Posterior, until_converged
from bayescal.calibration.priors import ThetaPriors
from bayescal.calibration.target import CalibrationPosterior, Moves, default_sampler, default_starts
from bayescal.design import Prior
from bayescal.emulator.kernel import FloatArray
from bayescal.emulator.kron import Lru
from bayescal.errors import ConfigError
from bayescal.mcmc.chains import ChainBackend, dispersed_starts, run_chains
from bayescal.mcmc.samplers.mwg import MetropolisWithinGibbs

__all__ = ["JointPosterior", "Record", "calibrate_joint", "joint_sampler", "joint_starts"]

#: Between a record's label and the name of one of its error parameters (``box-coheating:phi``).
SEPARATOR = ":"


@dataclass(frozen=True)
class Record:
    """One record of a joint calibration.

    Attributes
    ----------
    label
        Its name in the joint posterior (the study's name).
    target
        Its calibration log posterior (:func:`~bayescal.calibration.target.build_target`).
    names
        The target's parameter inputs, in its order.
    held
        The inputs it holds at a value (normalised scale of its bounds): those it
        does not calibrate (``[design] reuse_screening``'s screened-out candidates).
    """

    label: str
    target: CalibrationPosterior
    names: tuple[str, ...]
    held: Mapping[str, float]

    @property
    def calibrated(self) -> tuple[str, ...]:
        """The inputs it calibrates."""
        return tuple(n for n in self.names if n not in self.held)

    @property
    def n_aux(self) -> int:
        """Its error parameters' count (``lambda``, the ``lambda*``, ``phi``, ``r``)."""
        return self.target.d - self.target.t


class JointPosterior:
    """Log posterior of several records sharing parameters, up to a constant (picklable).

    Parameters
    ----------
    records
        Two or more records; a parameter name means the same parameter in each.
    priors
        Every calibrated parameter's prior, in the joint order (the union of the
        records' calibrated parameters, in order of first appearance).
    """

    def __init__(self, records: Sequence[Record], priors: Mapping[str, Prior]) -> None:
        self.records = tuple(records)
        self.names = tuple(priors)
        self.priors = dict(priors)
        self.theta_priors = ThetaPriors(tuple(priors.values()))
        self.t = len(self.names)
        where = {name: k for k, name in enumerate(self.names)}
        self._maps = []
        offset = self.t
        for rec in self.records:
            missing = [n for n in rec.calibrated if n not in where]
            if missing:
                raise ConfigError(f"{rec.label} calibrates {missing}, which have no joint prior")
            # a held input keeps the record's value, even where another record calibrates it
            columns = np.array(
                [-1 if n in rec.held else where.get(n, -1) for n in rec.names], dtype=int
            )
            fill = np.array([rec.held.get(n, math.nan) for n in rec.names], dtype=float)
            self._maps.append((columns, fill, offset))
            offset += rec.n_aux
        self.d = offset
        self._reset()

    def _reset(self) -> None:
        # a move of one record's error parameters leaves the others' vectors as they
        # were: their terms are kept for the current state and the last proposal
        self._memos = [Lru(3) for _ in self.records]

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state.pop("_memos")
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._reset()

    @property
    def aux_names(self) -> tuple[str, ...]:
        """The records' error parameters, ``label:name`` each."""
        return tuple(
            f"{rec.label}{SEPARATOR}{name}" for rec in self.records for name in rec.target.aux_names
        )

    def record_vector(self, k: int, v: ArrayLike) -> FloatArray:
        """Record ``k``'s own vector ``[u_k, e_k]`` at the joint vector ``v``."""
        arr = np.asarray(v, dtype=float)
        columns, fill, offset = self._maps[k]
        u = np.where(columns >= 0, arr[np.maximum(columns, 0)], fill)
        return np.concatenate([u, arr[offset : offset + self.records[k].n_aux]])

    def __call__(self, v: ArrayLike) -> float:
        """``log p(theta) + sum_r [log p(e_r) + log L_r]`` at ``v``."""
        arr = np.asarray(v, dtype=float)
        total = self.theta_priors.scalar(arr[: self.t])
        for k, rec in enumerate(self.records):
            if total == -math.inf:
                return total
            own = self.record_vector(k, arr)
            value = self._memos[k].get(own.tobytes(), functools.partial(_term, rec, own))
            if value == -math.inf:
                return value
            total += value
        return total


def _term(rec: Record, own: FloatArray) -> float:
    """Record ``rec``'s log posterior at its vector ``own`` without its theta prior (the
    joint one counts once)."""
    value = float(rec.target(own))
    if value == -math.inf:
        return value
    return value - rec.target.prior_terms.theta_priors.scalar(own[: rec.target.t])


def joint_sampler(
    target: JointPosterior, n_burn: int, moves: Moves = "gibbs"
) -> MetropolisWithinGibbs:
    """Metropolis-within-Gibbs for ``target``, each record's error parameters set up as
    :func:`~bayescal.calibration.target.default_sampler` sets them for that record alone.

    ``moves = "joint"``: the joint block holds theta and every record's error
    parameters except its ``lambda`` (and the ``lambda*`` of a record with one white
    output), screened by a stand-in where it holds more than theta.
    """
    t = target.t
    lower, upper, scales = [0.0] * t, [1.0] * t, [0.5] * t
    block = list(range(t))
    screen = False
    offset = t
    for rec in target.records:
        own = default_sampler(rec.target, n_burn, moves)
        first = rec.target.t
        assert own.lower is not None
        assert own.upper is not None
        assert own.scales is not None
        lower += list(own.lower)[first:]
        upper += list(own.upper)[first:]
        scales += list(np.broadcast_to(own.scales, (rec.target.d,)))[first:]
        if moves == "joint" and not rec.target.plain:
            block += [offset + k for k in range(1, rec.n_aux)]  # all but its lambda
            screen = True
        offset += rec.n_aux
    joint = tuple(block) if len(block) >= 2 else ()
    # the records' own sampler settings (adaptation batches and cap) with the joint layout
    return dataclasses.replace(
        default_sampler(target.records[0].target, n_burn, moves),
        lower=lower,
        upper=upper,
        scales=scales,
        joint=joint,
        joint_after_burn=len(joint) if moves == "joint" else 0,
        screen=screen and bool(joint),
    )


def joint_starts(target: JointPosterior, n_chains: int, seed: int) -> FloatArray:
    """Dispersed starts: theta by strata in [0.05, 0.95] (``default_rng([seed, 3])``),
    each record's error parameters as :func:`~bayescal.calibration.target.default_starts`."""
    rng = np.random.default_rng([seed, 3])
    columns = [dispersed_starts(np.zeros(target.t), np.ones(target.t), n_chains, rng)]
    for k, rec in enumerate(target.records):
        columns.append(default_starts(rec.target, n_chains, seed + k)[:, rec.target.t :])
    return np.column_stack(columns)


def calibrate_joint(
    target: JointPosterior,
    *,
    n_chains: int = 4,
    n_burn: int = 1000,
    n_draws: int = 1000,
    max_draws: int | None = None,
    seed: int = 0,
    moves: Moves = "gibbs",
    backend: ChainBackend = "processes",
    callback: Callback = None,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_seconds: float = 30.0,
    on_extend: Callable[[int, int], Callable[[int], None] | None] | None = None,
) -> Posterior:
    """Sample ``target`` as :func:`~bayescal.calibration.posterior.calibrate` samples one
    record: ``n_chains`` chains of ``n_burn`` + ``n_draws``, extended up to
    ``max_draws`` while a diagnostic fails, resumable from ``checkpoint_dir``.

    The posterior's ``aux_names`` are the records' error parameters
    (``label:name``); it carries no noise models (each record's are its own).
    """
    if backend not in ("processes", "serial"):
        raise ConfigError(
            f"a joint calibration runs its chains 'processes' or 'serial', got {backend!r}"
        )
    sampler = joint_sampler(target, n_burn, moves)
    x0 = joint_starts(target, n_chains, seed)
    names = (*target.names, *target.aux_names)

    def run_once(kept: int, folder: Any, report: Callback) -> Posterior:
        chains = run_chains(
            sampler,
            target,
            x0,
            kept,
            seed=seed,
            names=names,
            backend=backend,
            callback=report,
            checkpoint_dir=folder,
            checkpoint_seconds=checkpoint_seconds,
        )
        draws = chains.draws
        return Posterior.build(
            names=target.names,
            priors=target.priors,
            unit_draws=draws[..., : target.t],
            log_density=chains.log_density,
            acceptance=chains.acceptance,
            seed=int(seed),
            aux=draws[..., target.t :],
            aux_names=target.aux_names,
        )

    plan: dict[str, object] = {
        "n_burn": n_burn,
        "n_chains": n_chains,
        "seed": int(seed),
        "moves": moves,
        "joint": [rec.label for rec in target.records],
    }
    return until_converged(
        run_once,
        n_draws,
        max_draws,
        plan,
        checkpoint_dir=checkpoint_dir,
        callback=callback,
        on_extend=on_extend,
    )
