"""``bayescal joint``: two records of one wall calibrated together.

The 14-day virtual wall of :mod:`sequential_study`: study ``a`` trains on days
2-7, study ``b`` on days 8-13 of the same record, and ``bseq`` is ``b`` with
``a``'s posterior as its prior (``[study] prior_from``). ``b`` and ``bseq`` have
the same design, runs and emulator (the design spans the priors' bounds, which
``prior_from`` keeps), so the joint calibration of ``a`` and ``b`` and the
sequential one differ only by the logit-normal fitted to ``a``'s draws and by
Monte Carlo error.
"""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from bayescal.calibration.joint import JointPosterior, Record
from bayescal.calibration.priors import ThetaPriors
from bayescal.calibration.target import build_target
from bayescal.cli import main
from bayescal.config import load_study
from bayescal.design import BetaPrior
from bayescal.errors import ConfigError
from bayescal.pipeline import Options, load_results, run
from bayescal.pipeline.joint import _disagreements, _record, joint
from bayescal.store.posterior import load_posterior
from sequential_study import write_study

#: Longer chains than the helper study's, for Monte Carlo errors a few % of an SD.
CHAINS = (
    "burn = 150\nsamples = 200\nmax_samples = 200",
    "burn = 300\nsamples = 1200\nmax_samples = 1200",
)
SECOND = 'warmup = "1D"\ntrain_from = "2012-02-08T00:00"\n'


def _edit(folder: Path, *pairs: tuple[str, str]) -> Path:
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    for old, new in pairs:
        assert old in text, old
        text = text.replace(old, new)
    path.write_text(text, encoding="utf-8")
    return folder


def _second(folder: Path, extra: str = "") -> Path:
    """The record's days 8-13 (its own design and emulator), ``extra`` in ``[study]``."""
    return _edit(write_study(folder, None, extra), CHAINS, ('warmup = "1D"\n', SECOND))


