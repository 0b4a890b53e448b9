"""The screening artefacts: ``screening/morris.csv``, ``proposal.json`` and ``design.csv``.

``morris.csv`` has one row per output and parameter: ``output, statistic,
parameter, candidate, mu_star, mu_star_conf, mu, sigma, normalised, rank,
trajectories`` (mu*, its 95 % half-interval, mu and sigma in the output's
unit per whole prior range; ``normalised`` is mu* over the output's largest).
``proposal.json`` holds the proposed parameters, their scores, the rule and
the run counts; ``design.csv`` the Morris points (physical values, ``u:``
normalised ones and the trajectory of each). Every file is written through
:mod:`bayescal.atomic`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np
import pandas as pd

from bayescal.atomic import atomic_write_json, atomic_write_text, read_json
from bayescal.screening import MorrisDesign, MorrisIndices, Proposal

__all__ = [
    "DESIGN_FILE",
    "FOLDER",
    "MORRIS_FILE",
    "PROPOSAL_FILE",
    "SCREENING_FORMAT",
    "indices_frame",
    "load_proposal",
    "save_screening",
]

SCREENING_FORMAT: Final = "bayescal-screening/1"
#: Folder in a study's output folder.
FOLDER: Final = "screening"
MORRIS_FILE: Final = "morris.csv"
PROPOSAL_FILE: Final = "proposal.json"
DESIGN_FILE: Final = "design.csv"


def indices_frame(
    indices: Sequence[MorrisIndices], candidates: Sequence[str], statistic: str
) -> pd.DataFrame:
    """The Morris indices of every output as one table (the rows of ``morris.csv``)."""
    rows = []
    for ix in indices:
        for j, name in enumerate(ix.names):
            rows.append(
                {
                    "output": ix.output,
                    "statistic": statistic,
                    "parameter": name,
                    "candidate": name in candidates,
                    "mu_star": ix.mu_star[j],
                    "mu_star_conf": ix.mu_star_conf[j],
                    "mu": ix.mu[j],
                    "sigma": ix.sigma[j],
                    "normalised": ix.normalised[j],
                    "rank": int(ix.ranks[j]),
                    "trajectories": ix.trajectories,
                }
            )
    return pd.DataFrame(rows)


def save_screening(
    folder: Path,
    design: MorrisDesign,
    values: np.ndarray,
    indices: Sequence[MorrisIndices],
    proposal: Proposal,
    *,
    candidates: Sequence[str],
    statistic: str,
    runs: Mapping[str, Any],
) -> list[Path]:
    """Write ``morris.csv``, ``proposal.json`` and ``design.csv`` into ``folder``.

    Parameters
    ----------
    folder
        The screening folder (created if missing).
    design
        The Morris trajectories.
    values
        Physical parameter values of the design, shape ``(runs, k)``.
    indices
        Morris indices, one per output.
    proposal
        The proposed parameters.
    candidates
        Names of the screening candidates (the others are calibrated already).
    statistic
        The scalar screened (``"mean"`` or ``"rmse"``).
    runs
        Counts to record (runs, cached, failed, seconds...).
    """
    folder.mkdir(parents=True, exist_ok=True)
    frame = indices_frame(indices, candidates, statistic)
    written = [atomic_write_text(folder / MORRIS_FILE, frame.to_csv(index=False))]
    document = {
        "format": SCREENING_FORMAT,
        "selected": list(proposal.selected),
        "score": proposal.score,
        "deciding_output": proposal.deciding,
        "threshold": proposal.threshold,
        "max_parameters": proposal.max_parameters,
        "statistic": statistic,
        "candidates": list(candidates),
        "trajectories": design.trajectories,
        "levels": design.levels,
        "seed": design.seed,
        "runs": dict(runs),
    }
    written.append(atomic_write_json(folder / PROPOSAL_FILE, document))
    points = pd.DataFrame(values, columns=list(design.names))
    points.index.name = "run"
    points.insert(0, "trajectory", design.trajectory)
    for j, name in enumerate(design.names):
        points[f"u:{name}"] = design.unit[:, j]
    written.append(atomic_write_text(folder / DESIGN_FILE, points.to_csv(lineterminator="\n")))
    return written


def load_proposal(folder: Path) -> dict[str, Any]:
    """``proposal.json`` of a screening folder, as written."""
    document = read_json(folder / PROPOSAL_FILE)
    if not isinstance(document, dict) or document.get("format") != SCREENING_FORMAT:
        raise ValueError(f"{folder / PROPOSAL_FILE} is not a bayescal screening proposal")
    return document
