"""The calibration report: figures, the self-contained HTML page and the posterior CSV."""

from __future__ import annotations

import base64
import dataclasses
import html
import io
import re
from pathlib import Path

import matplotlib.image as mpimg
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest
import xarray as xr

from bayescal.calibration.posterior import Posterior, calibrate
from bayescal.config import load_study
from bayescal.emulator.assemble import Assembled, assemble
from bayescal.emulator.gp import Emulator, LooResult
from bayescal.emulator.training import train
from bayescal.examples import copy_example
from bayescal.metrics import KEY_COLUMNS, metric_columns
from bayescal.pipeline.predict import (
    delta_series,
    metrics_table,
    predict_band,
    predictions_dataset,
)
from bayescal.pipeline.stages import prepare
from bayescal.report import figures as fg
from bayescal.report.html import ReportInputs, render, write_report
from bayescal.report.study import delta_correlation, report_settings
from bayescal.runner import RunFailure
from virtual_wall import PRIORS, VirtualExperiment, simulate, virtual_experiment

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SECTIONS = (
    "Summary",
    "Calibration parameters",
    "Fit metrics",
    "Emulator",
    "Discrepancy",
    "Figures",
    "Failed runs",
    "Settings",
)
EVIL = "Wall <script>alert('x')</script> & co"
N_CHAINS, N_DRAWS = 4, 20


