"""What ``bayescal compare`` notes beside the ELPD: left-out bands off their rate, and
periods predicted confidently wrong."""

from __future__ import annotations

import numpy as np

from bayescal.calibration.cv import PeriodScores
from bayescal.pipeline.compare import _band_notes


def _scores(pit: np.ndarray) -> PeriodScores:
    m = pit.shape[1]
    return PeriodScores(
        psis=np.zeros(m), pareto_k=np.zeros(m), lppd=np.zeros(m),
        refit=np.full(m, np.nan), log_jacobian=0.0, draws=10, pit=pit,
    )  # fmt: skip


def test_bands_that_hold_say_nothing() -> None:
    # every period's PITs uniform on a fine grid: both bands at their rate in every period
    pit = np.tile((np.arange(200)[:, None] + 0.5) / 200, (1, 12))
    assert _band_notes("v", _scores(pit)) == []


def test_wide_narrow_and_confidently_wrong() -> None:
    rng = np.random.default_rng(1)
    middle = 0.5 + 0.05 * (rng.random((48, 12)) - 0.5)
    notes = _band_notes("cond", _scores(middle))
    assert len(notes) == 2
    assert notes[0].startswith("cond: left-out 95 % band 1.000 ± 0.000, wider than its rate")
    assert "50 % band 1.000" in notes[1]
    assert "conservative" in notes[1]
    # two periods far outside their band: the 95 % band holds none of their samples
    pit = rng.random((48, 12))
    pit[:, [3, 7]] = 0.9999
    notes = _band_notes("ship", _scores(pit))
    assert notes[-1] == (
        "ship: the left-out 95 % band held less than half of the samples of period(s) "
        "3 (0%), 7 (0%): confidently wrong there"
    )
    assert not any("wider" in n for n in notes)
