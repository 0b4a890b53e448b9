"""bayescal compare: ranking two variants of a tiny study, and its one-line errors."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner, Result

from bayescal.cli import main
from compare_study import wall_data, write_variant


@pytest.fixture(scope="module")
def variants(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """Two variants of the virtual wall with AR(1) noise: white and AR(1) error models."""
    root = tmp_path_factory.mktemp("compare")
    data = wall_data()
    return (
        root,
        write_variant(root / "white", data, "white"),
        write_variant(root / "ar1", data, "ar1"),
    )


@pytest.fixture(scope="module")
def ranked(variants: tuple[Path, Path, Path]) -> tuple[Result, Path]:
    root, white, ar1 = variants
    out = root / "ranking"
    args = ["compare", str(white), str(ar1), "--output", str(out), "--draws", "60"]
    result = CliRunner().invoke(main, [*args, "--max-refits", "1", "--quiet", "--no-catalogue"])
    return result, out


def test_ar1_errors_win_on_ar1_noise(ranked: tuple[Result, Path]) -> None:
    result, out = ranked
    assert result.exit_code == 0, result.output
    table = pd.read_csv(out / "compare.csv")
    assert list(table["variant"]) == ["ar1", "white"]
    assert list(table["rank"]) == [1, 2]
    best, other = table.iloc[0], table.iloc[1]
    assert best["elpd_diff"] == 0.0
    assert other["elpd_diff"] == pytest.approx(best["elpd"] - other["elpd"])
    # The noise is AR(1) with phi = 0.9: white errors must lose by more than 2 SE.
    assert other["elpd_diff"] > 2.0 * other["se_diff"] > 0.0
    assert other["error_model"] == "heat_flux_in white"
    assert (table["refits"] <= 1).all()
    # whether each calibration passed its MCMC diagnostics, a column of its own
    assert set(table["diagnostics"]) <= {"passed", "failed"}
    assert ((table["diagnostics"] == "failed") == (table["diagnostic_warnings"] > 0)).all()
    assert (table["psis_only"] == table["k_high"] - table["refits"]).all()
    periods = pd.read_csv(out / "compare-periods.csv")
    assert len(periods) == 2 * int(best["periods"]) == 12
    for name, group in periods.groupby("variant"):
        row = table.set_index("variant").loc[name]
        assert group["elpd_i"].sum() == pytest.approx(row["elpd"])
        assert int((group["method"] == "refit").sum()) == row["refits"]
        # the left-out bands: the mean of the periods' shares, its SE over the periods
        for level in ("95", "50"):
            shares = group[f"band{level}_i"].to_numpy()
            assert np.all((shares >= 0.0) & (shares <= 1.0))
            assert row[f"loo_band{level}"] == pytest.approx(shares.mean())
            se = shares.std(ddof=1) / np.sqrt(shares.size)
            assert row[f"loo_band{level}_se"] == pytest.approx(se)
        assert row["loo_band95_worst"] == pytest.approx(group["band95_i"].min())
    assert (out / "compare.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = (out / "compare.md").read_text(encoding="utf-8")
    # the fixture's short chains may fail their diagnostics: then the name is marked
    mark = "**ar1** ⚠" if best["diagnostics"] == "failed" else "ar1"
    assert f"| 1 | {mark} |" in summary
    assert "The test window is read by none of it" in summary
    text = result.output
    assert "ar1: best" in text
    for _, row in table.iterrows():
        line = next(x for x in text.splitlines() if f" {row['variant']} " in f" {x} ")
        assert line.endswith("FAILED !" if row["diagnostics"] == "failed" else "  ok")
    assert f"{best['loo_band95']:.3f}±{best['loo_band95_se']:.3f}" in text
    assert "white: worse by" in text
    assert f"wrote {out / 'compare.csv'}" in text


def test_a_second_comparison_reuses_the_scores(
    variants: tuple[Path, Path, Path], ranked: tuple[Result, Path]
) -> None:
    root, white, ar1 = variants
    first = pd.read_csv(ranked[1] / "compare.csv")
    args = ["compare", str(ar1), str(white), "--output", str(root / "again"), "--draws", "60"]
    result = CliRunner().invoke(main, [*args, "--max-refits", "1", "--no-catalogue"])
    assert result.exit_code == 0, result.output
    assert "white: calibrate: up to date, reused" in result.output
    assert "white: leave-period-out scores up to date, reused" in result.output
    # the cost is stated before anything runs, and each variant says when it starts
    lines = result.output.splitlines()
    assert lines[0].startswith("compare: 2 variants, up to about ")
    assert "up to 1 refits of" in lines[0]
    assert "variant 1 of 2: ar1" in lines
    assert "variant 2 of 2: white" in lines
    again = pd.read_csv(root / "again" / "compare.csv")
    np.testing.assert_array_equal(again["elpd"], first["elpd"])


def test_a_variant_whose_calibration_failed_is_marked_not_ranked_silently(
    variants: tuple[Path, Path, Path],
    ranked: tuple[Result, Path],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The white variant's chains made to fail their diagnostics (the stages and scores
    are reused): compare.csv flags it, the printed table and compare.md mark it and a
    note says why its rank is not reliable."""
    import dataclasses

    from bayescal.pipeline import compare as compare_module

    root, white, ar1 = variants
    calibrated = compare_module._calibrated
    failed = ("k_cb: R-hat 1.05 > 1.01", "cp_cb: bulk ESS 80 < 400")

    def shaky(label: str, *args: object) -> object:
        res = calibrated(label, *args)  # type: ignore[arg-type]
        if label != "white" or res.posterior is None:
            return res
        diag = dataclasses.replace(res.posterior.diagnostics, warnings=failed)
        post = dataclasses.replace(res.posterior, diagnostics=diag)
        return dataclasses.replace(res, posterior=post)

    monkeypatch.setattr(compare_module, "_calibrated", shaky)
    out = root / "shaky"
    args = ["compare", str(ar1), str(white), "--output", str(out), "--draws", "60"]
    result = CliRunner().invoke(main, [*args, "--max-refits", "1", "--quiet", "--no-catalogue"])
    assert result.exit_code == 0, result.output
    table = pd.read_csv(out / "compare.csv").set_index("variant")
    assert table.loc["white", "diagnostics"] == "failed"
    assert table.loc["white", "diagnostic_warnings"] == 2
    first = pd.read_csv(ranked[1] / "compare.csv").set_index("variant")
    assert table.loc["white", "elpd"] == first.loc["white", "elpd"]  # scores unchanged
    row = next(line for line in result.output.splitlines() if " white " in f" {line} ")
    assert row.endswith("FAILED !")
    assert "white: worse by" in result.output
    assert "its calibration FAILED its MCMC diagnostics: the rank is not reliable" in (
        result.output
    )
    assert "note: white: its calibration FAILED its MCMC diagnostics (k_cb: R-hat 1.05" in (
        result.output
    )
    summary = (out / "compare.md").read_text(encoding="utf-8")
    assert "| **white** ⚠ |" in summary
    assert "- white: its calibration FAILED its MCMC diagnostics" in summary


