"""Whether a calibration helped: the catalogue comparison and the first-screen warnings."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from bayescal.calibration.posterior import Posterior
from bayescal.design import UniformPrior
from bayescal.report.trust import ABSORBS, catalogue_verdicts, held_out_outputs, trust_warnings


def _table(rows: list[tuple[str, str, str, int, float]]) -> pd.DataFrame:
    """A metrics table from ``(output, model, window, n, rmse)`` rows."""
    frame = pd.DataFrame(rows, columns=["output", "model", "window", "n", "rmse"])
    frame["mse"] = frame["rmse"] ** 2
    return frame


def _pair(output: str, window: str, nominal: float, calibrated: float, n: int = 48) -> list:
    return [
        (output, "nominal", window, n, nominal),
        (output, "calibrated", window, n, calibrated),
    ]


def test_better_worse_and_within_five_percent_on_the_test_window() -> None:
    table = _table(
        # the training window is in sample: a calibrated fit always looks good there
        _pair("better", "train", 2.0, 0.5)
        + _pair("better", "test", 2.0, 1.0)
        + _pair("worse", "train", 2.0, 0.5)
        + _pair("worse", "test", 2.0, 2.2)
        + _pair("same", "train", 2.0, 0.5)
        + _pair("same", "test", 2.0, 2.08)
        + _pair("slightly", "test", 2.0, 1.92)
        + [("corrected", "calibrated+delta", "test", 48, 0.1)]
        + _pair("corrected", "test", 1.0, 1.2)
    )
    verdicts = {v.output: v for v in catalogue_verdicts(table)}
    assert list(verdicts) == ["better", "worse", "same", "slightly", "corrected"]
    assert {k: v.verdict for k, v in verdicts.items()} == {
        "better": "better",
        "worse": "worse",
        "same": "no better",
        "slightly": "no better",
        # the corrected model does not rescue the calibrated parameters
        "corrected": "worse",
    }
    assert verdicts["better"].line() == (
        "better (test window): better: calibrated RMSE 1, nominal (catalogue) 2 (-50 %)"
    )
    assert "no better" in verdicts["same"].line()
    assert "(+4 %)" in verdicts["same"].line()
    assert verdicts["better"].warning() is None
    assert verdicts["same"].warning() is None
    warning = verdicts["worse"].warning()
    assert warning is not None
    assert warning.startswith("worse: the calibrated prediction is worse than the nominal")
    assert "test window: RMSE 2.2 against 2" in warning
    assert warning.endswith(ABSORBS)


def test_a_held_out_sensor_is_judged_over_its_whole_record() -> None:
    # better on the test window, much worse on the (longer) training periods it never saw
    table = _table(
        _pair("sensor", "train", 1.0, 2.0, n=300)
        + _pair("sensor", "test", 1.0, 0.8, n=100)
        + _pair("flux", "test", 1.0, 0.5)
    )
    (flux, sensor) = sorted(catalogue_verdicts(table, held_out=["sensor"]), key=str)
    assert sensor.held_out
    assert sensor.calibrated == pytest.approx(np.sqrt((300 * 4.0 + 100 * 0.64) / 400))
    assert sensor.nominal == pytest.approx(1.0)
    assert sensor.verdict == "worse"
    assert "held-out sensor, whole record" in (sensor.warning() or "")
    # not held out: the test window alone, where it is better
    (alone,) = [v for v in catalogue_verdicts(table) if v.output == "sensor"]
    assert alone.verdict == "better"
    assert flux.verdict == "better"


def test_without_a_test_window_the_verdict_is_unknown_not_better() -> None:
    verdict = catalogue_verdicts(_table(_pair("flux", "train", 2.0, 0.5)))[0]
    assert verdict.verdict == "unknown"
    assert verdict.warning() is None
    assert verdict.line() == "flux (test window): not known (no test window to compare on)"


def test_held_out_outputs_are_read_from_the_attrs() -> None:
    assert held_out_outputs({"held_out": "a,b"}) == ("a", "b")
    assert held_out_outputs({"held_out": ""}) == ()
    assert held_out_outputs({}) == ()


def _posterior(unit: np.ndarray) -> Posterior:
    chains, draws = unit.shape[:2]
    priors = {"k": UniformPrior(0.1, 0.3, unit="W/(m·K)"), "c": UniformPrior(1.0, 2.0)}
    lam = np.random.default_rng(1).gamma(5.0, 1.0, (chains, draws, 2))
    accepted = np.full((chains, 4), 0.3)
    return Posterior.build(
        ["k", "c"], priors, unit, lam=lam[..., 0], lam_star=lam[..., 1], acceptance=accepted
    )


def test_trust_warnings_gather_bounds_of_both_phases_and_the_catalogue() -> None:
    rng = np.random.default_rng(0)
    flat = rng.random((2, 300, 2))
    piled = flat.copy()
    piled[..., 0] = 1.0 - np.abs(rng.normal(0.0, 0.03, (2, 300)))
    table = _table(_pair("flux", "test", 1.0, 1.5))
    assert trust_warnings(_posterior(flat)) == ()
    found = trust_warnings(_posterior(piled), _posterior(piled), table)
    assert [w.split(":")[0] for w in found] == ["calibration", "difference process", "flux"]
    assert "k leans on the upper bound of its prior (0.3 W/(m·K))" in found[0]
    assert trust_warnings(None, None, _table(_pair("flux", "test", 1.0, 0.5))) == ()


def _posterior_with_prior_from(centre: tuple[float, float]) -> Posterior:
    """A posterior whose draws sit at ``centre`` (normalised) under a prior fitted to
    draws around 0.5: its shared parameters' prior is that logit-normal."""
    from bayescal.design import PosteriorPrior, fit_logit_normal

    rng = np.random.default_rng(2)
    names = ("k", "c")
    previous = 0.5 + 0.02 * rng.standard_normal((4000, 2))
    joint = fit_logit_normal(names, previous, source="../first")
    priors = {
        n: PosteriorPrior(0.0, 1.0, joint=joint, index=i, unit="1") for i, n in enumerate(names)
    }
    draws = np.asarray(centre) + 0.01 * rng.standard_normal((4, 500, 2))
    aux = np.ones((4, 500, 2)) + 0.01 * rng.standard_normal((4, 500, 2))
    return Posterior.build(
        names,
        priors,
        draws,
        acceptance=np.full((4, 4), 0.3),
        aux=aux,
        aux_names=("lambda", "lambda_star"),
    )


def test_a_posterior_in_the_thin_tail_of_a_prior_from_draws_is_a_warning() -> None:
    """The records disagree where the new centre lies farther out than 95 % of the prior."""
    from bayescal.report.trust import prior_conflicts

    assert prior_conflicts(_posterior_with_prior_from((0.51, 0.49))) == ()
    far = prior_conflicts(_posterior_with_prior_from((0.56, 0.5)))  # 3 prior SD out
    assert len(far) == 1
    assert far[0].startswith("the posterior of k, c lies where the prior from ../first is thin")
    assert "`bayescal joint`" in far[0]
    assert any(
        "../first is thin" in w for w in trust_warnings(_posterior_with_prior_from((0.56, 0.5)))
    )
