"""The truths and study edits of ``scripts/wall_truths.py``."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))

import wall_truths


def test_truths_are_a_latin_hypercube_over_the_middle_of_the_example_priors() -> None:
    from bayescal.config import load_study
    from bayescal.examples import path

    study = load_study(path("wall"))
    for name, (lo, hi) in wall_truths.PRIORS.items():
        prior = study.parameters[name].prior
        assert (prior.lower, prior.upper) == (lo, hi)  # the example's own priors
    drawn = wall_truths.truths(10)
    assert drawn == wall_truths.truths(10)  # seeded
    for name, (lo, hi) in wall_truths.PRIORS.items():
        inner = ((np.array([t[name] for t in drawn]) - lo) / (hi - lo) - 0.1) / 0.8
        assert sorted(np.floor(inner * 10).astype(int)) == list(range(10))


def test_runs_and_sequential_reach_the_wall_study(tmp_path: Path) -> None:
    from bayescal.config import load_study
    from bayescal.examples import copy_example

    folder = tmp_path / "runs"
    copy_example("wall", folder)
    assert load_study(folder).design.runs == 30
    wall_truths.set_runs(folder / "study.toml", 15)
    assert load_study(folder).design.runs == 15

    folder = tmp_path / "sequential"
    copy_example("wall", folder)
    wall_truths.set_sequential(folder / "study.toml", 7, 4, 15)
    design = load_study(folder).design
    assert (design.runs, design.sequential, design.batch, design.max_runs) == (7, True, 4, 15)