class LinearDelta:
    """A stand-in discrepancy: a fixed offset plus a multiple of the first input."""

    def __init__(self, n_rows: int) -> None:
        self.shape = np.linspace(-0.1, 0.1, n_rows)[:, None]

    def predict(self, x_new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        mean = 0.05 + self.shape * x_new[:, 0][None, :]
        return mean, np.full_like(mean, 1e-3)


def _png_ok(data: bytes) -> bool:
    """A PNG with more than one distinct pixel value (not a blank image)."""
    if not data.startswith(PNG_SIGNATURE):
        return False
    pixels = mpimg.imread(io.BytesIO(data), format="png")
    first = pixels[0, 0]
    return bool(np.any(pixels != first))


@dataclasses.dataclass(frozen=True)
class Parts:
    """A small calibrated virtual wall, with and without a (stand-in) discrepancy."""

    ve: VirtualExperiment
    em: Emulator
    loo: LooResult
    post: Posterior
    post_delta: Posterior
    ds_plain: xr.Dataset
    ds_delta: xr.Dataset


@pytest.fixture(scope="module")
def parts() -> Parts:
    ve = virtual_experiment(seed=4, runs=8, periods=6, warmup_days=2, test_days=1)
    a: Assembled = assemble(ve.design, ve.runs, ve.measured, ve.boundary, ve.layout, components=2)
    em = train(a, n_burn=100, n_draws=20, n_chains=1, seed=0)
    post, post_delta = (
        calibrate(em, a, n_chains=N_CHAINS, n_burn=30, n_draws=N_DRAWS, seed=s, backend="serial")
        for s in (1, 2)
    )
    times = np.datetime64("2024-01-01T00:00", "ns") + np.arange(ve.layout.n_total) * np.timedelta64(
        30, "m"
    )
    nominal = simulate(ve.boundary, {n: 0.5 * (p.lower + p.upper) for n, p in PRIORS.items()})
    delta_model = LinearDelta(a.outputs.sd.size)
    band = predict_band(em, a, post, draws=20)
    corrected = predict_band(em, a, post_delta, draws=20, discrepancy=delta_model)
    delta = delta_series(a, delta_model, ["heat_flux_in"])
    common = (times, ve.layout, ve.measured, {"heat_flux_in": nominal}, band, ve.boundary)
    ds_plain = predictions_dataset(*common)
    ds_delta = predictions_dataset(*common, corrected=corrected, delta=delta)
    return Parts(ve, em, em.loo_cv(), post, post_delta, ds_plain, ds_delta)


def _correlation(ds: xr.Dataset) -> pd.DataFrame:
    train_mask = ds["window"].values == "train"
    d = ds["heat_flux_in_delta"].values[train_mask]
    row = {
        b: float(np.corrcoef(d, ds[f"bc_{b}"].values[train_mask])[0, 1])
        for b in ("temp_surf_out", "temp_surf_in")
    }
    return pd.DataFrame({"heat_flux_in": row}).T


def _inputs(parts: Parts, *, with_delta: bool, failures: bool) -> ReportInputs:
    ve = parts.ve
    design = ve.design
    ds = parts.ds_delta if with_delta else parts.ds_plain
    fails: tuple[RunFailure, ...] = ()
    if failures:
        fails = (
            RunFailure(3, "k3", design.row(3), "bayescal.errors.SimulatorError", "<b>boom</b>", 2),
        )
    return ReportInputs(
        study_name=EVIL,
        description="line one\n<img src=x onerror=alert(1)>",
        config_hash="abc123",
        design=design,
        failures=fails,
        emulator=parts.em,
        loo=parts.loo,
        posterior=parts.post,
        discrepancy_posterior=parts.post_delta if with_delta else None,
        predictions=ds,
        metrics=metrics_table(ds),
        delta_correlation=_correlation(ds) if with_delta else None,
        delta_explained={"heat_flux_in": 0.4} if with_delta else None,
        warnings=("R-hat of k_cb is 1.2 <above 1.01>",) if failures else (),
        settings={"runs (design)": 8, "<setting>": "<value>"},
    )


@pytest.fixture(scope="module")
def full_report(parts: Parts, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("full")
    return write_report(_inputs(parts, with_delta=True, failures=True), folder)


def _images(text: str) -> list[bytes]:
    found = re.findall(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    return [base64.b64decode(s) for s in found]


def test_report_has_every_section_and_embeds_every_figure(full_report: Path) -> None:
    assert full_report.name == "report.html"
    text = full_report.read_text(encoding="utf-8")
    for title in SECTIONS:
        assert f"<h2>{title}</h2>" in text, title
    assert "The test window is read only for these final metrics" in text
    # Posterior (3) + emulator (3) figures, and per output: fit, fit with Delta, Delta vs BC.
    images = _images(text)
    assert len(images) == 8 + 3
    pngs = sorted((full_report.parent / "figures").glob("*.png"))
    assert len(pngs) == len(images)
    assert sorted(images) == sorted(p.read_bytes() for p in pngs)
    assert all(_png_ok(data) for data in images)
    # Self-contained: nothing fetched from elsewhere.
    assert not re.search(r"<(script|link)\b", text)
    assert not re.search(r'src="(?!data:)', text)


def test_user_strings_are_escaped(full_report: Path) -> None:
    text = full_report.read_text(encoding="utf-8")
    assert "<script>" not in text
    assert "&lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt; &amp; co" in text
    assert "<img src=x" not in text
    assert "&lt;b&gt;boom&lt;/b&gt;" in text  # failure message
    assert "&lt;above 1.01&gt;" in text  # warning
    assert "&lt;setting&gt;" in text
    assert "&lt;value&gt;" in text


def test_warnings_failures_and_metrics_are_shown(full_report: Path) -> None:
    text = full_report.read_text(encoding="utf-8")
    assert 'class="warn"' in text
    assert "simulator run failed" not in text
    assert "1 run(s) failed" in text
    for model in ("nominal", "calibrated", "calibrated + Δ"):
        assert f"<td>{model}</td>" in text
    assert "training window" in text
    assert "test window" in text
    assert "maximum</b> absolute error" in text
    assert "<th>meets Guideline 14</th>" in text


def test_draws_csv_matches_the_posterior(parts: Parts, full_report: Path) -> None:
    post = parts.post
    table = pd.read_csv(full_report.parent / "posterior_draws.csv")
    names = [*post.names, "lambda", "lambda_star"]
    assert list(table.columns) == ["chain", "draw", *names]
    assert len(table) == N_CHAINS * N_DRAWS
    draws = post.all_draws()
    for chain in range(N_CHAINS):
        rows = table[table["chain"] == chain].sort_values("draw")
        np.testing.assert_array_equal(rows["draw"].to_numpy(), np.arange(N_DRAWS))
        # CSV floats are written with repr (shortest round-trip): equal to the last bit.
        np.testing.assert_array_equal(rows[names].to_numpy(), draws[chain])


def test_report_without_discrepancy_or_failures_and_with_two_outputs(
    parts: Parts, tmp_path: Path
) -> None:
    # A stale figure from an earlier report must not survive in figures/.
    (tmp_path / "figures").mkdir()
    (tmp_path / "figures" / "delta_bc_old.png").write_bytes(PNG_SIGNATURE)
    # A second output (a shifted copy) gets its own tables and figure.
    ds = parts.ds_plain.copy()
    for kind in ("measured", "nominal", "calibrated", "calibrated_lower", "calibrated_upper"):
        ds[f"temp_interface_{kind}"] = ds[f"heat_flux_in_{kind}"] + 15.0
    ds.attrs["outputs"] = "heat_flux_in,temp_interface"
    inputs = dataclasses.replace(
        _inputs(parts, with_delta=False, failures=False), predictions=ds, metrics=metrics_table(ds)
    )
    text = write_report(inputs, tmp_path).read_text(encoding="utf-8")
    for title in SECTIONS:
        assert f"<h2>{title}</h2>" in text, title
    assert len(_images(text)) == 8 + 2
    assert len(list((tmp_path / "figures").glob("*.png"))) == 8 + 2
    assert "temp_interface [°C], training window" in text
    assert "MSE [(W/m²)²]" in text
    assert "MSE [°C²]" in text
    assert "No simulator run failed." in text
    assert "The difference process Δ (<code>[discrepancy] enabled</code>" in text
    assert "was not used: no Δ was estimated." in text
    assert "<code>[outputs.errors.NAME] discrepancy</code>): none." in text
    assert 'class="ok"' in text
    assert "calibrated + Δ" not in text


def test_loo_predictions_reproduce_the_emulators_residuals(parts: Parts) -> None:
    em, loo = parts.em, parts.loo
    out = fg.loo_predictions(em)
    sim, mean, sd = out["heat_flux_in"]
    # The simulations come back from the standardised ones (scale and shift only).
    runs = parts.ve.runs["heat_flux_in"]
    assert sim.shape == mean.shape == sd.shape == loo.z.shape
    assert np.all((sim >= runs.min() - 1e-9) & (sim <= runs.max() + 1e-9))
    # The figures' unstandardised predictions give back the emulator's residuals.
    np.testing.assert_allclose((sim - mean) / sd, loo.z, rtol=1e-7, atol=1e-7)


def test_figure_functions_work_alone_on_plain_arrays(tmp_path: Path) -> None:
    # The report tests check the PNG of every figure function on pipeline objects;
    # here the array-based ones are called alone on synthetic data.
    rng = np.random.default_rng(0)
    written = [
        fg.plot_rho_sensitivity(tmp_path / "d.png", rng.random((3, 4)), ["a", "b", "c", "d"]),
        fg.plot_pca_variance(tmp_path / "e.png", [0.7, 0.2, 0.06, 0.04], 2),
        fg.plot_emulator_loo(
            tmp_path / "f.png",
            {"heat_flux_in": rng.normal(size=50)},
            {"heat_flux_in": rng.normal(size=50)},
            {"heat_flux_in": rng.normal(size=50)},
        ),
        fg.plot_delta_vs_boundary(
            tmp_path / "h.png", "heat_flux_in", rng.normal(size=40), {"x": rng.normal(size=40)}
        ),
    ]
    for path in written:
        assert _png_ok(path.read_bytes()), path.name
    assert not list(tmp_path.glob(".*.tmp"))  # atomic writes leave no temporary files


def test_rho_heatmap_needs_one_label_per_input(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="rho has 3 columns, got 2 input labels"):
        fg.plot_rho_sensitivity(tmp_path / "x.png", np.full((2, 3), 0.5), ["a", "b"])


def test_fit_figure_without_predictions_still_renders(tmp_path: Path) -> None:
    n = 10
    times = np.datetime64("2024-01-01", "ns") + np.arange(n) * np.timedelta64(1, "h")
    nan = np.full(n, np.nan)
    path = fg.plot_fit(tmp_path / "x.png", times, ["warmup"] * n, "heat_flux_in", nan, nan)
    assert _png_ok(path.read_bytes())


def test_posterior_overlay_accepts_the_discrepancy_phase(parts: Parts, tmp_path: Path) -> None:
    post = parts.post
    shifted = dataclasses.replace(post, unit_draws=post.unit_draws * 0.5)
    path = fg.plot_posterior_histograms(tmp_path / "x.png", post, shifted)
    assert _png_ok(path.read_bytes())


def test_blank_png_is_detected(tmp_path: Path) -> None:
    # The non-blank check used above must reject an image of a single colour.
    fig = plt.figure(figsize=(2, 2))
    fig.savefig(tmp_path / "blank.png", format="png")
    plt.close(fig)
    assert not _png_ok((tmp_path / "blank.png").read_bytes())
    assert not _png_ok(b"GIF89a" + bytes(100))


def test_posterior_table_shows_the_parameters_units(parts: Parts) -> None:
    priors = {
        name: dataclasses.replace(prior, unit="W/(m·K)" if name == "k_cb" else "")
        for name, prior in parts.post.priors.items()
    }
    post = dataclasses.replace(parts.post, priors=priors)
    inputs = dataclasses.replace(_inputs(parts, with_delta=False, failures=False), posterior=post)
    text = render(inputs, [])
    assert "<th>parameter</th><th>unit</th><th>mean</th>" in text
    assert "<td>k_cb</td><td>W/(m·K)</td>" in text
    assert "<td>cp_cb</td><td>–</td>" in text  # no unit given
    assert "<td>lambda</td><td>1</td>" in text  # a precision in standardised units


def test_metric_tables_take_their_columns_from_the_one_list(parts: Parts) -> None:
    inputs = _inputs(parts, with_delta=False, failures=False)
    assert list(inputs.metrics.columns) == [
        *KEY_COLUMNS,
        *(c.name for c in metric_columns("csv")),
    ]
    text = render(inputs, [])
    headers = [c.title.format(u="W/m²", u2="(W/m²)²") for c in metric_columns("report")]
    assert "<th>model</th>" + "".join(f"<th>{html.escape(h)}</th>" for h in headers) in text


def test_delta_correlation_of_the_report(parts: Parts) -> None:
    ds = _inputs(parts, with_delta=True, failures=False).predictions
    table = delta_correlation(ds)
    reference = _correlation(ds)  # the same Pearson r, written out here
    assert list(table.index) == ["heat_flux_in"]
    np.testing.assert_allclose(
        table[reference.columns].to_numpy(float), reference.to_numpy(float), rtol=1e-12
    )


def test_settings_say_how_far_the_calibration_may_be_extended(tmp_path: Path) -> None:
    folder = copy_example("wall", tmp_path / "wall")
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    ctx = prepare(load_study(folder))
    cal = ctx.study.calibration
    shown = report_settings(ctx.study, ctx.measured.layout)["calibration MCMC"]
    longer = f", extended up to {4 * cal.samples} until converged"
    assert str(shown).endswith(f"({cal.burn} + {cal.samples}{longer})")
    fixed = f"[calibration]\nmax_samples = {cal.samples}\n"
    path.write_text(text.replace("[calibration]\n", fixed), encoding="utf-8")
    ctx = prepare(load_study(folder))
    shown = report_settings(ctx.study, ctx.measured.layout)["calibration MCMC"]
    assert str(shown).endswith(f"({cal.burn} + {cal.samples})")


def test_the_first_screen_says_when_the_calibration_did_not_help(
    parts: Parts, tmp_path: Path
) -> None:
    """A parameter piled at its upper bound and a calibrated prediction worse than the
    nominal on the test window: both are warnings above the first table, and one line per
    output compares the two predictions out of sample."""
    from bayescal.report.study import write_study_report

    ctx = prepare(load_study(copy_example("wall", tmp_path / "wall")))
    unit = parts.post.unit_draws.copy()
    unit[..., 0] = 1.0 - np.abs(np.random.default_rng(0).normal(0.0, 0.03, unit.shape[:2]))
    piled = dataclasses.replace(parts.post, unit_draws=unit)
    metrics = metrics_table(parts.ds_plain)
    test = metrics["window"] == "test"
    nominal = float(metrics.loc[test & (metrics["model"] == "nominal"), "rmse"].iloc[0])
    metrics.loc[test & (metrics["model"] == "calibrated"), "rmse"] = 1.5 * nominal

    def page(posterior: Posterior, table: pd.DataFrame, name: str) -> str:
        path = write_study_report(
            ctx.study,
            ctx.measured.layout,
            tmp_path / name,
            design=parts.ve.design,
            failures=(),
            emulator=parts.em,
            loo=parts.loo,
            posterior=posterior,
            discrepancy=None,
            predictions=parts.ds_plain,
            metrics=table,
        )
        return html.unescape(path.read_text(encoding="utf-8"))

    text = page(piled, metrics, "bad")
    first_table = text.index("<table")
    name = parts.post.names[0]
    lean = text.index(f"calibration: {name} leans on the upper bound of its prior")
    worse = text.index("heat_flux_in: the calibrated prediction is worse than the nominal")
    verdict = text.index("heat_flux_in (test window): worse: calibrated RMSE")
    assert max(lean, worse, verdict) < first_table
    assert "treat it as a fitting constant" in text[lean:first_table]
    assert "treat them as fitting constants, not properties" in text[worse:first_table]
    assert "No warnings" not in text
    # the calibration as it came out: nothing piled at a bound, the table as computed
    plain = page(parts.post, metrics_table(parts.ds_plain), "plain")
    assert "leans on" not in plain
    assert "heat_flux_in (test window): " in plain[: plain.index("<table")]


def test_the_first_screen_is_the_answer(parts: Parts) -> None:
    """The fit table, the calibrated quantities beside their catalogue values, the
    convergence verdict and one band line per output come before any folded section;
    every other section folds; tables scroll inside their box."""
    from bayescal.calibration.posterior import Derived

    post = parts.post
    k = post.draws[..., post.names.index("k_cb")]
    derived = {"R_layer": Derived(0.15 / k, "m²·K/W", "resistance of the layer")}
    nominal = {"k_cb": 0.12, "R_layer": 0.15 / 0.12}
    inputs = dataclasses.replace(
        _inputs(parts, with_delta=False, failures=False),
        posterior=post.with_derived(derived),
        nominal=nominal,
    )
    text = render(inputs, [])
    first = text[: text.index("<details><summary><h2>")]
    for title in SECTIONS[1:]:
        assert f"<details><summary><h2>{title}</h2></summary>" in text, title
    assert "<h2>Summary</h2>" in first
    assert "<th>nominal (catalogue)</th><th>calibrated</th>" in first
    assert "<td>test window (out of sample)</td>" in first
    rows = inputs.metrics
    test_rmse = rows[(rows["window"] == "test") & (rows["model"] == "calibrated")]["rmse"]
    assert f"<td>{float(test_rmse.iloc[0]):.4g}</td>" in first
    flat = (0.15 / k).reshape(-1)
    low, high = np.percentile(flat, [2.5, 97.5])
    row = re.search(
        r"<td>R_layer</td><td>m²·K/W</td><td>([0-9.]+)</td><td>([0-9.]+) – ([0-9.]+)</td>"
        r"<td>([0-9.]+)</td>",
        first,
    )
    assert row, "no row of R_layer"
    shown = [float(v) for v in row.groups()]
    # two significant digits of the interval's width: within a tenth of it
    np.testing.assert_allclose(shown[:3], [np.mean(flat), low, high], atol=(high - low) / 10)
    assert shown[3] == pytest.approx(0.15 / 0.12, rel=1e-4)
    assert first.index("<td>R_layer</td>") < first.index("<td>k_cb</td>")  # derived first
    assert "<td>cp_cb</td>" in first  # every parameter; no nominal given: "–"
    assert "Converged?" in first
    assert "heat_flux_in: the 95 % band " in first
    assert 'class="scroll"><table>' in text
    assert "overflow-x:auto" in text


def test_settings_state_the_emulator_training_used(tmp_path: Path) -> None:
    folder = copy_example("wall", tmp_path / "wall")
    ctx = prepare(load_study(folder))
    settings = report_settings(ctx.study, ctx.measured.layout)
    assert ctx.study.emulator.training == "map"
    assert str(settings["emulator training ([emulator] training)"]).startswith("map: ")
    assert not any("MCMC (burn" in str(key) for key in settings)
    assert settings["in-likelihood discrepancy ([outputs.errors.NAME] discrepancy)"] == "none"
    assert settings["difference process Δ ([discrepancy] enabled)"] == "not used"
    # an in-likelihood discrepancy is named as the summary and the uncertainty table name it
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    path.write_text(text + "\n[outputs.errors.heat_flux_in]\ndiscrepancy = true\n", "utf-8")
    ctx = prepare(load_study(folder))
    settings = report_settings(ctx.study, ctx.measured.layout)
    shown = settings["in-likelihood discrepancy ([outputs.errors.NAME] discrepancy)"]
    assert shown == "heat_flux_in (over the periods' conditions)"


def test_many_warnings_fold_after_the_first_few(parts: Parts) -> None:
    """A short run failing every diagnostic must not push the answer off the first screen:
    the first five warnings show, the rest fold under them."""
    warnings = tuple(f"warning number {k}" for k in range(8))
    inputs = dataclasses.replace(
        _inputs(parts, with_delta=False, failures=False), warnings=warnings
    )
    text = render(inputs, [])
    folded = text.index("<details><summary>3 more warning(s)</summary>")
    assert text.index("<li>warning number 4</li>") < folded < text.index("warning number 5")
    assert folded < text.index("<table")
