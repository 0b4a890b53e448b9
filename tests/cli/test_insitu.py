"""``bayescal show``'s ISO 9869-1 line: on wall studies only, near the wall example's truth."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from bayescal import examples
from bayescal.cli import main
from bayescal.cli.insitu import iso9869_line
from bayescal.config import load_study
from bayescal.data.measured import load_measured
from bayescal.pipeline import run

#: The wall example's data: EnergyPlus at k_cb = 0.124, cp_cb = 845, cp_fb = 800 with
#: board conductivity 0.03157 (its data/README.md): R = 2 x 0.027 / 0.03157 + 0.15 / 0.124.
TRUE_U = 1.0 / (0.13 + 2 * 0.027 / 0.03157 + 0.150 / 0.124 + 0.04)


def _u(line: str) -> float:
    found = re.search(r"U = ([0-9.]+) W", line)
    assert found is not None, line
    return float(found.group(1))


def test_the_wall_examples_training_days_give_its_true_u_within_two_percent() -> None:
    study = load_study(examples.path("wall"))
    line = iso9869_line(study, load_measured(study))
    assert line is not None
    assert "on the 24 training days" in line
    assert _u(line) == pytest.approx(TRUE_U, rel=0.02)
    assert "first met after" in line


def test_no_line_for_a_study_that_is_not_a_wall() -> None:
    study = load_study(examples.path("box-freefloat"))
    assert iso9869_line(study, load_measured(study)) is None


def test_show_prints_it(tmp_path: Path) -> None:
    folder = examples.copy_example("wall", tmp_path / "wall")
    run(load_study(folder), until="design")  # show needs a finished stage
    result = CliRunner().invoke(main, ["show", str(folder)])
    assert result.exit_code == 0, result.output
    assert "ISO 9869-1 average method on the 24 training days: U = " in result.output
