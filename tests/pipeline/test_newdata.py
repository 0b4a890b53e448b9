"""``bayescal predict --data``: the calibrated model on new conditions.

A virtual wall (the calibrated model itself makes the data, white noise of known
variance) is calibrated on one synthetic winter and predicts another record of
the same wall under other weather (:mod:`bayescal.pipeline.newdata`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from bayescal.calibration.conditional import OutputDiscrepancy
from bayescal.cli import main
from bayescal.config import load_study
from bayescal.errors import ConfigError, DataError
from bayescal.metrics import honest_range
from bayescal.pipeline import Options, load_results, run
from bayescal.pipeline.newdata import (
    NEW_WINDOW,
    conditions_outside,
    new_assembled,
    predict_as,
    predict_new,
    write_new_prediction,
)
from bayescal.pipeline.predict import conditioned_discrepancy
from compare_study import STUDY, wall_data

NOISE_SD = float(np.sqrt(0.007))  # virtual_wall.NOISE_VARIANCE


def _study_text(name: str, discrepancy: bool) -> str:
    text = STUDY.format(name=name, model="white")
    if discrepancy:
        text = text.replace('model = "white"', 'model = "white"\ndiscrepancy = true')
    return text + '\n[predict]\nmethod = "simulator"\nruns = 40\n'


def _calibrate(factory: pytest.TempPathFactory, discrepancy: bool) -> Any:
    folder = factory.mktemp("newdata") / "wall"
    folder.mkdir()
    wall_data(seed=3, phi=0.0).to_csv(folder / "wall.csv", index=False)
    (folder / "study.toml").write_text(_study_text("wall", discrepancy), encoding="utf-8")
    study = load_study(folder)
    run(study, until="calibrate", options=Options(backend="serial"))
    return load_results(study)


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """White errors, no discrepancy: the bands' noise is estimated again from the runs."""
    return _calibrate(tmp_path_factory, discrepancy=False)


