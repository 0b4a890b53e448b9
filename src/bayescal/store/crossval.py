"""Leave-one-period-out scores of a calibration: ``leave-period-out.npz``.

``bayescal compare`` scores every study it ranks
(:class:`~bayescal.calibration.cv.PeriodScores`: PSIS estimates, Pareto ``k``
and exact refits per training period, in physical units) and keeps them in the
study's output folder with the key they were computed for (the calibrate
stage's key and the number of draws). A later comparison with the same key
reuses them, refits included, and only adds the refits still missing.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from bayescal.atomic import atomic_write_npz, read_npz
from bayescal.calibration.cv import PeriodScores

__all__ = ["FILE", "load_scores", "save_scores"]

FILE = "leave-period-out.npz"
_FORMAT = 2  # 2: the leave-one-out PIT of every sample


def save_scores(scores: PeriodScores, path: str | os.PathLike[str], key: str) -> Path:
    """Write ``scores`` with the ``key`` they belong to (atomically)."""
    return atomic_write_npz(
        path,
        {
            "format": np.array(_FORMAT),
            "key": np.array(key),
            "psis": scores.psis,
            "pareto_k": scores.pareto_k,
            "lppd": scores.lppd,
            "refit": scores.refit,
            "log_jacobian": np.array(scores.log_jacobian),
            "draws": np.array(scores.draws),
            "refit_warnings": np.array(scores.refit_warnings, dtype=str),
            "pit": scores.pit,
        },
    )


def load_scores(path: str | os.PathLike[str], key: str) -> PeriodScores | None:
    """The scores stored for ``key``; ``None`` if missing, damaged or for another key."""
    try:
        data = read_npz(path)
        if int(data["format"]) != _FORMAT or str(data["key"]) != key:
            return None
        return PeriodScores(
            psis=np.asarray(data["psis"], dtype=float),
            pareto_k=np.asarray(data["pareto_k"], dtype=float),
            lppd=np.asarray(data["lppd"], dtype=float),
            refit=np.asarray(data["refit"], dtype=float),
            log_jacobian=float(data["log_jacobian"]),
            draws=int(data["draws"]),
            refit_warnings=tuple(str(w) for w in data["refit_warnings"]),
            pit=np.asarray(data["pit"], dtype=float),
        )
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
        return None
