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


def _heads(
    ix: MorrisIndices | SobolIndices, candidates: Sequence[str], statistic: str
) -> list[dict[str, Any]]:
    """The columns both tables open with, one row per parameter of one output."""
    return [
        {
            "output": ix.output,
            "statistic": statistic,
            "parameter": name,
            "candidate": name in candidates,
        }
        for name in ix.names
    ]


def indices_frame(
    indices: Sequence[MorrisIndices], candidates: Sequence[str], statistic: str
) -> pd.DataFrame:
    """The Morris indices of every output as one table (the rows of ``morris.csv``)."""
    rows = []
    for ix in indices:
        for j, head in enumerate(_heads(ix, candidates, statistic)):
            rows.append(
                {
                    **head,
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


def _points(values: np.ndarray, names: Sequence[str], unit: np.ndarray) -> pd.DataFrame:
    """The rows of ``design.csv``: physical values, then the ``u:`` normalised ones."""
    points = pd.DataFrame(values, columns=list(names))
    points.index.name = "run"
    for j, name in enumerate(names):
        points[f"u:{name}"] = unit[:, j]
    return points


def _save(
    folder: Path,
    method: str,
    table: pd.DataFrame,
    proposal: Proposal,
    details: Mapping[str, Any],
    points: pd.DataFrame,
) -> list[Path]:
    """Write ``method``'s table, ``proposal.json`` and ``design.csv``; drop the other table.

    ``proposal.json`` holds the proposal, then ``details`` (the method's keys).
    """
    folder.mkdir(parents=True, exist_ok=True)
    name, other = (MORRIS_FILE, SOBOL_FILE) if method == "morris" else (SOBOL_FILE, MORRIS_FILE)
    written = [atomic_write_text(folder / name, table.to_csv(index=False))]
    (folder / other).unlink(missing_ok=True)  # the other method's table
    document = {
        "format": SCREENING_FORMAT,
        "method": method,
        "selected": list(proposal.selected),
        "score": proposal.score,
        "deciding_output": proposal.deciding,
        "threshold": proposal.threshold,
        "max_parameters": proposal.max_parameters,
        **details,
    }
    written.append(atomic_write_json(folder / PROPOSAL_FILE, document))
    written.append(atomic_write_text(folder / DESIGN_FILE, points.to_csv(lineterminator="\n")))
    return written


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
    details = {
        "statistic": statistic,
        "candidates": list(candidates),
        "trajectories": design.trajectories,
        "levels": design.levels,
        "seed": design.seed,
        "runs": dict(runs),
    }
    points = _points(values, design.names, design.unit)
    points.insert(0, "trajectory", design.trajectory)
    table = indices_frame(indices, candidates, statistic)
    return _save(folder, "morris", table, proposal, details, points)


def sobol_frame(
    indices: Sequence[SobolIndices], candidates: Sequence[str], statistic: str
) -> pd.DataFrame:
    """The Sobol indices of every output as one table (the rows of ``sobol.csv``)."""
    rows = []
    for ix in indices:
        s1_lower, s1_upper, st_lower, st_upper = ix.s1_lower, ix.s1_upper, ix.st_lower, ix.st_upper
        for j, head in enumerate(_heads(ix, candidates, statistic)):
            rows.append(
                {
                    **head,
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

    The parameters are those of :func:`save_screening`, but ``design`` is the
    Latin hypercube that was run (its values are written) and ``indices`` are
    Sobol indices, one per output.
    """
    details = {
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
    points = _points(design.values, design.names, design.unit)
    table = sobol_frame(indices, candidates, statistic)
    return _save(folder, "sobol", table, proposal, details, points)


def load_proposal(folder: Path) -> dict[str, Any]:
    """``proposal.json`` of a screening folder, as written."""
    document = read_json(folder / PROPOSAL_FILE)
    if not isinstance(document, dict) or document.get("format") != SCREENING_FORMAT:
        raise ValueError(f"{folder / PROPOSAL_FILE} is not a bayescal screening proposal")
    return document
