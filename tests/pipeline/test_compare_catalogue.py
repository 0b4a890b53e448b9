"""The catalogue model as a variant of ``bayescal compare``: every parameter at its
nominal value, the error model fitted on the same emulator, scored the same way.

On the virtual wall whose data come from a truth far from the nominal values the
calibration must beat it clearly; where the nominal values are the truth the two
must agree within the noise of the comparison (its own paired standard error);
and a catalogue at least as good must be said loudly."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bayescal.cli.progress import comparison_text
from bayescal.pipeline import Options
from bayescal.pipeline.catalogue import (
    DOES_NOT_IMPROVE,
    Scored,
    catalogue_labels,
    catalogue_warnings,
)
from bayescal.pipeline.compare import Comparison, compare
from bayescal.report.compare import SMALL_DIFFERENCE, comparison_markdown
from bayescal.report.trust import ABSORBS
from compare_study import TRUTH, wall_data, write_variant

LOUD = (
    "calibration does not improve on the catalogue values on the left-out periods: the "
    "parameters absorb model error; treat them as fitting constants, not properties"
)


def _study(root: Path, name: str, k_cb: float, cp_cb: float) -> Path:
    """The AR(1) variant of the tiny wall with the nominal values given."""
    folder = write_variant(root / name, wall_data(), "ar1")
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    text = text.replace("nominal = 0.12\n", f"nominal = {k_cb}\n")
    path.write_text(text.replace("nominal = 800.0\n", f"nominal = {cp_cb}\n"), encoding="utf-8")
    return folder


def _compare(study: Path, tmp_path: Path) -> Comparison:
    options = Options(backend="serial", chains_backend="vectorised")
    return compare(
        [study], output=tmp_path / "cmp", options=options, max_refits=1, draws_per_chain=60
    )


def _rows(result: Comparison) -> tuple[pd.Series, pd.Series]:
    table = result.table.set_index("model")
    return table.loc["calibrated"], table.loc["catalogue"]


def test_calibration_beats_a_catalogue_far_from_the_truth(tmp_path: Path) -> None:
    # truth k 0.124, cp 845 (TRUTH); the catalogue says 0.085 and 660 (bounds 0.08-0.16,
    # 640-960): a wall that stores and conducts too little
    result = _compare(_study(tmp_path, "far", 0.085, 660.0), tmp_path)
    assert list(result.table["variant"]) == ["far", "catalogue"]
    calibrated, catalogue = _rows(result)
    assert catalogue["catalogue_of"] == "far"
    assert catalogue["parameters"] == "nominal: k_cb=0.085 cp_cb=660"
    assert catalogue["error_model"] == calibrated["error_model"] == "heat_flux_in ar1"
    # a clear margin in the comparison's own terms: more than SMALL_DIFFERENCE nats and
    # more than twice the SE of the paired difference
    diff, se = float(catalogue["elpd_diff"]), float(catalogue["se_diff"])
    assert diff > max(SMALL_DIFFERENCE, 2.0 * se), (diff, se)
    assert result.warnings == ()
    assert any(n.startswith("far improves on the catalogue values") for n in result.notes)
    # the catalogue fits the error model alone: fewer effective parameters
    assert catalogue["p_loo"] < calibrated["p_loo"]
    page = (tmp_path / "cmp" / "compare.md").read_text(encoding="utf-8")
    mark = "**catalogue** ⚠" if catalogue["diagnostics"] == "failed" else "catalogue"
    assert f"| 2 | {mark} | catalogue |" in page
    assert "WARNING" not in page


def test_a_catalogue_at_the_truth_is_within_the_noise(tmp_path: Path) -> None:
    nominal = (TRUTH["k_cb"], TRUTH["cp_cb"])
    result = _compare(_study(tmp_path, "true", *nominal), tmp_path)
    calibrated, catalogue = _rows(result)
    second = result.table.iloc[1]
    diff, se = float(second["elpd_diff"]), float(second["se_diff"])
    assert se > 0.0
    # the ELPDs differ by less than twice the SE compare reports for their difference
    assert abs(calibrated["elpd"] - catalogue["elpd"]) == pytest.approx(diff)
    assert diff <= 2.0 * se, (diff, se)
    # and the loud line is there exactly when the catalogue is ahead or within one SE
    behind = float(calibrated["elpd"] - catalogue["elpd"])
    assert (result.warnings != ()) == (behind <= se)
    if result.warnings:
        assert result.warnings[0].startswith(LOUD)
        page = (tmp_path / "cmp" / "compare.md").read_text(encoding="utf-8")
        assert f"**WARNING: {LOUD}" in page


def _scored(label: str, values: list[float], model: str = "m", of: str = "") -> Scored:
    return Scored(label, np.array(values), model, of)


def test_the_loud_line_when_the_catalogue_is_at_least_as_good() -> None:
    assert f"{DOES_NOT_IMPROVE}: {ABSORBS}" == LOUD
    cal = _scored("cal", [-10.0, -11.0, -9.0, -10.5])
    # the catalogue ahead
    loud, notes = catalogue_warnings(
        [cal, _scored("catalogue", [-9.0, -10.0, -8.5, -10.0], of="cal")]
    )
    assert len(loud) == 1
    assert loud[0].startswith(LOUD + " (ELPD of cal minus catalogue: -3.0 ± ")
    assert notes == []
    # behind, but by less than one SE of the paired difference
    loud, _ = catalogue_warnings([cal, _scored("catalogue", [-10.0, -13.0, -7.5, -10.5], of="cal")])
    assert len(loud) == 1
    # clearly behind: a note of the margin, no warning
    loud, notes = catalogue_warnings(
        [cal, _scored("catalogue", [-14.0, -15.5, -13.0, -14.0], of="cal")]
    )
    assert loud == []
    assert notes[0].startswith("cal improves on the catalogue values on the left-out periods")
    # the catalogue of one error model is held against the variants of that error model only
    white = _scored("white", [-30.0, -31.0, -29.0, -30.0], "white")
    cat_white = _scored("catalogue (white)", [-28.0, -29.0, -27.5, -28.0], "white", of="white")
    cat_m = _scored("catalogue (cal)", [-14.0, -15.5, -13.0, -14.0], of="cal")
    loud, notes = catalogue_warnings([cal, white, cat_white, cat_m])
    assert len(loud) == 1
    assert "catalogue (white)" in loud[0]
    assert "error model white" in loud[0]
    assert len(notes) == 1


def test_catalogue_rows_per_error_model_and_the_printed_warning() -> None:
    assert catalogue_labels(["a", "b"], ["ar1", "ar1"]) == {0: "catalogue"}
    assert catalogue_labels(["a", "b", "c"], ["ar1", "white", "ar1"]) == {
        0: "catalogue (a)",
        1: "catalogue (b)",
    }
    assert catalogue_labels(["catalogue", "b"], ["ar1", "ar1"]) == {0: "catalogue (nominal)"}
    table = pd.DataFrame(
        {
            "rank": [1, 2], "variant": ["catalogue", "cal"], "model": ["catalogue", "calibrated"],
            "elpd": [-10.0, -11.0], "se": [1.0, 1.0], "elpd_diff": [0.0, 1.0],
            "se_diff": [0.0, 2.0], "p_loo": [1.0, 3.0], "k_high": [0, 0], "refits": [0, 0],
            "periods": [6, 6], "catalogue_of": ["cal", ""],
            "diagnostics": ["passed", "passed"], "diagnostic_warnings": [0, 0],
        }
    )  # fmt: skip
    text = comparison_text(table, [], {}, [LOUD])
    assert text.splitlines()[0] == f"WARNING: {LOUD}"
    assert "catalogue: best [catalogue: the nominal values, error model of cal]" in text
    page = comparison_markdown(table, pd.DataFrame(), [], None, [LOUD])
    assert page.splitlines()[2] == f"**WARNING: {LOUD}**"
    assert "A catalogue row is the nominal (catalogue) model" in page