def _one_line_error(result: Result, *needles: str) -> None:
    assert result.exit_code == 2, result.output
    assert result.output.startswith("error: ")
    assert result.output.count("\n") == 1
    assert "Traceback" not in result.output
    for needle in needles:
        assert needle in result.output


def test_fewer_than_two_studies(variants: tuple[Path, Path, Path]) -> None:
    _, white, _ = variants
    result = CliRunner().invoke(main, ["compare", str(white), "--no-catalogue"])
    _one_line_error(result, "at least two studies", "got 1")
    _one_line_error(CliRunner().invoke(main, ["compare"]), "at least one study", "got 0")
    twice = CliRunner().invoke(main, ["compare", str(white), str(white / "study.toml")])
    _one_line_error(twice, "given more than once")


def test_study_not_found(variants: tuple[Path, Path, Path]) -> None:
    root, white, _ = variants
    result = CliRunner().invoke(main, ["compare", str(white), str(root / "nowhere")])
    _one_line_error(result, "nowhere", "file not found")


def test_different_measurements_are_refused(variants: tuple[Path, Path, Path]) -> None:
    root, white, _ = variants
    data = wall_data()
    data.loc[100, "q_si"] += 0.5  # a training sample (warm-up is the first 48)
    other = write_variant(root / "edited", data, "ar1")
    result = CliRunner().invoke(main, ["compare", str(white), str(other)])
    _one_line_error(result, "cannot compare white and edited", "measured heat_flux_in differs")
    shorter = write_variant(root / "shorter", wall_data(days=5), "white")
    result = CliRunner().invoke(main, ["compare", str(white), str(shorter)])
    _one_line_error(result, "6 training periods of 48 samples, shorter 5 of 48")
    assert not (root / "edited" / "out").exists()  # refused before running anything


