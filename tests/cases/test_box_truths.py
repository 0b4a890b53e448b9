"""The truths of ``scripts/box_truths.py``: inside the priors' middle, one per stratum."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))

import box_truths


def test_truths_are_a_latin_hypercube_over_the_middle_of_the_priors() -> None:
    drawn = box_truths.truths(10)
    assert drawn == box_truths.truths(10)  # seeded
    for name, (lo, hi) in box_truths.PRIORS.items():
        unit = (np.array([t[name] for t in drawn]) - lo) / (hi - lo)
        inner = (unit - 0.1) / 0.8  # the middle 80 % mapped to [0, 1]
        assert np.all((inner > 0.0) & (inner < 1.0))
        # one truth in each tenth of the middle: a Latin hypercube
        assert sorted(np.floor(inner * 10).astype(int)) == list(range(10))


def test_binomial_floor_is_the_one_the_docs_quote() -> None:
    # docs/case-studies.md: at least 7 of 10 and 25 of 30 for 95 % intervals
    assert box_truths.binomial_floor(10) == 7
    assert box_truths.binomial_floor(30) == 25


def test_a_stopped_run_keeps_the_truths_it_finished(tmp_path: Path) -> None:
    import pandas as pd

    drawn = box_truths.truths(10)
    rows = [{"truth": i} | {f"{k}_true": drawn[i][k] for k in box_truths.PRIORS} for i in range(3)]
    csv = tmp_path / "box_truths_freefloat.csv"
    pd.DataFrame(rows).to_csv(csv, index=False)
    kept = box_truths.finished(csv, drawn)
    assert [r["truth"] for r in kept] == [0, 1, 2]
    # other truths (another count, hence another hypercube) are not kept
    assert box_truths.finished(csv, box_truths.truths(5)) == []
    assert box_truths.finished(tmp_path / "none.csv", drawn) == []


def test_the_discrepancy_can_be_replaced_in_both_examples(tmp_path: Path) -> None:
    from bayescal.config import load_study
    from bayescal.examples import copy_example

    for mode, output in (("coheating", "heating_power"), ("freefloat", "temp_air_in")):
        for kind, expected in (
            ("none", False),
            ("conditions", "conditions"),
            ("independent", "independent"),
            ("both", "both"),
        ):
            folder = tmp_path / f"{mode}-{kind}"
            copy_example(f"box-{mode}", folder)
            box_truths.set_discrepancy(folder / "study.toml", kind)
            study = load_study(folder)
            assert study.outputs.errors[output].discrepancy == expected


def test_layers_reach_both_examples(tmp_path: Path) -> None:
    from bayescal.config import load_study
    from bayescal.config.simulators import BoxSimulator
    from bayescal.examples import copy_example

    for mode in ("coheating", "freefloat"):
        folder = tmp_path / mode
        copy_example(f"box-{mode}", folder)
        assert load_study(folder).simulator.window_model == "transmittance"  # type: ignore[union-attr]
        box_truths.set_simulator(folder / "study.toml", box_truths.LAYERS)
        simulator = load_study(folder).simulator
        assert isinstance(simulator, BoxSimulator)
        assert (simulator.window_model, simulator.sky_model) == ("layers", "perez")
