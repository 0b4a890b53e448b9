"""The paper's test-box examples: the built-in box calibrated on an EnergyPlus truth.

``box-coheating`` and ``box-freefloat`` are virtual experiments (their
``data/README.md``): the "measurements" are the EnergyPlus model of the box at
known parameters plus noise, the calibrated model is the built-in finite-volume
box (the free-float phase has a known pseudo-random heat input, without which
k_wall is not identified). References are the stated truth and the nominal
model, never the code under test. The pipeline runs at reduced size (fewer
runs, short chains).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bayescal import examples
from bayescal.config import BoxSimulator, load_study
from bayescal.data.measured import load_measured
from bayescal.pipeline import Options, Results, run
from box_study import reduced_box

SERIAL = Options(backend="serial", chains_backend="serial")
CASES = ("box-coheating", "box-freefloat")
#: The truth of scripts/make_box_example.py (and of the examples' data/README.md).
TRUTH = {"k_wall": 0.14, "d_wall": 1900.0, "r_ag": 0.22, "t_w": 0.58}
#: The paper's Table 5: nominal value and uniform prior of each parameter.
TABLE_5 = {
    "k_wall": (0.125, 0.05, 0.2),
    "d_wall": (2250.0, 1500.0, 3000.0),
    "r_ag": (0.26, 0.17, 0.35),
    "t_w": (0.61, 0.5, 0.72),
}


@pytest.mark.parametrize("case", CASES)
def test_examples_validate_with_the_papers_set_up(case: str) -> None:
    assert case in examples.available()
    folder = examples.path(case)
    assert (folder / "data" / "README.md").is_file()
    study = load_study(folder)
    box = study.simulator
    assert isinstance(box, BoxSimulator)
    assert box.mode == case.removeprefix("box-")
    assert box.window_azimuth == 180.0  # window facing south
    assert box.constants == {"c_wall": 800.0, "emissivity": 0.85, "absorptivity": 0.4}
    for name, (nominal, lower, upper) in TABLE_5.items():
        p = study.parameters[name]
        assert (p.nominal, p.prior.lower, p.prior.upper) == (nominal, lower, upper), name
        assert lower < TRUTH[name] < upper, name  # the truth lies inside the prior
    measured = load_measured(study)
    # 5-minute data: 3 warm-up days, 11 training days, and the paper's 800 test values.
    assert measured.forcing.step == 300.0
    assert measured.layout.test == 800
    output = box.output_names()[0]
    assert np.isfinite(measured.outputs[output]).all()


def _folder(case: str, tmp_path: Path, moves: str = "gibbs") -> Path:
    folder = reduced_box(case, tmp_path / case)
    path = folder / "study.toml"
    text = path.read_text(encoding="utf-8")
    path.write_text(text.replace("[calibration]\n", f'[calibration]\nmoves = "{moves}"\n'))
    return folder


@pytest.fixture(scope="module", params=[(c, m) for c in CASES for m in ("gibbs", "joint")], ids=str)
def results(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Results:
    """Each box with both kinds of moves (the examples ship ``"joint"``: screened joint
    moves of the parameters, lambda*, phi and r)."""
    case, moves = request.param
    folder = _folder(case, tmp_path_factory.mktemp("box"), moves)
    return run(load_study(folder), until="predict", options=SERIAL)


def _metric(res: Results, model: str, window: str, name: str = "mse") -> float:
    assert res.predictions is not None
    m = res.predictions.metrics
    row = m[(m["model"] == model) & (m["window"] == window)]
    assert len(row) == 1
    return float(row[name].to_numpy(dtype=float)[0])


@pytest.mark.slow
def test_calibration_beats_the_nominal_box_on_training_data(results: Results) -> None:
    assert _metric(results, "calibrated", "train") < _metric(results, "nominal", "train")


@pytest.mark.slow
def test_wall_conductivity_is_found(results: Results) -> None:
    post = results.posterior
    assert post is not None
    lower, upper = post.interval(0.95)
    k = post.names.index("k_wall")
    # k_wall sets the box's heat-loss coefficient, which both phases see directly
    # (heating power against the inside-outside difference; the inside temperature's
    # response to the known heat input). The examples' error model (AR(1) with a
    # discrepancy in the likelihood, chosen by leave-one-day-out ELPD) carries the
    # EnergyPlus-versus-built-in difference. Full size (docs/case-studies.md): co-heating
    # 0.1334-0.1451, free-float 0.1366-0.1464, both covering the truth since the data
    # are made with EnergyPlus at 60 steps per hour (at 12, EnergyPlus's lagged air
    # biased the free-float k_wall by +5 %); at this reduced size free-float is only
    # held near the truth.
    if results.context.study.study.name.endswith("coheating"):
        assert lower[k] <= TRUTH["k_wall"] <= upper[k]
    else:
        mean = float(post.draws[..., k].mean())
        assert abs(mean - TRUTH["k_wall"]) < 0.08 * TRUTH["k_wall"]
        assert lower[k] - TRUTH["k_wall"] < 0.5 * (upper[k] - lower[k])
    # And it is identified: the interval is a small part of the prior's 0.05-0.2.
    assert upper[k] - lower[k] < 0.1 * (0.2 - 0.05)
