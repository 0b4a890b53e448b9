"""The parameters to calibrate, from any screening's indices (Morris mu*, Sobol ST).

For each output, a parameter's *score* is its index over the largest index of
that output (1 for the most influential): ``mu*`` for Morris
(:mod:`~bayescal.screening.morris`), the total Sobol index ``ST`` for
:mod:`~bayescal.screening.sobol`. Its score is its best over the outputs, so
a parameter that matters for one output only is kept. Parameters whose score
reaches ``threshold`` are proposed, most influential first, at most
``max_parameters`` of them. This is a screening rule, not a test: look at
the intervals before dropping a parameter near the threshold.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

__all__ = ["Proposal", "Ranked", "propose"]


class Ranked(Protocol):
    """What :func:`propose` reads of one output's indices."""

    @property
    def output(self) -> str:
        """The output the indices belong to."""

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names, in column order."""

    @property
    def measure(self) -> str:
        """The index ranked by (``"mu*"``, ``"ST"``)."""

    @property
    def normalised(self) -> np.ndarray:
        """The index over the output's largest, shape ``(k,)``."""


@dataclass(frozen=True)
class Proposal:
    """The parameters proposed for calibration (see the module notes).

    Attributes
    ----------
    selected
        Proposed parameters, most influential first.
    score
        Parameter -> best normalised index over the outputs. [-]
    deciding
        Parameter -> the output where its score was reached.
    threshold
        Score a parameter must reach. [-]
    max_parameters
        Cap on the number proposed (``None``: no cap).
    measure
        The index scored: ``"mu*"`` (Morris) or ``"ST"`` (Sobol).
    """

    selected: tuple[str, ...]
    score: dict[str, float]
    deciding: dict[str, str]
    threshold: float
    max_parameters: int | None
    measure: str = "mu*"


def propose(
    indices: Sequence[Ranked], threshold: float = 0.1, max_parameters: int | None = None
) -> Proposal:
    """The parameters whose index reaches ``threshold`` of the top one for some output.

    Parameters
    ----------
    indices
        Indices of one method, one per output (same parameter names).
    threshold
        Fraction of the largest index of an output. [-]
    max_parameters
        Propose at most this many.
    """
    if not indices:
        raise ValueError("propose needs the indices of at least one output")
    names = indices[0].names
    table = np.vstack([ix.normalised for ix in indices])  # (outputs, k)
    best = np.argmax(table, axis=0)
    score = {n: float(table[best[j], j]) for j, n in enumerate(names)}
    deciding = {n: indices[int(best[j])].output for j, n in enumerate(names)}
    order = sorted(names, key=lambda n: -score[n])
    selected = [n for n in order if score[n] >= threshold]
    if max_parameters is not None:
        selected = selected[:max_parameters]
    return Proposal(
        tuple(selected), score, deciding, float(threshold), max_parameters, indices[0].measure
    )
