"""``bayescal screen`` end to end on the fixture wall: runs, files, page, proposal, --apply;
and screening candidates held at their nominal values by ``run``."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from bayescal.cli import main
from bayescal.config import build_simulator, load_study
from bayescal.config.edit import set_screen_flags
from bayescal.errors import ConfigError
from bayescal.pipeline import run
from bayescal.pipeline.screen import screen, screening_statistic
from bayescal.simulators.wrappers import FixedParameters
from screen_study import SERIAL, screen_study

pytest.importorskip("SALib", reason="screening needs SALib")


@pytest.fixture
def study_dir(tmp_path: Path) -> Path:
    return screen_study(tmp_path, "trajectories = 4\nbootstrap = 100\nthreshold = 0.05\n")


def test_candidates_are_held_at_nominal_by_run(study_dir: Path) -> None:
    study = load_study(study_dir)
    assert study.calibrated == ("k_cb", "cp_cb", "cp_fb")
    assert study.candidates == ("k_fb", "d_fb")
    assert list(study.priors()) == ["k_cb", "cp_cb", "cp_fb"]
    assert len(study.screening_priors()) == 5
    simulator = build_simulator(study)
    assert isinstance(simulator, FixedParameters)
    assert simulator.parameter_names == ("k_cb", "cp_cb", "cp_fb")
    assert build_simulator(study, screening=True).parameter_names[-2:] == ("k_fb", "d_fb")


def test_screen_ranks_writes_and_applies(study_dir: Path) -> None:
    study = load_study(study_dir)
    res = screen(study, options=SERIAL, apply=True)
    assert res.design.runs == 4 * 6
    assert res.runs.n_failed == 0
    folder = study_dir / "out" / "screening"
    for name in ("screening.html", "morris.csv", "proposal.json", "design.csv"):
        assert (folder / name).is_file(), name
    table = pd.read_csv(folder / "morris.csv")
    assert len(table) == 5
    # the conductivities set the steady flux: the boards (R = 1.7 m²·K/W) and the concrete (1.25)
    top = set(table.sort_values("rank")["parameter"].iloc[:2])
    assert top == {"k_fb", "k_cb"}
    # a density range of 1 kg/m³ in 116 cannot matter
    assert table.set_index("parameter").loc["d_fb", "normalised"] < 0.05
    assert "d_fb" not in res.proposal.selected
    page = (folder / "screening.html").read_text(encoding="utf-8")
    assert page.count("data:image/png;base64,") == 2
    # --apply: proposed parameters calibrated, the others screened
    raw = tomllib.loads((study_dir / "study.toml").read_text(encoding="utf-8"))["parameters"]
    assert {n for n, p in raw.items() if not p.get("screen", False)} == set(res.proposal.selected)
    assert (study_dir / "study.toml.bak").is_file()
    assert "# a candidate: the boards' conductivity" in (study_dir / "study.toml").read_text()
    # a second screen runs nothing: every run is in the cache
    again = screen(load_study(study_dir), options=SERIAL)
    assert again.runs.n_cached == again.design.runs
    np.testing.assert_allclose(again.indices[0].mu_star, res.indices[0].mu_star)


def test_screen_command(study_dir: Path) -> None:
    result = CliRunner().invoke(main, ["screen", str(study_dir), "--backend", "serial", "-q"])
    assert result.exit_code == 0, result.output
    assert "screening.html" in result.output


def test_run_needs_a_calibrated_parameter(study_dir: Path) -> None:
    set_screen_flags(study_dir / "study.toml", dict.fromkeys(["k_cb", "cp_cb", "cp_fb"], True))
    with pytest.raises(ConfigError, match="no parameter to calibrate"):
        run(load_study(study_dir), options=SERIAL)


def test_flags_are_added_where_missing(tmp_path: Path) -> None:
    path = tmp_path / "study.toml"
    path.write_text(
        "[parameters.a]\nunit = '1'\n\n[parameters.b]  # b\nscreen = true # keep me\n"
        "[parameters.b.prior]\nlower = 0\n",
        encoding="utf-8",
    )
    assert set_screen_flags(path, {"a": True, "b": False}) == ["a", "b"]
    text = path.read_text(encoding="utf-8")
    assert "unit = '1'\nscreen = true\n\n[parameters.b]" in text
    assert "screen = false  # keep me" in text
    assert set_screen_flags(path, {"a": True}) == []
    with pytest.raises(ConfigError, match=r"no \[parameters.<name>\] table"):
        set_screen_flags(path, {"c": True})


def test_a_study_file_that_cannot_be_written_is_said_in_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "study.toml"
    text = "[parameters.a]\nunit = '1'\n"
    path.write_text(text, encoding="utf-8")

    def refuse(target: Path, content: str) -> None:
        raise PermissionError(13, "Permission denied", str(target))

    monkeypatch.setattr("bayescal.config.edit.atomic_write_text", refuse)
    with pytest.raises(ConfigError, match="cannot write the screen flags") as info:
        set_screen_flags(path, {"a": True})
    assert "\n" not in str(info.value)
    assert path.read_text(encoding="utf-8") == text  # nothing lost


def test_statistics() -> None:
    sim = np.array([[1.0, 2.0, 3.0], [2.0, 2.0, 2.0]])
    obs = np.array([1.0, np.nan, 1.0])
    np.testing.assert_allclose(screening_statistic(sim, obs, np.array([0, 2]), "mean"), [2, 2])
    np.testing.assert_allclose(
        screening_statistic(sim, obs, np.array([0, 1, 2]), "rmse"), [np.sqrt(2), 1.0]
    )