@pytest.fixture(scope="module")
def studies(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("joint")
    a = _edit(write_study(root / "a"), CHAINS)
    folders = {
        "a": a,
        "b": _second(root / "b"),
        "bseq": _second(root / "bseq", f'prior_from = "{a}"\n'),
    }
    for folder in folders.values():
        run(load_study(folder), until="calibrate", options=Options(backend="serial"))
    return folders


@pytest.fixture(scope="module")
def together(
    studies: dict[str, Path], tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, object]:
    out = tmp_path_factory.mktemp("joint-out")
    said: list[str] = []
    result = joint([studies["a"], studies["b"]], out, say=said.append)
    assert said[0].startswith("joint calibration of a, b: 2 parameters (k_cb, cp_cb)")
    return out, result


def _column(post: object, k: int) -> np.ndarray:
    draws = post.draws  # type: ignore[attr-defined]
    return draws.reshape(-1, draws.shape[-1])[:, k]


def _target_parts(folder: Path) -> tuple[object, ...]:
    em = load_results(load_study(folder)).emulator
    assert em is not None
    return em.emulator, em.assembled.w_star, em.assembled.lam_star_prior


def test_the_joint_density_is_the_product_of_the_records(studies: dict[str, Path]) -> None:
    a = _record(load_results(load_study(studies["a"])))
    b = _record(load_results(load_study(studies["b"])))
    priors = dict(
        zip(a.names, load_results(load_study(studies["a"])).context.priors.values(), strict=True)
    )
    target = JointPosterior([a, b], priors)
    assert target.d == 2 + a.n_aux + b.n_aux
    assert target.aux_names == ("a:lambda", "a:lambda_star", "b:lambda", "b:lambda_star")
    rng = np.random.default_rng(4)
    for _ in range(5):
        u = rng.uniform(0.2, 0.8, 2)
        ea, eb = rng.gamma(5.0, 1.0, a.n_aux), rng.gamma(5.0, 1.0, b.n_aux)
        v = np.concatenate([u, ea, eb])
        expected = a.target(np.concatenate([u, ea])) + b.target(np.concatenate([u, eb]))
        assert target(v) == pytest.approx(expected, rel=1e-12, abs=1e-9)
    # the prior of a shared parameter counts once: records built with Beta priors
    beta = {n: BetaPrior(p.lower, p.upper, 2.0, 3.0, unit=p.unit) for n, p in priors.items()}
    a_beta, b_beta = (
        dataclasses.replace(r, target=build_target(*_target_parts(studies[k]), list(beta.values())))
        for r, k in ((a, "a"), (b, "b"))
    )
    weighted = JointPosterior([a_beta, b_beta], beta)
    counted_twice = a_beta.target(np.concatenate([u, ea])) + b_beta.target(np.concatenate([u, eb]))
    once = ThetaPriors(tuple(beta.values())).scalar(u)
    assert once != 0.0
    assert weighted(v) == pytest.approx(counted_twice - once, rel=1e-12)
    # outside a bound: zero density
    assert target(np.concatenate([[1.2, 0.5], ea, eb])) == -np.inf
    # a record that does not calibrate cp_cb holds it at its value there
    held = Record("b", b.target, b.names, {"cp_cb": 0.3})
    only = JointPosterior([a, held], priors)
    v = np.concatenate([u, ea, eb])
    assert np.array_equal(only.record_vector(1, v)[:2], [u[0], 0.3])
    assert only(v) == pytest.approx(
        a.target(np.concatenate([u, ea])) + b.target(np.concatenate([[u[0], 0.3], eb])), rel=1e-12
    )


def test_joint_equals_the_sequential_calibration(
    studies: dict[str, Path], together: tuple[Path, object]
) -> None:
    out, result = together
    post = result.posterior  # type: ignore[attr-defined]
    assert post.diagnostics.ok, post.warnings
    assert result.warnings == ()  # type: ignore[attr-defined]
    sequential = load_results(load_study(studies["bseq"])).posterior
    alone = {k: load_results(load_study(studies[k])).posterior for k in ("a", "b")}
    assert sequential is not None
    for k, name in enumerate(post.names):
        j, s = _column(post, k), _column(sequential, k)
        # both chains pass R-hat <= 1.01 and ESS >= 400: each mean's Monte Carlo error is
        # below 0.05 SD, so 0.2 SD is the bound with room for the fitted prior
        assert abs(j.mean() - s.mean()) < 0.2 * j.std(), name
        width = np.diff(np.quantile(j, [0.025, 0.975]))[0]
        assert width == pytest.approx(np.diff(np.quantile(s, [0.025, 0.975]))[0], rel=0.10), name
        for own in alone.values():
            assert j.std() < 0.9 * _column(own, k).std(), name  # two records know more than one
    summary = pd.read_csv(out / "joint-summary.csv")
    assert sorted(set(summary["source"])) == ["a", "b", "joint"]
    # the wall's derived quantities (its U-value ...) at the joint draws, beside each study's
    u = summary[summary["parameter"] == "U_value"].set_index("source")
    assert list(u.index) == ["a", "b", "joint"]
    assert u.loc["joint", "sd"] < min(u.loc["a", "sd"], u.loc["b", "sd"])
    back = load_posterior(out / "posterior.nc")
    assert back.aux_names == ("a:lambda", "a:lambda_star", "b:lambda", "b:lambda_star")
    assert np.array_equal(back.unit_draws, post.unit_draws)
    assert (out / "joint.png").stat().st_size > 10_000
    page = (out / "joint.md").read_text(encoding="utf-8")
    assert "| quantity | unit | a | b | joint |" in page
    assert "WARNING" not in page  # the records agree


def test_cli_joint_resumes_the_finished_chains_and_prints_the_table(
    studies: dict[str, Path], together: tuple[Path, object]
) -> None:
    out, result = together
    cli = CliRunner().invoke(
        main, ["joint", str(studies["a"]), str(studies["b"]), "--out", str(out), "-q"]
    )
    assert cli.exit_code == 0, cli.output
    lines = cli.output.splitlines()
    assert lines[0] == "means [95 % intervals]"
    assert lines[1].split() == ["parameter", "unit", "a", "b", "joint"]
    assert lines[2].startswith("k_cb")
    # the chains' snapshots in --out are resumed: the same draws, none sampled again
    again = load_posterior(out / "posterior.nc")
    assert np.array_equal(again.unit_draws, result.posterior.unit_draws)  # type: ignore[attr-defined]


def test_records_that_disagree_are_a_warning() -> None:
    rows = [
        ("k", "a", 1.0, 0.9, 1.1),
        ("k", "b", 2.0, 1.9, 2.1),
        ("k", "joint", 1.5, 1.45, 1.55),
        ("c", "a", 5.0, 4.0, 6.0),
        ("c", "joint", 5.1, 4.5, 5.5),
    ]
    summary = pd.DataFrame(rows, columns=["parameter", "source", "mean", "lower", "upper"])
    said = _disagreements(summary)
    assert len(said) == 2
    assert said[0].startswith(
        "k: the joint mean 1.5 lies outside the 95 % interval of a alone [0.9, 1.1]"
    )
    assert "the records disagree" in said[1]


def test_studies_that_cannot_be_calibrated_together_are_one_line(
    studies: dict[str, Path], tmp_path: Path
) -> None:
    def refused(*paths: Path, out: Path | None = None) -> str:
        with pytest.raises(ConfigError) as err:
            joint(list(paths), out or tmp_path / "out")
        return err.value.one_line()

    assert "needs two studies or more, got 1" in refused(studies["a"])
    assert "nowhere: file not found" in refused(studies["a"], tmp_path / "nowhere")
    assert "prior_from" in refused(studies["a"], studies["bseq"])
    twin = tmp_path / "twin" / "a"
    shutil.copytree(studies["a"], twin)
    assert "two studies are named 'a'" in refused(studies["a"], twin)
    other = _edit(
        write_study(tmp_path / "other"),
        ("[parameters.k_cb]", "[parameters.k_other]"),
        ("[parameters.cp_cb]", "[parameters.cp_other]"),
    )
    assert "share no calibrated parameter" in refused(studies["a"], other)
    wider = _edit(
        write_study(tmp_path / "wider"), ("lower = 0.08, upper = 0.16", "lower = 0.05, upper = 0.2")
    )
    line = refused(studies["a"], wider)
    assert "k_cb has the prior" in line
    assert "give k_cb the same prior in every study" in line
    stale = tmp_path / "stale"
    shutil.copytree(studies["b"], stale)
    _edit(stale, ("pca_components = 2", "pca_components = 3"))
    line = refused(studies["a"], stale)
    assert "the study changed since its emulator stage ran (emulator.pca_components" in line
    assert "run `bayescal run" in line
    assert "is the output folder of" in refused(
        studies["a"], studies["b"], out=studies["b"] / "out"
    )
    fresh = write_study(tmp_path / "fresh")
    assert "fresh/out has no finished calibration" in refused(studies["a"], fresh)
    assert not (tmp_path / "out" / "posterior.nc").exists()
    cli = CliRunner().invoke(
        main, ["joint", str(studies["a"]), str(fresh), "--out", str(tmp_path / "o")]
    )
    assert cli.exit_code == 2
    assert cli.output.count("\n") == 1
    assert cli.output.startswith("error: ")


def test_joint_md_puts_the_warnings_first_and_the_notes_before_the_figure() -> None:
    from bayescal.report.joint import joint_markdown

    rows = [("k", "a", "1", 1.0, 0.9, 1.1), ("k", "joint", "1", 1.0, 0.95, 1.05)]
    summary = pd.DataFrame(rows, columns=["parameter", "source", "unit", "mean", "lower", "upper"])
    page = joint_markdown(summary, ["a"], ["they disagree"], "joint.png", ["b holds c"])
    lines = page.splitlines()
    assert lines[2] == "**WARNING:** they disagree"
    assert "| k | 1 | 1 [0.9, 1.1] | 1 [0.95, 1.05] |" in lines
    assert lines.index("Note: b holds c") < lines.index(
        "![each record alone and together](joint.png)"
    )
