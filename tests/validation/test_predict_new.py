"""``bayescal predict --data`` on another weather, at known truths (issue 34's acceptance).

``scripts/predict_truths.py`` calibrates a virtual-wall study (12 training days,
20 design runs, white noise of SD sqrt(0.007) W/m², the white error model, 4 x
(500 + 1000) draws) at each truth and predicts another record of the same wall
(another weather and noise seed, 8 days) with :func:`bayescal.pipeline.newdata.predict_new`.
Pooled over the truths, the 95 % band must cover 0.90-0.99 and the 50 % band
0.40-0.60 of the new record's samples, without and with the in-likelihood
discrepancy (``discrepancy = true``: kriged at the new conditions, its noise the
conditional of lambda* given the re-run simulator, ``[predict] noise =
"simulator"``).

Measured (docs/case-studies.md, "Predicting new conditions"): over 10 truths the
95 % band covered 0.951 and the 50 % band 0.508 (pooled, 3840 samples; every
truth within the range an honest band shows on its 384 samples); with the
discrepancy 0.952 and 0.510 (10 and 9 of 10 truths within that range; with the
calibration's lambda* as the noise, ``noise = "calibration"``, 0.998 and 0.707); with
``noise = "basis"`` 0.951 and 0.509.
``BAYESCAL_VALIDATION_TRUTHS`` sets the number of truths (2 when unset, about 15 s; 10: about 75 s).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))

import predict_truths

N_TRUTHS = int(os.environ.get("BAYESCAL_VALIDATION_TRUTHS", "2"))

pytestmark = pytest.mark.slow


VARIANTS = {
    "white": [],
    "discrepancy": ["--discrepancy"],
    # [predict] noise = "basis": the discrepancy output's noise from what its basis leaves
    "discrepancy-basis": ["--discrepancy", "--noise", "basis"],
}


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_bands_on_another_weather_hold_over_the_truths(tmp_path: Path, variant: str) -> None:
    extra = VARIANTS[variant]
    report = predict_truths.main(["--truths", str(N_TRUTHS), "--out", str(tmp_path), *extra])
    total = report["summary"]
    assert isinstance(total, dict)
    assert 0.90 <= total["pooled95"] <= 0.99, total
    assert 0.40 <= total["pooled50"] <= 0.60, total
    # the truth's own model, calibrated: closer to the record than the nominal values
    assert total["rmse_calibrated"] < total["rmse_nominal"], total
    assert (tmp_path / f"predict_truths_{report['variant']}.csv").is_file()
