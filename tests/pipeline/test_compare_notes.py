"""What ``bayescal compare`` notes beside the ELPD: left-out bands off their rate,
periods predicted confidently wrong, and variants whose calibration failed its MCMC
diagnostics."""

from __future__ import annotations

from typing import cast

import numpy as np
import pandas as pd

from bayescal.calibration.cv import PeriodScores
from bayescal.config import Study
from bayescal.pipeline.compare import Variant, _band_notes, _notes
from bayescal.report.compare import comparison_markdown


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


def _table(diagnostics: list[str]) -> pd.DataFrame:
    """A ranking of two variants, the second's calibration as given."""
    return pd.DataFrame(
        {
            "rank": [1, 2], "variant": ["ar1", "white"], "elpd": [-10.0, -30.0],
            "se": [1.0, 1.0], "elpd_diff": [0.0, 20.0], "se_diff": [0.0, 2.0],
            "p_loo": [3.0, 4.0], "k_high": [0, 0], "refits": [0, 0], "periods": [6, 6],
            "diagnostics": diagnostics, "diagnostic_warnings": [0, 2],
        }
    )  # fmt: skip


def test_a_variant_whose_calibration_failed_is_noted_first() -> None:
    pit = np.tile((np.arange(200)[:, None] + 0.5) / 200, (1, 12))
    failed = ("k_cb: R-hat 1.05 > 1.01", "k_cb: bulk ESS 80 < 400")
    variants = [
        Variant("ok", cast(Study, None), _scores(pit)),
        Variant("shaky", cast(Study, None), _scores(pit), diagnostics=failed),
    ]
    notes = _notes(variants, max_refits=0)
    assert notes == [
        "shaky: its calibration FAILED its MCMC diagnostics (k_cb: R-hat 1.05 > 1.01 and 1 "
        "more): its scores and rank rest on chains that have not converged; run longer "
        "chains ([calibration] burn, samples, max_samples) before choosing it"
    ]


def test_the_summary_page_marks_a_failed_variant() -> None:
    page = comparison_markdown(_table(["passed", "failed"]), pd.DataFrame(), ["a note"], None)
    head = next(line for line in page.splitlines() if line.startswith("| rank"))
    assert head.endswith("| MCMC diagnostics |")
    assert "| 1 | ar1 |" in page
    white = next(line for line in page.splitlines() if line.startswith("| 2 |"))
    assert white.startswith("| 2 | **white** ⚠ |")
    assert white.endswith("| **FAILED** |")
    assert "- **ar1**: best\n" in page
    assert "- **white**: worse by 20.0 ± 2.0 (10.0 SE); its calibration FAILED its MCMC" in page
    calm = comparison_markdown(_table(["passed", "passed"]), pd.DataFrame(), [], None)
    assert "FAILED" not in calm
    assert "| 2 | white |" in calm
