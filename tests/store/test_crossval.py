"""leave-period-out.npz: round trip, key check, damaged files."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bayescal.calibration.cv import PeriodScores
from bayescal.store.crossval import load_scores, save_scores


def _scores() -> PeriodScores:
    return PeriodScores(
        psis=np.array([1.5, -2.25, 3.0]),
        pareto_k=np.array([0.1, np.inf, 0.8]),
        lppd=np.array([2.0, -1.0, 3.5]),
        refit=np.array([np.nan, -2.5, np.nan]),
        log_jacobian=-4.75,
        draws=400,
        refit_warnings=("the refit without period 1 has 2 diagnostic warning(s)",),
    )


def test_scores_round_trip_for_their_key_only(tmp_path: Path) -> None:
    path = tmp_path / "leave-period-out.npz"
    s = _scores()
    save_scores(s, path, "key-a")
    back = load_scores(path, "key-a")
    assert back is not None
    for name in ("psis", "pareto_k", "lppd", "refit"):
        np.testing.assert_array_equal(getattr(back, name), getattr(s, name))
    assert (back.log_jacobian, back.draws, back.refit_warnings) == (
        s.log_jacobian,
        s.draws,
        s.refit_warnings,
    )
    assert back.elpd == s.elpd
    assert load_scores(path, "key-b") is None  # another calibration: recompute


def test_missing_or_damaged_file_means_recompute(tmp_path: Path) -> None:
    path = tmp_path / "leave-period-out.npz"
    assert load_scores(path, "k") is None
    save_scores(_scores(), path, "k")
    path.write_bytes(path.read_bytes()[:100])
    assert load_scores(path, "k") is None
