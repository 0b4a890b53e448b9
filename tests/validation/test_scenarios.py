"""Scenario changes on known truths: the paired interval of a retrofit's effect covers it.

For ``BAYESCAL_VALIDATION_TRUTHS`` truths (2 when unset; ``make validate``: 10)
drawn from the inner 80 % of the priors, the tiny virtual-wall study is
calibrated on data the built-in wall makes at the truth (white noise), and the
scenario "60 mm of EPS outside" is compared with the baseline
(:func:`bayescal.pipeline.scenario.run_scenarios`). The 95 % paired interval of
the change of the mean inside heat flux must cover the truth's change at a rate
consistent with 95 % (at least the binomial 2.5 % quantile of the truths), and
be narrower than the unpaired interval at every truth. With
``BAYESCAL_VALIDATION_REPORT=FILE`` each truth is appended as a JSON line.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from scenario_wall import calibrated_wall, eps_scenario, true_change
from virtual_wall import random_truth

N_TRUTHS = int(os.environ.get("BAYESCAL_VALIDATION_TRUTHS", "2"))


@pytest.mark.slow
def test_the_paired_change_covers_the_true_change_at_its_rate(tmp_path: Path) -> None:
    rng = np.random.default_rng(20261128)
    covered, ratios = [], []
    for i in range(N_TRUTHS):
        truth = {k: v for k, v in random_truth(rng).items() if k in ("k_cb", "cp_cb")}
        results = calibrated_wall(tmp_path / f"truth{i}", 100 + i, truth)
        result = eps_scenario(results)
        table = result.table
        row = table[(table["summary"] == "mean") & (table["output"] == "heat_flux_in")].iloc[0]
        change = true_change(results, result, truth)
        covered.append(bool(row["lower95"] <= change <= row["upper95"]))
        ratios.append(float(row["paired_over_unpaired"]))
        report = os.environ.get("BAYESCAL_VALIDATION_REPORT")
        if report:
            line = {
                "experiment": "scenario-eps",
                "truth": truth,
                "true_change": change,
                "interval95": [float(row["lower95"]), float(row["upper95"])],
                "unpaired95": [float(row["unpaired_lower95"]), float(row["unpaired_upper95"])],
                "covered": covered[-1],
            }
            with open(report, "a", encoding="utf-8") as stream:
                stream.write(json.dumps(line) + "\n")
    floor = int(stats.binom.ppf(0.025, N_TRUTHS, 0.95))
    assert sum(covered) >= floor, (covered, floor)
    assert max(ratios) < 1.0, ratios
