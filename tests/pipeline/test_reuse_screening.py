"""``[design] reuse_screening``: a Sobol screening's runs join the calibration's design.

A 14-day virtual wall record (the built-in wall at a known truth, white noise;
:mod:`sequential_study`) calibrates the concrete's conductivity and specific heat;
the boards' conductivity and density are screening candidates held at their
nominal values, which are the truth's. The screening's Latin hypercube varies
all four; with ``reuse_screening`` its runs come first in the design, from the
run cache, and the emulator takes all four as inputs.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from bayescal.calibration.identifiability import identifiability
from bayescal.config import load_study
from bayescal.errors import ConfigError
from bayescal.pipeline import Options, run
from bayescal.pipeline.reuse import screening_design
from bayescal.pipeline.screen import screen
from bayescal.runner import sandbox
from reuse_study import NEW_RUNS, SCREENING_RUNS, SOBOL, Counting
from reuse_study import reuse_study as _study
from sequential_study import END, TRUTH

pytest.importorskip("SALib", reason="Sobol screening needs SALib")

SERIAL = Options(backend="serial", chains_backend="serial")


@pytest.fixture(scope="module")
def reused(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """Screen, then run to the predictions, counting the simulator runs of each step."""
    folder = _study(tmp_path_factory.mktemp("reuse") / "wall")
    with pytest.MonkeyPatch.context() as patch:
        counts: dict[str, int] = {}
        said: list[str] = []
        for step in ("screen", "simulate", "predict", "again"):
            counter = Counting()
            patch.setattr(sandbox, "execute", counter)
            study = load_study(folder)
            if step == "screen":
                screen(study, options=SERIAL)
                result = None
            else:
                until = "simulate" if step == "simulate" else "predict"
                result = run(study, until=until, options=SERIAL, say=said.append)
            counts[step] = counter.calls
        yield {"folder": folder, "counts": counts, "said": said, "results": result}


def test_the_screening_runs_are_not_run_again(reused: dict[str, Any]) -> None:
    counts = reused["counts"]
    assert counts["screen"] == SCREENING_RUNS
    assert counts["simulate"] == NEW_RUNS  # the screening's runs came from the cache
    res = reused["results"]
    assert res.simulations.n_cached == SCREENING_RUNS + NEW_RUNS  # all cached by then
    predictions = counts["predict"]
    study = load_study(reused["folder"])
    assert predictions == study.predict.runs + 1  # posterior draws and the nominal run only
    assert counts["again"] == 0  # every stage reused


def test_the_design_is_the_screening_then_the_new_runs(reused: dict[str, Any]) -> None:
    study = load_study(reused["folder"])
    design = reused["results"].design
    assert design.runs == SCREENING_RUNS + NEW_RUNS
    assert design.names == ("k_cb", "cp_cb", "k_fb", "d_fb")
    screening = screening_design(study)
    np.testing.assert_array_equal(design.values[:SCREENING_RUNS], screening.values)
    new = design.values[SCREENING_RUNS:]
    np.testing.assert_allclose(new[:, 2], 0.0316, rtol=1e-12)
    np.testing.assert_allclose(new[:, 3], 116.6, rtol=1e-12)
    for k in (0, 1):  # the calibrated ones vary over their ranges
        assert np.ptp(new[:, k]) > 0.5 * (design.priors[design.names[k]].upper
                                          - design.priors[design.names[k]].lower)  # fmt: skip
    said = reused["said"]
    assert any(f"the {SCREENING_RUNS} runs of the Sobol screening, then {NEW_RUNS}" in s
               for s in said)  # fmt: skip


def test_the_emulator_takes_the_screened_out_inputs(reused: dict[str, Any]) -> None:
    em = reused["results"].emulator
    assert em.emulator.parameter_names == ("k_cb", "cp_cb", "k_fb", "d_fb")
    assert em.assembled.theta.shape == (SCREENING_RUNS + NEW_RUNS, 4)
    # its accuracy where the calibration uses it (the screened-out inputs at nominal) is said
    line = next(s for s in reused["said"] if "at the nominal values of the 2 screened-out" in s)
    new = float(line.split("screened-out parameters ")[1].split(" ")[0])
    # no worse at the nominal slice than over all the runs, the screening's included
    # (measured 0.085 against 0.091 W/m²; the noise SD of the data is 0.084)
    overall = float(em.loo.rmse["heat_flux_in"])
    assert 0.0 < new < 1.25 * overall


def test_the_calibration_holds_them_at_nominal_and_covers_the_truth(
    reused: dict[str, Any],
) -> None:
    post = reused["results"].posterior
    assert post.names == ("k_cb", "cp_cb", "k_fb", "d_fb")
    draws = post.draws.reshape(-1, 4)
    np.testing.assert_allclose(draws[:, 2], 0.0316, rtol=1e-12)
    np.testing.assert_allclose(draws[:, 3], 116.6, rtol=1e-12)
    for k, name in enumerate(("k_cb", "cp_cb")):
        lower, upper = np.quantile(draws[:, k], [0.025, 0.975])
        assert lower <= TRUTH[name] <= upper, (name, lower, upper)
        assert np.std(draws[:, k]) > 0.0
    # the interval is narrower than the prior: the data, not the prior, place it
    assert np.ptp(np.quantile(draws[:, 0], [0.025, 0.975])) < 0.2 * (0.16 - 0.08)
    # what the data fix is said of the calibrated parameters only (the held are not fixed
    # by the data, nor correlated with anything)
    ident = identifiability(post)
    assert ident.names == ("k_cb", "cp_cb")
    assert ident.correlation.shape == (2, 2)


def test_show_lists_the_held_ones_apart_from_the_posterior(reused: dict[str, Any]) -> None:
    from bayescal.cli.progress import describe

    text = describe(reused["results"])
    table = text.split("posterior (physical units):")[1].split("held at their nominal")[0]
    assert "k_cb" in table
    assert "k_fb" not in table
    assert "d_fb" not in table
    assert "held at their nominal values, not calibrated (screened out; the emulator keeps " in (
        text
    )
    assert ": k_fb 0.0316, d_fb 116.6" in text


def test_without_a_screening_it_says_to_screen_first(tmp_path: Path) -> None:
    study = load_study(_study(tmp_path / "wall"))
    with pytest.raises(ConfigError, match=r"holds no screening to reuse") as info:
        run(study, until="design", options=SERIAL)
    assert "bayescal screen" in info.value.one_line()
    assert "\n" not in info.value.one_line()


def test_a_screening_with_other_settings_is_refused(tmp_path: Path) -> None:
    folder = _study(tmp_path / "wall")
    screen(load_study(folder), options=SERIAL)
    path = folder / "study.toml"
    path.write_text(
        path.read_text(encoding="utf-8").replace(
            f"runs = {SCREENING_RUNS}\n", f"runs = {SCREENING_RUNS + 2}\n"
        ),
        encoding="utf-8",
    )
    with pytest.raises(ConfigError, match=r"was run with other settings") as info:
        run(load_study(folder), until="design", options=SERIAL)
    assert "run `bayescal screen` again" in info.value.one_line()


@pytest.mark.parametrize(
    ("design", "screening", "match"),
    [
        ("reuse_screening = true\n", "\n[screening]\ntrajectories = 4\n",
         r"design\.reuse_screening: only a Sobol screening's Latin hypercube can join the "
         r"design, and \[screening\] method is 'morris'.*set method = 'sobol'"),
    ],
)  # fmt: skip
def test_impossible_combinations_are_one_line(
    tmp_path: Path, design: str, screening: str, match: str
) -> None:
    with pytest.raises(ConfigError, match=match) as info:
        load_study(_study(tmp_path / "wall", design, screening))
    assert "\n" not in str(info.value)


def test_off_by_default_keeps_the_design(tmp_path: Path) -> None:
    study = load_study(_study(tmp_path / "wall", design="", screening=SOBOL))
    assert not study.design.reuse_screening
    assert "reuse_screening" not in study.design.key_dump()


def test_a_morris_screening_in_the_folder_is_refused(tmp_path: Path) -> None:
    folder = _study(tmp_path / "wall", design="", screening="\n[screening]\ntrajectories = 3\n")
    screen(load_study(folder), options=SERIAL)  # Morris, into the same output folder
    path = folder / "study.toml"
    text = (
        path.read_text(encoding="utf-8")
        .replace("\n[screening]\ntrajectories = 3\n", SOBOL)
        .replace(f"runs = {NEW_RUNS}\n", f"runs = {NEW_RUNS}\nreuse_screening = true\n", 1)
    )
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"is a morris screening, whose runs cannot join") as info:
        run(load_study(folder), until="design", options=SERIAL)
    assert "method = 'sobol'" in info.value.one_line()


def test_the_report_leaves_the_held_ones_out_of_its_table_and_figures(
    reused: dict[str, Any], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from bayescal.pipeline import write_study_report
    from bayescal.report import figures

    post = reused["results"].posterior
    assert post.held_names == ("k_fb", "d_fb")
    labels: dict[str, list[str]] = {}
    save = figures.save_figure

    def keep_labels(fig: Any, path: Any) -> Any:
        shown = [a for a in fig.axes if a.get_visible()]
        labels[Path(path).name] = [a.get_xlabel() + a.get_ylabel() for a in shown]
        return save(fig, path)

    monkeypatch.setattr(figures, "save_figure", keep_labels)
    for plot in (figures.plot_posterior_histograms, figures.plot_traces, figures.plot_pairs):
        plot(tmp_path / f"{plot.__name__}.png", post)
    for name, found in labels.items():
        text = " ".join(found)
        assert "k_cb" in text, name
        assert "k_fb" not in text, name
        assert "d_fb" not in text, name
    assert len(labels["plot_pairs.png"]) == 3  # 2 x 2, the upper corner hidden
    page = write_study_report(reused["results"]).read_text(encoding="utf-8")
    held = "Held at their nominal values, not calibrated: k_fb, d_fb."
    assert held in page
    # the posterior table after that note (the screening's tables elsewhere name them)
    posterior = page.split(held)[1].split("</table>")[0]
    assert "<td>k_cb</td>" in posterior
    assert "<td>k_fb</td>" not in posterior
    assert "<td>d_fb</td>" not in posterior
    # nor in the table of what the calibration answers (U, R, the parameters)
    from bayescal.report.answer import quantities_table

    rows = quantities_table(post, {}, lambda header, body: body)
    names = [row[0] for row in rows]
    assert "k_cb" in names
    assert "k_fb" not in names


def test_new_records_and_scenarios_run_with_the_held_ones_at_nominal(
    reused: dict[str, Any], tmp_path: Path
) -> None:
    # The screening's simulator takes every parameter: the new record's runs and the
    # scenarios' pass the screened-out ones at their nominal values (or the scenario's).
    from bayescal.pipeline.newdata import predict_new
    from bayescal.pipeline.scenario import run_scenarios

    res = reused["results"]
    record = reused["folder"] / "wall.csv"  # the days after the study's end: a new record
    pred = predict_new(res, record, start=pd.Timestamp(END), method="simulator")
    flux = pred.dataset["heat_flux_in_calibrated"].to_numpy()
    assert np.isfinite(flux).any()
    path = tmp_path / "boards.toml"
    path.write_text("[scenarios.warmer_boards]\nset = { k_fb = 0.04 }\n", encoding="utf-8")
    result = run_scenarios(res, path)
    table = result.table
    row = table[(table["summary"] == "mean") & (table["output"] == "heat_flux_in")].iloc[0]
    # boards that conduct better change the mean inside flux, paired draw by draw
    assert row["lower95"] > 0.0 or row["upper95"] < 0.0, row
