"""Coverage of the 95 % intervals of a posterior whose prior is a previous posterior.

Ten known truths of the virtual wall (``k_cb`` and ``cp_cb`` drawn uniformly
from the inner 80 % of the study's prior bounds, :func:`virtual_wall.random_truth`;
the boards as the study has them), each a 14-day record with white noise. The
first study calibrates on its first eight days (the study of
``test_sequential.py``); the second, with ``[study] prior_from`` the first, on
the record from the first's test window (less one warm-up) to the end, as
``bayescal update`` writes it. Its 95 % intervals of the two parameters, 20 in
all, must cover the truths at least 16 times.

Were each interval to cover with probability 0.95 independently, 16 or more of
20 would occur with probability 0.984 (``scipy.stats.binom(20, 0.95).sf(15)``),
and even at a true coverage of 0.90 with probability 0.867: the bound flags
intervals that are clearly too narrow, e.g. a previous posterior counted twice
(at a true coverage of 0.6, 16 or more of 20 has probability 0.051). The two
intervals of one truth share its record, so they are not independent; the
draws are seeded, so the test's outcome is fixed.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from scipy import stats

from bayescal.config import load_study
from bayescal.pipeline import Options, load_results, run
from sequential_study import calibrated_truths, interval_hits, second_study

TRUTHS = 10
LEAST = 16  # of 2 * TRUTHS intervals


@pytest.mark.slow
def test_intervals_after_prior_from_cover_the_truths(tmp_path: Path) -> None:
    assert stats.binom(2 * TRUTHS, 0.95).sf(LEAST - 1) > 0.98  # the docstring's figure
    covered: list[bool] = []
    seen: list[str] = []
    for folder, truth in calibrated_truths(tmp_path, TRUTHS):
        second = load_study(second_study(folder, prior_from=True))
        run(second, until="calibrate", options=Options(backend="serial"))
        post = load_results(second).posterior
        assert post is not None
        covered += interval_hits(post, truth, seen)
    print(f"{sum(covered)} of {len(covered)} intervals cover the truths")
    assert sum(covered) >= LEAST, "\n".join(seen)
