"""``scripts/iso9869_days.py``: its truths, its day counts and the Twin House's catalogue U."""

from __future__ import annotations

import datetime as dt
import sys
from pathlib import Path

import numpy as np
import pytest

from paths import SHARED_DATA

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))

import iso9869_days as script

from bayescal.config import load_study
from bayescal.data.measured import load_measured
from bayescal.iso9869 import average_method


def test_truths_are_a_latin_hypercube_over_the_middle_of_the_priors() -> None:
    study = script.wall_study()
    names = ["k_cb", "cp_cb", "cp_fb"]
    drawn = script.truths(study, 10, names)
    assert drawn == script.truths(study, 10, names)  # seeded
    for name in names:
        prior = study.parameters[name].prior
        unit = (np.array([t[name] for t in drawn]) - prior.lower) / (prior.upper - prior.lower)  # type: ignore[union-attr]
        inner = (unit - 0.1) / 0.8
        assert sorted(np.floor(inner * 10).astype(int)) == list(range(10))


def test_days_within_the_band_count_from_the_last_day_outside_it() -> None:
    # One sample a day, ΔT = 10 K, q = 10 then 5 W/m²: R(D) = 10 D / (5 D + 5), which
    # approaches 2; U against U(R = 2) is 10.2 % off on day 9 (R = 1.8) and 9.2 % on
    # day 10 (R = 1.818), and nearer after.
    q = np.array([10.0] + [5.0] * 11)
    am = average_method(np.full(12, 10.0), np.zeros(12), q, 1)
    truth = 1.0 / (0.13 + 2.0 + 0.04)
    row = script.summary(script.Wall("built", truth, am))
    error = am.u / truth - 1.0
    assert abs(error[8]) > 0.10 >= abs(error[9])
    assert row["days_10"] == 10
    assert row["days"] == 12


def test_the_built_in_wall_on_the_wall_examples_weather_ends_near_its_truth() -> None:
    walls = script.virtual_walls(script.wall_study(), 2, 0.007**0.5, "wall")
    for wall in walls:
        assert wall.am.days[-1] == 34  # data/wall.csv: 1644 half-hours from 00:00
        assert abs(wall.am.u[-1] / wall.truth_u - 1.0) < 0.02


@pytest.mark.shared_data
def test_the_twinhouse_catalogue_u_is_the_layers_of_the_shared_readme() -> None:
    if not script.TWINHOUSE_FILE.is_file():
        pytest.skip(f"{SHARED_DATA} is absent: the Annex 58 measurements are not in a fresh clone")
    study = script.twinhouse_study()
    assert study is not None
    wall = script.measured_twinhouse(study)
    r = 0.010 / 0.8 + 0.080 / 0.04 + 0.030 / 1.0 + 0.300 / 0.22 + 0.010 / 1.0
    assert wall.truth_u == pytest.approx(1.0 / (0.13 + r + 0.04))
    assert wall.am.days[-1] == 40  # 22 Aug 00:00 to 1 Oct 00:00 local time


def test_a_cut_study_has_the_training_days_asked_for(tmp_path: Path) -> None:
    study = script.wall_study()
    data = load_measured(study)
    end = script.local_midnight(data) + dt.timedelta(days=3 + 5 + 1)  # warm-up, 5, test
    folder = script.cut_study("wall", tmp_path / "cut", end, 48, None)
    cut = load_study(folder)
    layout = load_measured(cut).layout
    assert (layout.m_star, layout.test) == (5, 48)
    text = (folder / "study.toml").read_text(encoding="utf-8")
    assert "chains = 4\nburn = 500\nsamples = 500\nmax_samples = 500" in text
    assert text.count("[calibration]") == 1