@pytest.fixture(scope="module")
def with_delta(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """White errors and a discrepancy over the conditions in the likelihood."""
    return _calibrate(tmp_path_factory, discrepancy=True)


def _write(path: Path, frame: pd.DataFrame) -> Path:
    frame.to_csv(path, index=False)
    return path


def test_predicts_another_winter_with_bands_that_hold(calibrated: Any, tmp_path: Path) -> None:
    new = _write(tmp_path / "other.csv", wall_data(seed=8, phi=0.0))
    pred = predict_new(calibrated, new)
    assert pred.method == "simulator"
    ds, m = pred.dataset, pred.metrics
    window = ds["window"].values
    assert (window == NEW_WINDOW).sum() == pred.record.layout.test
    assert set(m["window"]) == {NEW_WINDOW}
    row = m[(m["output"] == "heat_flux_in") & (m["model"] == "calibrated")].iloc[0]
    # the model is the truth's own: the errors are the sensor's noise
    assert row["rmse"] < 1.5 * NOISE_SD
    for column, count, rate in (("coverage95", "n_eff95", 0.95), ("coverage50", "n_eff50", 0.5)):
        low, high = honest_range(rate, float(row[count]))
        assert low <= float(row[column]) <= high, (column, row[column], low, high)
    # the band holds what the series says: lower <= mean <= upper where predicted
    keep = window == NEW_WINDOW
    lo, hi = ds["heat_flux_in_calibrated_lower"].values[keep], ds["heat_flux_in_calibrated_upper"]
    mean = ds["heat_flux_in_calibrated"].values[keep]
    assert np.all(lo <= mean)
    assert np.all(mean <= hi.values[keep])
    assert np.isnan(ds["heat_flux_in_calibrated"].values[~keep]).all()
    files = write_new_prediction(pred, tmp_path / "out")
    table = pd.read_csv(files["csv"])
    assert len(table) == keep.sum()
    assert {"heat_flux_in_calibrated_lower50", "heat_flux_in_calibrated_upper"} <= set(table)
    assert files["figure heat_flux_in"].stat().st_size > 0
    assert "RMSE" in files["summary"].read_text(encoding="utf-8")


def test_the_discrepancy_is_kriged_at_the_new_periods_conditions(
    with_delta: Any, tmp_path: Path
) -> None:
    # conditioned_discrepancy(at=...) places, on the new record's periods, the
    # discrepancy conditioned on the study's training residuals at the new x
    # (OutputDiscrepancy, checked against dense Gaussians in
    # tests/calibration/test_conditional.py); its variance never exceeds the
    # prior's r / tau (through the basis), reached far from every training period.
    calibrated = with_delta
    em, post = calibrated.emulator, calibrated.posterior
    new = _write(tmp_path / "other.csv", wall_data(seed=8, phi=0.0))
    record = predict_new(calibrated, new).record
    at = new_assembled(em.assembled, record, calibrated.context.study.emulator.history_periods)
    pick = np.arange(0, post.draws[..., 0].size, 97)
    study_layout = calibrated.context.measured.layout
    rng = np.random.default_rng(0)
    runs = {"heat_flux_in": 0.2 * rng.normal(size=(pick.size, study_layout.n_total))}
    mean, var = conditioned_discrepancy(em.emulator, em.assembled, post, pick, runs, at=at)[
        "heat_flux_in"
    ]
    layout = record.layout
    assert mean.shape == (pick.size, layout.n_total)
    predicted = np.isfinite(mean[0])
    assert predicted.sum() == layout.test
    assert not predicted[: layout.test_begin].any()
    obs = em.assembled.observations
    st = em.assembled.outputs.standardisations[0]
    ko = obs.block(0)[0]
    field = OutputDiscrepancy.build(em.emulator, obs, 0, at.x_test)
    aux = np.asarray(post.aux, float).reshape(-1, len(post.aux_names))[pick]
    bases = list(obs.outputs[0].bases)
    tau_inv = np.array([em.emulator.kernels[j].variance for j in bases])
    for s in (0, pick.size - 1):
        values = dict(zip(post.aux_names, aux[s], strict=True))
        y_sim = (study_layout.cut(runs["heat_flux_in"][s]) - st.mean[:, None]) / st.sd[:, None]
        shift, cov = field.condition(values, obs.weights_of(0, y_sim, 0.0))
        mu = st.sd[:, None] * (ko @ shift.T)  # (n, P)
        v = st.sd[:, None] ** 2 * np.einsum("nj,ajk,nk->na", ko, cov, ko)
        for i, start in enumerate(layout.test_starts):
            span = slice(start, start + layout.period)
            np.testing.assert_allclose(mean[s, span], mu[:, i], rtol=1e-10, atol=1e-12)
            np.testing.assert_allclose(var[s, span], v[:, i], rtol=1e-10, atol=1e-14)
        r = values[obs.coordinate("delta_rel", 0)]
        prior = st.sd**2 * r * ((ko**2) @ tau_inv)
        for start in layout.test_starts:
            assert np.all(var[s, start : start + layout.period] <= prior * (1 + 1e-9))
    assert np.abs(mean[:, predicted]).max() > 0


def test_a_file_without_measurements_is_predicted_without_metrics(
    calibrated: Any, tmp_path: Path
) -> None:
    frame = wall_data(seed=8, phi=0.0).drop(columns=["q_si"])
    pred = predict_new(calibrated, _write(tmp_path / "weather.csv", frame))
    assert pred.metrics.empty
    assert any("no measurement of heat_flux_in" in n for n in pred.notes)
    assert np.isfinite(pred.dataset["heat_flux_in_calibrated"].values).any()


def test_from_and_to_cut_the_record(calibrated: Any, tmp_path: Path) -> None:
    new = _write(tmp_path / "other.csv", wall_data(seed=8, phi=0.0))
    pred = predict_new(
        calibrated,
        new,
        start=pd.Timestamp("2012-02-02 07:00"),
        end=pd.Timestamp("2012-02-07 00:00"),
    )
    layout = pred.record.layout
    # warm-up of one day from 07:00, then whole days in the study's phase (midnight)
    assert layout.test_starts.size == 3
    first = pd.Timestamp(pred.record.times[layout.test_begin])
    assert first == pd.Timestamp("2012-02-04 00:00")


def test_emulator_route_inside_the_range_and_refused_outside(
    calibrated: Any, tmp_path: Path
) -> None:
    study = calibrated.context.measured.source
    inside = predict_new(calibrated, study, method="emulator")
    assert inside.method == "emulator"
    assert not inside.outside
    hot = wall_data(seed=8, phi=0.0)
    hot["T_se"] = hot["T_se"] + 15.0
    path = _write(tmp_path / "hot.csv", hot)
    assert conditions_outside(
        calibrated.emulator.assembled,
        new_assembled(
            calibrated.emulator.assembled,
            predict_new(calibrated, path).record,
            calibrated.context.study.emulator.history_periods,
        ).x_test,
    )
    with pytest.raises(ConfigError, match="outside the emulator's training range"):
        predict_new(calibrated, path, method="emulator")


def test_set_fixes_a_parameter_in_every_draw(calibrated: Any, tmp_path: Path) -> None:
    new = _write(tmp_path / "other.csv", wall_data(seed=8, phi=0.0))
    low = predict_new(calibrated, new, fixed={"k_cb": 0.09})
    high = predict_new(calibrated, new, fixed={"k_cb": 0.15})
    keep = low.dataset["window"].values == NEW_WINDOW
    swing = np.abs(
        high.dataset["heat_flux_in_calibrated"].values[keep]
        - low.dataset["heat_flux_in_calibrated"].values[keep]
    )
    assert swing.mean() > 0.1  # W/m²: a 60 % higher conductivity shows
    with pytest.raises(ConfigError, match="outside its prior"):
        predict_new(calibrated, new, fixed={"k_cb": 0.5})
    with pytest.raises(ConfigError, match="not a calibrated parameter"):
        predict_new(calibrated, new, fixed={"k_fb": 0.05})


def test_bad_new_records_are_one_line_errors(calibrated: Any, tmp_path: Path) -> None:
    frame = wall_data(seed=8, phi=0.0)
    with pytest.raises(DataError, match="T_se"):
        predict_new(calibrated, _write(tmp_path / "a.csv", frame.drop(columns=["T_se"])))
    shifted = frame.copy()
    shifted["time"] = (pd.to_datetime(frame["time"]) + pd.Timedelta("10min")).dt.strftime(
        "%Y-%m-%dT%H:%M:%S"
    )
    with pytest.raises(DataError, match=r"not on the study clock|not in step with the study"):
        predict_new(calibrated, _write(tmp_path / "b.csv", shifted))
    with pytest.raises(DataError, match="at least one whole period"):
        predict_new(calibrated, _write(tmp_path / "c.csv", frame.iloc[:60]))


def test_cli_predict_writes_the_files_and_says_the_verdict(calibrated: Any, tmp_path: Path) -> None:
    study = calibrated.context.study.path
    new = _write(tmp_path / "other.csv", wall_data(seed=8, phi=0.0))
    out = tmp_path / "pred"
    res = CliRunner().invoke(
        main, ["predict", str(study), "--data", str(new), "--out", str(out), "--backend", "serial"]
    )
    assert res.exit_code == 0, res.output
    assert "at the nominal values" in res.output
    assert {p.name for p in out.iterdir()} >= {
        "predictions.nc",
        "predictions.csv",
        "metrics.csv",
        "summary.md",
        "heat_flux_in.png",
    }
    bad = CliRunner().invoke(main, ["predict", str(study), "--data", str(tmp_path / "none.csv")])
    assert bad.exit_code == 2
    assert bad.output.count("\n") == 1
    assert "no such data file" in bad.output
    late = CliRunner().invoke(
        main, ["predict", str(study), "--data", str(new), "--from", "yesterday-ish"]
    )
    assert late.exit_code == 2
    assert "--from" in late.output


def test_predict_as_another_setup_holds_the_stated_accuracy(
    calibrated: Any, tmp_path: Path
) -> None:
    # the other set-up: the same wall under another winter, described by its own study
    # (its own file and column names), the flux's accuracy stated as the true noise SD
    other = tmp_path / "other"
    other.mkdir()
    frame = wall_data(seed=8, phi=0.0).rename(columns={"q_si": "flux"})
    frame.to_csv(other / "wall.csv", index=False)
    text = _study_text("other", discrepancy=False).replace('source = "q_si"', 'source = "flux"')
    text = text.replace('model = "white"', f'model = "white"\nsd = {NOISE_SD}')
    (other / "study.toml").write_text(text, encoding="utf-8")
    pred = predict_as(calibrated, load_study(other))
    row = pred.metrics[pred.metrics["model"] == "calibrated"].iloc[0]
    low, high = honest_range(0.95, float(row["n_eff95"]))
    assert low <= float(row["coverage95"]) <= high
    assert any("stated accuracy" in n for n in pred.notes)
    unstated = tmp_path / "unstated"
    unstated.mkdir()
    frame.to_csv(unstated / "wall.csv", index=False)
    (unstated / "study.toml").write_text(
        _study_text("unstated", discrepancy=False).replace('source = "q_si"', 'source = "flux"'),
        encoding="utf-8",
    )
    with pytest.raises(ConfigError, match="no stated accuracy of heat_flux_in"):
        predict_as(calibrated, load_study(unstated))
