"""The first screen: the fit against the catalogue, whether bands hold, which discrepancy."""

from __future__ import annotations

from types import SimpleNamespace
from typing import cast

import pandas as pd

from bayescal.calibration.posterior import Posterior
from bayescal.metrics import honest_range
from bayescal.report.answer import band_lines, discrepancy_used, fit_table


def _metrics(cover_train: float, cover_test: float) -> pd.DataFrame:
    rows = [
        ("q", "nominal", "train", 2.0, float("nan"), float("nan")),
        ("q", "nominal", "test", 2.0, float("nan"), float("nan")),
        ("q", "calibrated", "train", 1.0, cover_train, 1000.0),
        ("q", "calibrated", "test", 1.5, cover_test, 300.0),
    ]
    return pd.DataFrame(
        rows, columns=["output", "model", "window", "rmse", "coverage95", "n_eff95"]
    )


def _plain(header: object, rows: list[list[object]]) -> str:
    return repr((header, rows))


def test_a_band_within_the_honest_range_holds() -> None:
    low, high = honest_range(0.95, 300.0)
    (line,) = band_lines(_metrics(0.95, 0.5 * (low + high)))
    assert line.startswith("q: the 95 % band holds: covers 0.950 of the training periods")
    assert f"an honest band {low:.2f}-{high:.2f} on about 300 independent samples" in line


def test_a_band_outside_the_honest_range_is_too_narrow_or_too_wide() -> None:
    low, _ = honest_range(0.95, 300.0)
    (line,) = band_lines(_metrics(0.95, low - 0.05))
    assert line.startswith("q: the 95 % band is too narrow: ")
    (line,) = band_lines(_metrics(1.0, 0.95))
    assert line.startswith("q: the 95 % band is too wide: ")


def test_the_fit_table_compares_with_the_catalogue_per_window() -> None:
    text = fit_table(_metrics(0.95, 0.95), (), _plain)
    assert "'training periods (fitted)', '2', '1', '-50 %'" in text
    assert "'test window (out of sample)', '2', '1.5', '-25 %'" in text
    held = fit_table(_metrics(0.95, 0.95), ("q",), _plain)
    assert "test window (held-out sensor: out of sample)" in held


def test_an_in_likelihood_discrepancy_is_not_the_difference_process() -> None:
    """The summary named only the difference process ("discrepancy: not estimated")
    while the uncertainty table said "ar1 + discrepancy (conditions)": both are named now."""
    noise = (
        SimpleNamespace(name="q", discrepancy="conditions"),
        SimpleNamespace(name="r", discrepancy=False),
    )
    post = cast(Posterior, SimpleNamespace(noise=noise))
    assert discrepancy_used(post, None) == ("q (over the periods' conditions)", "not used")
    plain = cast(Posterior, SimpleNamespace(noise=()))
    assert discrepancy_used(plain, post) == ("none", "estimated")
