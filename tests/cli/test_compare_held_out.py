"""bayescal compare scores the held-out sensors every variant holds out.

Two variants of the virtual wall calibrate the inside heat flux alone and hold out the
thermometer at the concrete / inside-board interface (true, white noise of 0.05 K, stated
accuracy 0.05 K): one with the paper's prior for the concrete's conductivity (the truth,
0.124, inside it), one with a prior that excludes it (0.14-0.16), so that its parameters
fit the flux as best they can and misplace the interface temperature. The held-out
thermometer must rank them (right first, by more than two SE of the paired difference)
and the catalogue values (k 0.12, cp 800) between them or behind, the wrong variant named
in a WARNING for a mean further off than the catalogue's; the page and the printed table
carry the scores; a variant that calibrates the sensor it would be scored
on leaves it unscored, with a note.
"""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.errors import ConfigError
from bayescal.pipeline.compare import Comparison, compare
from compare_study import two_sensor_data, write_sensors_variant

FLUX, TEMP = "heat_flux_in", "temp_interface_2"


def held_out_variant(folder: Path, data: pd.DataFrame, k_prior: tuple[float, float]) -> Path:
    """The flux calibrated, the interface thermometer held out with a stated 0.05 K."""
    write_sensors_variant(folder, data, (FLUX,))
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    text = text.replace(
        'calibrate = ["heat_flux_in"]', f'calibrate = ["heat_flux_in"]\nheld_out = ["{TEMP}"]'
    )
    text = text.replace("lower = 0.08, upper = 0.16", f"lower = {k_prior[0]}, upper = {k_prior[1]}")
    if not k_prior[0] <= 0.12 <= k_prior[1]:  # the nominal value inside the prior
        text = text.replace("nominal = 0.12", f"nominal = {0.5 * (k_prior[0] + k_prior[1])}")
    text += f"\n[outputs.errors.{TEMP}]\nsd = 0.05\n\n[predict]\nruns = 20\n"
    path.write_text(text, encoding="utf-8")
    return folder


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("held")
    data = two_sensor_data()
    return {
        "root": root,
        "right": held_out_variant(root / "right", data, (0.08, 0.16)),
        "wrong": held_out_variant(root / "wrong", data, (0.14, 0.16)),
        "calibrates": write_sensors_variant(root / "calibrates", data, (FLUX, TEMP)),
    }


@pytest.fixture(scope="module")
def ranked(folders: dict[str, Path]) -> tuple[Comparison, list[str]]:
    said: list[str] = []
    result = compare(
        [folders["right"], folders["wrong"]],
        output=folders["root"] / "ranking",
        draws_per_chain=60,
        max_refits=0,
        say=said.append,
    )
    return result, said


def test_the_held_out_thermometer_ranks_the_variants(
    ranked: tuple[Comparison, list[str]],
) -> None:
    result, said = ranked
    held = result.held_out.set_index("variant")
    assert set(held["output"]) == {TEMP}
    assert list(result.held_out["model"]).count("catalogue") == 1
    right, wrong = held.loc["right"], held.loc["wrong"]
    assert right["rank"] == 1
    assert right["draws"] == 20
    assert right["sd"] == 0.05
    assert wrong["lpd_diff"] > 2.0 * wrong["se_diff"] > 0.0
    assert wrong["rmse"] > right["rmse"]
    # the right variant's bands of a sensor it never saw (stated accuracy = the true
    # noise SD, white) hold their rates within 3.5 binomial SEs of the 6 x 48 samples
    # (measured 0.948 and 0.521)
    n = 6 * 48
    for level, share in ((0.95, right["band95"]), (0.5, right["band50"])):
        assert abs(share - level) <= 3.5 * math.sqrt(level * (1.0 - level) / n), (level, share)
    catalogue = held[held["model"] == "catalogue"].iloc[0]
    assert catalogue["draws"] == 1
    assert catalogue["diagnostics"] == "none"  # the nominal run: no chains behind it
    assert catalogue["rank"] > 1
    # the catalogue behind the best calibrated variant by more than one SE: no density
    # warning; the variant whose mean lies further off than the catalogue's is named
    held_warnings = [w for w in result.warnings if "held-out sensor" in w]
    assert len(held_warnings) == 1, held_warnings
    assert "the calibrated prediction is further off" in held_warnings[0]
    assert "RMSE wrong " in held_warnings[0]
    assert "right" not in held_warnings[0]
    assert any(
        line.startswith(f"held-out sensors {TEMP}: the simulator at up to 20") for line in said
    )


def test_the_page_the_csv_and_the_printed_table_carry_the_scores(
    ranked: tuple[Comparison, list[str]], folders: dict[str, Path]
) -> None:
    result, _ = ranked
    out = folders["root"] / "ranking"
    assert result.files["held_out"] == out / "compare-held-out.csv"
    assert pd.read_csv(out / "compare-held-out.csv")["variant"].tolist() == (
        result.held_out["variant"].tolist()
    )
    page = (out / "compare.md").read_text(encoding="utf-8")
    assert "## Held-out sensors" in page
    first = next(line for line in page.splitlines() if line.startswith(f"| {TEMP} | 1 |"))
    # the test's short chains fail the MCMC checks: the row is marked, as in the ranking
    assert first.startswith(f"| {TEMP} | 1 | **right** ⚠ | calibrated |"), first
    printed = CliRunner().invoke(
        main,
        ["compare", str(folders["right"]), str(folders["wrong"]), "--draws", "60",
         "--max-refits", "0", "--output", str(folders["root"] / "printed"), "--quiet"],
    )  # fmt: skip
    assert printed.exit_code == 0, printed.output
    assert f"held-out sensor {TEMP} (never calibrated on; training periods, stated SD 0.05" in (
        printed.output
    )
    assert "compare-held-out.csv" in printed.output


def test_a_sensor_one_variant_calibrates_is_not_scored(folders: dict[str, Path]) -> None:
    said: list[str] = []
    result = compare(
        [folders["right"], folders["calibrates"]],
        output=folders["root"] / "mixed",
        draws_per_chain=60,
        max_refits=0,
        catalogue=False,
        say=said.append,
    )
    assert result.held_out.empty
    assert "held_out" not in result.files
    assert any(
        n.startswith(
            f"held-out sensors not scored, since not every variant holds them out ({TEMP} by right)"
        )
        for n in result.notes
    )


def test_held_out_measurements_that_differ_are_refused(
    folders: dict[str, Path], tmp_path: Path
) -> None:
    other = two_sensor_data(bias=0.2)  # the same flux, another thermometer record
    moved = held_out_variant(tmp_path / "moved", other, (0.08, 0.16))
    with pytest.raises(ConfigError, match=f"the held-out sensor {TEMP} differs .*first at 20"):
        compare([folders["right"], moved], output=tmp_path / "no", max_refits=0)
    assert not (tmp_path / "no").exists()
    # --no-held-out compares them on the flux alone
    result = CliRunner().invoke(
        main,
        ["compare", str(folders["right"]), str(moved), "--no-held-out", "--no-catalogue",
         "--draws", "60", "--max-refits", "0", "--output", str(tmp_path / "yes"), "--quiet"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "held-out sensor" not in result.output
