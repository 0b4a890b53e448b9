"""bayescal compare across output sets: variants that calibrate different sensors.

Three variants of the virtual wall on the same measured inside heat flux: the
flux alone, the flux and an interface thermometer that reads true, and the flux
and the same thermometer reading 0.3 K high (an offset no parameter of the model
explains: model error the calibration absorbs into the concrete's properties).
Scored on the flux, the output all three calibrate, each period left out whole:
the true thermometer must not hurt the flux (measured 220.0 against 218.6 nats),
the biased one must lose by more than two SE of the paired difference (measured
-50.5, 270 +- 40 nats behind): ``compare`` sees a second sensor that makes the
shared one worse.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.errors import ConfigError
from bayescal.pipeline.compare import Comparison, compare
from compare_study import two_sensor_data, write_sensors_variant

FLUX, TEMP = "heat_flux_in", "temp_interface_2"


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("outputs")
    good, biased = two_sensor_data(), two_sensor_data(bias=0.3)
    return {
        "root": root,
        "flux": write_sensors_variant(root / "flux", good, (FLUX,)),
        "both": write_sensors_variant(root / "both", good, (FLUX, TEMP)),
        "biased": write_sensors_variant(root / "biased", biased, (FLUX, TEMP)),
    }


@pytest.fixture(scope="module")
def ranked(folders: dict[str, Path]) -> tuple[Comparison, list[str]]:
    said: list[str] = []
    result = compare(
        [folders["flux"], folders["both"], folders["biased"]],
        output=folders["root"] / "ranking",
        draws_per_chain=60,
        max_refits=1,
        catalogue=False,
        say=said.append,
    )
    return result, said


def test_variants_with_other_sensors_are_scored_on_the_shared_output(
    ranked: tuple[Comparison, list[str]], folders: dict[str, Path]
) -> None:
    result, said = ranked
    table = result.table.set_index("variant")
    assert set(table["scored_on"]) == {FLUX}
    assert table.loc["both", "error_model"] == f"{FLUX} white; {TEMP} white"
    # the note says what is scored, first, and the page repeats it
    assert result.notes[0].startswith(f"scored on {FLUX} alone (both also {TEMP}")
    assert any(line.startswith(f"scored on {FLUX} alone") for line in said)
    page = (folders["root"] / "ranking" / "compare.md").read_text(encoding="utf-8")
    assert "| scored on |" in page
    assert f"scored on {FLUX} alone" in page
    # the variant with more outputs keeps its flux-only scores beside (not over) others
    kept = sorted(p.name for p in (folders["both"] / "out").glob("leave-period-out*.npz"))
    assert len(kept) == 1, kept
    assert kept[0].startswith("leave-period-out.on-"), kept
    assert (folders["flux"] / "out" / "leave-period-out.npz").is_file()
    # only the flux's samples have a PIT: 48 a day, 6 training days
    for v in result.variants:
        assert v.scores.pit.shape == (48, 6)


def test_a_true_sensor_does_not_hurt_and_a_biased_one_does(
    ranked: tuple[Comparison, list[str]],
) -> None:
    table = ranked[0].table.set_index("variant")
    flux, both, biased = (table.loc[k] for k in ("flux", "both", "biased"))
    # the true thermometer: the flux predicted no worse (within 2 SE of the paired diff)
    assert both["elpd"] > flux["elpd"] - 2.0 * max(flux["se_diff"], both["se_diff"], 1.0)
    # the biased one pulls the parameters away: the flux predicted clearly worse
    assert biased["rank"] == 3
    assert biased["elpd_diff"] > 2.0 * biased["se_diff"] > 0.0
    assert biased["elpd_diff"] > 50.0


def test_scoring_on_an_output_one_variant_lacks_is_refused(folders: dict[str, Path]) -> None:
    result = CliRunner().invoke(
        main,
        ["compare", str(folders["flux"]), str(folders["both"]), "--on", TEMP,
         "--output", str(folders["root"] / "refused"), "--no-catalogue", "--quiet"],
    )  # fmt: skip
    assert result.exit_code != 0, result.output
    assert f"cannot score on {TEMP}: the outputs every variant calibrates are {FLUX}" in (
        result.output
    )
    assert "Traceback" not in result.output
    assert not (folders["root"] / "refused").exists()


def test_the_printed_ranking_names_the_output_scored(
    ranked: tuple[Comparison, list[str]], folders: dict[str, Path]
) -> None:
    result = CliRunner().invoke(
        main,
        ["compare", str(folders["flux"]), str(folders["both"]), "--on", FLUX, "--draws", "60",
         "--max-refits", "1", "--output", str(folders["root"] / "printed"), "--no-catalogue",
         "--quiet"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert f"(log density of the measurements of {FLUX} in their units" in result.output
    assert f"scored on {FLUX} alone (both also {TEMP})" in result.output


def test_variants_without_a_shared_output_are_refused(
    folders: dict[str, Path], tmp_path: Path
) -> None:
    temp_only = write_sensors_variant(tmp_path / "temp", two_sensor_data(), (TEMP,))
    with pytest.raises(ConfigError, match="no output in common to score"):
        compare([folders["flux"], temp_only], output=tmp_path / "cmp", catalogue=False)


def test_on_narrows_the_same_outputs_and_reuses_saved_scores(
    ranked: tuple[Comparison, list[str]], folders: dict[str, Path]
) -> None:
    said: list[str] = []
    again = compare(
        [folders["both"], folders["biased"]],
        output=folders["root"] / "narrowed",
        draws_per_chain=60,
        max_refits=1,
        catalogue=False,
        say=said.append,
        on=[FLUX],
    )
    assert set(again.table["scored_on"]) == {FLUX}
    assert sum("leave-period-out scores up to date, reused" in line for line in said) == 2
    first = ranked[0].table.set_index("variant")
    for _, row in again.table.iterrows():
        assert row["elpd"] == pytest.approx(first.loc[row["variant"], "elpd"], rel=1e-12)
    # without --on the two score both outputs, whose measured temperatures differ
    with pytest.raises(ConfigError, match="the measured temp_interface_2 differs"):
        compare([folders["both"], folders["biased"]], output=folders["root"] / "whole")


def test_a_study_with_its_catalogue_scores_every_output(folders: dict[str, Path]) -> None:
    whole = compare(
        [folders["both"]],
        output=folders["root"] / "whole",
        draws_per_chain=60,
        max_refits=0,
    )
    assert sorted(whole.table["model"]) == ["calibrated", "catalogue"]
    assert set(whole.table["scored_on"]) == {f"{FLUX} {TEMP}"}
    assert not any(n.startswith("scored on") for n in whole.notes)
    for v in whole.variants:
        assert v.scores.pit.shape == (96, 6)  # both outputs' samples
    assert (folders["both"] / "out" / "leave-period-out.npz").is_file()
