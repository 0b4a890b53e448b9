"""Coverage of the 95 % intervals of a joint calibration of two records (``bayescal joint``).

The ten known truths of ``test_prior_from_coverage.py`` (the same seed, the same
14-day records): the first study calibrates on the record's first eight days,
the second (its own study, no ``prior_from``) on the record from the first's
test window (less one warm-up) to the end, and :func:`bayescal.pipeline.joint.joint`
calibrates both together. Its 95 % intervals of the two parameters, 20 in all,
must cover the truths at least 16 times: under independent intervals of
coverage 0.95 that happens with probability 0.984, at 0.90 with 0.867, at 0.6
with 0.051 (a record counted twice, or one record's likelihood dropped, would
narrow or shift them).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from bayescal.config import load_study
from bayescal.pipeline import Options, run
from bayescal.pipeline.joint import joint
from sequential_study import calibrated_truths, interval_hits, second_study

TRUTHS = 10
LEAST = 16  # of 2 * TRUTHS intervals


@pytest.mark.slow
def test_joint_intervals_of_two_records_cover_the_truths(tmp_path: Path) -> None:
    covered: list[bool] = []
    seen: list[str] = []
    for folder, truth in calibrated_truths(tmp_path, TRUTHS):
        second_file = second_study(folder, prior_from=False)
        run(load_study(second_file), until="calibrate", options=Options(backend="serial"))
        post = joint([folder, second_file], folder / "joint").posterior
        covered += interval_hits(post, truth, seen)
    print(f"{sum(covered)} of {len(covered)} intervals cover the truths")
    assert sum(covered) >= LEAST, "\n".join(seen)
