"""The screening artefacts: ``screening/morris.csv`` or ``sobol.csv``, ``proposal.json``,
``design.csv``.

``morris.csv`` has one row per output and parameter: ``output, statistic,
parameter, candidate, mu_star, mu_star_conf, mu, sigma, normalised, rank,
trajectories`` (mu*, its 95 % half-interval, mu and sigma in the output's
unit per whole prior range; ``normalised`` is mu* over the output's largest).
``proposal.json`` holds the proposed parameters, their scores, the rule and
the run counts; ``design.csv`` the Morris points (physical values, ``u:``
normalised ones and the trajectory of each).

``sobol.csv`` (``[screening] method = "sobol"``) has one row per output and
parameter: ``output, statistic, parameter, candidate, S1, S1_conf, S1_lower,
S1_upper, ST, ST_conf, ST_lower, ST_upper, normalised, rank, length_scale,
runs, q2, loo_rmse, sd``: the indices on the GP mean, the Saltelli sample's
95 % half-widths, the 95 % intervals with the GP's uncertainty
(:class:`bayescal.screening.SobolIndices`), ``ST`` over the output's largest,
the GP's length scale of the parameter and its leave-one-out accuracy
(``q2``, ``loo_rmse`` against the statistic's ``sd`` over the runs). Its
``design.csv`` is the Latin hypercube. Only the table of the method last run
is kept, and ``proposal.json`` names it (``method``). Every file is written
through :mod:`bayescal.atomic`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Final

import numpy as np
import pandas as pd

from bayescal.atomic import atomic_write_json, atomic_write_text, read_json
from bayescal.design import Design
from bayescal.screening import MorrisDesign, MorrisIndices, Proposal, SobolIndices

__all__ = [
    "DESIGN_FILE",
    "FOLDER",
    "MORRIS_FILE",
    "PROPOSAL_FILE",
    "SCREENING_FORMAT",
    "SOBOL_FILE",
    "indices_frame",
    "load_proposal",
    "save_screening",
    "save_sobol",
    "sobol_frame",
]

SCREENING_FORMAT: Final = "bayescal-screening/1"
#: Folder in a study's output folder.
FOLDER: Final = "screening"
MORRIS_FILE: Final = "morris.csv"
PROPOSAL_FILE: Final = "proposal.json"
DESIGN_FILE: Final = "design.csv"
SOBOL_FILE: Final = "sobol.csv"


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
    (folder / SOBOL_FILE).unlink(missing_ok=True)  # the other method's table
    document = {
        "format": SCREENING_FORMAT,
        "method": "morris",
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


def sobol_frame(
    indices: Sequence[SobolIndices], candidates: Sequence[str], statistic: str
) -> pd.DataFrame:
    """The Sobol indices of every output as one table (the rows of ``sobol.csv``)."""
    rows = []
    for ix in indices:
        s1_lower, s1_upper, st_lower, st_upper = ix.s1_lower, ix.s1_upper, ix.st_lower, ix.st_upper
        for j, name in enumerate(ix.names):
            rows.append(
                {
                    "output": ix.output,
                    "statistic": statistic,
                    "parameter": name,
                    "candidate": name in candidates,
                    "S1": ix.s1[j],
                    "S1_conf": ix.s1_conf[j],
                    "S1_lower": s1_lower[j],
                    "S1_upper": s1_upper[j],
                    "ST": ix.st[j],
                    "ST_conf": ix.st_conf[j],
                    "ST_lower": st_lower[j],
                    "ST_upper": st_upper[j],
                    "normalised": ix.normalised[j],
                    "rank": int(ix.ranks[j]),
                    "length_scale": ix.lengths[j],
                    "runs": ix.runs,
                    "q2": ix.q2,
                    "loo_rmse": ix.loo_rmse,
                    "sd": ix.sd,
                }
            )
    return pd.DataFrame(rows)


def save_sobol(
    folder: Path,
    design: Design,
    indices: Sequence[SobolIndices],
    proposal: Proposal,
    *,
    candidates: Sequence[str],
    statistic: str,
    runs: Mapping[str, Any],
) -> list[Path]:
    """Write ``sobol.csv``, ``proposal.json`` and ``design.csv`` into ``folder``.

    Parameters
    ----------
    folder
        The screening folder (created if missing).
    design
        The Latin hypercube that was run.
    indices
        Sobol indices, one per output.
    proposal
        The proposed parameters.
    candidates
        Names of the screening candidates (the others are calibrated already).
    statistic
        The scalar screened (``"mean"`` or ``"rmse"``).
    runs
        Counts to record (runs, cached, failed...).
    """
    folder.mkdir(parents=True, exist_ok=True)
    frame = sobol_frame(indices, candidates, statistic)
    written = [atomic_write_text(folder / SOBOL_FILE, frame.to_csv(index=False))]
    (folder / MORRIS_FILE).unlink(missing_ok=True)  # the other method's table
    document = {
        "format": SCREENING_FORMAT,
        "method": "sobol",
        "selected": list(proposal.selected),
        "score": proposal.score,
        "deciding_output": proposal.deciding,
        "threshold": proposal.threshold,
        "max_parameters": proposal.max_parameters,
        "measure": proposal.measure,
        "statistic": statistic,
        "candidates": list(candidates),
        "seed": design.seed,
        "saltelli": indices[0].base if indices else None,
        "paths": indices[0].paths if indices else None,
        "q2": {ix.output: None if np.isnan(ix.q2) else ix.q2 for ix in indices},
        "reliable": {ix.output: ix.reliable for ix in indices},
        "runs": dict(runs),
    }
    written.append(atomic_write_json(folder / PROPOSAL_FILE, document))
    points = pd.DataFrame(design.values, columns=list(design.names))
    points.index.name = "run"
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