def test_a_failing_study_is_named(variants: tuple[Path, Path, Path], tmp_path: Path) -> None:
    _, white, _ = variants
    broken = tmp_path / "broken"
    shutil.copytree(white, broken, ignore=shutil.ignore_patterns("out"))
    path = broken / "study.toml"
    text = path.read_text(encoding="utf-8")
    # Conductivities below zero: every simulator run fails.
    text = text.replace("nominal = 0.12", "nominal = -0.15")
    path.write_text(text.replace("lower = 0.08, upper = 0.16", "lower = -0.2, upper = -0.1"))
    result = CliRunner().invoke(main, ["compare", str(broken), str(white), "-q"])
    _one_line_error(result, "broken: running up to calibrate failed")


LOUD = (
    "calibration does not improve on the catalogue values on the left-out periods: the "
    "parameters absorb model error; treat them as fitting constants, not properties"
)


def test_one_study_against_its_catalogue(
    variants: tuple[Path, Path, Path], ranked: tuple[Result, Path]
) -> None:
    """The catalogue is on by default: one study is ranked against its nominal values
    (its calibration reused from the fixture), the row marked, the verdict said."""
    root, _, ar1 = variants
    out = root / "catalogue"
    args = ["compare", str(ar1), "--output", str(out), "--draws", "60", "--max-refits", "1"]
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[0].startswith("compare: 1 variants and 1 catalogue model")
    assert "ar1: calibrate: up to date, reused" in result.output
    assert "catalogue: fitting the error model with every parameter at its nominal value" in (
        result.output
    )
    table = pd.read_csv(out / "compare.csv", keep_default_na=False).set_index("variant")
    assert list(table.index) in (["ar1", "catalogue"], ["catalogue", "ar1"])
    assert table.loc["catalogue", "model"] == "catalogue"
    assert table.loc["catalogue", "catalogue_of"] == "ar1"
    assert table.loc["ar1", "model"] == "calibrated"
    assert table.loc["catalogue", "parameters"] == "nominal: k_cb=0.12 cp_cb=800"
    assert "[catalogue: the nominal values, error model of ar1]" in result.output
    # the loud line exactly when the catalogue is ahead or within one SE behind
    behind = table.loc["ar1", "elpd"] - table.loc["catalogue", "elpd"]
    se = float(table["se_diff"].max())
    warned = f"WARNING: {LOUD}" in result.output
    assert warned == (behind <= se), result.output
    summary = (out / "compare.md").read_text(encoding="utf-8")
    assert (f"**WARNING: {LOUD}" in summary) == warned
    if not warned:
        assert "note: ar1 improves on the catalogue values on the left-out periods" in (
            result.output
        )
    # a second comparison reuses the catalogue's scores and fit
    args[3] = str(root / "catalogue-again")
    again = CliRunner().invoke(main, args)
    assert again.exit_code == 0, again.output
    assert "catalogue: leave-period-out scores up to date, reused" in again.output
    assert "fitting the error model" not in again.output
    assert pd.read_csv(root / "catalogue-again" / "compare.csv")["elpd"].tolist() == (
        pd.read_csv(out / "compare.csv")["elpd"].tolist()
    )


def test_the_catalogue_option_is_in_the_cli_reference() -> None:
    reference = Path(__file__).resolve().parents[2] / "docs" / "cli.md"
    text = reference.read_text(encoding="utf-8")
    assert "| `--catalogue` / `--no-catalogue` | flag | `--catalogue` |" in text
    assert "Also rank the catalogue model" in text
